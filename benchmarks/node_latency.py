"""Latency and drops of the ROS node at 10 Hz input, at every suite resolution.

Writes benchmarks/results/node_latency.{md,json}.

    python -m benchmarks.node_latency                  # building 0-30 s, 8 resolutions
    python -m benchmarks.node_latency --resolutions 32x512 --duration 5   # quick

For each resolution, the same window of one scenario as :mod:`benchmarks.speed_resolutions`
(default: ``building`` from 0 s for 30 s; simulated with the suite's scenario code and cached,
:mod:`benchmarks._pieces`) is played by ``lili-odom play --rate 1 --restamp`` (LiDAR, IMU and
wheels, RELIABLE, no ``/clock``) into the node with the real pipeline (``pipeline.method``
lili, the defaults, ``reliable_inputs``), as ``benchmarks.faults --play-rates`` does it
(:func:`benchmarks.faults.worker_play`): the node in-process in a fresh worker, the player
its subprocess, a recorder of ``/lili_odom/odometry`` beside the node, an isolated DDS domain
(random ``ROS_DOMAIN_ID``, ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) and the package's
Fast DDS profile. ``--restamp`` moves the header stamps onto the system clock as a live driver
stamps, so the node (no ``use_sim_time``) measures its latency on its own clock: from each
scan's sweep end (``header.stamp`` + sweep) to the moment its odometry is published
(:mod:`lili_odom.ros.latency`). The player's own work (reading the bag, publishing) runs on
the same cores, as a LiDAR driver does on the robot.

Per resolution: clouds published / received by the node / processed / dropped by its queue /
missing (stamp gaps) / odometry messages recorded, the latency p50 / p99 / max the node
reports (over its last 1000 scans, so the whole window up to 100 s), the mean processing time
per scan, and the cores other processes used meanwhile. Targets: p99 at most 100 ms at
128 x 1024; every scan processed (none dropped) at every resolution.

With ``--repeats N`` each resolution is played N times in a row; the table shows the run
with the median p99 and a list under it gives every run's p99, drops and steal time, so one
run on a noisy machine does not decide a target.
"""
from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path
from typing import Any

from benchmarks._common import RESULTS, machine_info, write_results
from benchmarks._pieces import (DEFAULT_PIECE, add_piece_arguments, format_resolution,
                                piece_bags, piece_command, suite_resolutions, warm_file_cache)
from benchmarks.faults import run_in_subprocess
from benchmarks.speed import (LoadMeter, _cpu_busy_jiffies, _fmt, _other_load, machine_load_lines,
                              steal_cores, steal_jiffies)

TARGET_P99_S = 0.100
TARGET_RESOLUTION = "128x1024"
#: Keys of a worker result kept in the report (the job's bag path is not: no machine paths).
KEPT = ("status", "rate", "method", "play_ok", "play_s", "published", "received", "processed",
        "dropped", "missing", "no_output", "errors", "odometry", "nothing_lost", "accounted",
        "mean_processing_s", "imu_received", "wheel_received", "latency_p50_s",
        "latency_p99_s", "latency_max_s", "latency_window_scans", "latency_scans",
        "latency_run_max_s", "latency_invalid", "processing_status", "stage_ms",
        "spin_thread_left",
        "stderr_tail", "received_latency_s")
#: Scans at the start of a run reported apart in the subscriber's view (start-up costs).
FIRST_SCANS = 10


def play_job(bag: Path, method: str = "lili", rate: float = 1.0,
             duration: float = DEFAULT_PIECE[2],
             parameters: dict[str, Any] | None = None) -> dict[str, Any]:
    """The :func:`benchmarks.faults.worker_play` job: ``bag`` at ``rate`` with stamps moved
    onto the system clock, no ``/clock``, the node with ``pipeline.method`` = ``method`` and
    ``parameters`` (node parameters by their dotted names) on top of the defaults."""
    return {"method": method, "rate": rate, "bag": str(bag),
            "parameters": dict(parameters or {}),
            "play_args": ["--restamp", "--clock-hz", "0"],
            "play_timeout": max(600.0, 3.0 * duration / max(rate, 1e-3))}


