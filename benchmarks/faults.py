"""Robustness benchmark: fault-injection runs, play rates the node sustains, report.

Fault runs: a piece of a simulated tunnel trial (default Trial 1, 64x512, 70-110 s: the
entrance and the start of the featureless stretch) is run once clean and once per fault
(and with all faults at once) for each method, the bag read in header-stamp order, faults
injected by :class:`lili_odom.evaluation.faults.FaultInjector`, odometry by
:func:`lili_odom.evaluation.faults.run_stream` (the offline runner's loop). Every run is its own
subprocess, so a crash or a native abort is recorded instead of ending the benchmark, and its
peak RSS is its own. Per run: ATE / RPE / final error vs truth, clouds in the bag vs dropped by
the injector vs processed vs skipped (pipeline counter names), wall time, peak RSS.

Play rates (``--play-rates``): ``lili-odom play --rate R`` of the CI bag into the node
(in-process, real pipeline, isolated DDS domain) and a recorder, for increasing R; the fastest
rate at which every scan arrived, none was dropped and every scan gave one odometry message.
The same worker (:func:`worker_play`) serves ``python -m benchmarks.node_latency``.

Bad-input tests (``--bad-input-tests``): runs the robustness test files and counts the cases.

Writes ``benchmarks/results/robustness.json`` (each part under its own key, so the parts can be
re-run separately; ``python -m benchmarks.long_run`` adds ``long_run`` or, at another
resolution, ``long_run_<rows>x<cols>``) and renders
``benchmarks/results/robustness.md`` from it.

    python -m benchmarks.faults                       # fault runs (~15 min on 2 cores)
    python -m benchmarks.faults --play-rates --no-faults
    python -m benchmarks.faults --duration 20 --methods none   # quick
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

from benchmarks._common import CI_BAG, RESULTS, ROOT
LIDAR, IMU, WHEEL = "/ouster/points", "/ouster/imu", "/platform/odom"
ROBUSTNESS_TESTS = ["test/test_robustness_cloud.py", "test/test_robustness_sensors.py",
                    "test/test_robustness_cli.py", "test/test_faults.py",
                    "test/test_nothing_lost.py"]


def fault_cases(duration: float) -> dict[str, dict]:
    """FaultSpec keyword arguments per case; windows in seconds after the piece's start."""
    wheel = (max(0.0, duration - 20.0), duration)  # the last 20 s: the featureless stretch
    lidar = (duration / 2.0, duration / 2.0 + 0.5)
    faults = {
        "imu_drop_30pct": dict(imu_drop_fraction=0.3),
        "wheel_outage_20s": dict(wheel_outage=wheel),
        "lidar_outage_0.5s": dict(lidar_outage=lidar),
        "reorder_50ms": dict(reorder_fraction=0.2, reorder_max_delay_s=0.05),
    }
    combined: dict = {}
    for spec in faults.values():
        combined.update(spec)
    return {"clean": {}, **faults, "all_faults": combined}


