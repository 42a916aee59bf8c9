"""Speed of the odometry on full OS1-128 scans into benchmarks/results/speed.{md,json}.

    python -m benchmarks.speed                        # 300 scans from 90 s and from 5 s of Trial 1
    python -m benchmarks.speed --scans 30 --start 90 --methods kiss lili
    python -m benchmarks.speed --set lili.return_ratio=0 --name speed_paper   # other settings
    python -m benchmarks.speed --previous old/speed.json   # also show an earlier run's figures

On the same scans of the simulated tunnel Trial 1 (128 x 1024, seed 0; one piece per window,
from the simulator cache, generated first if absent, about 30 s each), one after the other, each in its own fresh
process so that the peak RSS is per method:

* ``kiss``: KISS-ICP alone, ``KissICP.register_frame`` on the parsed points (range 1-100 m,
  our voxel size, deskewing with its constant-velocity model, per-point times in [0, 1]);
* ``none``, ``zhang``, ``hessian``, ``lili``: our pipeline through the replay loop
  (:class:`lili_odom.evaluation.replay.Replay`, exactly as ``lili-odom run`` drives it) with
  that detector; its timing hooks give the stages.

Each window starts ``--start`` seconds into the trial (default: 90 s, a featureless,
degenerate stretch, and 5 s, the cluttered entrance). IMU and wheel messages from
``gravity_window_s + 0.5`` s before the window are fed so the estimator initialises as it
would on a robot; ``/tf_static`` is fed first. The bag is read and decoded message by message
*outside* the timings; what is timed is what the node does per message: cloud parsing
(``messages.scan_from_msg``), IMU/wheel buffering and the pipeline stages. The first
``--warmup`` scans (local map filling up, first scan without detector) are run but not counted.

Reported per method: scans/s (timed scans / time spent in the feeder, resp. in parsing plus
``register_frame`` for KISS-ICP), mean and p95 per-stage times [ms] (parse, predict, deskew
incl. voxelisation, ICP, detector, iSAM2, map update, total = parse + pipeline), the time
ratio to KISS-ICP alone, peak RSS, and the targets: ``lili`` >= 10 scans/s (the OS1 spins at
10 Hz), the LiLi detector <= 50 ms per scan on average, ``lili`` at most 2x KISS-ICP's time.
The machine (CPU, cores), the git commit (and uncommitted changes under ``lili_odom/``) and
the load other processes put on the machine during the run are recorded with the figures.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import (RESULTS, ROOT, SET_HELP, apply_set, machine_info, parse_set,
                                write_results)
from lili_odom.evaluation.timing import median_run

METHODS = ("kiss", "none", "zhang", "lili")
ALL_METHODS = ("kiss", "none", "zhang", "hessian", "lili")
STAGES = ("parse", "predict", "deskew", "icp", "detector", "fusion", "map", "total")
STAGE_TITLES = {"parse": "parse", "predict": "predict", "deskew": "deskew", "icp": "ICP",
                "detector": "detector", "fusion": "iSAM2", "map": "map", "total": "total"}
KISS_STAGES = ("parse", "deskew", "icp", "map", "total")  # the others do not exist in KISS-ICP
TARGET_SCANS_PER_S = 10.0
GOAL_SCANS_PER_S = 20.0
TARGET_DETECTOR_MS = 50.0
TARGET_KISS_RATIO = 2.0
WINDOW_NAMES = {90.0: "featureless tunnel (degenerate)", 5.0: "entrance (not degenerate)"}
#: The report's pointer to the per-resolution reports beside it.
SEE_ALSO = ("Whole runs at every resolution of the scenario suite (32, 64 and 128 beams; 512, "
            "1024 and 2048 columns): `lili-odom run` against KISS-ICP's own pipeline on the "
            "same bag, side by side in one benchmark, target at most 1.5x KISS-ICP's wall time, "
            "in [`speed_resolutions.md`](speed_resolutions.md) (`python -m "
            "benchmarks.speed_resolutions`); the node's latency and drops at 10 Hz in "
            "[`node_latency.md`](node_latency.md) (`python -m benchmarks.node_latency`).")


# ----------------------------------------------------------------------------- one method

def _window_reader(bag: Path, topics: list[str], log_start: float):
    """A :class:`BagReader` whose header-stamp-ordered iteration starts at ``log_start`` [s]."""
    from lili_odom.bagio.reader import BagReader

    class WindowReader(BagReader):
        def raw_messages(self, start: float | None = None):
            return super().raw_messages(log_start if start is None else start)

    return WindowReader(bag, topics=topics, required=[topics[0]])


def _tf_static(bag: Path):
    """The bag's first ``/tf_static`` message (None when it has none)."""
    from lili_odom.bagio.reader import BagReader

    with BagReader(bag, topics=["/tf_static"], required=[]) as reader:
        for item in reader:
            return item.msg
    return None


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux


