"""The accumulated map: merge local-map snapshots into a bounded voxel map and save it.

:class:`MapAccumulator` keeps one point per voxel (the first one seen) of every cloud added,
so areas that have left the odometry's local map stay in the saved map. The clouds are in the
odometry frame (built at the fused poses). Memory is bounded: when more than ``max_points``
voxels are held, the voxel size grows by half and the map is downsampled again (logged by the
caller through :attr:`MapAccumulator.coarsened`).

:func:`save_points` writes ``.pcd`` (binary, x y z float32) or ``.ply`` (binary, via trimesh)
by the file's extension.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from lili_odom.geometry import drop_nonfinite_rows

__all__ = ["MapAccumulator", "save_points", "MAP_SUFFIXES"]

MAP_SUFFIXES = (".pcd", ".ply")


class MapAccumulator:
    """Voxel map of everything added (odometry frame, metres).

    Args:
        voxel_size: edge of the voxels [m] (default 0.2).
        max_points: voxels kept at most before the voxel size grows (default 5 000 000,
            about 60 MB of points and keys).
    """

    def __init__(self, voxel_size: float = 0.2, max_points: int = 5_000_000) -> None:
        if not voxel_size > 0:
            raise ValueError(f"voxel_size must be > 0, got {voxel_size}")
        if int(max_points) < 1:
            raise ValueError(f"max_points must be >= 1, got {max_points}")
        self.voxel_size = float(voxel_size)
        self.max_points = int(max_points)
        self.coarsened = 0
        self._keys = np.zeros(0, dtype=np.int64)
        self._points = np.zeros((0, 3), dtype=np.float32)

    def __len__(self) -> int:
        return len(self._keys)

    def _voxel_keys(self, points: np.ndarray) -> np.ndarray:
        idx = np.floor(points / self.voxel_size).astype(np.int64)
        idx += 1 << 20  # 21 bits per axis: +-1e6 voxels (200 km at 0.2 m)
        idx = np.clip(idx, 0, (1 << 21) - 1)
        return (idx[:, 0] << 42) | (idx[:, 1] << 21) | idx[:, 2]

    def add(self, points: np.ndarray) -> None:
        """Merge an (N, 3) cloud; voxels already held keep their point."""
        pts = drop_nonfinite_rows(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        if not len(pts):
            return
        keys = self._voxel_keys(pts)
        keys, first = np.unique(keys, return_index=True)
        new = ~np.isin(keys, self._keys, assume_unique=True)
        if new.any():
            self._keys = np.concatenate([self._keys, keys[new]])
            self._points = np.concatenate([self._points,
                                           pts[first[new]].astype(np.float32)])
        while len(self._keys) > self.max_points:
            self._coarsen()

    def _coarsen(self) -> None:
        self.voxel_size *= 1.5
        self.coarsened += 1
        keys = self._voxel_keys(self._points.astype(np.float64))
        keys, first = np.unique(keys, return_index=True)
        self._keys, self._points = keys, self._points[first]

    def points(self) -> np.ndarray:
        """(N, 3) float64 copy of the map."""
        return self._points.astype(np.float64)

    def clear(self) -> None:
        self._keys = np.zeros(0, dtype=np.int64)
        self._points = np.zeros((0, 3), dtype=np.float32)


def save_points(path: str | Path, points: np.ndarray) -> Path:
    """Write an (N, 3) cloud to ``path`` (``.pcd`` or ``.ply`` by extension); returns the
    absolute path. Raises ValueError for another extension, OSError when writing fails."""
    path = Path(path).expanduser().resolve()
    suffix = path.suffix.lower()
    if suffix not in MAP_SUFFIXES:
        raise ValueError(f"{path.name}: map files are .pcd or .ply, not {suffix or 'no extension'!r}")
    pts = np.ascontiguousarray(np.asarray(points, dtype=np.float32).reshape(-1, 3))
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    if suffix == ".pcd":
        header = ("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z\n"
                  "SIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
                  f"WIDTH {len(pts)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(pts)}\n"
                  "DATA binary\n")
        with open(tmp, "wb") as f:
            f.write(header.encode("ascii"))
            f.write(pts.astype("<f4").tobytes())
    else:
        import trimesh

        trimesh.PointCloud(pts).export(str(tmp), file_type="ply")
    tmp.replace(path)
    return path
