"""Scenarios of the suite as data: a world, a trial of it, a sensor profile and an error profile.

A scenario is one YAML file ``config/scenarios/<name>.yaml``::

    name: building                 # = the file name
    split: tuning                  # tuning | validation
    kind: building                 # scene kind (picks a peer preset): tunnel, corridor, building,
                                   # open, mine, warehouse
    description: ...
    world: building                # name under config/worlds, or a YAML path
    trial: 1                       # key of the world's trials
    start: 0.0                     # trial-time window [s]; duration null = to the end
    duration: null
    sensor: {model: OS1-64, cols: 1024}   # optional mount: [x, y, z, roll, pitch, yaw] (m, deg)
    errors: {wheel_scale_error: 0.03, slips: [{t: 20.0, duration: 0.6, gain: 0.25}]}
    seeds: [0, 1]
    ci: {start: 60.0, duration: 20.0, resolution: 32x512}   # optional short CI piece

``sensor.model`` names an Ouster family and channel count (``OS1-64``, ``OS0-128``); the fields
not given default to that family's datasheet values (``OUSTER_FAMILIES``). Every ``errors``
field not given keeps the simulator's model (a per-seed random wheel scale error, Poisson slips,
the Ouster IMU's datasheet noise and bias).

``scenario_request`` turns a scenario and a seed into a ``SimRequest``; ``scenario_bag`` returns
the cached rosbag2 bag (LiDAR ``/ouster/points``, IMU ``/ouster/imu``, wheels
``/platform/odom``, truth ``/ground_truth/odom``, extrinsics on ``/tf_static``).
"""
from __future__ import annotations

import dataclasses
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from lili_odom.sim.generator import SimRequest, ensure_bag
from lili_odom.sim.sensors import ImuConfig, parse_resolution
from lili_odom.sim.world import world_path

__all__ = [
    "OUSTER_FAMILIES",
    "SensorProfile",
    "Slip",
    "ErrorProfile",
    "CiPiece",
    "Scenario",
    "SPLITS",
    "scenario_dir",
    "scenario_names",
    "load_scenario",
    "load_scenarios",
    "scenario_request",
    "scenario_bag",
    "scenario_trajectory",
    "scenario_table",
]

SPLITS = ("tuning", "validation")

#: Ouster families (rev6 datasheets): vertical field of view [deg] (uniform beam spacing),
#: range on an 80 % target [m] and range noise sigma [m].
OUSTER_FAMILIES = {
    "OS0": {"elevation_max_deg": 45.0, "elevation_min_deg": -45.0, "max_range": 50.0, "range_sigma": 0.03},
    "OS1": {"elevation_max_deg": 22.5, "elevation_min_deg": -22.5, "max_range": 120.0, "range_sigma": 0.03},
    "OS2": {"elevation_max_deg": 11.25, "elevation_min_deg": -11.25, "max_range": 240.0, "range_sigma": 0.05},
}


@dataclass
class SensorProfile:
    """The LiDAR of a scenario: Ouster ``model`` (family-channels), ``rows`` x ``cols`` (10 Hz),
    vertical field of view [deg], range on an 80 % target ``max_range`` [m], range noise
    ``range_sigma`` [m], and its ``mount`` on the robot: ``base_link`` -> ``os_sensor`` as
    (x, y, z [m], roll, pitch, yaw [deg]), ``None`` for the Husky's mast mount (0.10 m forward,
    0.65 m up, level). Defaults: the simulator's OS1-128 x 1024 on the mast."""

    model: str = "OS1-128"
    rows: int = 128
    cols: int = 1024
    elevation_max_deg: float = 22.5
    elevation_min_deg: float = -22.5
    max_range: float = 120.0
    range_sigma: float = 0.03
    mount: tuple[float, ...] | None = None

    @classmethod
    def from_data(cls, data: dict | None) -> "SensorProfile":
        """Build from YAML data: the model's family and channel count fill the fields not given."""
        data = dict(data or {})
        unknown = set(data) - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise ValueError(f"sensor: unknown keys {sorted(unknown)}")
        model = str(data.get("model", cls.model))
        m = re.fullmatch(r"(OS[012])-(\d+)", model)
        if not m:
            raise ValueError(f"sensor model must look like OS1-64, got {model!r}")
        base = dict(OUSTER_FAMILIES[m.group(1)], rows=int(m.group(2)))
        base.update(data)
        base["model"] = model
        if base.get("mount") is not None:
            mount = base["mount"]
            if (not isinstance(mount, (list, tuple)) or len(mount) != 6
                    or not all(isinstance(v, (int, float)) and np.isfinite(v) for v in mount)):
                raise ValueError(f"sensor: mount must be [x, y, z, roll, pitch, yaw] (m, deg), got {mount!r}")
            base["mount"] = tuple(float(v) for v in mount)
        profile = cls(**base)
        if profile.rows < 1 or profile.cols < 8 or profile.elevation_max_deg <= profile.elevation_min_deg:
            raise ValueError(f"bad sensor profile {profile}")
        return profile

    @property
    def resolution(self) -> tuple[int, int]:
        return int(self.rows), int(self.cols)

    @property
    def label(self) -> str:
        """``OS1-64 x 1024`` style name; ``(own mount)`` appended when the scenario gives one."""
        label = f"{self.model.split('-')[0]}-{self.rows} x {self.cols}"
        return label if self.mount is None else label + " (own mount)"

    def base_to_sensor(self) -> tuple[float, ...] | None:
        """The mount as ``SimRequest.base_to_sensor`` (angles in radians), None for the mast."""
        if self.mount is None:
            return None
        x, y, z, roll, pitch, yaw = self.mount
        return (x, y, z, *np.deg2rad([roll, pitch, yaw]).tolist())

    def lidar_overrides(self) -> dict:
        """``LidarConfig`` field overrides (rows and cols travel as the request's resolution)."""
        return {"elevation_max_deg": float(self.elevation_max_deg), "elevation_min_deg": float(self.elevation_min_deg),
                "max_range": float(self.max_range), "range_sigma": float(self.range_sigma)}


