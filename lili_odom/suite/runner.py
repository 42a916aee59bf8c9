"""Plan the suite's jobs, make their bags, run them on a backend and collect the rows.

The jobs are every (scenario, seed, method) of the request. With a backend that runs on this
machine (``prepares_bags``), the driver simulates each (scenario, seed) bag once (or finds it
in the simulator cache, keyed by content) and then submits the jobs that read it, so jobs of
earlier bags run while later bags are simulated. Rows are written to ``suite.json`` as they
finish (:class:`~lili_odom.suite.report.SuiteFile`), so an interrupted or failing suite keeps
every finished row; ``suite.md`` and the figures are written at the end (also after Ctrl-C).
"""
from __future__ import annotations

import logging
import time
from collections import OrderedDict
from concurrent.futures import CancelledError, Future, as_completed
from dataclasses import dataclass, field
from pathlib import Path

from lili_odom.suite.jobs import BagSpec, Job, error_row

log = logging.getLogger(__name__)

PRESETS = ("full", "ci")


@dataclass
class SuiteRequest:
    """What to run (the ``lili-odom suite`` options).

    Attributes:
        scenarios: scenario names (None: every scenario of the preset).
        preset: ``full`` (each scenario's own window and sensor) or ``ci`` (the scenarios with a
            CI piece, their short piece at its resolution, first seed only).
        methods: our methods and peers to run, in table order.
        split: ``tuning``, ``validation`` or ``all``.
        seeds: seeds to run (None: the scenario's own seeds; the first one with ``ci``).
        resolution: ``RxC`` overriding every scenario's sensor (None: the scenario's).
        bags: users' own bags (directories or ``.mcap``) run instead of / besides scenarios;
            scenario = the bag's name, split = ``user``.
        truth_topic: ground-truth topic (``nav_msgs/Odometry`` of base_link).
        config_path / overrides: configuration of our methods.
        rpe_segment_m: RPE segment [m].
        out: output directory (``suite.json``, ``suite.md``, figures).
        work_dir: per-run files (trajectories, our runner's outputs; default ``out/runs``).
        cache_dir: simulator cache (None: ``$LILI_ODOM_SIM_CACHE`` or ``data/sim``).
        resume: keep the successful rows of an existing ``suite.json`` and skip their jobs.
        command: the command line, recorded in the outputs.
    """

    out: Path
    scenarios: list[str] | None = None
    preset: str = "full"
    methods: list[str] = field(default_factory=lambda: ["none", "lili", "wheels"])
    split: str = "all"
    seeds: list[int] | None = None
    resolution: str | None = None
    bags: list[Path] = field(default_factory=list)
    truth_topic: str = "/ground_truth/odom"
    config_path: str | None = None
    overrides: list[tuple[str, str]] = field(default_factory=list)
    rpe_segment_m: float = 10.0
    cache_dir: str | None = None
    work_dir: Path | None = None
    resume: bool = False
    command: str = ""


@dataclass
class Target:
    """One (scenario, seed) bag and the identity of its rows."""

    scenario: str
    split: str
    kind: str
    seed: int
    bag: BagSpec
    info: dict


def select_scenarios(request: SuiteRequest) -> list:
    """The scenarios of the request (preset, names, split); raises ValueError for unknown
    names or an empty selection."""
    from lili_odom.suite.scenario import load_scenarios

    if request.preset not in PRESETS:
        raise ValueError(f"unknown preset {request.preset!r} (known: {', '.join(PRESETS)})")
    if request.bags and request.scenarios is None:
        return []
    scenarios = load_scenarios(request.scenarios)
    if request.preset == "ci":
        if request.scenarios is not None:
            missing = [s.name for s in scenarios if s.ci is None]
            if missing:
                raise ValueError(f"scenario(s) without a CI piece: {', '.join(missing)}")
        scenarios = [s for s in scenarios if s.ci is not None]
    if request.split != "all":
        scenarios = [s for s in scenarios if s.split == request.split]
    if not scenarios and not request.bags:
        raise ValueError("no scenario matches the selection")
    return scenarios


def plan_targets(request: SuiteRequest, scenarios: list) -> list[Target]:
    """One target per (scenario, seed), then one per user bag."""
    ci = request.preset == "ci"
    targets = []
    for sc in scenarios:
        seeds = request.seeds if request.seeds is not None else (sc.seeds[:1] if ci else sc.seeds)
        if ci:
            res = request.resolution or "x".join(str(v) for v in sc.ci.resolution)
        else:
            res = request.resolution or "x".join(str(v) for v in sc.sensor.resolution)
        info = {"kind": sc.kind, "description": sc.description,
                "sensor": f"{sc.sensor.model.split('-')[0]}-{res.replace('x', ' x ')}",
                "errors": sc.errors.label(), "world": Path(sc.world).stem,
                "window_s": ([sc.ci.start, sc.ci.start + sc.ci.duration] if ci
                             else [sc.start, None if sc.duration is None else sc.start + sc.duration])}
        for seed in seeds:
            targets.append(Target(sc.name, sc.split, sc.kind, int(seed),
                                  BagSpec(scenario=sc.name, seed=int(seed), ci=ci,
                                          resolution=request.resolution, cache_dir=request.cache_dir),
                                  info))
    for bag in request.bags:
        bag = Path(bag)
        name = bag.stem if bag.suffix == ".mcap" else bag.name
        targets.append(Target(name, "user", "user", 0, BagSpec(path=str(bag.resolve())),
                              {"kind": "user", "description": str(bag), "sensor": "", "errors": ""}))
    return targets