# --------------------------------------------------------------------------- one fault run
def worker_fault_run(job: dict) -> dict:
    """Run one (case, method) in this process; returns the JSON-able result.

    Optional job keys: ``config`` (a parameter file relative to the repository, default the
    built-in defaults) and ``threads`` (native threads, 0 = the configuration's)."""
    import logging

    from lili_odom.bagio.reader import BagReader
    from lili_odom.config import load_config
    from lili_odom.evaluation.faults import FaultInjector, FaultSpec, read_bag, run_stream

    logging.basicConfig(level=logging.ERROR)
    config = job.get("config", "default")
    cfg = load_config(None if config == "default" else ROOT / config)
    cfg.pipeline.method = job["method"]
    if job.get("threads"):
        cfg.pipeline.scan_matcher.max_threads = job["threads"]
        detector = getattr(cfg.pipeline, job["method"], None)  # "none" has no registration
        if detector is not None:
            detector.registration.max_threads = job["threads"]
    cfg.validate()
    topics = [cfg.lidar_topic, cfg.imu_topic, cfg.wheel_topic, cfg.ground_truth_topic,
              "/tf_static"]
    spec = FaultSpec(seed=job["seed"], **{k: tuple(v) if isinstance(v, list) else v
                                          for k, v in job["faults"].items()})
    with BagReader(job["bag"], topics=topics) as reader:
        inj = FaultInjector(spec)
        window = tuple(job["window"]) if job.get("window") else None
        run = run_stream(inj(read_bag(reader, window)), cfg)
        late = reader.stats.late
    m = run.metrics(segment_m=job.get("rpe_segment", 100.0))
    acc = run.accounting()
    seen = inj.stats.seen.get(cfg.lidar_topic, 0)
    return {
        "case": job["case"], "method": job["method"], "faults": spec.describe(),
        "metrics": m.to_dict() if m is not None else None,
        "clouds_in_bag": seen,
        "clouds_dropped_by_injector": inj.stats.dropped.get(cfg.lidar_topic, 0),
        "reader_late": late,
        "injector": inj.stats.to_dict(),
        "accounting": acc,
        "all_clouds_accounted": int(acc["balanced"] and seen == acc["clouds_in"]
                                    + inj.stats.dropped.get(cfg.lidar_topic, 0)),
        "counters": run.counters,
        "degenerate_fraction": (sum(d > 0 for d in run.dimensions) / len(run.dimensions)
                                if run.dimensions else 0.0),
        "wall_time_s": run.wall_time_s,
        "scans_per_second": len(run.estimates) / run.wall_time_s if run.wall_time_s else 0.0,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
    }


def run_in_subprocess(kind: str, job: dict, timeout: float) -> dict:
    """Run a worker in a fresh interpreter; a crash or a signal becomes a result."""
    t0 = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, "-m", "benchmarks.faults", "--worker", kind,
                               json.dumps(job)],
                              capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    except subprocess.TimeoutExpired:
        return {**job, "status": "timeout", "wall_s": time.perf_counter() - t0}
    status = "ok"
    if proc.returncode < 0:
        status = f"native abort (signal {-proc.returncode})"
    elif proc.returncode != 0:
        status = "crash"
    try:
        out = json.loads(proc.stdout.strip().splitlines()[-1])
    except (ValueError, IndexError):
        out = None
    if out is None:
        status = "crash" if status == "ok" else status
        out = {**job}
    elif status != "ok":
        # the worker printed its complete result, then died while the interpreter exited
        status += " at exit, after the result"
    if status != "ok":
        out["stderr_tail"] = proc.stderr[-1500:]
    out["status"] = status
    return out


def fault_runs(args) -> dict:
    from lili_odom.sim.generator import ensure_trial_bag

    if args.bag:
        bag, window = Path(args.bag), ((args.start, args.start + args.duration)
                                       if args.window else None)
        label = f"{Path(args.bag).name}" + (f" {window[0]:g}-{window[1]:g} s" if window else "")
    else:
        bag = ensure_trial_bag(args.trial, resolution=args.resolution, seed=0,
                               start=args.start, duration=args.duration,
                               progress=not args.no_progress)
        window = None
        label = (f"Trial {args.trial}, {args.resolution}, {args.start:g}-"
                 f"{args.start + args.duration:g} s")
    cases = fault_cases(args.duration)
    if args.cases:
        cases = {k: v for k, v in cases.items() if k in args.cases}
    bag_arg = os.path.relpath(bag, ROOT)  # no machine paths in the results
    jobs = [{"case": c, "method": m, "faults": spec, "seed": args.seed, "bag": bag_arg,
             "window": window} for m in args.methods for c, spec in cases.items()]
    results: list = []
    out = {"bag": label, "seed": args.seed,
           "cases": {k: FaultSpecText(v) for k, v in cases.items()}, "runs": results}
    for i, job in enumerate(jobs, 1):
        r = run_in_subprocess("fault", job, args.timeout)
        results.append(r)
        save_results({"faults": out}, ("faults",))  # a partial report survives an interrupt
        m = r.get("metrics") or {}
        print(f"[{i}/{len(jobs)}] {job['method']:5s} {job['case']:18s} {r['status']}: "
              f"ATE {m.get('ate_rmse_m', float('nan')):.3f} m, "
              f"{r.get('accounting', {}).get('processed', '?')} scans, "
              f"{r.get('wall_time_s', float('nan')):.0f} s, "
              f"RSS {r.get('peak_rss_mb', float('nan')):.0f} MB", flush=True)
    return out