def _kiss_icp(config: Any, stage_acc: dict[str, float]):
    """KISS-ICP's own pipeline with our scan matcher settings, its building blocks timed into
    ``stage_acc`` (deskew, icp, map) [s]."""
    from kiss_icp.config import KISSConfig
    from kiss_icp.kiss_icp import KissICP

    sm = config.pipeline.scan_matcher
    kc = KISSConfig()
    kc.data.max_range = sm.max_range
    kc.data.min_range = sm.min_range
    kc.data.deskew = True
    kc.mapping.voxel_size = sm.voxel
    kc.mapping.max_points_per_voxel = sm.max_points_per_voxel
    kc.registration.max_num_iterations = sm.max_iterations
    kc.registration.convergence_criterion = sm.convergence
    kc.registration.max_num_threads = sm.max_threads
    kc.adaptive_threshold.initial_threshold = sm.initial_threshold
    kc.adaptive_threshold.min_motion_th = sm.min_motion_th
    kiss = KissICP(kc)

    def timed(fn, stage):
        def wrapper(*a, **kw):
            t0 = time.perf_counter()
            try:
                return fn(*a, **kw)
            finally:
                stage_acc[stage] = stage_acc.get(stage, 0.0) + time.perf_counter() - t0
        return wrapper

    # KissICP.register_frame itself, with its building blocks timed in place
    kiss.preprocessor.preprocess = timed(kiss.preprocessor.preprocess, "deskew")
    kiss.voxelize = timed(kiss.voxelize, "deskew")
    kiss.registration.align_points_to_map = timed(kiss.registration.align_points_to_map, "icp")
    kiss.adaptive_threshold.update_model_deviation = timed(
        kiss.adaptive_threshold.update_model_deviation, "map")
    kiss.local_map.update = timed(kiss.local_map.update, "map")
    return kiss


def _window_items(bag: Path, config: Any, start: float, scans: int):
    """The bag's messages for one window: ``/tf_static`` first, IMU and wheels from
    ``gravity_window_s + 0.5`` s before the window (so the estimator initialises as on a
    robot), clouds from ``start`` s on, at most ``scans`` of them (then the IMU / wheel
    messages continue)."""
    topics = [config.lidar_topic, config.imu_topic, config.wheel_topic]
    tf_msg = _tf_static(bag)
    with _window_reader(bag, topics, 0.0) as probe:
        t_bag0 = probe.start_time
    t_window = t_bag0 + start
    lead = config.pipeline.fusion.gravity_window_s + 0.5
    if tf_msg is not None:
        yield "/tf_static", tf_msg
    with _window_reader(bag, topics, max(t_bag0, t_window - lead)) as reader:
        for item in reader:
            if item.topic == config.lidar_topic and item.stamp < t_window - 1e-6:
                continue
            yield item.topic, item.msg


