"""One suite job, (scenario, seed, method), and the row it produces.

A :class:`Job` holds everything a worker needs to run it anywhere (plain, picklable data):
where its bag comes from (:class:`BagSpec`), the method, the configuration of our odometry
and where to write its files. :func:`execute` runs a job and always returns a row: a failing
job becomes a row with ``error`` set to a one-line reason.

Row keys (``suite.json``): ``scenario``, ``split`` (``tuning`` | ``validation`` | ``user``),
``kind``, ``seed``, ``method``, ``ate_m``, ``rpe_pct``, ``final_m``, ``distance_m``,
``scans_per_s``, ``degenerate_fraction`` (null for peers), ``scans``, ``wall_s`` and, for a
failed job only, ``error`` (the metrics are then null). See :mod:`lili_odom.suite.scoring`
for the definitions of the metrics.
"""
from __future__ import annotations

import json
import logging
import math
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

log = logging.getLogger(__name__)

#: Keys every row carries (``error`` is added for failed jobs only).
ROW_KEYS = ("scenario", "split", "kind", "seed", "method", "ate_m", "rpe_pct", "final_m",
            "distance_m", "scans_per_s", "degenerate_fraction", "scans", "wall_s")
METRIC_KEYS = ("ate_m", "rpe_pct", "final_m", "distance_m", "scans_per_s",
               "degenerate_fraction", "scans", "wall_s")


@dataclass(frozen=True)
class BagSpec:
    """Where a job's bag comes from.

    Either a scenario to simulate (``scenario``, ``seed``, ``ci``, ``resolution`` as
    ``"RxC"`` or None for the scenario's own sensor), or an existing bag (``path``).
    """

    scenario: str = ""
    seed: int = 0
    ci: bool = False
    resolution: str | None = None
    path: str | None = None
    cache_dir: str | None = None

    def resolve(self, progress: bool = False, jobs: int | None = 1) -> Path:
        """The bag's path, simulating it first when it is not cached."""
        if self.path is not None:
            return Path(self.path)
        from lili_odom.suite.scenario import load_scenarios, scenario_bag
        from lili_odom.sim.sensors import parse_resolution

        (scenario,) = load_scenarios([self.scenario])
        resolution = parse_resolution(self.resolution) if self.resolution else None
        return Path(scenario_bag(scenario, self.seed, ci=self.ci, resolution=resolution,
                                 cache_dir=self.cache_dir, progress=progress, jobs=jobs))


@dataclass(frozen=True)
class Job:
    """One (scenario, seed, method) run.

    Attributes:
        scenario / split / kind / seed / method: identify the row.
        bag: where the bag comes from.
        out_dir: the job's own directory (estimate, logs; ours: the runner's outputs).
        truth_path: the run's ground truth in TUM format, shared by the jobs of one bag.
        config_path: ROS 2 parameter file for our methods (None: built-in defaults).
        overrides: ``(dotted.name, value)`` pairs applied on top (``--set``).
        truth_topic: ground-truth topic of the bag.
        rpe_segment_m: RPE segment length [m].
    """

    scenario: str
    split: str
    kind: str
    seed: int
    method: str
    bag: BagSpec
    out_dir: str
    truth_path: str
    config_path: str | None = None
    overrides: tuple[tuple[str, str], ...] = ()
    truth_topic: str = "/ground_truth/odom"
    rpe_segment_m: float = 10.0

    @property
    def label(self) -> str:
        return f"{self.scenario} s{self.seed} {self.method}"


def empty_row(job: Job) -> dict:
    """A row with the job's identity and every metric null."""
    row = {"scenario": job.scenario, "split": job.split, "kind": job.kind, "seed": job.seed,
           "method": job.method}
    row.update({k: None for k in METRIC_KEYS})
    return row


def error_row(job: Job, reason: str) -> dict:
    """The row of a failed job: metrics null, ``error`` = one line."""
    row = empty_row(job)
    row["error"] = " ".join(str(reason).split())[:500] or "failed"
    return row


def _finite_or_none(x) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def execute(job: Job) -> dict:
    """Run ``job`` in this process and return its row (never raises for a job's failure)."""
    from lili_odom.suite.methods import run_method
    from lili_odom.suite.scoring import score

    try:
        out_dir = Path(job.out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        bag = job.bag.resolve(progress=False)
        run = run_method(job, bag)
        if len(run.stamps) == 0:
            return error_row(job, "no pose estimated")
        if len(run.truth_stamps) == 0:
            return error_row(job, f"no ground truth on {job.truth_topic}")
        write_tum_atomic(Path(job.truth_path), run.truth_stamps, run.truth_poses)
        write_tum_atomic(out_dir / "estimate_base.tum", run.stamps, run.poses)
        metrics = score(run.stamps, run.poses, run.truth_stamps, run.truth_poses,
                        segment_m=job.rpe_segment_m)
    except KeyboardInterrupt:
        raise
    except BaseException as exc:  # noqa: BLE001 - every failure becomes a row
        from lili_odom.errors import UserError

        reason = str(exc) if isinstance(exc, UserError) else f"{type(exc).__name__}: {exc}"
        log.debug("job %s failed", job.label, exc_info=True)
        return error_row(job, reason)
    row = empty_row(job)
    row.update({k: _finite_or_none(v) for k, v in metrics.items() if k in METRIC_KEYS})
    row["scans"] = int(run.scans)
    row["wall_s"] = _finite_or_none(run.wall_s)
    row["scans_per_s"] = (_finite_or_none(run.scans / run.wall_s)
                          if run.scans and run.wall_s and run.wall_s > 0 else None)
    row["degenerate_fraction"] = _finite_or_none(run.degenerate_fraction)
    return row


def write_tum_atomic(path: Path, stamps, poses) -> None:
    """Write a TUM trajectory (stamp x y z qx qy qz qw) through a temporary file."""
    from lili_odom.bagio.tum import write_tum

    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}")
    write_tum(tmp, list(zip((float(s) for s in stamps), poses)))
    os.replace(tmp, path)


def job_to_dict(job: Job) -> dict:
    return asdict(job)


def job_from_dict(d: dict) -> Job:
    d = dict(d)
    d["bag"] = BagSpec(**d["bag"])
    d["overrides"] = tuple(tuple(x) for x in d.get("overrides", ()))
    return Job(**d)


def dumps_row(row: dict) -> str:
    return json.dumps(row, sort_keys=False)
