"""Generate a simulated Husky bag (LiDAR, IMU, wheels, truth, tf_static) and cache trials.

Public API:

* ``SimRequest`` — what to simulate (world, trial, seed, resolution, feature density, window,
  and optional overrides of the LiDAR, IMU and wheel-odometry models).
* ``sensors_for(request) -> SensorSuite`` — the sensor suite a request simulates.
* ``simulate_bag(request, out, progress=True, jobs=1) -> BagSummary`` — write one bag.
* ``ensure_bag(request, cache_dir=None, name=None) -> Path`` — generate or reuse a cached bag;
  the cache key holds every parameter (overrides included), the seed and the simulator code
  version (hash of the simulator sources and of the world file).
* ``ensure_trial_bag(trial, cache_dir=None, **request_fields) -> Path`` — the same for a trial
  with the default sensor models.

Time base: trial time t = 0 is mapped to ``EPOCH_NS`` (header stamps are ``EPOCH_NS + t``).
Messages are written in header-stamp order; a cloud's bag log time is its stamp + one scan
period (a real driver publishes a finished scan), all others are logged at their stamp.
"""
from __future__ import annotations

import dataclasses
import hashlib
import heapq
import json
import os
import shutil
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from lili_odom.extrinsics import pose_from_xyz_rpy
from lili_odom.sim import world as world_mod
from lili_odom.sim.bag_writer import TOPICS, SimBagWriter
from lili_odom.sim.imu import simulate_imu
from lili_odom.sim.lidar import LidarSimulator
from lili_odom.sim.mesh import build_mesh
from lili_odom.sim.ros_messages import MessageFactory
from lili_odom.sim.sensors import SensorSuite, default_sensors
from lili_odom.sim.trajectory import Trajectory
from lili_odom.sim.wheels import simulate_wheel_odom

__all__ = ["EPOCH_NS", "SimRequest", "BagSummary", "Simulation", "simulate_bag", "ensure_bag", "ensure_trial_bag",
           "default_cache_dir", "code_version", "cache_key", "sensors_for"]

EPOCH_NS = 1_700_000_000 * 1_000_000_000  # 2023-11-14T22:13:20Z, trial time 0


@dataclass
class SimRequest:
    """What to simulate. ``world``: name under config/worlds or a YAML path; ``trial``: key of
    the world's ``trials``; ``start`` / ``duration`` [s] cut a piece of the trial (trial time).

    ``lidar``, ``imu``, ``wheels``: field overrides of ``LidarConfig`` (rows and cols come from
    ``resolution``), ``ImuConfig`` and ``WheelOdomConfig``; ``None`` keeps the defaults.
    ``base_to_sensor``: the LiDAR's mount, ``base_link`` -> ``os_sensor`` as (x, y, z [m], roll,
    pitch, yaw [rad]); ``None`` keeps the Husky's mast mount (``HUSKY_BASE_TO_SENSOR``)."""

    world: str = "tunnel"
    trial: int = 1
    seed: int = 0
    resolution: tuple[int, int] = (128, 1024)
    feature_density: float | None = None
    start: float = 0.0
    duration: float | None = None
    lidar: dict | None = None
    imu: dict | None = None
    wheels: dict | None = None
    base_to_sensor: tuple[float, ...] | None = None


def _override(config, overrides: dict | None, forbidden: tuple[str, ...] = ()) -> None:
    """Set the fields named in ``overrides`` on the dataclass ``config`` (unknown names raise)."""
    names = {f.name for f in dataclasses.fields(config)}
    for key, value in (overrides or {}).items():
        if key not in names or key in forbidden:
            raise ValueError(f"{type(config).__name__} has no settable field {key!r}")
        if isinstance(value, list):
            value = tuple(tuple(v) if isinstance(v, list) else v for v in value)
        setattr(config, key, value)


def sensors_for(req: SimRequest) -> SensorSuite:
    """Sensor suite of ``req``: the defaults at ``req.resolution`` with the request's overrides."""
    suite = default_sensors(tuple(req.resolution))
    _override(suite.lidar, req.lidar, forbidden=("rows", "cols"))
    _override(suite.imu, req.imu)
    _override(suite.wheels, req.wheels)
    if req.base_to_sensor is not None:
        if len(req.base_to_sensor) != 6 or not np.all(np.isfinite(req.base_to_sensor)):
            raise ValueError(f"base_to_sensor must be 6 finite numbers, got {req.base_to_sensor!r}")
        suite.extrinsics.base_to_sensor = pose_from_xyz_rpy(req.base_to_sensor)
    return suite


