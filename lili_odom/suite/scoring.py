"""The suite's metrics, the same code for every method (``evo`` underneath).

Given an estimate (base_link poses in the method's odometry frame) and the ground truth
(base_link in the world), matched by stamp (within 20 ms):

* ``ate_m``: absolute trajectory error, RMSE of the position error after an SE(3) alignment
  (Umeyama, no scale) of the whole estimate onto the truth [m]
  (:func:`lili_odom.evaluation.metrics.evaluate`).
* ``rpe_pct``: relative translation error in percent of the distance travelled: the RMSE of the
  position error over every pair of poses ``segment_m`` metres of path apart (default
  :data:`RPE_SEGMENT_M` = 10 m; half the path when the run is shorter than two segments),
  divided by the segment length, times 100 [%].
* ``final_m``: end-point error with the start known: the estimate is anchored at the truth's
  first matched pose (position and orientation), and ``final_m`` is the distance between
  where it then ends and where the robot really ends [m]. This is the drift a user sees after
  starting the odometry at a known pose.
* ``distance_m``: length of the matched truth path [m].
"""
from __future__ import annotations

import numpy as np

#: Default RPE segment length [m].
RPE_SEGMENT_M = 10.0
#: Largest stamp difference [s] for matching an estimate pose to a truth pose.
MAX_DT_S = 0.02


def _trajectory(stamps: np.ndarray, poses: np.ndarray):
    from evo.core.trajectory import PoseTrajectory3D

    return PoseTrajectory3D(poses_se3=list(np.asarray(poses, dtype=float)),
                            timestamps=np.asarray(stamps, dtype=float))


def anchored_final_error(est_stamps: np.ndarray, est_poses: np.ndarray,
                         ref_stamps: np.ndarray, ref_poses: np.ndarray,
                         max_dt: float = MAX_DT_S) -> float:
    """End-point position error [m] of the estimate anchored at the truth's first matched pose."""
    from evo.core import sync

    ref, est = sync.associate_trajectories(_trajectory(ref_stamps, ref_poses),
                                           _trajectory(est_stamps, est_poses), max_diff=max_dt)
    ref_p, est_p = ref.poses_se3, est.poses_se3
    T_anchor = ref_p[0] @ np.linalg.inv(est_p[0])
    return float(np.linalg.norm((T_anchor @ est_p[-1])[:3, 3] - ref_p[-1][:3, 3]))


def score(est_stamps: np.ndarray, est_poses: np.ndarray, ref_stamps: np.ndarray,
          ref_poses: np.ndarray, segment_m: float = RPE_SEGMENT_M) -> dict[str, float]:
    """``{"ate_m", "rpe_pct", "rpe_segment_m", "final_m", "distance_m", "matched"}`` of an
    estimate against the truth (see module docstring). Raises ValueError when no pose of the
    estimate matches the truth in time or a pose is not finite."""
    from lili_odom.evaluation.metrics import evaluate

    est_stamps = np.asarray(est_stamps, dtype=float)
    est_poses = np.asarray(est_poses, dtype=float).reshape(-1, 4, 4)
    if not np.isfinite(est_poses).all() or not np.isfinite(est_stamps).all():
        raise ValueError("estimate holds non-finite poses")
    try:
        m = evaluate(est_stamps, est_poses, np.asarray(ref_stamps, dtype=float),
                     np.asarray(ref_poses, dtype=float), segment_m=segment_m, max_dt=MAX_DT_S)
    except Exception as exc:  # noqa: BLE001 - evo raises its own errors for unmatched data
        raise ValueError(f"cannot score: {exc}") from None
    rpe_pct = 100.0 * m.rpe_rmse_m / m.rpe_segment_m if m.rpe_segment_m > 0 else float("nan")
    return {
        "ate_m": m.ate_rmse_m,
        "rpe_pct": rpe_pct,
        "rpe_segment_m": m.rpe_segment_m,
        "final_m": anchored_final_error(est_stamps, est_poses, ref_stamps, ref_poses),
        "distance_m": m.path_length_m,
        "matched": m.matched_poses,
    }
