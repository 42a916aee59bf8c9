"""Door ``detect``: cloud and pose files into ``lili-odom detect``.

A case writes a reference cloud (a box room) and a scan of it (shifted by 0.2 m) as ``.npy``,
then breaks one or two of: the reference or scan file (wrong shape, dtype, NaN/Inf rows,
finite-but-huge coordinates, a handful of points, one point repeated, nothing; a ``.ply`` or
``.pcd`` of random or truncated bytes), the ``--initial-pose`` file (NaN, wrong shape, huge
translation, a non-rotation, text), ``--voxel-size`` (zero, negative, NaN, tiny, huge) and
runs :func:`lili_odom.cli.main` in this process. Expected: exit code 0, or exit code 2 with one
line on stderr (:class:`~lili_odom.errors.UserError`); no exception escapes.
"""
from __future__ import annotations

import contextlib
import io
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from lili_odom.fuzz.api import room
from lili_odom.fuzz.outcome import CLEAN, DOCUMENTED, OTHER, Outcome, from_exception, one_line

F64_MAX = float(np.finfo(np.float64).max)


def _pick(rng: np.random.Generator, options: list) -> Any:
    return options[int(rng.integers(len(options)))]


def _bad_cloud(rng: np.random.Generator, good: np.ndarray, path: Path) -> tuple[Path, str]:
    what = int(rng.integers(12))
    n = len(good)
    if what == 0:
        np.save(path, good[:, :2])
        return path, "shape (N, 2)"
    if what == 1:
        np.save(path, good.astype(_pick(rng, [np.complex64, np.int8, np.bool_, np.float16])))
        return path, "odd dtype"
    if what == 2:
        np.save(path, good.astype(str))
        return path, "strings"
    if what == 3:
        p = good.copy()
        p[rng.random(n) < _pick(rng, [0.1, 1.0])] = _pick(rng, [np.nan, np.inf])
        np.save(path, p)
        return path, "non-finite rows"
    if what == 4:
        p = good.copy()
        p[rng.random(n) < _pick(rng, [0.01, 0.5, 1.0])] = _pick(rng, [F64_MAX, -1e308, 1e300,
                                                                        1e19, 1e12])
        np.save(path, p)
        return path, "huge coordinates"
    if what == 5:
        np.save(path, good[: int(rng.integers(0, 8))])
        return path, "a handful of points"
    if what == 6:
        np.save(path, np.repeat(good[:1], int(rng.integers(1, 2000)), axis=0))
        return path, "one point repeated"
    if what == 7:
        np.save(path, good * _pick(rng, [1e-9, 1e5, 0.0]))
        return path, "scaled"
    if what == 8:
        ply = path.with_suffix(".ply")
        ply.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 100\n"
                        + rng.integers(0, 256, int(rng.integers(0, 400)), dtype=np.uint8).tobytes())
        return ply, "ply garbage"
    if what == 9:
        pcd = path.with_suffix(".pcd")
        head = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
                f"WIDTH {_pick(rng, [10, -1, 10**9, 'x'])}\nHEIGHT 1\nPOINTS 10\n"
                f"DATA {_pick(rng, ['binary', 'ascii', 'binary_compressed'])}\n")
        k = int(rng.integers(0, len(head) + 1))
        pcd.write_bytes(head[:k].encode() + rng.integers(0, 256, int(rng.integers(0, 200)),
                                                         dtype=np.uint8).tobytes())
        return pcd, "pcd garbage"
    if what == 10:
        path.write_bytes(rng.integers(0, 256, int(rng.integers(0, 300)), dtype=np.uint8).tobytes())
        return path, "npy random bytes"
    np.save(path, good.reshape(-1))
    return path, "1-D array"


def _bad_pose(rng: np.random.Generator, path: Path) -> str:
    T = np.eye(4)
    what = int(rng.integers(7))
    if what == 0:
        T[0, 3] = np.nan
    elif what == 1:
        T = np.eye(3)
    elif what == 2:
        T[:3, 3] = _pick(rng, [1e308, 1e6, -1e12])
    elif what == 3:
        T[:3, :3] *= _pick(rng, [2.0, 0.0, -1.0, 1e-9])
    elif what == 4:
        T[:3, :3] = rng.normal(size=(3, 3))
    elif what == 5:
        path.write_text("one two three\n")
        return "pose text"
    else:
        path.write_text("")
        return "pose empty"
    np.savetxt(path, T)
    return f"pose {one_line(T.tolist(), 60)}"


def run_case(rng: np.random.Generator) -> Outcome:
    from lili_odom.cli import main

    method = _pick(rng, ["lili", "zhang", "hessian"])
    good = room(rng, int(rng.integers(100, 300)))
    with tempfile.TemporaryDirectory(prefix="lili_fuzz_detect_") as tmp:
        work = Path(tmp)
        ref, scan = work / "reference.npy", work / "scan.npy"
        np.save(ref, good)
        np.save(scan, good - [0.2, 0.0, 0.0])
        argv = ["detect", "--method", method]
        parts = [method]
        for _ in range(int(rng.integers(1, 3))):
            what = int(rng.integers(5))
            if what == 0:
                ref, text = _bad_cloud(rng, good, ref)
                parts.append(f"reference {text}")
            elif what == 1:
                scan, text = _bad_cloud(rng, good - [0.2, 0, 0], scan)
                parts.append(f"scan {text}")
            elif what == 2:
                pose = work / "pose.txt"
                parts.append(_bad_pose(rng, pose))
                argv += ["--initial-pose", str(pose)]
            elif what == 3:
                v = _pick(rng, ["0", "-1", "nan", "1e-6", "1e9", "inf"])
                argv += ["--voxel-size", v]
                parts.append(f"voxel {v}")
            else:
                argv.append("--json")
        argv += ["--reference", str(ref), "--scan", str(scan)]
        case = "; ".join(parts)
        err, out = io.StringIO(), io.StringIO()
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
                code = main(argv)
        except SystemExit as exc:  # argparse
            code = exc.code if isinstance(exc.code, int) else 2
        except Exception as exc:  # noqa: BLE001 - classified
            return from_exception(exc, (), case)
    err = io.StringIO(err.getvalue().replace(str(work), "<tmp>"))
    lines = [ln for ln in err.getvalue().splitlines() if ln.startswith("lili-odom detect: error:")]
    if code == 0:
        return Outcome(CLEAN, "", case)
    if code == 2 and len(lines) == 1:
        return Outcome(DOCUMENTED, one_line(lines[0]), case, "UserError")
    if code == 2 and "usage:" in err.getvalue():
        return Outcome(DOCUMENTED, one_line(err.getvalue().splitlines()[-1]), case, "usage")
    return Outcome(OTHER, f"exit code {code}: {one_line(err.getvalue()[-300:])}", case)