@dataclass
class BagSummary:
    """What was written: path, message counts per topic, trial window [s], wall time [s]."""

    path: Path
    counts: dict[str, int]
    t_start: float
    t_end: float
    scans: int
    wall_time: float
    extra: dict = field(default_factory=dict)

    @property
    def scans_per_second(self) -> float:
        return self.scans / max(self.wall_time, 1e-9)


_SOURCES = ("world.py", "layout.py", "mesh.py", "trajectory.py", "lidar.py", "imu.py", "wheels.py",
            "sensors.py", "ros_messages.py", "bag_writer.py", "generator.py")


def code_version() -> str:
    """Hash of the simulator sources (changes whenever the simulated data could change)."""
    h = hashlib.sha256()
    here = Path(__file__).resolve().parent
    for name in _SOURCES:
        h.update((here / name).read_bytes())
    return h.hexdigest()[:16]


def cache_key(req: SimRequest) -> str:
    """Stable key of a request: parameters + seed + code version + world file content."""
    wpath = world_mod.world_path(req.world)
    payload = dataclasses.asdict(req)
    if payload["base_to_sensor"] is None:  # no mount: the same payload as before the field
        del payload["base_to_sensor"]
    payload["world"] = Path(req.world).stem
    payload["world_sha"] = hashlib.sha256(wpath.read_bytes()).hexdigest()[:16]
    payload["code"] = code_version()
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:12]


class Simulation:
    """Everything needed to produce the messages of one request (world, trajectory, sensors)."""

    def __init__(self, req: SimRequest, sensors: SensorSuite | None = None):
        self.req = req
        self.sensors = sensors or sensors_for(req)
        self.world = world_mod.load_world(req.world)
        if req.trial not in self.world.trials:
            raise ValueError(f"world {self.world.name!r} has no trial {req.trial} (has {sorted(self.world.trials)})")
        self.plan = self.world.trials[req.trial]
        self.trajectory = Trajectory(self.world, self.plan, seed=req.seed, husky=self.sensors.husky)
        self._lidar: LidarSimulator | None = None

    @property
    def lidar(self) -> LidarSimulator:
        if self._lidar is None:
            mesh = build_mesh(self.world, self.req.feature_density)
            self._lidar = LidarSimulator(self.sensors.lidar, mesh)
        return self._lidar

    def window(self) -> tuple[float, float]:
        t0 = max(0.0, float(self.req.start))
        t1 = self.trajectory.duration
        if self.req.duration is not None:
            t1 = min(t1, t0 + float(self.req.duration))
        if t1 <= t0:
            raise ValueError(f"empty time window: start {t0} s, trial lasts {self.trajectory.duration:.1f} s")
        return t0, t1

    def scan_starts(self) -> np.ndarray:
        """Start times of the scans that fit entirely in the window (on the 10 Hz grid)."""
        t0, t1 = self.window()
        P = self.sensors.lidar.scan_period
        k0 = int(np.ceil(t0 / P - 1e-9))
        k1 = int(np.floor((t1 - P) / P + 1e-9))
        return np.arange(k0, k1 + 1) * P

    def scan(self, t_start: float):
        """Simulated scan starting at trial time ``t_start``."""
        k = int(round(t_start / self.sensors.lidar.scan_period))
        T = self.trajectory.pose(t_start + self.lidar.column_times()) @ self.sensors.extrinsics.base_to_lidar
        rng = np.random.default_rng([self.req.seed, 7301, k])
        return self.lidar.scan(T, rng, stamp=t_start)


def _ns(t: float) -> int:
    return EPOCH_NS + int(round(t * 1e9))


# ---------------------------------------------------------------------------------------------
# parallel scan workers (each process builds its own Embree scene)
# ---------------------------------------------------------------------------------------------
_WORKER: dict = {}


def _worker_init(req: SimRequest) -> None:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    _WORKER["sim"] = Simulation(req)
    _WORKER["msgs"] = MessageFactory()


def _worker_scan(t_start: float) -> bytes:
    sim, msgs = _WORKER["sim"], _WORKER["msgs"]
    scan = sim.scan(t_start)
    return bytes(msgs.serialize(msgs.pointcloud2(scan, _ns(t_start))))