@dataclass
class Slip:
    """A wheel slip: from trial time ``t`` [s] for ``duration`` [s] the measured speed over-reads
    by ``gain`` (0.25 = 25 %), with a small spurious yaw rate; only while the robot moves."""

    t: float
    duration: float = 0.5
    gain: float = 0.25


@dataclass
class ErrorProfile:
    """Wheel-odometry and IMU errors of a scenario.

    ``wheel_scale_error``: fixed speed scale error (0.03 = the wheels over-read speed by 3 %,
    -0.02 under-read); ``None`` draws one per seed (sigma 3 %). ``wheel_yaw_scale_error``: the
    same for the yaw rate (``None``: sigma 5 %). ``slips``: fixed slip events; ``None`` uses
    random ones at ``slip_rate_hz`` (``None``: the model's one per 40 s). ``wheel_outages``:
    [t0, t1) trial-time windows without wheel messages. ``imu``: ``ImuConfig`` field overrides
    (empty: the ICM-20948 datasheet noise and bias)."""

    wheel_scale_error: float | None = None
    wheel_yaw_scale_error: float | None = None
    slips: list[Slip] | None = None
    slip_rate_hz: float | None = None
    wheel_outages: list[tuple[float, float]] = field(default_factory=list)
    imu: dict[str, float] = field(default_factory=dict)

    @classmethod
    def from_data(cls, data: dict | None) -> "ErrorProfile":
        data = dict(data or {})
        unknown = set(data) - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise ValueError(f"errors: unknown keys {sorted(unknown)}")
        if data.get("slips") is not None:
            data["slips"] = [s if isinstance(s, Slip) else Slip(**s) for s in data["slips"]]
        data["wheel_outages"] = [tuple(float(v) for v in w) for w in data.get("wheel_outages") or []]
        for t0, t1 in data["wheel_outages"]:
            if not t1 > t0:
                raise ValueError(f"errors: wheel outage [{t0}, {t1}] is empty")
        imu_fields = {f.name for f in dataclasses.fields(ImuConfig)}
        bad = set(data.get("imu") or {}) - imu_fields
        if bad:
            raise ValueError(f"errors.imu: unknown ImuConfig fields {sorted(bad)}")
        data["imu"] = {k: float(v) for k, v in (data.get("imu") or {}).items()}
        return cls(**data)

    def wheel_overrides(self) -> dict:
        """``WheelOdomConfig`` field overrides."""
        out: dict = {}
        if self.wheel_scale_error is not None:
            out["scale_error"] = float(self.wheel_scale_error)
        if self.wheel_yaw_scale_error is not None:
            out["yaw_scale_error"] = float(self.wheel_yaw_scale_error)
        if self.slips is not None:
            out["slip_events"] = [[float(s.t), float(s.duration), float(s.gain)] for s in self.slips]
        if self.slip_rate_hz is not None:
            out["slip_rate_hz"] = float(self.slip_rate_hz)
        if self.wheel_outages:
            out["outages"] = [[float(a), float(b)] for a, b in self.wheel_outages]
        return out

    def label(self) -> str:
        """Short text: ``wheels +3.0 %, 3 slips, 1 outage``."""
        parts = ["wheels " + ("random scale" if self.wheel_scale_error is None else f"{100 * self.wheel_scale_error:+.1f} %")]
        if self.slips is not None:
            parts.append(f"{len(self.slips)} slip{'s' if len(self.slips) != 1 else ''}")
        else:
            parts.append("random slips")
        if self.wheel_outages:
            parts.append(f"{len(self.wheel_outages)} outage{'s' if len(self.wheel_outages) != 1 else ''}")
        if self.imu:
            parts.append("IMU " + ", ".join(f"{k}={v:g}" for k, v in self.imu.items()))
        return ", ".join(parts)


