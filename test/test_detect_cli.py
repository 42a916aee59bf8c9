"""``lili-odom detect`` end to end on a small plane, and its error handling."""
import json
from pathlib import Path

import numpy as np
import pytest

from conftest import plane_pair
from lili_odom.cli import main


def _write(tmp_path):
    ref, scan, T = plane_pair(seed=3)
    np.save(tmp_path / "ref.npy", ref)
    np.save(tmp_path / "scan.npy", scan)
    np.savetxt(tmp_path / "init.txt", T)
    return T


def test_detect_json_contract(tmp_path, capsys):
    T = _write(tmp_path)
    rc = main(["detect", "--reference", str(tmp_path / "ref.npy"), "--scan", str(tmp_path / "scan.npy"),
               "--initial-pose", str(tmp_path / "init.txt"), "--method", "lili", "--json", "--raw"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)  # exactly one JSON object
    assert out["method"] == "lili" and out["dimension"] == 3
    assert out["voxel_size"] is None and out["scan_points"] == 4000
    assert np.asarray(out["pose"]).shape == (4, 4)
    assert abs(out["pose"][2][3] - T[2, 3]) < 0.01
    assert len(out["basis"]) == 3
    assert all(len(b["translation"]) == 3 and len(b["rotation"]) == 3 for b in out["basis"])
    assert out["runtime_s"] > 0


def test_detect_reads_ascii_pcd_and_ply(tmp_path, capsys):
    T = _write(tmp_path)
    ref = np.load(tmp_path / "ref.npy")
    with open(tmp_path / "ref.pcd", "w") as f:
        f.write("VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
                f"WIDTH {len(ref)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(ref)}\nDATA ascii\n")
        np.savetxt(f, ref, fmt="%.6f")
    scan = np.load(tmp_path / "scan.npy")
    with open(tmp_path / "scan.ply", "w") as f:
        f.write(f"ply\nformat ascii 1.0\nelement vertex {len(scan)}\nproperty float x\n"
                "property float y\nproperty float z\nend_header\n")
        np.savetxt(f, scan, fmt="%.6f")
    rc = main(["detect", "--reference", str(tmp_path / "ref.pcd"), "--scan", str(tmp_path / "scan.ply"),
               "--initial-pose", str(tmp_path / "init.txt"), "--json", "--raw"])
    assert rc == 0
    assert json.loads(capsys.readouterr().out)["dimension"] == 3


def test_detect_bad_files_exit_nonzero_with_one_line(tmp_path, capsys):
    _write(tmp_path)
    (tmp_path / "bad.npy").write_bytes(b"not numpy")
    (tmp_path / "bad_pose.txt").write_text("1 2 3\n")
    cases = [
        ["--reference", str(tmp_path / "missing.npy"), "--scan", str(tmp_path / "scan.npy")],
        ["--reference", str(tmp_path / "bad.npy"), "--scan", str(tmp_path / "scan.npy")],
        ["--reference", str(tmp_path / "ref.npy"), "--scan", str(tmp_path / "scan.xyz")],
        ["--reference", str(tmp_path / "ref.npy"), "--scan", str(tmp_path / "scan.npy"),
         "--initial-pose", str(tmp_path / "bad_pose.txt")],
    ]
    for args in cases:
        rc = main(["detect", *args])
        err = capsys.readouterr().err.strip()
        assert rc != 0
        assert len(err.splitlines()) == 1 and "error" in err


def test_detect_voxelises_as_the_odometry_unless_raw(tmp_path, capsys):
    from lili_odom.sim.shapes import make_case

    case = make_case("closed_cylinder")  # a Table I case: true dimension 2
    np.save(tmp_path / "ref.npy", case.reference)
    np.save(tmp_path / "scan.npy", case.scan)
    np.savetxt(tmp_path / "init.txt", case.initial_pose)
    common = ["detect", "--reference", str(tmp_path / "ref.npy"), "--scan", str(tmp_path / "scan.npy"),
              "--initial-pose", str(tmp_path / "init.txt"), "--json"]
    assert main(common) == 0
    voxelised = json.loads(capsys.readouterr().out)
    assert main([*common, "--raw"]) == 0
    raw = json.loads(capsys.readouterr().out)
    scan = np.load(tmp_path / "scan.npy")
    reach = np.linalg.norm(scan, axis=1).max()
    assert voxelised["voxel_size"] == pytest.approx(reach / 100.0)
    assert raw["voxel_size"] is None and raw["scan_points"] == len(scan)
    assert voxelised["scan_points"] < len(scan)
    assert voxelised["dimension"] == raw["dimension"] == case.true_dimension


def test_prepare_thins_to_the_odometry_budget_and_caps_the_voxel():
    from lili_odom.degeneracy.detection_input import odometry_voxel_size, prepare

    ref, scan, _ = plane_pair(seed=1)
    far = scan * 100.0  # reaches ~280 m: the voxel rule is capped at max_range
    assert odometry_voxel_size(far, max_range=100.0) == pytest.approx(1.0)
    assert odometry_voxel_size(scan, max_range=100.0) == pytest.approx(np.linalg.norm(scan, axis=1).max() / 100)
    prepared = prepare(ref, scan, voxel_size=0.01, detection_points=500)
    assert 0 < len(prepared.scan) <= 500
    assert prepared.reference.voxel_size >= 0.01
    with pytest.raises(ValueError):
        prepare(ref, np.full((10, 3), np.nan))
    with pytest.raises(ValueError):
        odometry_voxel_size(np.zeros((5, 3)))


OUSTER = Path(__file__).resolve().parents[2] / "shared" / "data" / "ouster"


def test_detect_on_the_real_os1_pair_is_constrained_and_registers():
    """The real OS1-128 outdoor pair: dimension 0 and the reference motion within 3 cm."""
    pytest.importorskip("ouster.sdk")
    if not (OUSTER / "OS-1-128_v2.3.0_1024x10_lb_n3.pcap").exists():
        pytest.skip("real Ouster recordings not present")
    from lili_odom.degeneracy.detection_input import odometry_detector, prepare
    from lili_odom.io.ouster import sensor_frame_points

    reference, scan = sensor_frame_points(OUSTER / "OS-1-128_v2.3.0_1024x10_lb_n3.pcap",
                                          OUSTER / "OS-1-128_v2.3.0_1024x10.json", count=2)
    poses = np.loadtxt(OUSTER / "OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt").reshape(-1, 3, 4)
    T0, T1 = (np.vstack([p, [0.0, 0.0, 0.0, 1.0]]) for p in poses[:2])
    truth = np.linalg.inv(T0) @ T1
    prepared = prepare(reference, scan)
    assert prepared.voxel_size == pytest.approx(1.0)
    for method in ("lili", "zhang"):
        result = odometry_detector(method).detect(prepared.reference, prepared.scan, truth)
        assert result.ok and result.dimension == 0
        assert np.linalg.norm(result.pose[:3, 3] - truth[:3, 3]) < 0.03
