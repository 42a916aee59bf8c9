"""Unit tests of the scenario suite's pieces: frames of peer trajectories, scoring, rows,
failure rows, the results file and the report."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from lili_odom import geometry
from lili_odom.config import ExtrinsicsConfig, pose_from_xyz_rpy
from lili_odom.suite.frames import lidar_to_base
from lili_odom.suite.jobs import ROW_KEYS, BagSpec, Job, execute
from lili_odom.suite.report import SuiteFile, markdown, validate_row
from lili_odom.suite.scoring import score
from lili_odom.suite.standings import markdown_lines, standings


def _base_trajectory(n: int = 50) -> np.ndarray:
    """A base_link trajectory in the world: an arc with some climb and roll."""
    poses = []
    for i in range(n):
        s = 0.2 * i
        poses.append(pose_from_xyz_rpy([5.0 + 4.0 * math.sin(s / 4.0), -2.0 + 4.0 * (1 - math.cos(s / 4.0)),
                                        0.3 + 0.05 * s, 0.02 * math.sin(s), 0.01 * s, 0.7 + s / 4.0]))
    return np.array(poses)


def test_lidar_to_base_recovers_base_motion_with_the_mounting():
    T_bl = ExtrinsicsConfig().T_base_lidar()  # yawed 180 deg, 0.69 m up, 0.10 m ahead
    world_base = _base_trajectory()
    # what a LiDAR odometry reports: the LiDAR's pose in the frame of its first scan
    world_lidar = world_base @ T_bl
    lidar_traj = np.linalg.inv(world_lidar[0])[None] @ world_lidar
    got = lidar_to_base(lidar_traj, T_bl)
    want = np.linalg.inv(world_base[0])[None] @ world_base
    np.testing.assert_allclose(got, want, atol=1e-9)
    np.testing.assert_allclose(got[0], np.eye(4), atol=1e-12)
    # without the mounting the positions are wrong by decimetres or more
    wrong = lidar_to_base(lidar_traj, np.eye(4))
    assert np.max(np.linalg.norm(wrong[:, :3, 3] - want[:, :3, 3], axis=1)) > 0.5


def _straight(n: int = 201, length: float = 20.0):
    stamps = np.linspace(0.0, 20.0, n)
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 0, 3] = np.linspace(0.0, length, n)
    poses[:, 1, 3] = 0.5 * np.sin(np.linspace(0.0, 3.0, n))  # not a line: alignable
    return stamps, poses


def _corner(n: int = 401):
    """10 m along x, then 10 m along y, 0.05 m per pose (orientation fixed)."""
    stamps = np.linspace(0.0, 20.0, n)
    s = np.linspace(0.0, 20.0, n)
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 0, 3] = np.minimum(s, 10.0)
    poses[:, 1, 3] = np.maximum(s - 10.0, 0.0)
    return stamps, poses


def test_score_of_a_known_scale_error():
    """Positions over-read by 1 % about the start: the SE(3) alignment keeps the rotation
    (the cross-covariance of a point set and its scaled copy is symmetric), so every metric
    has a closed form."""
    stamps, truth = _corner()
    est = truth.copy()
    est[:, :3, 3] *= 1.01
    # the estimate lives in its own frame: rotated and shifted, which the metrics ignore
    T = pose_from_xyz_rpy([3.0, -1.0, 0.5, 0.1, -0.05, 1.2])
    est = T[None] @ est
    m = score(stamps, est, stamps, truth, segment_m=10.0)
    p = truth[:, :3, 3]
    rms_spread = np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1)))
    assert m["ate_m"] == pytest.approx(0.01 * rms_spread, rel=1e-3)
    assert m["final_m"] == pytest.approx(0.01 * math.hypot(10.0, 10.0), rel=1e-6)
    # pairs 10 m of path apart start at s in [0, 10] and span the corner: chord^2 =
    # (10 - s)^2 + s^2, mean 200/3 m^2; the error is 1 % of the chord
    assert m["rpe_pct"] == pytest.approx(100 * 0.01 * math.sqrt(200 / 3) / 10.0, rel=0.02)
    assert m["distance_m"] == pytest.approx(20.0, rel=1e-9)
    assert m["matched"] == len(stamps)
    exact = score(stamps, T[None] @ truth, stamps, truth)
    assert exact["ate_m"] < 1e-9 and exact["final_m"] < 1e-9 and exact["rpe_pct"] < 1e-9


def test_score_final_error_sees_a_heading_error_at_the_start():
    stamps, truth = _straight()
    est = truth.copy()
    # the path drifts off by 2 deg while the start pose is right: anchored at the true start
    # the end is off by the chord; the ATE's alignment rotates the drift away
    R = pose_from_xyz_rpy([0, 0, 0, 0, 0, math.radians(2.0)])[:3, :3]
    est[:, :3, 3] = truth[:, :3, 3] @ R.T
    m = score(stamps, est, stamps, truth)
    end = np.linalg.norm(truth[-1, :3, 3])
    assert m["final_m"] == pytest.approx(end * 2 * math.sin(math.radians(1.0)), rel=1e-6)
    assert m["ate_m"] < 1e-6  # a rigid rotation is aligned away


def test_score_rejects_non_finite_estimates():
    stamps, truth = _straight()
    est = truth.copy()
    est[5, 0, 3] = np.nan
    with pytest.raises(ValueError):
        score(stamps, est, stamps, truth)


def _job(tmp_path, bag, method="wheels") -> Job:
    return Job(scenario="broken", split="user", kind="user", seed=0, method=method,
               bag=BagSpec(path=str(bag)), out_dir=str(tmp_path / "runs" / method),
               truth_path=str(tmp_path / "runs" / "truth.tum"))


@pytest.mark.parametrize("method", ["lili", "wheels", "kiss"])
def test_a_broken_bag_gives_a_failure_row(tmp_path, method):
    bag = tmp_path / "bad.mcap"
    bag.write_bytes(b"\x89MCAP0\r\n" + b"garbage" * 100)
    row = execute(_job(tmp_path, bag, method))
    assert set(ROW_KEYS) <= set(row)
    assert row["method"] == method and row["scenario"] == "broken"
    assert row["error"] and "\n" not in row["error"]
    assert all(row[k] is None for k in ("ate_m", "rpe_pct", "final_m", "scans_per_s"))


def test_a_missing_bag_gives_a_failure_row_through_the_local_backend(tmp_path):
    from lili_odom.suite.backends import LocalBackend

    backend = LocalBackend(jobs=1)
    try:
        row = backend.submit(_job(tmp_path, tmp_path / "nope")).result(timeout=120)
    finally:
        backend.shutdown()
    assert "no such file" in row["error"]
    assert (tmp_path / "runs" / "wheels" / "log.txt").exists()


def _row(scenario, method, ate, split="tuning", error=None, seed=0):
    row = {"scenario": scenario, "split": split, "kind": "tunnel", "seed": seed, "method": method,
           "ate_m": ate, "rpe_pct": 1.0, "final_m": 0.5, "distance_m": 20.0, "scans_per_s": 10.0,
           "degenerate_fraction": None, "scans": 100, "wall_s": 10.0}
    if error:
        row.update({k: None for k in ("ate_m", "rpe_pct", "final_m", "distance_m", "scans_per_s")})
        row["error"] = error
    return row


def test_suite_file_keeps_rows_and_resumes(tmp_path):
    path = tmp_path / "suite.json"
    f = SuiteFile(path, backend="local", command="lili-odom suite", preset="ci",
                  rpe_segment_m=10.0, scenarios={"a": {"split": "tuning"}})
    f.add(_row("a", "lili", 0.1))
    f.add(_row("a", "none", None, error="boom"))
    doc = json.loads(path.read_text())  # on disk after every row
    assert doc["backend"] == "local" and len(doc["rows"]) == 2
    for r in doc["rows"]:
        validate_row(r)
    again = SuiteFile(path, backend="local", command="x", preset="ci", rpe_segment_m=10.0,
                      scenarios={}, resume=True)
    assert again.finished_keys() == {("a", 0, "lili")}  # the failed row is run again
    with pytest.raises(ValueError):
        validate_row({"scenario": "a"})


def test_markdown_reports_splits_apart_and_bolds_the_best(tmp_path):
    rows = [_row("t1", "lili", 0.1), _row("t1", "none", 2.0), _row("t1", "genz", None, error="crashed"),
            _row("v1", "lili", 0.5, split="validation"), _row("v1", "none", 0.3, split="validation")]
    doc = {"backend": "local", "command": "lili-odom suite --preset ci", "preset": "ci",
           "rpe_segment_m": 10.0, "rows": rows,
           "scenarios": {"t1": {"split": "tuning"}, "v1": {"split": "validation"}}}
    md = markdown(doc)
    tuning, validation = md.index("## Tuning"), md.index("## Validation")
    assert tuning < validation
    assert "| t1 | 20.0 | **0.100** | 2.000 | – |" in md
    v_table = md[md.index("### v1"):]
    assert v_table.index("| **none** | 0.300") < v_table.index("| lili | 0.500")
    assert "1 failed: crashed" in md
    assert "`lili-odom suite --preset ci`" in md


def test_standings_compare_with_the_best_lidar_peer_and_the_floors():
    rows = [_row("a", "lili", 0.05, seed=1), _row("a", "genz", 0.06, seed=1),
            _row("a", "kiss", 0.04, seed=1, error="crashed"), _row("a", "wheels", 0.5, seed=1),
            _row("a", "none", 0.03, seed=1),
            _row("a", "lili", 0.2, seed=2), _row("a", "rko", 0.1, seed=2), _row("a", "kiss", 0.3, seed=2),
            _row("b", "lili", None, seed=0, error="crashed"), _row("b", "genz", 1.0, seed=0),
            _row("c", "genz", 1.0, seed=0)]  # no lili row: no standing
    first, second, failed = standings(rows)
    assert (first.best_peer, first.best_peer_ate_m) == ("genz", 0.06)  # the failed kiss is not best
    assert first.ahead_of_peers and not first.ahead_of_floors  # none is better
    assert first.share_pct == pytest.approx(0.25)
    assert (second.best_peer, second.ahead_of_peers, second.ahead_of_floors) == ("rko", False, True)
    assert not failed.ahead_of_peers and not failed.ahead_of_floors and failed.share_pct is None
    lines = markdown_lines([first, second, failed], max_share_pct=0.5)
    assert lines[-1].startswith("`lili` is ahead of the best LiDAR peer on 1 of 3 runs, within 0.5 % "
                                "of the distance on 1 of 3 and ahead of wheel odometry alone and "
                                "`none` on 1 of 3")
    assert "| a | 2 | 20.0 | 0.200 | rko 0.100 | 2.00 | 1.00 | – | **no** | **no** | yes |" in lines


def test_markdown_lists_every_run_and_where_lili_stands():
    rows = [_row("v", "lili", 0.02, split="validation", seed=s) for s in (1, 2)]
    rows += [_row("v", "genz", 0.03, split="validation", seed=1),
             _row("v", "genz", 0.01, split="validation", seed=2)]
    md = markdown({"rows": rows, "scenarios": {"v": {"split": "validation"}}})
    assert "| v | 20.0 | **0.020** | **0.020** |" in md  # the mean over the seeds
    assert "| v | 2 | 20.0 | 0.020 | **0.010** |" in md
    assert "ahead of the best LiDAR peer on 1 of 2 runs" in md


def test_a_hanging_job_is_stopped_and_reported(tmp_path):
    """A job that never finishes (its bag's metadata is a FIFO nobody writes) is stopped at the
    timeout; its row says so and its process is gone."""
    import os

    from lili_odom.suite.backends import LocalBackend

    bag = tmp_path / "hanging"
    bag.mkdir()
    os.mkfifo(bag / "metadata.yaml")
    backend = LocalBackend(jobs=1, timeout_s=5.0)
    try:
        row = backend.submit(_job(tmp_path, bag)).result(timeout=120)
    finally:
        backend.shutdown()
    assert row["error"] == "timed out after 5 s"
    assert not backend._running
