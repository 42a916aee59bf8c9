"""Diagnostics of an offline run directory (``lili-odom run`` / ``evaluate`` output): its error
against the truth by component in the true body frame, scan-to-scan jumps, and its tilt
against gravity with the accelerometer bias. Each ``*_table`` returns Markdown lines.

A run directory holds ``estimate.tum`` and ``truth.tum`` (TUM: stamp x y z qx qy qz qw, poses
of base_link) and ``scans.csv`` (:mod:`lili_odom.evaluation.runner`). Errors are in metres and
degrees; estimate and truth are associated as the metrics do (evo, 0.02 s).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from lili_odom import geometry

__all__ = ["associated", "errors_in_true_body_frame", "error_table", "jump_table",
           "true_accel_bias", "tilt_series", "tilt_table"]


def associated(run_dir: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(estimate stamps [s], (n, 4, 4) true poses, (n, 4, 4) estimated poses) of a run
    directory's ``truth.tum`` / ``estimate.tum``, associated as the metrics do (evo)."""
    from evo.core import sync
    from evo.core.trajectory import PoseTrajectory3D

    from lili_odom.bagio.tum import read_tum

    trajectories = [PoseTrajectory3D(poses_se3=list(T), timestamps=t)
                    for t, T in (read_tum(run_dir / "truth.tum"), read_tum(run_dir / "estimate.tum"))]
    truth, est = sync.associate_trajectories(*trajectories, max_diff=0.02)
    return np.asarray(est.timestamps), np.array(truth.poses_se3), np.array(est.poses_se3)


