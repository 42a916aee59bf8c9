"""Bad bags and bad parameters on the command line (issue #6): ``lili-odom run`` and
``lili-odom play`` exit non-zero with a single-line message on stderr, never a traceback.

Every case runs ``lili_odom.cli.main`` in-process (an exception escaping it fails the test
with its traceback); a representative subset also runs the real entry point in a subprocess
(each costs ~2.5 s of imports on a 2-core machine).
"""
from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_types_from_msg

from lili_odom import messages as M
from lili_odom.bagio.factory import RosbagsFactory, jazzy_typestore

ROOT = Path(__file__).resolve().parents[1]
CI_BAG = ROOT / "bags" / "tunnel_entrance_32x256"
F = RosbagsFactory()


def in_process(*args: str) -> subprocess.CompletedProcess:
    """``lili-odom ARGS`` through ``cli.main`` in this process (stderr captured)."""
    from lili_odom.cli import main

    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        rc = main([str(a) for a in args])
    return subprocess.CompletedProcess(list(args), rc, out.getvalue(), err.getvalue())


def lili_odom(*args: str, timeout: float = 120.0, subprocess_run: bool = False
              ) -> subprocess.CompletedProcess:
    if not subprocess_run:
        return in_process(*args)
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(150 + os.getpid() % 50)  # never talk to anything else
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return subprocess.run([sys.executable, "-m", "lili_odom.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, env=env, cwd=ROOT)


def assert_one_line_error(proc: subprocess.CompletedProcess, command: str, *needles: str) -> str:
    err = proc.stderr.strip()
    assert proc.returncode != 0, (proc.returncode, proc.stdout[-2000:], err[-2000:])
    assert "Traceback" not in proc.stderr, proc.stderr[-4000:]
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err[-4000:]
    assert lines[0].startswith(f"lili-odom {command}: error:"), lines[0]
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


def run_cmd(bag, out: Path, *extra: str, subprocess_run: bool = False
            ) -> subprocess.CompletedProcess:
    return lili_odom("run", bag, "--method", "none", "--out", out, "--no-progress",
                     "--max-scans", "5", *extra, subprocess_run=subprocess_run)


# --------------------------------------------------------------------------------------------
# bags


def _ci_mcap() -> Path:
    if not CI_BAG.is_dir():
        pytest.skip("CI bag missing")
    return next(CI_BAG.glob("*.mcap"))


def _write_bag(path: Path, connections: dict[str, str], messages, typestore=None) -> Path:
    ts = typestore or F.typestore
    w = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    w.open()
    conns = {t: w.add_connection(t, ty, typestore=ts) for t, ty in connections.items()}
    for topic, t, data in messages:
        w.write(conns[topic], int(t * 1e9), data)
    w.close()
    return path


def _imu_bytes(t: float) -> bytes:
    return F.serialize(F.new("sensor_msgs/msg/Imu", header=M.header_msg(F, t, "os_imu")))


@pytest.fixture(scope="module")
def bad_bags(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("bags")
    data = _ci_mcap().read_bytes()
    bags = {}
    for name, n in (("truncated_60pct", int(len(data) * 0.6)), ("truncated_1k", 1000),
                    ("truncated_header", 5)):
        bags[name] = d / f"{name}.mcap"
        bags[name].write_bytes(data[:n])
    rng = np.random.default_rng(0)
    bags["random_bytes"] = d / "random.mcap"
    bags["random_bytes"].write_bytes(rng.integers(0, 256, 100_000, dtype=np.uint8).tobytes())
    bags["mcap_magic_then_garbage"] = d / "magic.mcap"
    bags["mcap_magic_then_garbage"].write_bytes(data[:8] + bytes(5000) + data[-8:])
    bags["empty_file"] = d / "empty.mcap"
    bags["empty_file"].write_bytes(b"")
    corrupt = bytearray(data)
    mid = len(corrupt) // 4
    corrupt[mid:mid + 4096] = bytes(4096)  # a zeroed block inside a compressed chunk
    bags["corrupt_chunk"] = d / "corrupt.mcap"
    bags["corrupt_chunk"].write_bytes(bytes(corrupt))
    (d / "dir_without_metadata").mkdir()
    bags["dir_without_metadata"] = d / "dir_without_metadata"
    meta_dir = d / "bad_metadata"
    meta_dir.mkdir()
    (meta_dir / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n")
    bags["bad_metadata"] = meta_dir
    bags["nonexistent"] = d / "no_such_bag"
    bags["not_a_bag_suffix"] = d / "notes.txt"
    bags["not_a_bag_suffix"].write_text("hello")
    return bags


RUN_CASES = ["truncated_60pct", "truncated_1k", "truncated_header", "random_bytes",
             "mcap_magic_then_garbage", "empty_file", "corrupt_chunk", "dir_without_metadata",
             "bad_metadata", "nonexistent", "not_a_bag_suffix"]


@pytest.mark.parametrize("case", RUN_CASES)
def test_run_bad_bag(case, bad_bags, tmp_path):
    proc = run_cmd(bad_bags[case], tmp_path / "out", "--max-scans", "200")
    line = assert_one_line_error(proc, "run")
    assert bad_bags[case].name in line


@pytest.mark.parametrize("case", ["truncated_60pct", "truncated_1k", "random_bytes",
                                  "empty_file", "nonexistent", "bad_metadata"])
def test_play_bad_bag(case, bad_bags):
    """Bags that cannot be opened (no ROS node is created in this process)."""
    proc = lili_odom("play", bad_bags[case], "--fast", "--delay", "0", "--quiet")
    assert_one_line_error(proc, "play", bad_bags[case].name)


@pytest.mark.parametrize("command, case", [("run", "truncated_60pct"), ("run", "random_bytes"),
                                           ("run", "nonexistent"), ("play", "truncated_1k"),
                                           ("play", "corrupt_chunk")])
def test_entry_point_in_a_subprocess(command, case, bad_bags, tmp_path):
    if command == "run":
        proc = run_cmd(bad_bags[case], tmp_path / "out", subprocess_run=True)
    else:  # corrupt_chunk opens: play starts publishing (own ROS domain) and then fails
        proc = lili_odom("play", bad_bags[case], "--fast", "--quiet", "--delay", "0",
                         subprocess_run=True)
    assert proc.returncode == 2
    assert_one_line_error(proc, command, bad_bags[case].name)


@pytest.fixture(scope="module")
def imu_only_bag(tmp_path_factory) -> Path:
    return _write_bag(tmp_path_factory.mktemp("imu_only") / "bag",
                      {"/ouster/imu": "sensor_msgs/msg/Imu"},
                      [("/ouster/imu", 10.0 + 0.01 * k, _imu_bytes(10.0 + 0.01 * k))
                       for k in range(10)])


def test_run_missing_lidar_topic(imu_only_bag, tmp_path):
    proc = run_cmd(imu_only_bag, tmp_path / "out")
    assert_one_line_error(proc, "run", "required topic /ouster/points", "/ouster/imu")


def test_play_missing_topic(imu_only_bag):
    proc = lili_odom("play", imu_only_bag, "--topics", "/ouster/points", "--fast", "--quiet")
    assert_one_line_error(proc, "play", "/ouster/points")


def test_run_lidar_topic_of_the_wrong_type(tmp_path):
    bag = _write_bag(tmp_path / "bag", {"/ouster/points": "sensor_msgs/msg/Imu"},
                     [("/ouster/points", 10.0, _imu_bytes(10.0))])
    proc = run_cmd(bag, tmp_path / "out")
    assert_one_line_error(proc, "run", "/ouster/points", "sensor_msgs/msg/Imu",
                          "sensor_msgs/msg/PointCloud2")


def _unknown_type_bag(path: Path, topic: str) -> Path:
    ts = jazzy_typestore()
    ts.register(get_types_from_msg("float64 value\nstring note\n", "acme_msgs/msg/Gizmo"))
    Gizmo = ts.types["acme_msgs/msg/Gizmo"]
    items = [(topic, 10.0 + 0.1 * k, ts.serialize_cdr(Gizmo(value=float(k), note="x"),
                                                       "acme_msgs/msg/Gizmo"))
             for k in range(5)]
    return _write_bag(path, {topic: "acme_msgs/msg/Gizmo"}, items, typestore=ts)


def test_run_unknown_message_type_on_the_lidar_topic(tmp_path):
    bag = _unknown_type_bag(tmp_path / "bag", "/ouster/points")
    proc = run_cmd(bag, tmp_path / "out")
    assert_one_line_error(proc, "run", "acme_msgs/msg/Gizmo")


def test_run_ignores_an_unknown_type_on_another_topic(tmp_path):
    """An extra topic of a type nobody knows is not read; the run fails only for lacking
    scans (this bag has none), still with one line."""
    ts = jazzy_typestore()
    ts.register(get_types_from_msg("float64 value\n", "acme_msgs/msg/Gizmo"))
    Gizmo = ts.types["acme_msgs/msg/Gizmo"]
    bag = _write_bag(tmp_path / "bag", {"/acme/gizmo": "acme_msgs/msg/Gizmo",
                                        "/ouster/points": "sensor_msgs/msg/PointCloud2"},
                     [("/acme/gizmo", 10.0, ts.serialize_cdr(Gizmo(value=1.0),
                                                             "acme_msgs/msg/Gizmo"))],
                     typestore=ts)
    proc = run_cmd(bag, tmp_path / "out")
    assert_one_line_error(proc, "run", "no scan could be processed")


def test_play_unknown_message_type(tmp_path):
    pytest.importorskip("rclpy")
    bag = _unknown_type_bag(tmp_path / "bag", "/acme/gizmo")
    proc = lili_odom("play", bag, "--fast", "--delay", "0", "--quiet", "--clock-hz", "0",
                     subprocess_run=True)  # creates a ROS node: isolated in its own process
    assert_one_line_error(proc, "play", "none of the bag's message types")


def test_run_output_directory_is_a_file(tmp_path, imu_only_bag):
    out = tmp_path / "a_file"
    out.write_text("x")
    proc = run_cmd(CI_BAG if CI_BAG.is_dir() else imu_only_bag, out)
    assert_one_line_error(proc, "run", "a_file")


def test_run_output_directory_holds_a_run(tmp_path, imu_only_bag):
    (tmp_path / "out" / "odometry").mkdir(parents=True)
    proc = run_cmd(imu_only_bag, tmp_path / "out")
    assert_one_line_error(proc, "run", "already holds a run")


# --------------------------------------------------------------------------------------------
# parameters


def _params_file(path: Path, body: str) -> Path:
    path.write_text("lili_odom:\n  ros__parameters:\n" + body)
    return path


@pytest.mark.parametrize("body, needles", [
    ("    pipeline:\n      fusion:\n        imu:\n          max_gap_s: -0.5\n",
     ["pipeline.fusion.imu.max_gap_s", "(0, 10]", "-0.5"]),
    ("    pipeline:\n      scan_matcher:\n        max_range: -5.0\n",
     ["pipeline.scan_matcher.max_range", "(0, 1000]", "-5.0"]),
    ("    pipeline:\n      scan_matcher:\n        min_range: 150.0\n",
     ["pipeline.scan_matcher.min_range", "max_range", "150.0"]),
    ("    pipeline:\n      lili:\n        k: 1\n", ["pipeline.lili.k", "[2, 100]", "got 1"]),
    ("    pipeline:\n      lili:\n        tau_displacement: 1.5\n",
     ["pipeline.lili.tau_displacement", "(0, 1)", "1.5"]),
    ("    pipeline:\n      fusion:\n        wheel:\n          yaw_floor: 0.0\n",
     ["pipeline.fusion.wheel.yaw_floor", "(0, 1000]", "0.0"]),
    ("    pipeline:\n      fusion:\n        wheel_weak_scale: 2.0\n",
     ["pipeline.fusion.wheel_weak_scale", "[0, 1]", "2.0"]),
    ("    pipeline:\n      fusion:\n        lidar:\n          restriction: squash\n",
     ["pipeline.fusion.lidar.restriction", "marginalize, project", "squash"]),
    ("    pipeline:\n      fusion:\n        imu:\n          gravity: 98.1\n",
     ["pipeline.fusion.imu.gravity", "[9.7, 9.9]", "98.1"]),
    ("    pipeline:\n      zhang:\n        num_neighbors: 0\n",
     ["pipeline.zhang.num_neighbors", "[3, 100]", "got 0"]),
    ("    pipeline:\n      hessian:\n        min_planarity: -1.0\n",
     ["pipeline.hessian.min_planarity", "[0, 1]"]),
    ("    pipeline:\n      sweep_duration: 0.0\n", ["pipeline.sweep_duration", "(0, 1]"]),
    ("    pipeline:\n      min_points: 3\n", ["pipeline.min_points", "[10,"]),
    ("    map_publish_period_s: -1.0\n", ["map_publish_period_s", "(0, 3600]"]),
    ("    pipeline:\n      fusion:\n        max_speed: .nan\n",
     ["pipeline.fusion.max_speed", "finite number"]),
    ("    pipeline:\n      method: magic\n", ["pipeline.method", "lili", "magic"]),
    ("    pipeline:\n      lili:\n        k: 2.5\n", ["pipeline.lili.k", "integer"]),
    ("    publish_tf: maybe\n", ["publish_tf", "true or false"]),
    ("    no_such_parameter: 1\n", ["no_such_parameter"]),
    ("    extrinsics:\n      base_to_sensor: [0, 0, 1]\n", ["extrinsics.base_to_sensor", "6"]),
])
def test_run_rejects_invalid_parameters_with_name_and_range(body, needles, tmp_path,
                                                            imu_only_bag):
    cfg = _params_file(tmp_path / "params.yaml", body)
    proc = run_cmd(imu_only_bag, tmp_path / "out", "--config", cfg)
    assert_one_line_error(proc, "run", "configuration", *needles)
    assert not (tmp_path / "out").exists()  # rejected before anything was written


def test_invalid_parameter_in_a_subprocess(tmp_path, imu_only_bag):
    cfg = _params_file(tmp_path / "params.yaml",
                       "    pipeline:\n      fusion:\n        max_rate: -1.0\n")
    proc = run_cmd(imu_only_bag, tmp_path / "out", "--config", cfg, subprocess_run=True)
    assert proc.returncode == 2
    assert_one_line_error(proc, "run", "pipeline.fusion.max_rate must be in (0, 1000] rad/s, "
                                       "got -1.0")


@pytest.mark.parametrize("text, needle", [
    ("lili_odom:\n  ros__parameters:\n    pipeline: {method: [unclosed\n", "not a valid YAML"),
    ("- just\n- a list\n", "parameter file"),
    ("lili_odom: 5\n", "must be a mapping"),
    ("lili_odom:\n  ros__parameters: [1, 2]\n", "must be a mapping"),
])
def test_run_rejects_malformed_parameter_files(text, needle, tmp_path, imu_only_bag):
    cfg = tmp_path / "params.yaml"
    cfg.write_text(text)
    proc = run_cmd(imu_only_bag, tmp_path / "out", "--config", cfg)
    assert_one_line_error(proc, "run", "configuration", needle)


def test_run_missing_or_binary_parameter_file(tmp_path, imu_only_bag):
    proc = run_cmd(imu_only_bag, tmp_path / "out", "--config", tmp_path / "nope.yaml")
    assert_one_line_error(proc, "run", "configuration", "nope.yaml")
    binary = tmp_path / "binary.yaml"
    binary.write_bytes(bytes(range(256)) * 4)
    proc = run_cmd(imu_only_bag, tmp_path / "out2", "--config", binary)
    assert_one_line_error(proc, "run", "configuration")


def test_every_default_is_inside_its_range():
    from lili_odom.config import PARAMETER_RANGES, NodeConfig, flatten

    NodeConfig().validate()
    names = flatten(NodeConfig())
    assert set(PARAMETER_RANGES) <= set(names), set(PARAMETER_RANGES) - set(names)
