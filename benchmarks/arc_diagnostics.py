"""Where does the tunnel error come from: the detector, or the estimate it is fed?

    python benchmarks/arc_diagnostics.py probe --times 60 130 150 200 250 300
    python benchmarks/arc_diagnostics.py jumps data/tunnel_runs/trial1_64x512_seed0/lili
    python benchmarks/arc_diagnostics.py errors data/tunnel_runs/trial1_64x512_seed0/lili
    python benchmarks/arc_diagnostics.py tilt RUN_DIR --trial 2 --seed 2

``probe`` runs LiLi on simulated Trial 1 scans registered against a local map built from the
*true* poses (the previous ``--history`` seconds of scans, each column placed with its true
pose, so no deskew or odometry error enters). Whatever LiLi reports there is the detector's
own answer for that place; anything more it reports in the odometry comes from the estimate.
The map and scan go through the odometry's own ``ScanMatcher`` settings (voxel 1 m, 0.5/1.5
voxel downsampling, ``detection_points`` thinning).

``jumps`` reads ``estimate.tum`` and ``truth.tum`` of a ``lili-odom run`` / ``evaluate`` run
directory and counts scan-to-scan changes of the lateral position error (in the true body
frame) above ``--threshold``: a registration that is stable to centimetres cannot produce
them, an estimator that oscillates does.

``errors`` tabulates the error of such a run by component (along the tunnel, lateral,
vertical, roll, pitch, yaw) in the true body frame, without alignment: slow drift and sudden
failures look different there, and so do along-axis (wheel) and lateral/yaw (LiDAR) errors.

``tilt`` follows a run's roll/pitch against gravity: the world-frame tilt error of the fused
pose and of the scan-to-map registration (the odometry frame is gravity-aligned at the start,
so only the start yaw and position are aligned), with the accelerometer bias the estimator
holds (``scans.csv``) and, for a simulated bag (``--trial``/``--seed``), the true one. At rest
the accelerometer cannot tell a bias from a tilt, so the start's gravity alignment takes a
bias ``b`` as a tilt of about ``b / g``; the local map is built in that frame. The
registration-minus-fused column is the map's tilt against the fused estimate, averaged over
the row's period (single registrations scatter by tenths of a degree).

All four append a section to ``benchmarks/results/arc_diagnostics.md`` (``--out`` to change).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from lili_odom import geometry  # noqa: E402

DEFAULT_OUT = ROOT / "benchmarks" / "results" / "arc_diagnostics.md"


def probe(times: list[float], resolution: tuple[int, int], history: float) -> list[str]:
    from kiss_icp.voxelization import voxel_down_sample

    from lili_odom.degeneracy.lili import LiliDetector
    from lili_odom.pipeline.odometry import PipelineConfig
    from lili_odom.pipeline.scan_matcher import ScanMatcher
    from lili_odom.sim.generator import SimRequest, Simulation

    sim = Simulation(SimRequest(trial=1, resolution=resolution))
    base_to_lidar = sim.sensors.extrinsics.base_to_lidar
    period = sim.sensors.lidar.scan_period
    cfg = PipelineConfig()

    def scan_in_world(t_start: float) -> tuple[np.ndarray, np.ndarray]:
        scan = sim.scan(t_start)
        col_t = t_start + scan.t_ns.astype(float) * 1e-9
        T = sim.trajectory.pose(col_t) @ base_to_lidar  # (cols, 4, 4) world <- os_lidar
        xyz = scan.xyz.astype(float)
        world = np.einsum("cij,rcj->rci", T[:, :3, :3], xyz) + T[None, :, :3, 3]
        keep = np.all(np.isfinite(world), -1) & (np.linalg.norm(xyz, axis=-1) > cfg.scan_matcher.min_range)
        return world[keep], sim.trajectory.pose(col_t[-1:])[0] @ base_to_lidar

    lines = [f"## LiLi on a map from the true poses (Trial 1, {resolution[0]}x{resolution[1]}, "
             f"{history:g} s of history)", "",
             "| t [s] | x [m] | points | L [m] | dimension | PCA eigenvalues | basis (scaled, v / L w) |",
             "|---|---|---|---|---|---|---|"]
    detector = LiliDetector(cfg.lili)
    for t in times:
        matcher = ScanMatcher(cfg.scan_matcher)
        voxel = matcher.config.voxel
        for k in range(int(round(history / period)), 0, -1):
            world, T_end = scan_in_world(t - k * period)
            local = geometry.transform_points(np.linalg.inv(T_end), world)
            matcher.update_map(voxel_down_sample(local, 0.5 * voxel), T_end, np.eye(4))
        world, T_end = scan_in_world(t)
        local = geometry.transform_points(np.linalg.inv(T_end), world)
        source = voxel_down_sample(voxel_down_sample(local, 0.5 * voxel), 1.5 * voxel)
        n = cfg.detection_points
        if n and len(source) > n:
            source = source[:: int(np.ceil(len(source) / n))]
        res = detector.detect(matcher.reference, source, T_end)
        basis = "; ".join("(" + ", ".join(f"{v:+.2f}" for v in row) + ")" for row in res.basis_scaled)
        eig = ", ".join(f"{v:.2f}" for v in res.eigenvalues[:3]) if res.eigenvalues is not None else ""
        lines.append(f"| {t:g} | {T_end[0, 3]:.1f} | {len(source)} | {res.characteristic_length:.1f} | "
                     f"{res.dimension} | {eig} | {basis or '-'} |")
        print(lines[-1], flush=True)
    return lines + [""]


def _associated(run_dir: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
    t_e, T_g, T_e = _associated(run_dir)
    align = T_g[0] @ np.linalg.inv(T_e[0])  # both start at the same pose
    err = np.einsum("nij,njk->nik", np.linalg.inv(T_g), align @ T_e)
    return t_e - t_e[0], err


def _run_name(run_dir: Path) -> str:
    return f"`{run_dir.name}` of `{run_dir.parent.parent.name}/{run_dir.parent.name}`"


def errors(run_dir: Path, period: float) -> list[str]:
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
    print("\n".join(lines))
    return lines + [""]


def jumps(run_dir: Path, threshold: float) -> list[str]:
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
    print("\n".join(lines))
    return lines + [""]


def _true_accel_bias(trial: int, seed: int, stamps: np.ndarray) -> np.ndarray:
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
    stamps, T_true, T_est = _associated(run_dir)
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
        "true_bias": (_true_accel_bias(trial, seed, stamps)
                      if trial is not None and seed is not None else None),
    }


def tilt(run_dir: Path, period: float, trial: int | None, seed: int | None) -> list[str]:
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
    print("\n".join(lines))
    return lines + [""]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("probe", help="LiLi against a map from the true poses")
    p.add_argument("--times", type=float, nargs="+", default=[60, 130, 150, 200, 211, 250, 300])
    p.add_argument("--resolution", default="64x512")
    p.add_argument("--history", type=float, default=5.0, help="seconds of scans in the map")
    j = sub.add_parser("jumps", help="lateral error jumps of a run directory")
    j.add_argument("run_dir", type=Path)
    j.add_argument("--threshold", type=float, default=0.05, help="[m]")
    e = sub.add_parser("errors", help="error by component of a run directory")
    e.add_argument("run_dir", type=Path)
    e.add_argument("--period", type=float, default=20.0, help="table row every N s")
    g = sub.add_parser("tilt", help="roll/pitch against gravity, with the accelerometer bias")
    g.add_argument("run_dir", type=Path)
    g.add_argument("--period", type=float, default=20.0, help="table row every N s")
    g.add_argument("--trial", type=int, help="simulated trial of the bag (true bias)")
    g.add_argument("--seed", type=int, help="simulator seed of the bag (true bias)")
    for q in (p, j, e, g):
        q.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    if args.command == "probe":
        rows, cols = (int(v) for v in args.resolution.lower().split("x"))
        lines = probe(args.times, (rows, cols), args.history)
    else:
        if not (args.run_dir / "estimate.tum").exists() or not (args.run_dir / "truth.tum").exists():
            print(f"error: {args.run_dir}: needs estimate.tum and truth.tum", file=sys.stderr)
            return 2
        if args.command == "jumps":
            lines = jumps(args.run_dir, args.threshold)
        elif args.command == "errors":
            lines = errors(args.run_dir, args.period)
        else:
            try:
                lines = tilt(args.run_dir, args.period, args.trial, args.seed)
            except ValueError as exc:
                print(f"error: {exc}", file=sys.stderr)
                return 2
    args.out.parent.mkdir(parents=True, exist_ok=True)
    header = "" if args.out.exists() else (
        "# Tunnel diagnostics\n\nProduced by `benchmarks/arc_diagnostics.py` "
        "(see its docstring); one section per invocation.\n\n")
    with open(args.out, "a") as f:
        f.write(header + "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