def received_summary(latencies: list[float], first: int = FIRST_SCANS) -> dict[str, Any]:
    """The subscriber's view of one run (``received_latency_s``: reception minus stamp [s] per
    odometry message, in arrival order): p50 / p99 / max [s] after the first ``first``
    messages and the max of those first ones (None where there are none)."""
    import numpy as np

    values = np.asarray(latencies, dtype=float)
    head, rest = values[:first], values[first:]
    out: dict[str, Any] = {"first": first,
                           "first_max_s": float(head.max()) if len(head) else None}
    if len(rest):
        p50, p99 = np.percentile(rest, [50.0, 99.0])
        out.update({"p50_s": float(p50), "p99_s": float(p99), "max_s": float(rest.max())})
    else:
        out.update({"p50_s": None, "p99_s": None, "max_s": None})
    return out


def evaluate(row: dict[str, Any], resolution: str) -> dict[str, Any]:
    """The targets for one resolution's result: ``no_drops`` (every published scan received,
    processed and answered, none dropped) and, at :data:`TARGET_RESOLUTION`, ``p99``."""
    t: dict[str, Any] = {"no_drops": {"met": bool(row.get("status") == "ok"
                                                  and row.get("nothing_lost"))}}
    p99 = row.get("latency_p99_s")
    if resolution == TARGET_RESOLUTION:
        t["p99"] = {"value": p99, "target": TARGET_P99_S,
                    "met": p99 is not None and p99 <= TARGET_P99_S}
    return t