def errors_in_true_body_frame(run_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    """(stamps from the first estimate [s], (n, 4, 4) errors ``T_true^-1 T_est``), both
    trajectories started at the same pose (no alignment), associated as the metrics do."""
    t_e, T_g, T_e = associated(run_dir)
    align = T_g[0] @ np.linalg.inv(T_e[0])  # both start at the same pose
    err = np.einsum("nij,njk->nik", np.linalg.inv(T_g), align @ T_e)
    return t_e - t_e[0], err


def _run_name(run_dir: Path) -> str:
    return f"`{run_dir.name}` of `{run_dir.parent.parent.name}/{run_dir.parent.name}`"


def error_table(run_dir: Path, period: float) -> list[str]:
    """Error of the estimate by component, in the true body frame, every ``period`` s."""
    t, err = errors_in_true_body_frame(run_dir)
    rot = np.degrees([geometry.log(E)[3:] for E in err])
    lines = [f"## Error by component: {_run_name(run_dir)}", "",
             "Estimate against truth, both started at the same pose (no alignment); position "
             "error in the true base_link frame (x along the tunnel), rotation error as the "
             "rotation vector of `T_true^-1 T_est`.", "",
             "| t [s] | along x [m] | lateral y [m] | vertical z [m] | roll [deg] | pitch [deg] "
             "| yaw [deg] |", "|---|---|---|---|---|---|---|"]
    for tq in [*np.arange(0.0, t[-1], period), t[-1]]:
        i = int(np.argmin(np.abs(t - tq)))
        lines.append(f"| {t[i]:.0f} | " + " | ".join(f"{v:+.2f}" for v in
                                                     (*err[i, :3, 3], *rot[i])) + " |")
    return lines + [""]


def jump_table(run_dir: Path, threshold: float) -> list[str]:
    t_all, err = errors_in_true_body_frame(run_dir)
    lateral = err[:, 1, 3]
    step = np.abs(np.diff(lateral))
    t = t_all[1:]
    edges = np.arange(0.0, t[-1] + 50.0, 50.0)
    counts = np.histogram(t[step > threshold], bins=edges)[0]
    lines = [f"## Lateral error jumps: {_run_name(run_dir)}", "",
             f"Scan-to-scan changes of the lateral error (true body frame) above {threshold:g} m: "
             f"{int((step > threshold).sum())} of {len(step)}; median change "
             f"{np.median(step) * 100:.1f} cm, 99th percentile {np.percentile(step, 99) * 100:.1f} cm.",
             "", "| window [s] | jumps |", "|---|---|"]
    lines += [f"| {a:.0f}-{b:.0f} | {c} |" for a, b, c in zip(edges[:-1], edges[1:], counts)]
    return lines + [""]


def true_accel_bias(trial: int, seed: int, stamps: np.ndarray) -> np.ndarray:
    """(n, 3) accelerometer bias [m/s^2] the simulator gave the IMU of ``trial``/``seed`` at
    bag ``stamps`` [s] (its IMU does not depend on the LiDAR resolution)."""
    from lili_odom.sim.generator import EPOCH_NS, SimRequest, Simulation
    from lili_odom.sim.imu import simulate_imu

    sim = Simulation(SimRequest(trial=trial, seed=seed, resolution=(16, 64)))
    imu = simulate_imu(sim.trajectory, sim.sensors.extrinsics.base_to_imu, sim.sensors.imu, seed)
    i = np.searchsorted(imu.t, stamps - EPOCH_NS * 1e-9).clip(0, len(imu.t) - 1)
    return imu.accel_bias[i]


def tilt_series(run_dir: Path, trial: int | None = None, seed: int | None = None) -> dict:
    """Per scan of a run directory: ``t`` [s from the first scan], ``heading`` (true yaw
    turned since the start [deg]), world-frame rotation errors ``fused`` and ``registration``
    ((n, 3) [deg], axes of the start heading), the estimated accelerometer bias ``bias``
    ((n, 3) [m/s^2], IMU frame) and, with ``trial``/``seed``, the simulator's ``true_bias``."""
    from scipy.spatial.transform import Rotation

    scans = np.genfromtxt(run_dir / "scans.csv", delimiter=",", names=True)
    if "icp_qw" not in (scans.dtype.names or ()):
        raise ValueError(f"{run_dir}/scans.csv has no registration orientation (older run)")
    stamps, T_true, T_est = associated(run_dir)
    R_true, R_est = T_true[:, :3, :3], T_est[:, :3, :3]
    k = np.searchsorted(scans["stamp"], stamps).clip(0, len(scans) - 1)
    row = scans[k]
    q = np.stack([row[f"icp_q{a}"] for a in "xyzw"], axis=1)
    ok = np.isfinite(q).all(axis=1)
    R_icp = np.repeat(np.eye(3)[None], len(q), axis=0)
    R_icp[ok] = Rotation.from_quat(q[ok]).as_matrix()
    def yaw(R: np.ndarray) -> np.ndarray:
        return Rotation.from_matrix(R).as_euler("ZYX")[..., 0]

    yaw0 = yaw(R_true[0])
    align = Rotation.from_euler("z", yaw0 - yaw(R_est[0])).as_matrix()
    heading = Rotation.from_euler("z", -yaw0).as_matrix()

    def world_error(R: np.ndarray) -> np.ndarray:  # degrees, axes of the start heading
        E = np.einsum("ij,njk,nlk->nil", align, R, R_true)
        return np.degrees(Rotation.from_matrix(E).as_rotvec() @ heading.T)

    return {
        "t": stamps - stamps[0],
        "heading": np.degrees(np.unwrap(yaw(R_true)) - yaw0),
        "fused": world_error(R_est),
        "registration": np.where(ok[:, None], world_error(R_icp), np.nan),
        "bias": np.stack([row[f"accel_bias_{a}"] for a in "xyz"], axis=1),
        "true_bias": (true_accel_bias(trial, seed, stamps)
                      if trial is not None and seed is not None else None),
    }


def tilt_table(run_dir: Path, period: float, trial: int | None, seed: int | None) -> list[str]:
    """World-frame tilt error of the fused pose and of the registration, with the estimated
    (and, for a simulated bag, true) accelerometer bias, one row every ``period`` s."""
    d = tilt_series(run_dir, trial, seed)
    t, turned, e_fused, ba, true_ba = d["t"], d["heading"], d["fused"], d["bias"], d["true_bias"]
    diff = d["registration"] - e_fused
    truth_note = " and the simulator's true one" if true_ba is not None else ""
    lines = [f"## Tilt against gravity: {_run_name(run_dir)}", "",
             "World-frame rotation error of the fused estimate and of the scan-to-map "
             "registration (rotation vector of `R_est R_true^T` after aligning the start yaw, "
             "in the axes of the start heading: x forward, y left) [deg]; registration - fused "
             "averaged over the row's period; accelerometer bias estimate (IMU frame) "
             f"[m/s^2]{truth_note}. "
             "At rest an accelerometer bias b reads as a tilt of about b / g (0.1 m/s^2 = "
             "0.58 deg).", "",
             "| t [s] | heading [deg] | fused x | fused y | registration - fused x | y | bias x | "
             "bias y" + (" | true bias x | true bias y |" if true_ba is not None else " |"),
             "|---" * (8 + 2 * (true_ba is not None)) + "|"]
    for tq in [*np.arange(0.0, t[-1], period), t[-1]]:
        i = int(np.argmin(np.abs(t - tq)))
        window = (t > tq - period) & (t <= tq)
        d = np.nanmean(diff[window], axis=0) if np.isfinite(diff[window]).any() else (np.nan,) * 3
        cells = [f"{t[i]:.0f}", f"{turned[i]:+.0f}", *(f"{v:+.2f}" for v in e_fused[i, :2]),
                 *(f"{v:+.2f}" for v in d[:2]), *(f"{v:+.3f}" for v in ba[i, :2])]
        if true_ba is not None:
            cells += [f"{v:+.3f}" for v in true_ba[i, :2]]
        lines.append("| " + " | ".join(cells) + " |")
    return lines + [""]