@dataclass
class CiPiece:
    """A short piece for the CI preset: trial-time window [s] and ``resolution`` (rows, cols)."""

    start: float
    duration: float
    resolution: tuple[int, int] = (32, 512)

    @classmethod
    def from_data(cls, data: dict | None) -> "CiPiece | None":
        if data is None:
            return None
        data = dict(data)
        unknown = set(data) - {"start", "duration", "resolution"}
        if unknown:
            raise ValueError(f"ci: unknown keys {sorted(unknown)}")
        res = data.get("resolution", "32x512")
        res = parse_resolution(res) if isinstance(res, str) else tuple(int(v) for v in res)
        return cls(start=float(data["start"]), duration=float(data["duration"]), resolution=res)


@dataclass
class Scenario:
    """One scenario of the suite (see the module docstring). ``distance`` [m] and
    ``duration_s`` [s] are those of the window driven with ``seeds[0]`` (filled on loading)."""

    name: str
    split: str
    kind: str
    description: str
    world: str
    trial: int = 1
    start: float = 0.0
    duration: float | None = None
    sensor: SensorProfile = field(default_factory=SensorProfile)
    errors: ErrorProfile = field(default_factory=ErrorProfile)
    seeds: list[int] = field(default_factory=lambda: [0])
    ci: CiPiece | None = None
    distance: float | None = None
    duration_s: float | None = None
    path: Path | None = None


_SCENARIO_KEYS = {"name", "split", "kind", "description", "world", "trial", "start", "duration", "sensor",
                  "errors", "seeds", "ci"}


def scenario_dir() -> Path:
    """``config/scenarios`` of the source tree, else of the installed share directory."""
    candidates = [
        Path(__file__).resolve().parents[2] / "config" / "scenarios",
        Path(sys.prefix) / "share" / "lili_odom" / "config" / "scenarios",
    ]
    for c in candidates:
        if c.is_dir():
            return c
    raise FileNotFoundError(f"no scenario directory (looked in {[str(c) for c in candidates]})")


def scenario_names() -> list[str]:
    """Names of the shipped scenarios, sorted."""
    return sorted(p.stem for p in scenario_dir().glob("*.yaml"))


def load_scenario(path: Path | str, *, measure: bool = True) -> Scenario:
    """Load one scenario file; with ``measure`` fill ``distance`` and ``duration_s``."""
    path = Path(path)
    data = yaml.safe_load(path.read_text()) or {}
    unknown = set(data) - _SCENARIO_KEYS
    if unknown:
        raise ValueError(f"{path.name}: unknown keys {sorted(unknown)}")
    missing = {"split", "kind", "world"} - set(data)
    if missing:
        raise ValueError(f"{path.name}: missing keys {sorted(missing)}")
    name = str(data.get("name", path.stem))
    if name != path.stem:
        raise ValueError(f"{path.name}: name {name!r} differs from the file name")
    if data["split"] not in SPLITS:
        raise ValueError(f"{path.name}: split must be one of {SPLITS}, got {data['split']!r}")
    world = str(data["world"])
    local = path.parent / world
    if local.suffix in (".yaml", ".yml") and local.exists():
        world = str(local)
    world_path(world)  # raises FileNotFoundError for an unknown world
    seeds = [int(s) for s in (data.get("seeds") or [0])]
    sc = Scenario(
        name=name, split=str(data["split"]), kind=str(data["kind"]), description=" ".join(str(data.get("description", "")).split()),
        world=world, trial=int(data.get("trial", 1)), start=float(data.get("start") or 0.0),
        duration=None if data.get("duration") is None else float(data["duration"]),
        sensor=SensorProfile.from_data(data.get("sensor")), errors=ErrorProfile.from_data(data.get("errors")),
        seeds=seeds, ci=CiPiece.from_data(data.get("ci")), path=path,
    )
    if measure:
        t0, t1, dist = _measure(sc, seeds[0])
        sc.distance, sc.duration_s = dist, t1 - t0
    return sc