def run_method(bag: Path | str, method: str, start: float, scans: int, warmup: int,
               progress: bool = False, overrides: dict[str, str] | None = None
               ) -> dict[str, Any]:
    """Run ``method`` over ``scans`` scans from ``start`` s into the bag, in this process.

    Our methods run through the replay loop (:class:`lili_odom.evaluation.replay.Replay`), its
    timing hooks giving the per-stage times and the time spent in the feeder.

    Returns a JSON-ready dict: scans, scans_per_s, stages (mean/p95/max ms or None),
    rss_peak_mb, rss_setup_mb, degenerate_fraction, counters.
    """
    from lili_odom import geometry, messages
    from lili_odom.config import load_config
    from lili_odom.evaluation.replay import Replay
    from lili_odom.evaluation.timing import stage_stats

    logging.basicConfig(level=logging.ERROR)
    bag = Path(bag)
    config = load_config(None)
    if method != "kiss":
        config.pipeline.method = method
        apply_set(config, overrides or {}, "speed")
    config.validate()
    sm = config.pipeline.scan_matcher

    per_scan: dict[str, list[float]] = {k: [] for k in STAGES}
    dims: list[int] = []
    n_out = 0
    timed_s = 0.0  # time spent in the timed region (after the warm-up scans)
    t_report = time.monotonic()

    def record(timings: dict[str, float], dim: int) -> None:
        nonlocal n_out, t_report
        n_out += 1
        if progress and time.monotonic() - t_report > 10.0:
            t_report = time.monotonic()
            print(f"    {method} @ {start:g} s: {n_out}/{scans} scans", file=sys.stderr,
                  flush=True)
        if n_out <= warmup:
            return
        for k, v in timings.items():
            if k in per_scan:
                per_scan[k].append(v)
        dims.append(dim)

    counters: dict[str, int] = {}
    fed = 0
    if method == "kiss":
        stage_acc: dict[str, float] = {}
        kiss = _kiss_icp(config, stage_acc)
        parse_fn = messages.default_cloud_parser(sm.min_range, sm.max_range)
        rss_setup = _rss_mb()
        for topic, msg in _window_items(bag, config, start, scans):
            if topic != config.lidar_topic:
                continue
            if fed >= scans:
                break
            fed += 1
            stage_acc.clear()
            t0 = time.perf_counter()
            scan = messages.scan_from_msg(msg, parse_fn)
            t1 = time.perf_counter()
            # the same input guard as the pipeline's (OdometryPipeline.process_scan)
            pts, t = scan.points, scan.times
            bad = geometry.nonfinite_rows(pts)
            if bad is not None:
                pts, t = pts[~bad], (None if t is None or len(t) != len(bad) else t[~bad])
            times = np.zeros(0)
            if t is not None and len(t) == len(pts):
                if len(t) and np.all(np.isfinite(t)) and np.ptp(t) > 0:
                    times = (t - t.min()) / np.ptp(t)
            kiss.register_frame(pts, times)
            t2 = time.perf_counter()
            record({"parse": t1 - t0, "total": t2 - t0,
                    **{k: stage_acc.get(k, 0.0) for k in ("deskew", "icp", "map")}}, 0)
            if n_out > warmup:
                timed_s += t2 - t0
    else:
        counting = warmup <= 0  # decided before each feeder call, as the call starts

        def on_call(seconds: float) -> None:
            nonlocal timed_s, counting
            if counting:
                timed_s += seconds
            counting = n_out >= warmup

        replay = Replay(config, on_call=on_call,
                        on_timings=lambda out, t: record(
                            t, out.degeneracy.dimension if out.degeneracy is not None else 0))
        rss_setup = _rss_mb()
        replay.run(_window_items(bag, config, start, scans), max_scans=scans)
        fed = replay.clouds_in
        counters = {k: int(v) for k, v in replay.pipeline.counters.items()}
    n = len(per_scan["total"])
    stages = KISS_STAGES if method == "kiss" else STAGES
    return {
        "method": method,
        "start_s": start,
        "scans_fed": fed,
        "scans_processed": n_out,
        "scans_timed": n,
        "warmup": warmup,
        "timed_s": timed_s,
        "scans_per_s": n / timed_s if timed_s > 0 else float("nan"),
        "stages": stage_stats(per_scan, STAGES, stages),
        "rss_peak_mb": _rss_mb(),
        "rss_setup_mb": rss_setup,
        "degenerate_fraction": float(np.mean(np.asarray(dims) > 0)) if dims else 0.0,
        "counters": counters,
    }