def median_run(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The run with the median ``latency_p99_s`` (the upper one of an even count; a run
    without a p99 counts as the slowest), with ``repeats``: every run's p50 / p99 [s],
    dropped scans and steal time [cores], in the order run. One run: that run as it is."""
    if len(runs) == 1:
        return dict(runs[0])

    def p99(run: dict[str, Any]) -> float:
        value = run.get("latency_p99_s")
        return float("inf") if value is None else float(value)

    row = dict(sorted(runs, key=p99)[len(runs) // 2])
    row["repeats"] = [{k: run.get(k) for k in ("latency_p50_s", "latency_p99_s", "dropped",
                                               "steal_cores")} for run in runs]
    return row


def benchmark(bags: dict[str, Path], method: str = "lili", rate: float = 1.0,
              duration: float = DEFAULT_PIECE[2], timeout: float = 1800.0,
              progress: bool = True, parameters: dict[str, Any] | None = None,
              repeats: int = 1) -> dict[str, Any]:
    """``repeats`` play runs per bag (``{"ROWSxCOLS": bag}``), each in a fresh worker
    process, the node with ``parameters`` on top of the defaults; per resolution the run with
    the median p99 (:func:`median_run`)."""
    meter = LoadMeter()
    rows: dict[str, Any] = {}
    for res, bag in bags.items():
        warm_file_cache(bag)
        runs = []
        for i in range(repeats):
            if progress:
                print(f"[{res}] playing {Path(bag).name} at {rate:g}x into the node"
                      + (f" ({i + 1} of {repeats})" if repeats > 1 else "") + " ...", flush=True)
            b0, _ = _cpu_busy_jiffies()
            s0 = steal_jiffies()
            c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            w0 = time.monotonic()
            r = run_in_subprocess("play", play_job(bag, method, rate, duration, parameters),
                                  timeout)
            run = {k: r[k] for k in KEPT if k in r}
            run["bag"] = Path(bag).name
            run["subscriber"] = received_summary(run.get("received_latency_s", []))
            run["other_load_cores"] = _other_load(b0, c0, time.monotonic() - w0)
            run["steal_cores"] = steal_cores(s0, time.monotonic() - w0)
            runs.append(run)
        row = median_run(runs)
        row["targets"] = evaluate(row, res)
        rows[res] = row
        if progress:
            print(f"[{res}] {row.get('status')}: published {row.get('published')}, received "
                  f"{row.get('received')}, processed {row.get('processed')}, dropped "
                  f"{row.get('dropped')}; latency p50 {_ms(row.get('latency_p50_s'))} / p99 "
                  f"{_ms(row.get('latency_p99_s'))} / max {_ms(row.get('latency_max_s'))} ms",
                  flush=True)
    return {"machine": machine_info(), "method": method, "rate": rate,
            "parameters": dict(parameters or {}),
            "target_p99_s": TARGET_P99_S, "target_resolution": TARGET_RESOLUTION,
            "load": meter.report(),
            "resolutions": rows}


def _ms(seconds: float | None) -> str:
    return "–" if seconds is None else _fmt(1000.0 * seconds, 0)


def markdown(report: dict[str, Any], command: str) -> str:
    m, load, piece = report["machine"], report["load"], report["piece"]
    target_ms = 1000 * report["target_p99_s"]
    lines = [
        "# Node latency and drops at 10 Hz input, at every suite resolution",
        "",
        f"`{command}`: the `{piece['scenario']}` scenario from {piece['start_s']:g} s for "
        f"{piece['duration_s']:g} s (seed {piece['seed']}) at each resolution, played by "
        f"`lili-odom play --rate {report['rate']:g} --restamp` (LiDAR, IMU, wheels; RELIABLE; "
        "stamps moved onto the system clock as a live driver stamps) into the node "
        f"(`pipeline.method` {report['method']}, defaults, `reliable_inputs`) in a fresh "
        "process, over DDS on loopback (isolated domain, the package's Fast DDS profile). "
        "Latency: measured by the node, from a scan's sweep end (`header.stamp` + sweep) to "
        "the publication of its odometry, on the node's clock; p50 / p99 / max over its last "
        "1000 scans (here: every scan). The player runs on the same cores.",
        "",
        *machine_load_lines(m, load),
        "",
        "published: clouds in the piece; received: reached the node; dropped: pushed out of "
        "the node's queue (processing slower than the LiDAR); missing: lost before the node "
        "(stamp gaps); odometry: messages recorded. Other load: cores used by processes other "
        "than the node and the player during the run; steal: cores the hypervisor gave to "
        "other guests of the host meanwhile (a virtual machine's cores running someone "
        "else's work: everything here ran slower).",
        "",
        f"Subscriber's view: the recorder's clock at reception minus the odometry's stamp "
        f"(the node's latency plus one DDS hop), p99 after the first {FIRST_SCANS} messages "
        f"and the largest of those first {FIRST_SCANS} (start-up).",
        "",
        "| resolution | used by | status | published | received | processed | dropped | "
        "missing | odometry | every scan processed | latency p50 / p99 / max [ms] | "
        f"p99 <= {target_ms:g} ms | subscriber: p99 after / max of the first {FIRST_SCANS} "
        "[ms] | mean processing [ms] | other load / steal [cores] |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---|---:|---|---:|---:|---:|",
    ]
    for res, r in report["resolutions"].items():
        users = ", ".join(report.get("suite_resolutions", {}).get(res, [])) or "–"
        t = r["targets"]
        sub = r.get("subscriber") or {}
        p99 = r.get("latency_p99_s")
        p99_cell = ("–" if p99 is None else ("yes" if p99 <= report["target_p99_s"] else "no"))
        if "p99" in t:
            p99_cell = f"**{'met' if t['p99']['met'] else 'missed'}** (target)"
        lines.append(
            f"| {res} | {users} | {r.get('status', '–')} | {r.get('published', '–')} | "
            f"{r.get('received', '–')} | {r.get('processed', '–')} | {r.get('dropped', '–')} | "
            f"{r.get('missing', '–')} | {r.get('odometry', '–')} | "
            f"{'yes' if t['no_drops']['met'] else '**no**'} | "
            f"{_ms(r.get('latency_p50_s'))} / {_ms(p99)} / {_ms(r.get('latency_max_s'))} | "
            f"{p99_cell} | {_ms(sub.get('p99_s'))} / {_ms(sub.get('first_max_s'))} | "
            f"{_ms(r.get('mean_processing_s'))} | "
            f"{_fmt(r.get('other_load_cores'), 2)} / {_fmt(r.get('steal_cores'), 2)} |")
    rows = report["resolutions"]
    repeated = {res: r["repeats"] for res, r in rows.items() if r.get("repeats")}
    if repeated:
        lines += ["", "Repeats (the table shows the run with the median p99): every run's "
                  "latency p99 [ms], dropped scans and steal [cores], in the order run:", ""]
        for res, reps in repeated.items():
            lines.append(f"- {res}: " + "; ".join(
                f"{_ms(x.get('latency_p99_s'))} ms, {x.get('dropped', '–')} dropped, "
                f"{_fmt(x.get('steal_cores'), 2)}" for x in reps))
    dropped = [res for res, r in rows.items() if not r["targets"]["no_drops"]["met"]]
    lines += ["", "Targets:",
              f"- every scan processed (none dropped) at 10 Hz: "
              + ("**met** at every resolution measured" if not dropped
                 else f"**missed** at {', '.join(dropped)}")]
    target = rows.get(report["target_resolution"])
    if target is not None:
        x = target["targets"]["p99"]
        lines.append(f"- latency p99 <= {target_ms:g} ms at {report['target_resolution']}: "
                     f"{_ms(x['value'])} ms, **{'met' if x['met'] else 'missed'}**")
    else:
        lines.append(f"- latency p99 <= {target_ms:g} ms at {report['target_resolution']}: "
                     "not measured in this run")
    stage_rows = {res: r["stage_ms"] for res, r in rows.items() if r.get("stage_ms")}
    if stage_rows:
        names = list(dict.fromkeys(k for v in stage_rows.values() for k in v))  # stage order
        lines += ["", "Node: mean time per scan and pipeline stage over its last 50 scans [ms] "
                  "(`processing time` status of `/diagnostics`; `total` is the pipeline's own "
                  "time, without parsing the cloud and publishing).", "",
                  "| resolution | " + " | ".join(names) + " |",
                  "|---|" + "---:|" * len(names)]
        for res, st in stage_rows.items():
            lines.append(f"| {res} | " + " | ".join(_fmt(st.get(k), 1) for k in names) + " |")
    failed = {res: r.get("stderr_tail", "") for res, r in rows.items() if r.get("status") != "ok"}
    if failed:
        lines += ["", "Runs that did not finish cleanly (the stderr tail is in the JSON): "
                  + ", ".join(f"{res} ({rows[res].get('status')})" for res in failed) + "."]
    return "\n".join(lines) + "\n"


def parse_parameters(ap: argparse.ArgumentParser, items: list[str]) -> dict[str, Any]:
    """``KEY=VALUE`` items as node parameters, each converted to its parameter's type and
    checked as a parameter file's are (:func:`lili_odom.config.apply_params`; values read as
    YAML scalars: 16, 1.5, true). An item without ``=``, an unknown key or a bad value is a
    usage error."""
    import yaml

    from lili_odom.config import NodeConfig, apply_params, flatten

    raw: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            ap.error(f"--set expects KEY=VALUE, got {item!r}")
        raw[key.strip()] = yaml.safe_load(value)
    try:
        values = flatten(apply_params(NodeConfig(), raw))
    except ValueError as exc:
        ap.error(f"--set: {exc}")
    return {key: values[key] for key in raw}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_piece_arguments(ap)
    ap.add_argument("--method", default="lili", choices=("lili", "zhang", "hessian", "none"))
    ap.add_argument("--rate", type=float, default=1.0, help="play rate (default 1: 10 Hz)")
    ap.add_argument("--timeout", type=float, default=1800.0, help="per run [s]")
    ap.add_argument("--out", type=Path, default=RESULTS,
                    help="directory for the results (default benchmarks/results)")
    ap.add_argument("--name", default="node_latency",
                    help="file name of the results without .md/.json (default node_latency)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="a node parameter on top of the defaults (e.g. "
                         "pipeline.detection_schedule.max_reuse=16); repeatable")
    ap.add_argument("--repeats", type=int, default=1,
                    help="play runs per resolution; the report shows the median p99's run "
                    "(default 1)")
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)
    if not args.rate > 0:
        ap.error("--rate must be positive")
    if args.repeats < 1:
        ap.error("--repeats must be at least 1")
    parameters = parse_parameters(ap, args.set)
    scenario, bags = piece_bags(ap, args, progress=not args.no_progress)
    report = benchmark(bags, args.method, args.rate, args.duration, args.timeout,
                       progress=not args.no_progress, parameters=parameters,
                       repeats=args.repeats)
    report["piece"] = {"scenario": scenario.name, "start_s": args.start,
                       "duration_s": args.duration, "seed": args.seed}
    report["suite_resolutions"] = {format_resolution(r): names
                                   for r, names in suite_resolutions().items()}
    command = piece_command(
        "benchmarks.node_latency", args,
        (f" --method {args.method}" if args.method != "lili" else "")
        + (f" --rate {args.rate:g}" if args.rate != 1.0 else "")
        + "".join(f" --set {item}" for item in args.set)
        + (f" --repeats {args.repeats}" if args.repeats != 1 else "")
        + (f" --name {args.name}" if args.name != "node_latency" else ""))
    path = write_results(args.out, args.name, markdown(report, command), report)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