def FaultSpecText(kwargs: dict) -> str:
    from lili_odom.evaluation.faults import FaultSpec

    return FaultSpec(**{k: tuple(v) if isinstance(v, list) else v
                        for k, v in kwargs.items()}).describe()


# --------------------------------------------------------------------------- play rates
def worker_play(job: dict) -> dict:
    """Play a bag at job['rate'] into an in-process node; returns its counts and the latency
    it measured (:meth:`lili_odom.ros.node.LiliOdomNode.diagnostics`).

    Optional job keys: ``bag`` (default the CI bag), ``parameters`` (more node parameters),
    ``play_args`` (more ``lili-odom play`` arguments, e.g. ``["--restamp"]``),
    ``play_timeout`` [s] (default 600). With ``--restamp`` the result also holds the node's
    ``latency_*`` figures, its processing-time status and ``received_latency_s``: per
    odometry message in arrival order, the recorder's system clock at reception minus the
    message's stamp [s]."""
    import random
    import threading

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from lili_odom.bagio.reader import BagReader
    from lili_odom.messages import stamp_seconds
    from lili_odom.ros.dds import apply_dds_defaults
    from lili_odom.ros.factory import message_class
    from lili_odom.ros.node import LiliOdomNode, parameters_from_mapping
    from lili_odom.ros.provider import OdometryPipelineProvider

    bag = Path(job.get("bag") or CI_BAG)
    with BagReader(bag, topics=[LIDAR]) as reader:
        published = reader.message_count
    apply_dds_defaults()  # as lili_odom_node does
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(random.randint(100, 200))
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.pop("ROS_STATIC_PEERS", None)
    env.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE",
                                           "RMW_IMPLEMENTATION")})
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(env["ROS_DOMAIN_ID"]))
    node = LiliOdomNode(context=ctx, provider=OdometryPipelineProvider(),
                        parameter_overrides=parameters_from_mapping(
                            {"pipeline.method": job["method"], "diagnostics_period": 0.0,
                             # play publishes RELIABLE: a lossless replay, so what is lost
                             # is the node's doing (dropped, counted), not the transport's
                             "reliable_inputs": True, **job.get("parameters", {})}))
    recorder = rclpy.create_node("recorder", context=ctx)
    got: list = []  # per odometry message: its stamp and the system clock at reception [s]

    def record(msg) -> None:
        got.append((stamp_seconds(msg.header), time.time()))

    recorder.create_subscription(message_class("nav_msgs/msg/Odometry"), "/lili_odom/odometry",
                                 record, QoSProfile(depth=1000,
                                                    reliability=ReliabilityPolicy.RELIABLE))
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    executor.add_node(recorder)
    spin = threading.Thread(target=executor.spin, daemon=True)
    spin.start()
    try:
        t0 = time.monotonic()
        play = subprocess.run([sys.executable, "-m", "lili_odom.cli", "play", str(bag),
                               "--rate", str(job["rate"]), "--delay", "20", "--quiet",
                               "--topics", LIDAR, IMU, WHEEL, *job.get("play_args", [])],
                              env=env, capture_output=True, text=True,
                              timeout=float(job.get("play_timeout", 600.0)))
        play_s = time.monotonic() - t0
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline:
            d = node.diagnostics()
            if (d["scans_waiting"] == 0 and d["scans_processed"] + d["scans_dropped"]
                    == d["scans_received"] and len(got) >= d["scans_processed"]
                    - d["scans_no_output"]):
                break
            time.sleep(0.1)
        time.sleep(0.3)
        diag = node.diagnostics()
        processing = next((st for st in node.diagnostic_statuses()
                           if st.name == "lili_odom: processing time"), None)
    finally:
        # the spin thread must be out of rclpy's wait before the interpreter exits: a daemon
        # thread still inside it at exit aborts the process (ros2/rclpy#1484)
        executor.shutdown(timeout_sec=2.0)
        spin.join(5.0)
        node.destroy_node()
        recorder.destroy_node()
        rclpy.try_shutdown(context=ctx)
        spin.join(5.0)
    return {"method": job["method"], "rate": job["rate"], "play_ok": play.returncode == 0,
            "spin_thread_left": spin.is_alive(),
            "play_s": play_s, "published": published, "received": diag["scans_received"],
            "processed": diag["scans_processed"], "dropped": diag["scans_dropped"],
            "no_output": diag["scans_no_output"], "errors": diag["scan_errors"],
            "odometry": len(got), "mean_processing_s": diag["mean_processing_s"],
            "imu_received": diag["imu_received"], "wheel_received": diag["wheel_received"],
            "missing": diag["scans_missing"],
            "nothing_lost": int(diag["scans_received"] == published and len(got) == published
                                and diag["scans_dropped"] == 0),
            "accounted": int(len(got) + diag["scans_dropped"] + diag["scans_no_output"]
                             == diag["scans_received"]),
            # with the stamps on the system clock (else these compare the bag's old stamps
            # with today): the node's latency figures, and reception minus stamp per odometry
            # message as the recorder saw it
            **({**{k: v for k, v in diag.items() if k.startswith("latency_")},
                "processing_status": processing.message if processing is not None else "",
                "stage_ms": ({k[len("stage_"):-len("_ms")]: float(v)
                              for k, v in processing.values.items()
                              if k.startswith("stage_") and k.endswith("_ms")}
                             if processing is not None else {}),
                "received_latency_s": [round(t - stamp, 5) for stamp, t in got]}
               if "--restamp" in job.get("play_args", []) else {})}


