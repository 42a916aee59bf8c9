"""Where a scan's latency goes in the node: arrival, queue, parsing, waiting, pipeline.

    python -m benchmarks.studies.node_latency_parts                      # 128 x 1024
    python -m benchmarks.studies.node_latency_parts --resolutions 32x512 128x1024 \\
        --set pipeline.scan_matcher.max_threads=1 --name node_latency_parts_one_thread

The piece and the play are those of ``benchmarks.node_latency`` (``lili-odom play --restamp``
at 10 Hz into the node in a fresh process, the stamps on the system clock). The node's
methods are wrapped with timers, and per scan this measures on the system clock [ms]:

* ``arrival``: from the sweep's end (the odometry's stamp) to the node's cloud callback (the
  player's publication and DDS);
* ``queue``: from the callback to the worker taking the cloud;
* ``parse``: the cloud into points and times (``lili_odom.messages.scan_from_msg``);
* ``wait``: the rest until the pipeline starts (feeding IMU and wheel samples, waiting for the
  samples that cover the sweep);
* ``pipeline``: ``OdometryPipeline.process_scan`` (``cpu``: the worker thread's CPU time in
  it);
* ``latency``: from the sweep's end to the odometry's publication (the node's own measure
  adds the ``publish`` call).

Means, p50 and p99 over the scans of the piece. Writes
``benchmarks/results/<name>.{md,json}`` (default name ``node_latency_parts``).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import RESULTS, machine_info, write_results
from benchmarks._pieces import add_piece_arguments, piece_bags, warm_file_cache
from benchmarks.node_latency import parse_parameters, play_job
from benchmarks.speed import steal_cores, steal_jiffies

PARTS = ("arrival", "queue", "parse", "wait", "pipeline", "cpu", "publish", "latency")


def _header_stamp(msg: Any) -> float:
    """``header.stamp`` [s] of a cloud: a message, or its CDR bytes."""
    from lili_odom.commands.play import header_stamp_ns
    from lili_odom.messages import stamp_seconds

    if isinstance(msg, (bytes, bytearray, memoryview)):
        return 1e-9 * header_stamp_ns(msg)
    return stamp_seconds(msg.header)


def trace(bag: Path, parameters: dict[str, Any]) -> dict[str, Any]:
    """Play ``bag`` into an in-process node with its methods timed (this process only);
    per-scan parts [s] and the node's counts."""
    from benchmarks.faults import worker_play
    from lili_odom import messages
    from lili_odom.pipeline.odometry import OdometryPipeline
    from lili_odom.ros.node import LiliOdomNode

    seen: dict[float, dict[str, float]] = {}  # by header stamp (rounded)
    by_output: dict[float, float] = {}  # odometry stamp -> header stamp

    def record(stamp: float, **values: float) -> None:
        seen.setdefault(round(stamp, 4), {}).update(values)

    on_scan, step = LiliOdomNode._on_scan, LiliOdomNode._step
    process, publish = OdometryPipeline.process_scan, LiliOdomNode._publish
    parse = messages.scan_from_msg

    def on_scan_timed(self, msg):
        record(_header_stamp(msg), callback=time.time())
        on_scan(self, msg)

    def step_timed(self, msg, wait):
        if msg is not None:
            record(_header_stamp(msg), taken=time.time())
        step(self, msg, wait)

    def parse_timed(msg, *args, **kwargs):
        t0 = time.time()
        scan = parse(msg, *args, **kwargs)
        record(scan.stamp, parse=time.time() - t0)
        return scan

    def process_timed(self, scan):
        t0, c0 = time.time(), time.thread_time()
        out = process(self, scan)
        record(scan.stamp, started=t0, pipeline=time.time() - t0, cpu=time.thread_time() - c0)
        if out is not None:
            by_output[round(out.stamp, 6)] = round(scan.stamp, 4)
        return out

    def publish_timed(self, out):
        t0 = time.time()
        publish(self, out)
        stamp = by_output.get(round(out.stamp, 6))
        if stamp is not None:
            seen[stamp].update(end=float(out.stamp), published=t0, publish=time.time() - t0)

    LiliOdomNode._on_scan, LiliOdomNode._step = on_scan_timed, step_timed
    OdometryPipeline.process_scan, LiliOdomNode._publish = process_timed, publish_timed
    messages.scan_from_msg = parse_timed
    result = worker_play(play_job(bag, parameters=parameters))
    scans = []
    for v in seen.values():
        if not {"callback", "taken", "parse", "started", "end", "published"} <= v.keys():
            continue
        scans.append({"arrival": v["callback"] - v["end"], "queue": v["taken"] - v["callback"],
                      "parse": v["parse"],
                      "wait": v["started"] - v["taken"] - v["parse"],
                      "pipeline": v["pipeline"], "cpu": v["cpu"], "publish": v["publish"],
                      "latency": v["published"] - v["end"]})
    keep = ("received", "processed", "dropped", "latency_p50_s", "latency_p99_s")
    return {"scans": scans, "node": {k: result.get(k) for k in keep}}