def plan_jobs(request: SuiteRequest, targets: list[Target]) -> list[Job]:
    work = Path(request.work_dir) if request.work_dir is not None else Path(request.out) / "runs"
    jobs = []
    for t in targets:
        run_dir = work / t.scenario / f"seed{t.seed}"
        for method in request.methods:
            jobs.append(Job(scenario=t.scenario, split=t.split, kind=t.kind, seed=t.seed,
                            method=method, bag=t.bag, out_dir=str(run_dir / method),
                            truth_path=str(run_dir / "truth.tum"),
                            config_path=request.config_path,
                            overrides=tuple((k, v) for k, v in request.overrides),
                            truth_topic=request.truth_topic,
                            rpe_segment_m=request.rpe_segment_m))
    return jobs


def run_suite(request: SuiteRequest, backend, *, progress: bool = True) -> dict:
    """Run the request on ``backend``; returns the suite document (as in ``suite.json``).

    KeyboardInterrupt cancels the outstanding jobs, writes what finished and re-raises.
    """
    from lili_odom.suite.report import SuiteFile, write_report

    scenarios = select_scenarios(request)
    targets = plan_targets(request, scenarios)
    jobs = plan_jobs(request, targets)
    out = Path(request.out)
    out.mkdir(parents=True, exist_ok=True)
    work = Path(request.work_dir) if request.work_dir is not None else out / "runs"
    suite = SuiteFile(out / "suite.json", backend=backend.name, command=request.command,
                      preset=request.preset, rpe_segment_m=request.rpe_segment_m,
                      scenarios={t.scenario: {"split": t.split, **t.info} for t in targets},
                      resume=request.resume, work_dir=work)
    done = suite.finished_keys()
    jobs = [j for j in jobs if (j.scenario, j.seed, j.method) not in done]
    by_target: "OrderedDict[tuple, list[Job]]" = OrderedDict()
    for j in jobs:
        by_target.setdefault((j.scenario, j.seed), []).append(j)
    bar = _Bar(len(jobs), enabled=progress)
    futures: dict[Future, Job] = {}
    t0 = time.perf_counter()
    interrupted = False
    try:
        for target in targets:
            key = (target.scenario, target.seed)
            if key not in by_target:
                continue
            target_jobs = by_target[key]
            if backend.prepares_bags:
                bar.status(f"bag {target.scenario} seed {target.seed}")
                try:
                    target.bag.resolve(progress=False, jobs=getattr(backend, "jobs", 1))
                except KeyboardInterrupt:
                    raise
                except Exception as exc:  # noqa: BLE001 - the bag's jobs fail, not the suite
                    reason = f"bag: {type(exc).__name__}: {exc}"
                    for j in target_jobs:
                        suite.add(error_row(j, reason))
                        bar.advance(j, failed=True)
                    continue
            for j in target_jobs:
                futures[backend.submit(j)] = j
            _collect(futures, suite, bar, block=False, report_to=out)
        bar.status("running")
        _collect(futures, suite, bar, block=True, report_to=out)
    except KeyboardInterrupt:
        interrupted = True
        backend.shutdown(cancel=True)
        _collect(futures, suite, bar, block=False)
    else:
        backend.shutdown()
    finally:
        bar.close()
        suite.set_wall_time(time.perf_counter() - t0)
        write_report(out, suite.document)
    if interrupted:
        raise KeyboardInterrupt
    return suite.document


def _collect(futures: dict, suite, bar, block: bool, report_to: Path | None = None) -> None:
    """Move finished futures' rows into the suite file (all of them with ``block``); with
    ``report_to``, rewrite the report each time a scenario's last job has finished."""
    from lili_odom.suite.report import write_report

    pending = list(futures)
    finished = as_completed(pending) if block else [f for f in pending if f.done()]
    for f in finished:
        job = futures.pop(f)
        try:
            row = f.result()
        except CancelledError:
            continue
        except Exception as exc:  # noqa: BLE001 - a backend failure is the job's failure
            row = error_row(job, f"{type(exc).__name__}: {exc}")
        suite.add(row)
        bar.advance(job, failed="error" in row)
        if report_to is not None and not any(j.scenario == job.scenario for j in futures.values()):
            try:
                write_report(report_to, suite.document)
            except Exception as exc:  # noqa: BLE001 - the final report is written anyway
                log.warning("interim report failed: %s", exc)


class _Bar:
    """A rich progress bar over jobs (or nothing)."""

    def __init__(self, total: int, enabled: bool) -> None:
        self._p = None
        self.failed = 0
        if enabled and total:
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                                       TimeElapsedColumn)

            self._p = Progress(TextColumn("suite"), BarColumn(), MofNCompleteColumn(),
                               TimeElapsedColumn(), TextColumn("{task.description}"))
            self._task = self._p.add_task("", total=total)
            self._p.start()

    def status(self, text: str) -> None:
        if self._p is not None:
            self._p.update(self._task, description=text)

    def advance(self, job: Job, failed: bool = False) -> None:
        self.failed += int(failed)
        if self._p is not None:
            note = f"{job.label}{' FAILED' if failed else ''}"
            self._p.update(self._task, advance=1, description=note)

    def close(self) -> None:
        if self._p is not None:
            self._p.stop()