def load_scenarios(names: list[str] | None = None, *, measure: bool = True) -> list[Scenario]:
    """The scenarios called ``names`` (all shipped ones when ``None``), in the given order.
    Unknown names raise ``ValueError`` listing the known ones."""
    known = scenario_names()
    names = known if names is None else list(names)
    bad = [n for n in names if n not in known]
    if bad:
        raise ValueError(f"unknown scenario(s) {', '.join(bad)}; known: {', '.join(known)}")
    d = scenario_dir()
    return [load_scenario(d / f"{n}.yaml", measure=measure) for n in names]


def scenario_request(scenario: Scenario, seed: int, *, ci: bool = False,
                     resolution: tuple[int, int] | str | None = None) -> SimRequest:
    """The simulation request of ``scenario`` with ``seed``: its window (or its CI piece with
    ``ci``), its sensor profile (``resolution`` overrides rows x cols) and error profile."""
    if ci and scenario.ci is None:
        raise ValueError(f"scenario {scenario.name!r} has no CI piece")
    if isinstance(resolution, str):
        resolution = parse_resolution(resolution)
    if ci:
        start, duration = scenario.ci.start, scenario.ci.duration
        res = resolution or scenario.ci.resolution
    else:
        start, duration = scenario.start, scenario.duration
        res = resolution or scenario.sensor.resolution
    errors = scenario.errors
    return SimRequest(
        world=scenario.world, trial=scenario.trial, seed=int(seed), resolution=tuple(int(v) for v in res),
        start=float(start), duration=duration,
        lidar=scenario.sensor.lidar_overrides(),
        imu=dict(errors.imu) or None,
        wheels=errors.wheel_overrides() or None,
        base_to_sensor=scenario.sensor.base_to_sensor(),
    )


def scenario_bag(scenario: Scenario, seed: int, *, ci: bool = False, resolution: tuple[int, int] | str | None = None,
                 cache_dir: Path | str | None = None, progress: bool = True, jobs: int | None = None) -> Path:
    """Path of the rosbag2 bag of ``scenario`` with ``seed`` (simulated on first use, then cached
    under ``cache_dir``, default ``$LILI_ODOM_SIM_CACHE``; the cache key holds the sensor and
    error profiles, the window, the world file and the simulator version)."""
    req = scenario_request(scenario, seed, ci=ci, resolution=resolution)
    rows, cols = req.resolution
    name = f"{scenario.name}{'_ci' if ci else ''}_{rows}x{cols}_seed{seed}"
    return ensure_bag(req, cache_dir, name, progress=progress, jobs=jobs)


def scenario_trajectory(scenario: Scenario, seed: int):
    """The ``Trajectory`` (truth of ``base_link`` in ``world``) of ``scenario`` with ``seed``."""
    from lili_odom.sim.generator import Simulation

    return Simulation(scenario_request(scenario, seed)).trajectory


def _measure(scenario: Scenario, seed: int, *, ci: bool = False) -> tuple[float, float, float]:
    """(t0, t1, distance [m]) of the scenario's window driven with ``seed``."""
    from lili_odom.sim.generator import Simulation

    sim = Simulation(scenario_request(scenario, seed, ci=ci))
    t0, t1 = sim.window()
    t = np.arange(t0, t1 + 1e-9, 0.05)
    p = sim.trajectory.pose(t)[:, :3, 3]
    return t0, t1, float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def scenario_table(scenarios: list[Scenario]) -> str:
    """Markdown table of ``scenarios``: name, split, kind, sensor, errors, distance, duration, CI
    piece and what makes each hard (the last sentence of its description starting "Hard:", else
    the description's first sentence)."""
    lines = ["| scenario | split | kind | sensor | errors | distance [m] | duration [s] | seeds | CI piece | what makes it hard |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for sc in scenarios:
        ci = "-" if sc.ci is None else (f"{sc.ci.start:g}-{sc.ci.start + sc.ci.duration:g} s, "
                                         f"{sc.ci.resolution[0]}x{sc.ci.resolution[1]}")
        hard = _hard_text(sc.description)
        lines.append(f"| `{sc.name}` | {sc.split} | {sc.kind} | {sc.sensor.label} | {sc.errors.label()} | "
                     f"{sc.distance:.0f} | {sc.duration_s:.0f} | {', '.join(str(s) for s in sc.seeds)} | {ci} | {hard} |")
    return "\n".join(lines) + "\n"


def _hard_text(description: str) -> str:
    m = re.search(r"Hard: (.*?)(?:\.(?:\s|$)|$)", description)
    if m:
        return m.group(1).strip()
    return description.split(". ")[0].strip().rstrip(".")
