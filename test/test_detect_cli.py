"""``lili-odom detect`` end to end on a small plane, and its error handling."""
import json

import numpy as np

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
               "--initial-pose", str(tmp_path / "init.txt"), "--method", "lili", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)  # exactly one JSON object
    assert out["method"] == "lili" and out["dimension"] == 3
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
               "--initial-pose", str(tmp_path / "init.txt"), "--json"])
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