def simulate_bag(req: SimRequest, out: Path | str, progress: bool = True, jobs: int = 1,
                 zstd_level: int | None = SimBagWriter.DEFAULT_ZSTD_LEVEL) -> BagSummary:
    """Simulate ``req`` and write a rosbag2 MCAP bag directory at ``out`` (must not exist)."""
    out = Path(out)
    wall0 = time.perf_counter()
    sim = Simulation(req)
    S = sim.sensors
    msgs = MessageFactory()
    t0, t1 = sim.window()
    traj = sim.trajectory
    # IMU and wheels are always simulated over the whole trial, so a piece equals a window of it
    imu = simulate_imu(traj, S.extrinsics.base_to_imu, S.imu, req.seed)
    wheels = simulate_wheel_odom(traj, S.wheels, req.seed)
    t_truth = np.arange(0.0, traj.duration + 1e-9, 1.0 / S.truth_rate_hz)
    scan_t = sim.scan_starts()

    def sel(t):
        return np.where((t >= t0 - 1e-9) & (t <= t1 + 1e-9))[0]

    # event queue ordered by header stamp (ties: tf, imu, wheels, truth, cloud)
    events: list[tuple[int, int, int]] = []
    events.append((_ns(t0), 0, 0))
    events += [(_ns(imu.t[i]), 1, i) for i in sel(imu.t)]
    events += [(_ns(wheels.t[i]), 2, i) for i in sel(wheels.t) if wheels.published[i]]
    ti = sel(t_truth)
    events += [(_ns(t_truth[i]), 3, i) for i in ti]
    events += [(_ns(t), 4, k) for k, t in enumerate(scan_t)]
    heapq.heapify(events)

    # truth over the whole trial too (bit-identical values whatever the window)
    kin = traj.kinematics(t_truth)
    truth_row = {int(i): int(i) for i in ti}
    # orientations as quaternions, converted once for all messages
    truth_quat = Rotation.from_matrix(kin.rotation).as_quat()
    cw, sw = np.cos(wheels.yaw), np.sin(wheels.yaw)
    R_wheels = np.zeros((len(wheels.yaw), 3, 3))
    R_wheels[:, 0, 0], R_wheels[:, 0, 1], R_wheels[:, 1, 0], R_wheels[:, 1, 1], R_wheels[:, 2, 2] = cw, -sw, sw, cw, 1.0
    wheel_quat = Rotation.from_matrix(R_wheels).as_quat()

    gyro_var, accel_var = S.imu.gyro_sigma ** 2, S.imu.accel_sigma ** 2
    W = S.wheels
    wheel_pose_cov = np.diag([0.01, 0.01, 1e3, 1e3, 1e3, 0.03])
    wheel_twist_cov = np.diag([W.v_sigma**2 + (W.scale_sigma * 1.0) ** 2, 1e-3, 1e-3, 1e3, 1e3, W.w_sigma**2])
    E = S.extrinsics
    period_ns = int(round(S.lidar.scan_period * 1e9))

    if jobs > 1 and len(scan_t) > 1:
        import multiprocessing as mp

        pool = mp.get_context("spawn").Pool(jobs, initializer=_worker_init, initargs=(req,))

        def bounded(times, window=2 * jobs + 1):
            """Ordered results with at most ``window`` clouds in flight (bounded memory)."""
            pending = deque()
            for t in times:
                pending.append(pool.apply_async(_worker_scan, (float(t),)))
                if len(pending) >= window:
                    yield pending.popleft().get()
            while pending:
                yield pending.popleft().get()

        scan_iter = bounded(scan_t)
    else:
        pool = None
        scan_iter = (msgs.serialize(msgs.pointcloud2(sim.scan(float(t)), _ns(float(t)))) for t in scan_t)

    bar = None
    if progress:
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

        bar = Progress(TextColumn("simulating {task.description}"), BarColumn(),
                       TextColumn("{task.completed}/{task.total} scans"), TimeElapsedColumn(), TimeRemainingColumn())
        bar.start()
        task = bar.add_task(out.name, total=len(scan_t))
    try:
        with SimBagWriter(out, zstd_level=zstd_level) as bag:
            while events:
                stamp, kind, i = heapq.heappop(events)
                if kind == 0:
                    tf = msgs.tf_static(stamp, [
                        ("base_link", "os_sensor", E.base_to_sensor),
                        ("os_sensor", "os_lidar", E.sensor_to_lidar),
                        ("os_sensor", "os_imu", E.sensor_to_imu),
                    ])
                    bag.write("/tf_static", stamp, msgs.serialize(tf))
                elif kind == 1:
                    m = msgs.imu(stamp, imu.gyro[i], imu.accel[i], gyro_var, accel_var)
                    bag.write("/ouster/imu", stamp, msgs.serialize(m))
                elif kind == 2:
                    c, s_ = np.cos(wheels.yaw[i]), np.sin(wheels.yaw[i])
                    T = np.eye(4)
                    T[:2, :2] = [[c, -s_], [s_, c]]
                    T[0, 3], T[1, 3] = wheels.x[i], wheels.y[i]
                    m = msgs.odometry(stamp, "odom", "base_link", T, (wheels.v[i], 0.0, 0.0), (0.0, 0.0, wheels.w[i]),
                                      wheel_pose_cov, wheel_twist_cov, quat=wheel_quat[i])
                    bag.write("/platform/odom", stamp, msgs.serialize(m))
                elif kind == 3:
                    r = truth_row[i]
                    T = np.eye(4)
                    T[:3, :3] = kin.rotation[r]
                    T[:3, 3] = kin.position[r]
                    v_body = kin.rotation[r].T @ kin.velocity[r]
                    m = msgs.odometry(stamp, "world", "base_link", T, v_body, kin.omega[r], quat=truth_quat[r])
                    bag.write("/ground_truth/odom", stamp, msgs.serialize(m))
                else:
                    data = next(scan_iter)
                    bag.write("/ouster/points", stamp + period_ns, data)
                    if bar is not None:
                        bar.advance(task)
            counts = dict(bag.counts)
    finally:
        if bar is not None:
            bar.stop()
        if pool is not None:
            pool.terminate()
            pool.join()
    return BagSummary(path=out, counts=counts, t_start=t0, t_end=t1, scans=len(scan_t),
                      wall_time=time.perf_counter() - wall0,
                      extra={"wheel_scale": wheels.scale, "wheel_yaw_scale": wheels.yaw_scale,
                             "path_length_m": traj.path_length(), "trial_duration_s": traj.duration})