def play_rates(args) -> dict:
    out: dict = {"bag": CI_BAG.name, "runs": [], "max_rate": {}}
    for method in args.play_methods:
        ladder = args.none_rates if method == "none" else args.lili_rates
        best = 0.0
        for rate in ladder:
            r = run_in_subprocess("play", {"method": method, "rate": rate}, args.timeout)
            out["runs"].append(r)
            print(f"play {method} x{rate:g}: {r.get('status')} received "
                  f"{r.get('received')}/{r.get('published')}, dropped {r.get('dropped')}, "
                  f"odometry {r.get('odometry')}", flush=True)
            if r.get("status") == "ok" and r.get("nothing_lost"):
                best = max(best, rate)
            elif best > 0 or rate >= 1:
                break  # the first rate that loses scans ends the ladder
        out["max_rate"][method] = best
    return out


# --------------------------------------------------------------------------- bad-input tests
def bad_input_tests(args) -> dict:
    import xml.etree.ElementTree as ET

    xml = Path(args.tmp) / "robustness_junit.xml"
    xml.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           f"--junitxml={xml}", *ROBUSTNESS_TESTS], cwd=ROOT,
                          capture_output=True, text=True, timeout=3600)
    per_file: dict[str, dict[str, int]] = {}
    for case in ET.parse(xml).getroot().iter("testcase"):
        name = case.get("classname", "").replace(".", "/") + ".py"
        f = per_file.setdefault(Path(name).name, {"passed": 0, "failed": 0, "skipped": 0,
                                                  "xfailed": 0})
        kinds = {child.tag for child in case}
        skipped = case.find("skipped")
        if "failure" in kinds or "error" in kinds:
            f["failed"] += 1
        elif skipped is not None and "xfail" in (skipped.get("type", "") + skipped.get(
                "message", "")).lower():
            f["xfailed"] += 1
        elif skipped is not None:
            f["skipped"] += 1
        else:
            f["passed"] += 1
    tail = proc.stdout.strip().splitlines()[-1] if proc.stdout.strip() else ""
    return {"files": per_file, "summary": tail, "returncode": proc.returncode,
            "wall_s": time.perf_counter() - t0}


