"""Read point clouds and poses from files: ``.npy`` (N x 3+), ``.ply`` (via trimesh), ``.pcd``.

Points are returned as (N, 3) float64 [m] in the file's own frame; rows with a non-finite
coordinate or one beyond ``MAX_COORDINATE_M`` (no sensor or map reaches it; such values make
distances overflow in the detectors) are dropped. Every failure is a ``UserError`` with a
one-line message naming the file.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from lili_odom.errors import UserError
from lili_odom.geometry import drop_nonfinite_rows

#: Largest plausible coordinate magnitude [m]; rows beyond it are dropped as corrupt.
MAX_COORDINATE_M = 1e7

_PCD_TYPES = {("F", 4): "f4", ("F", 8): "f8", ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4",
              ("I", 8): "i8", ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8"}


def load_points(path: str | Path) -> np.ndarray:
    """Load an (N, 3) float64 cloud; rows with non-finite or implausibly large coordinates
    (beyond ``MAX_COORDINATE_M``) are dropped."""
    path = Path(path)
    if not path.is_file():
        raise UserError(f"{path}: no such file")
    suffix = path.suffix.lower()
    try:
        if suffix == ".npy":
            pts = np.load(path, allow_pickle=False)
        elif suffix == ".ply":
            pts = _load_ply(path)
        elif suffix == ".pcd":
            pts = _load_pcd(path)
        else:
            raise UserError(f"{path}: unsupported cloud format '{suffix}' (use .npy, .ply or .pcd)")
    except UserError:
        raise
    except Exception as exc:  # noqa: BLE001 - any parser failure is a bad file for the user
        raise UserError(f"{path}: cannot read point cloud ({type(exc).__name__}: {exc})") from None
    pts = np.asarray(pts)
    if pts.ndim != 2 or pts.shape[1] < 3 or not np.issubdtype(pts.dtype, np.number):
        raise UserError(f"{path}: expected an N x 3 numeric array, got shape {pts.shape}")
    pts = drop_nonfinite_rows(pts[:, :3].astype(np.float64))
    pts = pts[np.all(np.abs(pts) <= MAX_COORDINATE_M, axis=1)]
    if len(pts) == 0:
        raise UserError(f"{path}: no finite points within {MAX_COORDINATE_M:g} m")
    return pts


def _load_ply(path: Path) -> np.ndarray:
    import trimesh

    geom = trimesh.load(path, process=False)
    vertices = getattr(geom, "vertices", None)
    if vertices is None:
        raise UserError(f"{path}: PLY file has no vertices")
    return np.asarray(vertices)


def _load_pcd(path: Path) -> np.ndarray:
    raw = path.read_bytes()
    header: dict[str, list[str]] = {}
    offset = 0
    while True:
        end = raw.find(b"\n", offset)
        if end < 0:
            raise UserError(f"{path}: truncated PCD header")
        line = raw[offset:end].decode("ascii", errors="replace").strip()
        offset = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        header[key.upper()] = values
        if key.upper() == "DATA":
            break
    fields = header.get("FIELDS", [])
    sizes = [int(v) for v in header.get("SIZE", [])]
    types = header.get("TYPE", [])
    counts = [int(v) for v in header.get("COUNT", ["1"] * len(fields))]
    npts = int(header.get("POINTS", ["0"])[0])
    if not all(f in fields for f in "xyz"):
        raise UserError(f"{path}: PCD has no x, y, z fields")
    if not (len(fields) == len(sizes) == len(types) == len(counts)):
        raise UserError(f"{path}: inconsistent PCD header")
    mode = header["DATA"][0].lower()
    if mode == "ascii":
        table = np.loadtxt(raw[offset:].decode("ascii").splitlines(), ndmin=2)
        cols = np.cumsum([0] + counts)
        return np.stack([table[:, cols[fields.index(c)]] for c in "xyz"], axis=1)
    if mode == "binary":
        dtype = np.dtype([(f"{n}_{i}", _PCD_TYPES[(t, s)], (c,))
                          for i, (n, s, t, c) in enumerate(zip(fields, sizes, types, counts))])
        data = np.frombuffer(raw, dtype=dtype, count=npts, offset=offset)
        return np.stack([data[f"{c}_{fields.index(c)}"][:, 0] for c in "xyz"], axis=1)
    raise UserError(f"{path}: PCD DATA '{mode}' not supported (use ascii or binary)")


def load_pose(path: str | Path) -> np.ndarray:
    """Load a 4x4 pose from a whitespace-separated text file."""
    path = Path(path)
    try:
        T = np.loadtxt(path, ndmin=2)
    except Exception as exc:  # noqa: BLE001
        raise UserError(f"{path}: cannot read 4x4 pose ({exc})") from None
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise UserError(f"{path}: expected a finite 4x4 matrix, got shape {T.shape}")
    return T