def default_cache_dir() -> Path:
    """``$LILI_ODOM_SIM_CACHE``, else ``data/sim`` of the source checkout (gitignored), else
    ``data/sim`` under the current directory."""
    env = os.environ.get("LILI_ODOM_SIM_CACHE")
    if env:
        return Path(env)
    root = Path(__file__).resolve().parents[2]
    if (root / "setup.py").exists() and (root / "lili_odom").is_dir():
        return root / "data" / "sim"
    return Path("data") / "sim"


def ensure_bag(req: SimRequest, cache_dir: Path | str | None = None, name: str | None = None, *,
               progress: bool = True, jobs: int | None = None) -> Path:
    """Return the path of a cached bag for ``req``, simulating it first if needed.

    The bag directory is ``<cache_dir>/<name>_<key>`` (``name`` defaults to
    ``<world>_trial<N>_<rows>x<cols>_seed<S>``); a JSON sidecar ``<dir>.json`` records the
    request and summary. Generation writes to a temporary directory and renames it at the end,
    so an interrupted run never leaves a bag that looks complete."""
    rows, cols = req.resolution
    name = name or f"{Path(req.world).stem}_trial{req.trial}_{rows}x{cols}_seed{req.seed}"
    name = f"{name}_{cache_key(req)}"
    cache_dir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    final = cache_dir / name
    if (final / "metadata.yaml").exists():
        return final
    cache_dir.mkdir(parents=True, exist_ok=True)
    tmp = cache_dir / f".{name}.partial-{os.getpid()}"
    if tmp.exists():
        shutil.rmtree(tmp)
    jobs = jobs if jobs is not None else min(2, os.cpu_count() or 1)
    summary = simulate_bag(req, tmp, progress=progress, jobs=jobs)
    # the mcap file is named after its directory; keep it consistent after the rename
    (tmp / f"{tmp.name}.mcap").rename(tmp / f"{name}.mcap")
    meta = tmp / "metadata.yaml"
    meta.write_text(meta.read_text().replace(f"{tmp.name}.mcap", f"{name}.mcap"))
    if final.exists():  # a concurrent run finished first
        shutil.rmtree(tmp)
    else:
        tmp.rename(final)
    sidecar = {"request": dataclasses.asdict(req), "code_version": code_version(),
               "counts": summary.counts, "window_s": [summary.t_start, summary.t_end],
               "wall_time_s": summary.wall_time, **summary.extra}
    (cache_dir / f"{name}.json").write_text(json.dumps(sidecar, indent=2, default=str))
    return final


def ensure_trial_bag(trial: int, cache_dir: Path | str | None = None, *, world: str = "tunnel", seed: int = 0,
                     resolution: tuple[int, int] | str = (128, 1024), feature_density: float | None = None,
                     start: float = 0.0, duration: float | None = None, progress: bool = True,
                     jobs: int | None = None) -> Path:
    """``ensure_bag`` for a trial of ``world`` with the default sensor models: the bag directory
    is ``<cache_dir>/<world>_trial<N>_<rows>x<cols>_seed<S>_<key>``."""
    from lili_odom.sim.sensors import parse_resolution

    if isinstance(resolution, str):
        resolution = parse_resolution(resolution)
    req = SimRequest(world=world, trial=int(trial), seed=int(seed), resolution=tuple(resolution),
                     feature_density=feature_density, start=float(start), duration=duration)
    return ensure_bag(req, cache_dir, progress=progress, jobs=jobs)