# --------------------------------------------------------------------------- report
def load_results() -> dict:
    path = RESULTS / "robustness.json"
    if path.exists():
        return json.loads(path.read_text())
    return {}


def save_results(data: dict, keys: tuple[str, ...] | None = None) -> None:
    """Write the JSON and the report; with ``keys``, only those sections of ``data`` replace
    the stored ones (the file is re-read, so runs of the other parts are kept)."""
    if keys is not None:
        stored = load_results()
        stored.update({k: data[k] for k in keys if k in data})
        data = stored
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "robustness.json").write_text(json.dumps(data, indent=1, default=float) + "\n")
    (RESULTS / "robustness.md").write_text(render(data))


def _f(x, fmt=".3f") -> str:
    try:
        return format(float(x), fmt)
    except (TypeError, ValueError):
        return "-"


#: Peak RSS the odometry must stay under on the long run [MiB] (1.5 GB = 1.5e9 bytes).
LONG_RUN_RSS_TARGET_MB = 1.5e9 / 2 ** 20


def long_run_lines(lr: dict, section: str = "long_run") -> list[str]:
    """The report's lines for one ``python -m benchmarks.long_run`` result stored under
    ``section`` (its plot is ``<section>_memory.png``)."""
    peak = lr["peak_rss_mb"]
    target = LONG_RUN_RSS_TARGET_MB
    return [f"## Long run (memory): {lr['bag']}", "",
            f"{lr['bag']}, method `{lr['method']}`: {lr['scans']} scans, path "
            f"{_f(lr.get('path_length_m'), '.0f')} m, ATE {_f(lr.get('ate_rmse_m'))} m, "
            f"wall {_f(lr.get('wall_time_s'), '.0f')} s. RSS sampled every "
            f"{lr['every']} scans, of the process and its child processes (the background "
            "detector; `/proc`).", "",
            f"- peak RSS: {_f(peak, '.0f')} MB (the larger of the process's getrusage peak and "
            "the largest sample), sampled max "
            f"{_f(lr['max_sampled_rss_mb'], '.0f')} MB; RSS after the first scan "
            f"{_f(lr['first_rss_mb'], '.0f')} MB",
            f"- peak RSS under 1.5 GB ({target:.0f} MB of 2^20 bytes): "
            f"**{'met' if peak < target else 'missed'}**",
            f"- second half trend: {_f(lr['trend_mb_per_100_scans'], '+.2f')} MB per 100 "
            f"scans (linear fit over scans {lr['second_half_from']}-{lr['scans']})",
            f"- local map points at the end: {lr.get('map_points_end', '-')} (max "
            f"{lr.get('map_points_max', '-')})", "",
            f"![long run memory]({section}_memory.png)", ""]