# ----------------------------------------------------------------------------- machine

def _cpu_jiffies() -> list[int]:
    """The machine's CPU time fields from /proc/stat (user, nice, system, idle, iowait, irq,
    softirq, steal, ...) [jiffies]."""
    return [int(x) for x in Path("/proc/stat").read_text().splitlines()[0].split()[1:]]


def _cpu_busy_jiffies() -> tuple[int, int]:
    """(busy, total) jiffies of the whole machine from /proc/stat; busy leaves out idle,
    iowait and steal (time the hypervisor gave to other guests, :func:`steal_cores`)."""
    f = _cpu_jiffies()
    idle = f[3] + (f[4] if len(f) > 4 else 0)
    return sum(f) - idle - _steal(f), sum(f)


def _steal(fields: list[int]) -> int:
    return fields[7] if len(fields) > 7 else 0


def steal_jiffies() -> int:
    """Jiffies the hypervisor has taken from this virtual machine since boot (0 on bare metal
    or where the kernel does not count it)."""
    return _steal(_cpu_jiffies())


def steal_cores(steal0: int, wall: float) -> float:
    """Mean cores the hypervisor took from this machine since ``steal0``
    (:func:`steal_jiffies`) over ``wall`` seconds: a virtual machine's cores that ran another
    guest, so every process here ran slower."""
    if wall <= 0:
        return 0.0
    return max(0.0, (steal_jiffies() - steal0) / os.sysconf("SC_CLK_TCK") / wall)


def _other_load(busy0: int, children0, wall: float) -> float:
    """Mean cores used by other processes since ``busy0`` (machine jiffies) and ``children0``
    (our children's rusage) over ``wall`` seconds."""
    if wall <= 0:
        return 0.0
    busy1, _ = _cpu_busy_jiffies()
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    ours = (c1.ru_utime + c1.ru_stime) - (children0.ru_utime + children0.ru_stime)
    return max(0.0, ((busy1 - busy0) / os.sysconf("SC_CLK_TCK") - ours) / wall)


def _other_processes(min_cpu: float = 10.0, limit: int = 6) -> list[str]:
    """The busiest other processes (lifetime %CPU >= min_cpu), paths reduced to file names."""
    try:
        out = subprocess.run(["ps", "-eo", "pid=,pcpu=,args="], capture_output=True, text=True,
                             timeout=20).stdout
    except (OSError, subprocess.SubprocessError):
        return []
    mine = {os.getpid(), os.getppid()}
    rows = []
    for line in out.splitlines():
        parts = line.split(None, 2)
        if len(parts) < 3:
            continue
        pid, cpu, args = int(parts[0]), float(parts[1]), parts[2]
        if pid in mine or cpu < min_cpu or args.startswith("ps "):
            continue
        words = [Path(w).name if "/" in w else w for w in args.split()][:6]
        rows.append((cpu, f"{cpu:.0f} % {' '.join(words)}"))
    return [r for _, r in sorted(rows, reverse=True)[:limit]]


class LoadMeter:
    """The machine's load while a benchmark runs: started at construction, read by
    :meth:`report` (JSON-ready: load averages before / after, wall time [s], mean cores used
    by other processes and taken by the hypervisor, the busiest other processes at the
    start)."""

    def __init__(self) -> None:
        self._busy0, _ = _cpu_busy_jiffies()
        self._children0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        self._load0 = os.getloadavg()
        self._others0 = _other_processes()
        self._steal0 = steal_jiffies()
        self._t0 = time.monotonic()

    def report(self) -> dict:
        wall = time.monotonic() - self._t0
        return {"loadavg_before": list(self._load0), "loadavg_after": list(os.getloadavg()),
                "wall_s": wall, "other_processes_cores": _other_load(self._busy0,
                                                                     self._children0, wall),
                "steal_cores": steal_cores(self._steal0, wall),
                "other_processes_at_start": self._others0}


