"""ATE and RPE of an estimated trajectory against the truth, computed with ``evo``.

* ATE: RMSE of the translation error after an SE(3) alignment (Umeyama, no scale) [m].
* RPE: RMSE of the relative *position* error over all pairs of poses ``segment_m`` metres of
  path apart (the paper: 100 m) [m]. When the run is shorter than two segments, the segment is
  shortened to half the path length and reported as such.
"""
from __future__ import annotations

import copy
from dataclasses import asdict, dataclass

import numpy as np


@dataclass
class TrajectoryMetrics:
    ate_rmse_m: float
    ate_max_m: float
    rpe_rmse_m: float
    rpe_segment_m: float
    path_length_m: float
    matched_poses: int
    final_error_m: float

    def to_dict(self) -> dict:
        return asdict(self)


def _traj(stamps: np.ndarray, poses: np.ndarray):
    from evo.core.trajectory import PoseTrajectory3D

    return PoseTrajectory3D(poses_se3=list(np.asarray(poses, dtype=float)),
                            timestamps=np.asarray(stamps, dtype=float))


def evaluate(est_stamps: np.ndarray, est_poses: np.ndarray, ref_stamps: np.ndarray,
             ref_poses: np.ndarray, segment_m: float = 100.0, max_dt: float = 0.02) -> TrajectoryMetrics:
    """Metrics of ``est`` against ``ref`` (poses (n, 4, 4), stamps [s])."""
    from evo.core import metrics, sync
    from evo.core.metrics import PoseRelation, Unit

    ref, est = sync.associate_trajectories(_traj(ref_stamps, ref_poses), _traj(est_stamps, est_poses),
                                           max_diff=max_dt)
    est_aligned = copy.deepcopy(est)
    est_aligned.align(ref, correct_scale=False)
    ape = metrics.APE(PoseRelation.translation_part)
    ape.process_data((ref, est_aligned))
    length = float(ref.path_length)
    seg = segment_m if length >= 2 * segment_m else max(length / 2.0, 1e-3)
    rpe = metrics.RPE(PoseRelation.point_distance, delta=seg, delta_unit=Unit.meters, all_pairs=True)
    try:
        rpe.process_data((ref, est))
        rpe_rmse = float(rpe.get_statistic(metrics.StatisticsType.rmse))
    except Exception:  # noqa: BLE001 - evo raises when no pair spans the segment
        rpe_rmse = float("nan")
    final = float(np.linalg.norm(est_aligned.positions_xyz[-1] - ref.positions_xyz[-1]))
    return TrajectoryMetrics(
        ate_rmse_m=float(ape.get_statistic(metrics.StatisticsType.rmse)),
        ate_max_m=float(ape.get_statistic(metrics.StatisticsType.max)),
        rpe_rmse_m=rpe_rmse,
        rpe_segment_m=float(seg),
        path_length_m=length,
        matched_poses=int(ref.num_poses),
        final_error_m=final,
    )


def _aligned(est_stamps: np.ndarray, est_poses: np.ndarray, ref_stamps: np.ndarray,
             ref_poses: np.ndarray, max_dt: float):
    """evo's (reference, estimate) associated within ``max_dt`` [s], the estimate SE(3)-aligned
    to the reference as for the ATE."""
    from evo.core import sync

    ref, est = sync.associate_trajectories(_traj(ref_stamps, ref_poses), _traj(est_stamps, est_poses),
                                           max_diff=max_dt)
    est.align(ref, correct_scale=False)
    return ref, est


def error_along_path(est_stamps: np.ndarray, est_poses: np.ndarray, ref_stamps: np.ndarray,
                     ref_poses: np.ndarray, max_dt: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
    """Position error [m] of the SE(3)-aligned estimate (as for the ATE) against the distance
    travelled along the truth [m], one value per matched pose."""
    ref, est = _aligned(est_stamps, est_poses, ref_stamps, ref_poses, max_dt)
    return (np.asarray(ref.distances, dtype=float),
            np.linalg.norm(est.positions_xyz - ref.positions_xyz, axis=1))


def body_frame_errors(est_stamps: np.ndarray, est_poses: np.ndarray, ref_stamps: np.ndarray,
                      ref_poses: np.ndarray, max_dt: float = 0.02) -> np.ndarray:
    """(n, 3) position error [m] of the SE(3)-aligned estimate (as for the ATE) along the
    reference's own forward, lateral and up axes, one row per matched pose."""
    ref, est = _aligned(est_stamps, est_poses, ref_stamps, ref_poses, max_dt)
    R = np.array([T[:3, :3] for T in ref.poses_se3])
    return np.einsum("nji,nj->ni", R, est.positions_xyz - ref.positions_xyz)