def render(data: dict) -> str:
    L = ["# Robustness (issue #6)", "",
         "Generated by `python -m benchmarks.faults` (fault runs, play rates, bad-input tests) and "
         "`python -m benchmarks.long_run` (memory); numbers from the JSON beside this file. "
         "Machine: 2 cores, shared with other jobs while measured (wall times and play rates "
         "are lower bounds of what an idle machine does).", ""]
    runs_all = (data.get("faults") or {}).get("runs", [])
    crashes = sum(r.get("status") == "crash" for r in runs_all)
    aborts = sum(str(r.get("status", "")).startswith("native abort") for r in runs_all)
    tests = data.get("bad_input_tests") or {}
    L += ["## Summary", ""]
    if tests:
        n = {k: sum(f[k] for f in tests["files"].values())
             for k in ("passed", "failed", "skipped", "xfailed")}
        L.append(f"- Robustness test cases: {sum(n.values())} ({n['passed']} passed, "
                 f"{n['failed']} failed, {n['xfailed']} xfailed = known defects, "
                 f"{n['skipped']} skipped in the parent process because they run in a "
                 "subprocess); every pipeline case runs in a subprocess, so a native abort "
                 "would fail a test: none did.")
    if runs_all:
        L.append(f"- Fault runs: {len(runs_all)}; crashes {crashes}, native aborts {aborts}, "
                 f"timeouts {sum(r.get('status') == 'timeout' for r in runs_all)}.")
    play_runs = (data.get("play_rates") or {}).get("runs", [])
    if play_runs:
        bad = [f"`{r.get('method')}` {r.get('rate'):g}x: {r.get('status')}" for r in play_runs
               if r.get("status") != "ok"]
        L.append(f"- Play runs: {len(play_runs)}; not ok: {', '.join(bad) if bad else 'none'}"
                 " (the stderr tail of each is in the JSON).")
    L.append("")
    if tests:
        L += ["## Bad input (tests)", "",
              "| file | passed | xfailed | skipped | failed |", "|---|---|---|---|---|"]
        for name, f in sorted(tests["files"].items()):
            L.append(f"| `{name}` | {f['passed']} | {f['xfailed']} | {f['skipped']} | "
                     f"{f['failed']} |")
        L += ["", f"pytest: `{tests.get('summary', '')}`", ""]
    fr = data.get("faults")
    if fr:
        L += ["## Fault injection", "",
              f"Bag: {fr['bag']} (seed {fr['seed']}). Windows are seconds after the piece's "
              "start. Cases:", ""]
        for k, v in fr["cases"].items():
            L.append(f"- `{k}`: {v}")
        L += ["", "| method | case | status | ATE [m] | ATE max [m] | RPE [m] (seg) | final [m] "
              "| clouds in bag | dropped by injector | processed | skipped (counter) | all "
              "accounted | wall [s] | scans/s | peak RSS [MB] |",
              "|---" * 15 + "|"]
        for r in fr["runs"]:
            m = r.get("metrics") or {}
            acc = r.get("accounting") or {}
            skips = ", ".join(f"{k} {v}" for k, v in acc.items()
                              if (k.startswith("skipped_") or k in ("fusion_rejected",
                                                                     "bad_clouds")) and v)
            L.append(
                f"| {r['method']} | {r['case']} | {r['status']} | {_f(m.get('ate_rmse_m'))} | "
                f"{_f(m.get('ate_max_m'))} | {_f(m.get('rpe_rmse_m'))} "
                f"({_f(m.get('rpe_segment_m'), '.0f')} m) | {_f(m.get('final_error_m'))} | "
                f"{r.get('clouds_in_bag', '-')} | {r.get('clouds_dropped_by_injector', '-')} | "
                f"{acc.get('processed', '-')} | {acc.get('skipped', '-')}"
                f"{' (' + skips + ')' if skips else ''} | "
                f"{'yes' if r.get('all_clouds_accounted') else 'NO'} | "
                f"{_f(r.get('wall_time_s'), '.0f')} | {_f(r.get('scans_per_second'), '.1f')} | "
                f"{_f(r.get('peak_rss_mb'), '.0f')} |")
        L.append("")
        for method in sorted({r["method"] for r in fr["runs"]}):
            rs = [r for r in fr["runs"] if r["method"] == method and r.get("metrics")]
            clean = next((r for r in rs if r["case"] == "clean"), None)
            faulty = [r for r in rs if r["case"] != "clean"]
            if clean and faulty:
                worst = max(faulty, key=lambda r: r["metrics"]["ate_rmse_m"])
                c = clean["metrics"]["ate_rmse_m"]
                w = worst["metrics"]["ate_rmse_m"]
                L.append(f"- `{method}`: clean ATE {c:.3f} m; worst fault run "
                         f"`{worst['case']}` {w:.3f} m ({w / c:.2f} x clean, "
                         f"{w - c:+.3f} m); every fault run's ATE <= {w:.3f} m and its "
                         f"final error <= "
                         f"{max(r['metrics']['final_error_m'] for r in faulty):.3f} m.")
        L += ["", "Accounting: every cloud of the piece was either dropped by the injector "
              "(LiDAR outage), rejected by the reader (`late`), rejected by the parser "
              "(`bad_clouds`), skipped by the pipeline with a counter (`skipped_bad_stamp`, "
              "`skipped_too_few_points`, `skipped_stale_stamp`, `fusion_rejected`) or "
              "processed into one odometry output ('all accounted' = yes).", ""]
    pr = data.get("play_rates")
    if pr:
        L += ["## Nothing lost over DDS (play -> node -> recorder)", "",
              f"`lili-odom play {pr['bag']} --rate R` into the node (in-process, real "
              "pipeline) and a recorder of `/lili_odom/odometry`. Nothing lost = every "
              "published scan reached the node's callback, none was dropped, one odometry "
              "message each.", "",
              "| method | rate | status | published | received | processed | dropped "
              "| no output | odometry | nothing lost | drops accounted | mean processing [s] |",
              "|---" * 12 + "|"]
        for r in pr["runs"]:
            L.append(f"| {r.get('method')} | {r.get('rate')} | {r.get('status', '-')} | "
                     f"{r.get('published', '-')} | "
                     f"{r.get('received', '-')} | {r.get('processed', '-')} | "
                     f"{r.get('dropped', '-')} | {r.get('no_output', '-')} | "
                     f"{r.get('odometry', '-')} | {'yes' if r.get('nothing_lost') else 'no'} "
                     f"| {'yes' if r.get('accounted') else 'no'} | "
                     f"{_f(r.get('mean_processing_s'))} |")
        L.append("")
        for m, rate in pr["max_rate"].items():
            L.append(f"- fastest rate with nothing lost, `{m}`: "
                     f"{'below the lowest rate tried' if not rate else f'{rate:g}x'}")
        L.append("")
    for section in sorted(k for k in data if k.startswith("long_run")):
        L += long_run_lines(data[section], section)
    notes = data.get("notes")
    if notes:
        L += ["## Findings", ""] + [f"- {n}" for n in notes] + [""]
    return "\n".join(L)