def machine_load_lines(m: dict, load: dict) -> list[str]:
    """Markdown lines naming the machine and commit (``machine_info()``) and the load
    (:meth:`LoadMeter.report`)."""
    dirty = m["uncommitted_lili_odom"]
    return [
        f"Machine: {m['cpu']}, {m['cores']} cores, Python {m['python']}; commit `{m['commit']}`"
        + (f" with uncommitted changes in {', '.join('`' + p + '`' for p in dirty)}"
           if dirty else "") + ".",
        "",
        f"Load: load average {load['loadavg_before'][0]:.2f} before, "
        f"{load['loadavg_after'][0]:.2f} after; other processes used "
        f"{load['other_processes_cores']:.2f} of {m['cores']} cores on average during the "
        f"{load['wall_s'] / 60:.1f} min run"
        + (f", the hypervisor took {load['steal_cores']:.2f} (steal time)"
           if "steal_cores" in load else "")
        + ("; busy at the start: " + "; ".join(f"`{p}`" for p in load["other_processes_at_start"])
           if load["other_processes_at_start"] else "") + ".",
    ]


# ----------------------------------------------------------------------------- driver

def _run_in_fresh_process(bag: Path, method: str, start: float, scans: int, warmup: int,
                          progress: bool, overrides: dict[str, str] | None = None
                          ) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="lili_speed_") as tmp:
        out = Path(tmp) / "result.json"
        cmd = [sys.executable, "-m", "benchmarks.speed", "--worker", str(out), "--bag", str(bag),
               "--methods", method, "--start", repr(start), "--scans", str(scans),
               "--warmup", str(warmup)]
        if not progress:
            cmd.append("--no-progress")
        for key, value in (overrides or {}).items():
            cmd += ["--set", f"{key}={value}"]
        proc = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=None, text=True)
        if proc.returncode != 0 or not out.exists():
            raise RuntimeError(f"{method} @ {start:g} s failed (exit {proc.returncode}): "
                               f"{proc.stdout[-2000:]}")
        return json.loads(out.read_text())


def _targets(results: dict[str, dict]) -> dict[str, Any]:
    lili, kiss = results.get("lili"), results.get("kiss")
    t: dict[str, Any] = {}
    if lili is not None:
        t["lili_scans_per_s"] = {"value": lili["scans_per_s"], "target": TARGET_SCANS_PER_S,
                                 "goal": GOAL_SCANS_PER_S,
                                 "met": lili["scans_per_s"] >= TARGET_SCANS_PER_S}
        det = lili["stages"]["detector"]["mean_ms"]
        t["lili_detector_mean_ms"] = {"value": det, "target": TARGET_DETECTOR_MS,
                                      "met": det <= TARGET_DETECTOR_MS}
        if kiss is not None:
            ratio = kiss["scans_per_s"] / lili["scans_per_s"]
            t["lili_time_vs_kiss"] = {"value": ratio, "target": TARGET_KISS_RATIO,
                                      "met": ratio <= TARGET_KISS_RATIO}
    return t


