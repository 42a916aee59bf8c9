"""The reference (map) side of a degeneracy detection, and guarded KISS-ICP alignment.

``ReferenceMap`` wraps a KISS-ICP ``VoxelHashMap`` (the very map the odometry registers against)
and lazily derives what the detectors need from the map's *own* points
(``voxel_map.point_cloud()``, which is thinned by the voxel map, not the raw reference):
a KD-tree, the median neighbour spacing ``s`` [m], and PCA normals.

``GuardedRegistration`` calls ``Registration.align_points_to_map`` only with inputs that cannot
abort the process (finite points, re-orthonormalised initial guess) and reports the silent
failure mode of KISS-ICP (no correspondences -> returns the initial guess unchanged).
"""
from __future__ import annotations

import os
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from kiss_icp.mapping import VoxelHashMap
from kiss_icp.registration import Registration
from scipy.spatial import cKDTree

from lili_odom.geometry import (drop_nonfinite_rows, is_valid_pose, orthonormalize,
                                transform_points)

MIN_POINTS = 10
SPACING_PROBES = 4000
"""Map points whose nearest-neighbour distances estimate ``ReferenceMap.spacing``."""

THREADED_QUERY_POINTS = 20_000
"""k-d tree queries of at least this many points use every core; smaller ones one thread
(scipy's threads cost more than they save on a scan's few thousand points, and take a core
from the background detector)."""


def kdtree_workers(n: int) -> int:
    """``workers`` argument of a ``cKDTree.query`` of ``n`` points."""
    return -1 if n >= THREADED_QUERY_POINTS else 1


#: (pid, executor) of the thread that builds k-d trees ahead; a forked child makes its own.
_tree_builder: tuple[int, ThreadPoolExecutor] | None = None


def _build_kdtree(points: np.ndarray) -> cKDTree:
    # An unbalanced tree builds ~2x faster and queries about as fast on scan-like clouds;
    # the odometry rebuilds it after every map update.
    return cKDTree(points, balanced_tree=False, compact_nodes=False)


def _builder() -> ThreadPoolExecutor:
    """This process's tree-building thread (a fork does not copy threads, so a child that
    inherited the parent's executor would wait forever on it)."""
    global _tree_builder
    if _tree_builder is None or _tree_builder[0] != os.getpid():
        _tree_builder = (os.getpid(),
                         ThreadPoolExecutor(max_workers=1, thread_name_prefix="lili_odom_kdtree"))
    return _tree_builder[1]