# --------------------------------------------------------------------------- main
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trial", type=int, default=1)
    ap.add_argument("--resolution", default="64x512")
    ap.add_argument("--start", type=float, default=70.0, help="piece start in the trial [s]")
    ap.add_argument("--duration", type=float, default=40.0, help="piece length [s]")
    ap.add_argument("--bag", help="use this bag instead of a simulated piece")
    ap.add_argument("--window", action="store_true",
                    help="with --bag: only --start..--start+--duration after its first stamp")
    ap.add_argument("--methods", nargs="+", default=["none", "lili"])
    ap.add_argument("--cases", nargs="+", help="only these cases (default: all)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-faults", action="store_true", help="skip the fault runs")
    ap.add_argument("--play-rates", action="store_true", help="measure the play rates")
    ap.add_argument("--play-methods", nargs="+", default=["none", "lili"])
    ap.add_argument("--none-rates", nargs="+", type=float, default=[1, 2, 4, 8, 16])
    ap.add_argument("--lili-rates", nargs="+", type=float, default=[0.25, 0.5, 1, 2])
    ap.add_argument("--bad-input-tests", action="store_true", help="run the robustness tests")
    ap.add_argument("--note", action="append", default=None,
                    help="a finding for the report (replaces the stored notes)")
    ap.add_argument("--tmp", default=os.environ.get("TMPDIR", "/tmp"))
    ap.add_argument("--timeout", type=float, default=3600.0, help="per run [s]")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--worker", nargs=2, metavar=("KIND", "JOB"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)

    if args.worker:
        kind, job = args.worker[0], json.loads(args.worker[1])
        result = worker_fault_run(job) if kind == "fault" else worker_play(job)
        print(json.dumps(result, default=float))
        return 0

    data: dict = {}
    if not args.no_faults:
        data["faults"] = fault_runs(args)
        save_results(data, ("faults",))
    if args.play_rates:
        data["play_rates"] = play_rates(args)
        save_results(data, ("play_rates",))
    if args.bad_input_tests:
        data["bad_input_tests"] = bad_input_tests(args)
    if args.note is not None:
        data["notes"] = args.note
    save_results(data, tuple(data))
    print(f"wrote {RESULTS / 'robustness.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