def benchmark(bag: Path | str | dict, methods=METHODS, starts=(90.0, 5.0), scans: int = 300,
              warmup: int = 10, progress: bool = True,
              overrides: dict[str, str] | None = None, repeats: int = 1) -> dict[str, Any]:
    """Every method on every window, each in a fresh process; the JSON-ready results.

    ``bag`` is one bag holding every window (``starts`` are seconds into it), or a dict
    ``{start: (piece bag, offset of the window in that bag [s])}``. With ``repeats`` > 1 the
    methods run in turn that many rounds per window (so a load change hits all of them), and
    each method is reported by its run with the median scans/s.
    """
    pieces = bag if isinstance(bag, dict) else {s: (Path(bag), s) for s in starts}
    meter = LoadMeter()
    windows = []
    for start in starts:
        runs: dict[str, list[dict]] = {m: [] for m in methods}
        for round_ in range(repeats):
            for method in methods:
                tag = f"[{start:g} s]" + (f" round {round_ + 1}/{repeats}" if repeats > 1 else "")
                if progress:
                    print(f"{tag} {method}: {scans} scans ...", flush=True)
                b0, _ = _cpu_busy_jiffies()
                c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
                w0 = time.monotonic()
                piece, offset = pieces[start]
                r = _run_in_fresh_process(piece, method, float(offset), scans, warmup,
                                          progress, overrides)
                r["other_load_cores"] = _other_load(b0, c0, time.monotonic() - w0)
                runs[method].append(r)
                if progress:
                    tot = r["stages"]["total"]
                    det = r["stages"]["detector"]
                    print(f"{tag} {method}: {r['scans_per_s']:.1f} scans/s, total "
                          f"{tot['mean_ms']:.1f} ms (p95 {tot['p95_ms']:.1f})"
                          + (f", detector {det['mean_ms']:.1f} ms" if det else "")
                          + f", peak RSS {r['rss_peak_mb']:.0f} MB", flush=True)
        res = {m: median_run(rs) for m, rs in runs.items()}
        kiss = res.get("kiss")
        for m, r in res.items():
            r["time_vs_kiss"] = (kiss["scans_per_s"] / r["scans_per_s"]) if kiss else None
            # the same ratio within each round (runs next to each other in time)
            r["repeats_time_vs_kiss"] = ([k["scans_per_s"] / x["scans_per_s"]
                                          for k, x in zip(runs["kiss"], runs[m])]
                                         if kiss else None)
        windows.append({"start_s": float(start), "name": WINDOW_NAMES.get(float(start), ""),
                        "methods": res, "targets": _targets(res), "repeats": repeats})
    return {
        "bag": ", ".join(sorted({Path(b).name for b, _ in pieces.values()})),
        "scans": scans,
        "warmup": warmup,
        "methods": list(methods),
        "overrides": dict(overrides or {}),
        "machine": machine_info(),
        "load": meter.report(),
        "windows": windows,
    }


# ----------------------------------------------------------------------------- report

def _fmt(x: float | None, digits: int = 1) -> str:
    return "–" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


def previous_summary(previous: dict[str, Any]) -> dict[str, Any]:
    """The figures of an earlier ``speed.json`` that the report shows next to the new ones:
    per window (start [s]) and method scans/s, x KISS and mean parse / deskew / detector /
    total [ms]; with that run's commit and the other processes' load."""
    windows = {}
    for w in previous["windows"]:
        rows = {}
        for name, r in w["methods"].items():
            st = r["stages"]
            rows[name] = {"scans_per_s": r["scans_per_s"], "time_vs_kiss": r.get("time_vs_kiss"),
                          **{f"{k}_ms": (st[k]["mean_ms"] if st.get(k) else None)
                             for k in ("parse", "deskew", "detector", "total")}}
            if st.get("detector"):
                rows[name]["detector_p95_ms"] = st["detector"]["p95_ms"]
        windows[f"{w['start_s']:g}"] = rows
    return {"commit": previous["machine"]["commit"],
            "other_processes_cores": previous["load"]["other_processes_cores"],
            "windows": windows}