class ReferenceMap:
    """A voxel-hash map of reference points (reference frame) plus derived geometry.

    Args:
        voxel_map: an existing KISS-ICP map (shared with the odometry), or None to build one.
        voxel_size: voxel edge [m] of ``voxel_map``; also bounds the correspondence search
            (KISS-ICP looks in the 27 neighbouring voxels only).
    """

    def __init__(self, voxel_map: VoxelHashMap, voxel_size: float, max_points_per_voxel: int):
        self.voxel_map = voxel_map
        self.voxel_size = float(voxel_size)
        self.max_points_per_voxel = int(max_points_per_voxel)

    @classmethod
    def from_points(
        cls,
        points: np.ndarray,
        voxel_size: float,
        max_points_per_voxel: int = 100,
        max_distance: float = 1e4,
    ) -> "ReferenceMap":
        """Build a map from (N, 3) reference points [m] in the reference frame."""
        points = drop_nonfinite_rows(np.asarray(points, dtype=np.float64))
        vm = VoxelHashMap(voxel_size, max_distance, max_points_per_voxel)
        if len(points):
            vm.add_points(points)
        return cls(vm, voxel_size, max_points_per_voxel)

    def invalidate(self) -> None:
        """Drop cached geometry after the underlying voxel map changed."""
        for name in ("points", "kdtree", "spacing", "_kdtree_future"):
            self.__dict__.pop(name, None)
        self._normals_cache = {}

    def build_kdtree_ahead(self) -> None:
        """Start building :attr:`kdtree` of the current points in a background thread
        (scipy builds without holding the GIL), so a later ``kdtree`` only waits for what is
        left of the build. The tree is the same as one built on access; a map change
        (:meth:`invalidate`) discards it."""
        if "kdtree" in self.__dict__ or "_kdtree_future" in self.__dict__:
            return
        points = self.points
        if not len(points):
            return
        try:
            future = _builder().submit(_build_kdtree, points)
        except RuntimeError:  # the interpreter is shutting down: build on access
            return
        self.__dict__["_kdtree_future"] = (os.getpid(), future)

    @cached_property
    def points(self) -> np.ndarray:
        """(M, 3) points actually stored in the voxel map [m]."""
        return np.asarray(self.voxel_map.point_cloud(), dtype=np.float64).reshape(-1, 3)

    @cached_property
    def kdtree(self) -> cKDTree:
        """scipy k-d tree of :attr:`points` (the one :meth:`build_kdtree_ahead` started, if
        any)."""
        ahead: tuple[int, Future] | None = self.__dict__.pop("_kdtree_future", None)
        if ahead is not None and ahead[0] == os.getpid():  # not one a parent process started
            return ahead[1].result()
        return _build_kdtree(self.points)

    @cached_property
    def spacing(self) -> float:
        """Median distance [m] from a map point to its nearest other map point.

        Measured on at most ``SPACING_PROBES`` evenly strided map points (each against the whole
        map, so every probe's distance is exact): the median of that many samples is within
        about 1 % of the median over all points, at a fraction of the cost on a large map.
        """
        points = self.points
        if len(points) < 2:
            return float("nan")
        probes = points[:: max(1, -(-len(points) // SPACING_PROBES))]
        d, _ = self.kdtree.query(probes, k=2, workers=kdtree_workers(len(probes)))
        return float(np.median(d[:, 1]))

    def normals(self, k: int = 10) -> tuple[np.ndarray, np.ndarray]:
        """PCA normals of every map point from its ``k`` nearest map neighbours.

        Returns:
            normals (M, 3) unit vectors (sign arbitrary) and planarity (M,) in [0, 1]
            (``(l2 - l3) / l1`` of the neighbourhood covariance eigenvalues l1>=l2>=l3).
        """
        cache = self.__dict__.setdefault("_normals_cache", {})
        if k not in cache:
            _, idx = self.kdtree.query(self.points, k=min(k, len(self.points)),
                                       workers=kdtree_workers(len(self.points)))
            nb = self.points[idx]  # (M, k, 3)
            centred = nb - nb.mean(axis=1, keepdims=True)
            cov = np.einsum("mki,mkj->mij", centred, centred) / max(idx.shape[1], 1)
            w, v = np.linalg.eigh(cov)  # ascending
            normals = v[:, :, 0]
            planarity = (w[:, 1] - w[:, 0]) / np.maximum(w[:, 2], 1e-300)
            cache[k] = (normals, planarity)
        return cache[k]


@dataclass
class AlignmentResult:
    pose: np.ndarray
    ok: bool
    reason: str = ""


class GuardedRegistration:
    """KISS-ICP point-to-point ICP with the process-aborting and silent failure modes handled.

    Note: the first ``Registration`` in a process sets TBB's thread limit for the whole process.
    """

    def __init__(self, max_iterations: int = 500, convergence: float = 1e-4, max_threads: int = 0):
        self.max_iterations = int(max_iterations)
        self.convergence = float(convergence)
        self._registration = Registration(self.max_iterations, self.convergence, max_threads)

    def align(
        self,
        points: np.ndarray,
        reference: ReferenceMap,
        initial_guess: np.ndarray,
        max_correspondence_distance: float,
        kernel: float,
    ) -> AlignmentResult:
        """Align ``points`` (scan frame) to ``reference`` starting from ``initial_guess``.

        Returns ``ok=False`` (pose = the guess) instead of calling native code with bad input, and
        when the map is empty or nothing lies within the correspondence distance.
        """
        try:
            guess = orthonormalize(initial_guess)
        except ValueError as exc:
            return AlignmentResult(np.eye(4), False, f"invalid initial guess: {exc}")
        points = drop_nonfinite_rows(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        if len(points) < MIN_POINTS:
            return AlignmentResult(guess, False, f"only {len(points)} finite scan points")
        if reference.voxel_map.empty():
            return AlignmentResult(guess, False, "reference map is empty")
        if not (np.isfinite(max_correspondence_distance) and max_correspondence_distance > 0):
            return AlignmentResult(guess, False, "invalid correspondence distance")
        if not (np.isfinite(kernel) and kernel > 0):
            return AlignmentResult(guess, False, "invalid kernel")
        pose = self._registration.align_points_to_map(
            points, reference.voxel_map, guess, float(max_correspondence_distance), float(kernel)
        )
        pose = np.asarray(pose, dtype=np.float64)
        if not is_valid_pose(pose, tol=1e-4):
            return AlignmentResult(guess, False, "registration returned an invalid pose")
        if np.array_equal(pose, guess):
            # KISS-ICP returns the guess bit-for-bit when it found no correspondence at all.
            probe = transform_points(guess, points[:: max(1, len(points) // 500)])
            d, _ = reference.kdtree.query(probe, distance_upper_bound=max_correspondence_distance,
                                          workers=kdtree_workers(len(probe)))
            if not np.any(np.isfinite(d)):
                return AlignmentResult(guess, False, "no correspondences within reach")
        return AlignmentResult(orthonormalize(pose), True)
