"""Real Ouster recordings (OS1-128, OS0-128 from the Ouster SDK's tests): the clouds in the
ouster-ros layouts parse, the odometry runs straight from the recording, a real scan pair
registers to the SDK's reference motion and the outdoor scene is constrained.

Skips when ``../shared`` (the recordings; ``LILI_ODOM_SHARED`` names another place) or the
Ouster SDK is absent.
"""
from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np
import pytest

SHARED = Path(os.environ.get("LILI_ODOM_SHARED", Path(__file__).resolve().parents[2] / "shared"))
DATA = SHARED / "data" / "ouster"
OS1 = DATA / "OS-1-128_v2.3.0_1024x10_lb_n3.pcap"
OS1_META = DATA / "OS-1-128_v2.3.0_1024x10.json"
OS1_POSES = DATA / "OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt"
OS0 = DATA / "OS-0-128-U1_v2.3.0_1024x10.pcap"
OS0_META = DATA / "OS-0-128-U1_v2.3.0_1024x10.json"

if not OS1.is_file():
    pytest.skip("the shared Ouster recordings are absent", allow_module_level=True)
pytest.importorskip("ouster.sdk")

from lili_odom.errors import UserError  # noqa: E402
from lili_odom.io.ouster import LAYOUTS, OusterRecording  # noqa: E402
from lili_odom.pointcloud2 import parse_cloud  # noqa: E402


@pytest.fixture(scope="module")
def os1_frames():
    """Per layout: the OS1 recording's clouds (rosbags PointCloud2)."""
    out = {}
    for layout in LAYOUTS:
        rec = OusterRecording(OS1, OS1_META, layout=layout)
        out[layout] = [m.msg for m in rec.clouds()]
    return out


def test_every_ouster_ros_layout_parses_to_the_same_points(os1_frames):
    assert len(os1_frames["original"]) == 3
    parsed = {k: parse_cloud(v[0]) for k, v in os1_frames.items()}
    orig_msg = os1_frames["original"][0]
    assert (orig_msg.height, orig_msg.width, orig_msg.point_step) == (128, 1024, 48)
    assert orig_msg.header.frame_id == "os_lidar" and orig_msg.row_step == 48 * 1024
    names = [(f.name, f.offset, f.datatype) for f in orig_msg.fields]
    assert names == [("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("intensity", 16, 7), ("t", 20, 6),
                     ("reflectivity", 24, 4), ("ring", 26, 4), ("ambient", 28, 4),
                     ("range", 32, 6)]
    rec = np.frombuffer(bytes(orig_msg.data), dtype=np.uint8).reshape(-1, 48)
    assert not rec[:, 12:16].any() and not rec[:, 36:48].any()  # padding is zero
    orig = parsed["original"]
    assert 100_000 < len(orig.xyz) < 110_000  # about 107 k returns (README)
    rng = np.linalg.norm(orig.xyz, axis=1)
    assert 8.0 < np.median(rng) < 14.0  # median range about 11 m
    # the range field (mm) is the distance from the lidar origin's beam offset: close to |xyz|
    assert np.median(np.abs(orig.range * 1e-3 - rng)) < 0.05
    assert orig.times.min() >= 0.0 and 0.09 < orig.times.max() <= 0.1  # a 10 Hz sweep
    assert set(np.unique(orig.ring)) <= set(range(128)) and len(np.unique(orig.ring)) > 100
    for layout in ("xyz", "xyzi", "xyzir"):
        msg = os1_frames[layout][0]
        assert msg.point_step == LAYOUTS[layout][0] and (msg.height, msg.width) == (128, 1024)
        np.testing.assert_array_equal(parsed[layout].xyz, orig.xyz)
        assert parsed[layout].times is None  # compact layouts carry no per-point time
    np.testing.assert_array_equal(parsed["xyzir"].ring, orig.ring)


def test_os0_wide_field_of_view_frame_parses():
    rec = OusterRecording(OS0, OS0_META)
    clouds = [m.msg for m in rec.clouds()]
    assert len(clouds) == 1
    p = parse_cloud(clouds[0])
    assert len(p.xyz) > 50_000
    elevation = np.degrees(np.arcsin(p.xyz[:, 2] / np.linalg.norm(p.xyz, axis=1)))
    assert elevation.max() - elevation.min() > 60.0  # OS0: 90 deg vertical field of view


def test_recording_messages_come_in_arrival_order_with_imu():
    rec = OusterRecording(OS1, OS1_META)
    items = list(rec)
    topics = [m.topic for m in items]
    assert topics.count("/ouster/points") == 3 and topics.count("/ouster/imu") >= 25
    assert rec.message_count == len(items)
    imu = [m.msg for m in items if m.topic == "/ouster/imu"]
    acc = np.array([[m.linear_acceleration.x, m.linear_acceleration.y,
                     m.linear_acceleration.z] for m in imu])
    assert 9.0 < np.median(np.linalg.norm(acc, axis=1)) < 11.5  # m/s^2, gravity
    assert imu[0].header.frame_id == "os_imu" and imu[0].orientation_covariance[0] == -1.0
    # a cloud is released when its sweep has ended (stamp + 0.1 s), as a driver does
    arrival = [m.stamp + (0.1 if m.topic == "/ouster/points" else 0.0) for m in items]
    assert arrival == sorted(arrival)


def _reference_poses() -> np.ndarray:
    rows = np.loadtxt(OS1_POSES).reshape(-1, 3, 4)
    return np.concatenate([rows, np.tile([[[0.0, 0.0, 0.0, 1.0]]], (len(rows), 1, 1))], axis=1)


def test_run_from_the_recording_registers_the_pair_and_saves_the_map(tmp_path, capsys):
    from lili_odom.cli import main
    from lili_odom.io.cloud_files import load_points

    out = tmp_path / "run"
    code = main(["run", str(OS1), "--metadata", str(OS1_META), "--out", str(out),
                 "--max-scans", "2", "--no-progress", "--save-map", str(tmp_path / "map.pcd")])
    assert code == 0
    printed = capsys.readouterr().out
    assert f"map: {(tmp_path / 'map.pcd').resolve()}" in printed
    est = np.loadtxt(out / "estimate.tum", ndmin=2)
    assert len(est) == 2
    # base_link is os_sensor here, the frame of the SDK's reference poses (frame 0 = identity)
    truth = _reference_poses()
    motion = est[1, 1:4] - est[0, 1:4]
    assert np.linalg.norm(motion - truth[1, :3, 3]) < 0.03, (motion, truth[1, :3, 3])
    with open(out / "scans.csv") as f:
        dims = [int(r["dimension"]) for r in csv.DictReader(f)]
    assert dims == [0, 0]  # an outdoor scene: constrained
    assert (out / "metrics.json").is_file() and (out / "odometry").is_dir()
    saved = load_points(tmp_path / "map.pcd")
    assert len(saved) > 10_000 and np.isfinite(saved).all()


def test_recording_errors_are_one_line_user_errors(tmp_path):
    with pytest.raises(UserError, match="needs --metadata"):
        OusterRecording(OS1)
    with pytest.raises(UserError, match="no such file"):
        OusterRecording(tmp_path / "missing.pcap", OS1_META)
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(UserError, match="cannot open the recording"):
        OusterRecording(OS1, bad)