def _previous_lines(prev: dict[str, Any], start: float, methods) -> list[str]:
    rows = prev["windows"].get(f"{start:g}")
    if not rows:
        return []
    cells = []
    for name in methods:
        r = rows.get(name)
        if r is None:
            continue
        label = "KISS-ICP" if name == "kiss" else f"`{name}`"
        extra = (f", detector {_fmt(r['detector_ms'])} / {_fmt(r.get('detector_p95_ms'))} ms"
                 if name not in ("kiss", "none") and r.get("detector_ms") is not None else "")
        cells.append(f"{label} {_fmt(r['scans_per_s'])} scans/s ({_fmt(r['time_vs_kiss'], 2)}x"
                     f" KISS; parse {_fmt(r['parse_ms'])}, deskew {_fmt(r['deskew_ms'])}{extra}, "
                     f"total {_fmt(r['total_ms'])} ms)")
    return ["", f"Before (commit `{prev['commit']}`, same command, other load "
                f"{prev['other_processes_cores']:.2f} cores): " + "; ".join(cells) + "."]


def markdown(report: dict[str, Any], command: str) -> str:
    m, load = report["machine"], report["load"]
    lines = [
        "# Odometry speed on full OS1-128 scans (issue #5)",
        "",
        SEE_ALSO,
        "",
        f"`{command}`: {report['scans']} scans of `{report['bag']}` per window and method "
        f"(the first {report['warmup']} not counted), each method in its own fresh process, "
        "one after the other. The bag is decoded outside the timings; timed is what the node "
        "does: parsing the PointCloud2, IMU/wheel buffering and the pipeline stages."
        + (" Our pipeline runs with " + ", ".join(f"`pipeline.{k}={v}`"
                                                  for k, v in report["overrides"].items())
           + " instead of the defaults." if report.get("overrides") else ""),
        "",
        *machine_load_lines(m, load),
        "",
        "Cells: mean / p95 [ms per scan]. `deskew` includes the voxelisation; `total` = parse + "
        "all pipeline stages (for KISS-ICP: parse + `register_frame`). scans/s = timed scans / "
        "time spent in the feeder (IMU/wheel buffering included), resp. in parse + "
        "`register_frame`. x KISS = time per scan relative to KISS-ICP alone. "
        "– = no such stage. other load = mean cores used by other processes while that method "
        "ran (from /proc/stat; the bag decoding is this benchmark's own, not counted there).",
    ]
    for w in report["windows"]:
        title = f"From {w['start_s']:g} s" + (f": {w['name']}" if w["name"] else "")
        lines += ["", f"## {title}", "",
                  "| method | scans/s | x KISS | " + " | ".join(STAGE_TITLES[k] for k in STAGES)
                  + " | peak RSS [MB] | degenerate | other load [cores] |",
                  "|---|" + "---:|" * (len(STAGES) + 5)]
        for name, r in w["methods"].items():
            cells = []
            for k in STAGES:
                s = r["stages"][k]
                cells.append("–" if s is None else f"{s['mean_ms']:.1f} / {s['p95_ms']:.1f}")
            label = "KISS-ICP `register_frame`" if name == "kiss" else f"`{name}`"
            deg = "–" if name == "kiss" else f"{100 * r['degenerate_fraction']:.0f} %"
            reps = r.get("repeats_scans_per_s") or []
            spread = (f" ({_fmt(min(reps))}-{_fmt(max(reps))})" if len(reps) > 1 else "")
            lines.append(f"| {label} | {_fmt(r['scans_per_s'])}{spread} | "
                         f"{_fmt(r['time_vs_kiss'], 2)} | "
                         + " | ".join(cells) + f" | {r['rss_peak_mb']:.0f} | {deg} | "
                         f"{r.get('other_load_cores', float('nan')):.2f} |")
        lili = w["methods"].get("lili")
        if w.get("repeats", 1) > 1 and lili and lili.get("repeats_time_vs_kiss"):
            lines += ["", f"`lili` against KISS-ICP within each of the {w['repeats']} rounds: "
                      + ", ".join(f"{x:.2f}x" for x in lili["repeats_time_vs_kiss"]) + "."]
        if report.get("previous"):
            lines += _previous_lines(report["previous"], w["start_s"], w["methods"])
        t = w["targets"]
        if t:
            lines += ["", "Targets:"]
            if "lili_scans_per_s" in t:
                x = t["lili_scans_per_s"]
                lines.append(f"- `lili` real time (>= {x['target']:g} scans/s, goal {x['goal']:g}): "
                             f"{x['value']:.1f} scans/s, **{'met' if x['met'] else 'not met'}**"
                             + (" (goal met too)" if x["value"] >= x["goal"] else ""))
            if "lili_detector_mean_ms" in t:
                x = t["lili_detector_mean_ms"]
                lines.append(f"- LiLi detector <= {x['target']:g} ms per scan: mean "
                             f"{x['value']:.1f} ms, **{'met' if x['met'] else 'not met'}**")
            if "lili_time_vs_kiss" in t:
                x = t["lili_time_vs_kiss"]
                lines.append(f"- `lili` at most {x['target']:g}x KISS-ICP's time: "
                             f"{x['value']:.2f}x, **{'met' if x['met'] else 'not met'}**")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", type=int, default=300, help="scans per window (default 300)")
    ap.add_argument("--start", type=float, nargs="+", default=[90.0, 5.0],
                    help="window start(s) [s into the trial] (default: 90 5)")
    ap.add_argument("--warmup", type=int, default=10,
                    help="first scans of each window run but not counted (default 10)")
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=ALL_METHODS)
    ap.add_argument("--bag", type=Path, help="bag to use (default: the cached Trial 1 bag)")
    ap.add_argument("--resolution", default="128x1024", help="of the Trial 1 bag")
    ap.add_argument("--out", type=Path, default=RESULTS,
                    help="directory for the results (default benchmarks/results)")
    ap.add_argument("--name", default="speed",
                    help="file name of the results without .md/.json (default speed)")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help=f"our methods only: {SET_HELP}")
    ap.add_argument("--repeats", type=int, default=1,
                    help="rounds of every method per window; each method is reported by its "
                    "run with the median scans/s (default 1)")
    ap.add_argument("--previous", type=Path,
                    help="an earlier speed.json whose figures the report shows as 'Before'")
    ap.add_argument("--worker", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.scans <= args.warmup:
        ap.error("--scans must exceed --warmup")
    if args.repeats < 1:
        ap.error("--repeats must be at least 1")
    overrides = parse_set(args.set, "speed")
    if args.worker is not None:  # one method in this (fresh) process
        r = run_method(args.bag, args.methods[0], args.start[0], args.scans, args.warmup,
                       progress=not args.no_progress, overrides=overrides)
        args.worker.write_text(json.dumps(r))
        return 0
    bag = args.bag
    if bag is None:
        # one piece of Trial 1 per window (a whole trial at 128x1024 would be ~20 GB), with
        # the lead-in the worker feeds before the window; a piece equals that window of the
        # whole trial (the simulator computes motion and sensors over the whole trial)
        from lili_odom.sim.generator import ensure_trial_bag

        lead = 3.0
        bag = {}
        for start in args.start:
            t0 = max(0.0, start - lead)
            bag[start] = (ensure_trial_bag(1, resolution=args.resolution, seed=0, start=t0,
                                           duration=(start - t0) + args.scans / 10.0 + 1.0,
                                           progress=not args.no_progress), start - t0)
    previous = (previous_summary(json.loads(args.previous.read_text()))
                if args.previous is not None else None)
    report = benchmark(bag, args.methods, args.start, args.scans, args.warmup,
                       progress=not args.no_progress, overrides=overrides,
                       repeats=args.repeats)
    if previous is not None:
        report["previous"] = previous
    command = (f"python -m benchmarks.speed --scans {args.scans} --start "
               f"{' '.join(f'{s:g}' for s in args.start)} --warmup {args.warmup} "
               f"--methods {' '.join(args.methods)}"
               + "".join(f" --set {k}={v}" for k, v in overrides.items())
               + (f" --repeats {args.repeats}" if args.repeats > 1 else "")
               + (f" --name {args.name}" if args.name != "speed" else ""))
    write_results(args.out, args.name, markdown(report, command), report)
    print(f"wrote {args.out / (args.name + '.md')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
