"""The offline runner on the committed CI bag: same pipeline as the node, outputs and metrics."""
import json
from pathlib import Path

import numpy as np
import pytest

from lili_odom.cli import main

BAG = Path(__file__).resolve().parents[1] / "bags" / "tunnel_entrance_32x256"


@pytest.mark.skipif(not BAG.is_dir(), reason="CI bag missing")
def test_run_none_tracks_the_truth_and_writes_every_output(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", str(BAG), "--method", "none", "--out", str(out), "--no-progress"]) == 0
    for name in ("estimate.tum", "truth.tum", "metrics.json", "trajectory.png", "odometry/metadata.yaml"):
        assert (out / name).exists(), name
    result = json.loads((out / "metrics.json").read_text())
    assert result["scans_processed"] >= 140  # 150 scans in the bag, the first initialises
    m = result["metrics"]
    assert m["path_length_m"] > 10.0
    # stated bound for this 12.6 m entrance piece at 32 x 256 beams (measured 0.16 m)
    assert m["ate_rmse_m"] < 0.5
    estimate_lines = (out / "estimate.tum").read_text().splitlines()
    assert len(estimate_lines) == result["scans_processed"]
    assert len(estimate_lines[0].split()) == 8
    scans = np.genfromtxt(out / "scans.csv", delimiter=",", names=True)
    assert len(scans) == result["scans_processed"]
    # the online wheel distance scale per scan: 1 until calibrated, always within its range
    assert np.all((scans["wheel_scale"] >= 0.8) & (scans["wheel_scale"] <= 1.25))
    # without a detector no scan has a subspace, so none has one of its origins
    for name in ("weak_directions", "reused", "screened"):
        assert np.all(scans[name] == 0), name


def test_scan_rows_say_where_the_subspace_came_from():
    from lili_odom.degeneracy.result import DegeneracyResult
    from lili_odom.evaluation.runner import _origin

    assert _origin(None) == (0, 0, 0)
    det = DegeneracyResult(method="lili", pose=np.eye(4), basis_scaled=np.eye(6)[:3],
                           characteristic_length=10.0, details={"weak": 2, "reused": True})
    assert _origin(det) == (2, 1, 0)
    screened = DegeneracyResult(method="lili", pose=np.eye(4), basis_scaled=np.zeros((0, 6)),
                                characteristic_length=10.0, details={"screened": True})
    assert _origin(screened) == (0, 0, 1)


def test_run_missing_bag_is_a_one_line_error(tmp_path, capsys):
    rc = main(["run", str(tmp_path / "nope"), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert rc != 0 and len(err.splitlines()) == 1


@pytest.mark.skipif(not BAG.is_dir(), reason="CI bag missing")
def test_scans_csv_and_tilt_diagnostics_show_the_bias_taken_for_a_tilt(tmp_path):
    """scans.csv carries the registration's orientation and the estimated biases, and
    ``run_diagnostics.tilt_series`` finds what the start's gravity alignment does with an
    accelerometer bias b at rest: it reads as a tilt of b / g (x error b_y / g, y error
    -b_x / g, IMU axes = base_link axes here)."""
    from lili_odom.evaluation.run_diagnostics import tilt_series, tilt_table

    out = tmp_path / "run"
    assert main(["run", str(BAG), "--method", "none", "--out", str(out), "--no-progress",
                 "--max-scans", "30"]) == 0
    scans = np.genfromtxt(out / "scans.csv", delimiter=",", names=True)
    q = np.stack([scans[f"icp_q{a}"] for a in "xyzw"], axis=1)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6)
    for name in ("accel_bias_x", "accel_bias_y", "accel_bias_z", "gyro_bias_x", "gravity_tilt_x"):
        assert np.isfinite(scans[name]).all(), name
    d = tilt_series(out, trial=3, seed=0)  # how the bag was made (bags/README.md)
    b = d["true_bias"][0]
    expected = np.degrees([b[1], -b[0]]) / 9.80665
    assert np.abs(expected).max() > 0.2  # the seed's bias is large enough to be seen
    np.testing.assert_allclose(d["fused"][0, :2], expected, atol=0.1)
    lines = tilt_table(out, 1.0, 3, 0)
    assert sum(line.startswith("| ") for line in lines) >= 3


@pytest.mark.skipif(not BAG.is_dir(), reason="CI bag missing")
def test_a_wheel_topic_missing_from_the_bag_is_named_with_the_candidates(tmp_path, caplog):
    cfg = tmp_path / "wheels.yaml"
    cfg.write_text("lili_odom:\n  ros__parameters:\n    wheel_topic: /wheels\n")
    rc = main(["run", str(BAG), "--method", "none", "--out", str(tmp_path / "o"),
               "--config", str(cfg), "--max-scans", "3", "--no-progress"])
    assert rc == 0
    notes = [r.getMessage() for r in caplog.records if "/wheels" in r.getMessage()]
    assert len(notes) == 1, caplog.text
    assert "IMU alone" in notes[0] and "/platform/odom (set wheel_topic)" in notes[0]
    assert "/ground_truth/odom" not in notes[0]
    assert not any("/ouster/imu" in r.getMessage() for r in caplog.records)


def test_icp_quaternions_are_converted_in_one_call_with_nan_for_unusable_poses():
    from scipy.spatial.transform import Rotation

    from lili_odom.evaluation.runner import _quaternions

    R = Rotation.from_euler("xyz", [0.1, -0.2, 0.3])
    T = np.eye(4)
    T[:3, :3] = R.as_matrix()
    bad = T.copy()
    bad[0, 0] = np.nan
    q = _quaternions([T, None, bad, np.eye(3), np.eye(4)])
    assert q.shape == (5, 4)
    np.testing.assert_allclose(q[0], R.as_quat(), atol=1e-12)
    assert np.isnan(q[1:4]).all()
    np.testing.assert_allclose(q[4], [0, 0, 0, 1], atol=1e-12)
    assert _quaternions([]).shape == (0, 4)
