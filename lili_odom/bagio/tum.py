"""TUM trajectory files: one pose per line, ``stamp tx ty tz qx qy qz qw``.

Stamps are seconds (header stamps, 9 decimals), translations metres, the quaternion is the
rotation of the body in the trajectory's frame (Hamilton, ``w`` last, ``w >= 0``). ``evo``
reads these with ``evo_ape tum truth.tum estimate.tum``.
"""
from __future__ import annotations

from pathlib import Path
from typing import IO, Iterable

import numpy as np
from scipy.spatial.transform import Rotation

from lili_odom.messages import matrix_to_pose_values

__all__ = ["format_tum_line", "TumWriter", "write_tum", "read_tum"]


def format_tum_line(stamp: float, T: np.ndarray) -> str:
    """One TUM line (no newline) for pose ``T`` (4x4) at ``stamp`` [s]."""
    p, q = matrix_to_pose_values(T)
    values = " ".join(f"{v:.9f}" for v in (*p, *q))
    return f"{stamp:.9f} {values}"


class TumWriter:
    """Streams poses into a TUM file (flushed on close; use as a context manager)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file: IO[str] | None = open(self.path, "w", encoding="ascii")
        self.count = 0

    def add(self, stamp: float, T: np.ndarray) -> None:
        if self._file is None:
            raise RuntimeError(f"{self.path} is closed")
        self._file.write(format_tum_line(stamp, T) + "\n")
        self.count += 1

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> "TumWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_tum(path: str | Path, poses: Iterable[tuple[float, np.ndarray]]) -> int:
    """Write ``[(stamp, 4x4)]``; returns the number of lines."""
    with TumWriter(path) as w:
        for stamp, T in poses:
            w.add(stamp, T)
        return w.count


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """-> (stamps (N,), poses (N, 4, 4)); ``#`` comment lines are skipped."""
    rows = np.loadtxt(path, comments="#", ndmin=2)
    if rows.size == 0:
        return np.zeros(0), np.zeros((0, 4, 4))
    if rows.shape[1] != 8:
        raise ValueError(f"{path}: expected 8 columns, got {rows.shape[1]}")
    poses = np.tile(np.eye(4), (rows.shape[0], 1, 1))
    poses[:, :3, :3] = Rotation.from_quat(rows[:, 4:8]).as_matrix()
    poses[:, :3, 3] = rows[:, 1:4]
    return rows[:, 0].copy(), poses