def summary(scans: list[dict[str, float]]) -> dict[str, dict[str, float]]:
    """Mean, p50 and p99 [ms] of each part over ``scans``."""
    out = {}
    for part in PARTS:
        ms = 1e3 * np.array([s[part] for s in scans])
        out[part] = ({"mean": float(ms.mean()), "p50": float(np.percentile(ms, 50)),
                      "p99": float(np.percentile(ms, 99))} if len(ms) else {})
    return out


def markdown(report: dict[str, Any], command: str) -> str:
    m = report["machine"]
    dirty = m.get("uncommitted_lili_odom") or []
    lines = ["# Where a scan's latency goes in the node", "",
             f"`{command}` (module docstring): the piece of `benchmarks.node_latency` played "
             "at 10 Hz into the node, its methods timed on the system clock. Machine: "
             f"{m['cpu']}, {m['cores']} cores, Python {m['python']}; commit `{m['commit']}`"
             + (" with uncommitted changes in " + ", ".join(f"`{p}`" for p in dirty)
                if dirty else "") + ".",
             "",
             "Mean / p99 per scan [ms]. arrival: sweep end to the cloud callback; queue: to "
             "the worker; parse: the cloud to points; wait: feeding IMU and wheels and waiting "
             "for the samples covering the sweep; pipeline (cpu: the worker thread's CPU time "
             "in it); latency: sweep end to the odometry's publication. Steal: cores the "
             "hypervisor took meanwhile.", "",
             "| resolution | scans | arrival | queue | parse | wait | pipeline | cpu | "
             "latency p50 / p99 | dropped | steal [cores] |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for res, r in report["resolutions"].items():
        s = r["summary"]

        def cell(part: str) -> str:
            x = s.get(part) or {}
            return f"{x['mean']:.1f} / {x['p99']:.1f}" if x else "–"

        lat = s.get("latency") or {}
        lines.append(f"| {res} | {r['count']} | {cell('arrival')} | {cell('queue')} | "
                     f"{cell('parse')} | {cell('wait')} | {cell('pipeline')} | {cell('cpu')} | "
                     + (f"{lat['p50']:.0f} / {lat['p99']:.0f}" if lat else "–")
                     + f" | {r['node'].get('dropped', '–')} | {r['steal_cores']:.2f} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_piece_arguments(ap)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="a node parameter on top of the defaults; repeatable")
    ap.add_argument("--name", default="node_latency_parts")
    ap.add_argument("--out", type=Path, default=RESULTS)
    ap.add_argument("--worker", nargs=2, metavar=("BAG", "PARAMETERS_JSON"),
                    help=argparse.SUPPRESS)  # one traced run, in a fresh process
    args = ap.parse_args(argv)
    if args.worker:
        print(json.dumps(trace(Path(args.worker[0]), json.loads(args.worker[1]))))
        return 0
    if not args.resolutions:
        args.resolutions = ["128x1024"]
    parameters = parse_parameters(ap, args.set)
    _, bags = piece_bags(ap, args)
    rows = {}
    for res, bag in bags.items():
        warm_file_cache(bag)
        print(f"[{res}] playing {Path(bag).name} into the traced node ...", flush=True)
        s0, w0 = steal_jiffies(), time.monotonic()
        run = subprocess.run([sys.executable, "-m", "benchmarks.studies.node_latency_parts",
                              "--worker", str(bag), json.dumps(parameters)],
                             capture_output=True, text=True, timeout=1800)
        if run.returncode != 0:
            raise SystemExit(f"node_latency_parts: the traced run failed: "
                             f"{run.stderr.strip()[-400:]}")
        traced = json.loads(run.stdout.strip().splitlines()[-1])
        rows[res] = {"count": len(traced["scans"]), "summary": summary(traced["scans"]),
                     "node": traced["node"],
                     "steal_cores": steal_cores(s0, time.monotonic() - w0)}
        lat = rows[res]["summary"]["latency"]
        print(f"[{res}] latency p50 {lat.get('p50', float('nan')):.0f} / p99 "
              f"{lat.get('p99', float('nan')):.0f} ms", flush=True)
    command = ("python -m benchmarks.studies.node_latency_parts --resolutions "
               + " ".join(bags) + "".join(f" --set {item}" for item in args.set)
               + (f" --name {args.name}" if args.name != "node_latency_parts" else ""))
    report = {"machine": machine_info(), "command": command, "parameters": parameters,
              "resolutions": rows}
    print(f"wrote {write_results(args.out, args.name, markdown(report, command), report)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
