"""Long run memory: the odometry over the whole of Trial 2 (430 m) with RSS sampled.

RSS of the process and its own child processes (the background detector) is read from
``/proc`` every ``--every`` processed scans (and the local map size beside it); reported: the
peak RSS (the larger of the process's ``getrusage`` peak and the largest sample), and the linear trend of the second
half in MB per 100 scans (local map pruning and the bounded fusion window should make it
flat). The run itself keeps only the estimated poses (about 0.03 MB per 100 scans); the
ground truth is read after it. ``--set`` overrides pipeline parameters and ``--no-save``
only prints (for looking for a growth). Adds the section ``--section`` (default ``long_run``
at 32x256, ``long_run_<rows>x<cols>`` at another resolution, so runs at several resolutions
stay side by side) to ``benchmarks/results/robustness.{json,md}``, with the peak RSS against
the 1.5 GB target, and writes ``benchmarks/results/<section>_memory.png``.

    python -m benchmarks.long_run                          # method none, 32x256 (~10 min)
    python -m benchmarks.long_run --method lili --resolution 128x1024   # ~15 GB of bag
"""
from __future__ import annotations

import argparse
import logging
import resource
import sys
import time

import numpy as np

from benchmarks._common import SET_HELP, apply_set, parse_set
from benchmarks._process_tree import tree_rss_mb
from benchmarks.faults import LONG_RUN_RSS_TARGET_MB, RESULTS, save_results

def second_half_trend(scans: np.ndarray, rss: np.ndarray) -> tuple[float, int]:
    """Slope [MB per 100 scans] of a least-squares line through the second half."""
    start = int(scans[-1] // 2)
    sel = scans >= start
    if sel.sum() < 3:
        return float("nan"), start
    slope = np.polyfit(scans[sel], rss[sel], 1)[0]
    return float(100.0 * slope), start


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trial", type=int, default=2)
    ap.add_argument("--resolution", default="32x256", help="e.g. 128x1024 for the full sensor")
    ap.add_argument("--method", default="none", choices=("lili", "zhang", "hessian", "none"))
    ap.add_argument("--every", type=int, default=20, help="sample RSS every N scans")
    ap.add_argument("--max-scans", type=int, default=0, help="stop after N scans (0 = all)")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help=SET_HELP)
    ap.add_argument("--section",
                    help="key of the result in robustness.json (default: long_run at 32x256, "
                    "else long_run_<resolution>)")
    ap.add_argument("--no-save", action="store_true",
                    help="print the figures only; leave robustness.md and the plot as they are")
    args = ap.parse_args(argv)
    section = args.section or ("long_run" if args.resolution == "32x256"
                               else f"long_run_{args.resolution}")
    if not section.startswith("long_run"):
        ap.error("--section must start with long_run")
    overrides = parse_set(args.set, "long_run")
    logging.basicConfig(level=logging.ERROR)

    from lili_odom.bagio.reader import BagReader
    from lili_odom.config import load_config
    from lili_odom.evaluation.faults import run_stream
    from lili_odom.messages import truth_sample
    from lili_odom.sim.generator import ensure_trial_bag

    bag = ensure_trial_bag(args.trial, resolution=args.resolution, seed=0,
                           progress=not args.no_progress)
    cfg = load_config(None)
    cfg.pipeline.method = args.method
    apply_set(cfg, overrides, "long_run")
    # the ground truth (100 Hz) is read after the run: kept along the run it would be this
    # benchmark's own memory growth (~0.3 MB per 100 scans), not the odometry's
    topics = [cfg.lidar_topic, cfg.imu_topic, cfg.wheel_topic, "/tf_static"]
    samples: list[tuple[int, float, float, int]] = []  # scan, wall, rss, map points
    t0 = time.perf_counter()
    count = [0]

    class Stop(Exception):
        pass

    def on_output(out, pipeline) -> None:
        count[0] += 1
        n = count[0]
        if n == 1 or n % args.every == 0:
            samples.append((n, time.perf_counter() - t0, tree_rss_mb(),
                            int(len(pipeline.local_map_points()))))
            if not args.no_progress and n % (args.every * 25) == 0:
                print(f"{n} scans, RSS {samples[-1][2]:.0f} MB, map {samples[-1][3]} points",
                      flush=True)

    def limited(items):
        for item in items:
            if args.max_scans and count[0] >= args.max_scans:
                return
            yield item

    with BagReader(bag, topics=topics) as reader:
        run = run_stream(limited(reader), cfg, on_output=on_output)
    peak = max(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
               max(s[2] for s in samples) if samples else 0.0)
    with BagReader(bag, topics=[cfg.ground_truth_topic]) as reader:
        run.truth.extend(filter(None, (truth_sample(item.msg) for item in reader)))
    arr = np.array(samples, dtype=float)
    scans, rss, points = arr[:, 0], arr[:, 2], arr[:, 3]
    trend, half = second_half_trend(scans, rss)
    m = run.metrics()
    result = {
        "bag": f"Trial {args.trial} ({args.resolution})", "method": args.method,
        "overrides": overrides,
        "scans": len(run.estimates), "every": args.every,
        "wall_time_s": run.wall_time_s, "peak_rss_mb": peak,
        "max_sampled_rss_mb": float(rss.max()), "first_rss_mb": float(rss[0]),
        "trend_mb_per_100_scans": trend, "second_half_from": half,
        "map_points_end": int(points[-1]), "map_points_max": int(points.max()),
        "ate_rmse_m": m.ate_rmse_m if m else None,
        "path_length_m": m.path_length_m if m else None,
        "accounting": run.accounting(),
        "samples": [[int(s), round(w, 2), round(r, 2), int(p)] for s, w, r, p in samples],
    }
    print(f"peak RSS {peak:.0f} MB (target under {LONG_RUN_RSS_TARGET_MB:.0f} MB: "
          f"{'met' if peak < LONG_RUN_RSS_TARGET_MB else 'missed'}), second-half trend "
          f"{trend:+.2f} MB/100 scans, {len(run.estimates)} scans in {run.wall_time_s:.0f} s")
    if args.no_save:
        return 0

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4))
    ax.plot(scans, rss, color="tab:blue", label="RSS")
    sel = scans >= half
    if sel.sum() >= 3:
        k, b = np.polyfit(scans[sel], rss[sel], 1)
        ax.plot(scans[sel], k * scans[sel] + b, "k--",
                label=f"second-half trend {100 * k:+.2f} MB/100 scans")
    ax.axhline(peak, color="tab:red", lw=0.8, ls=":", label=f"peak RSS {peak:.0f} MB")
    ax.set_xlabel("scans processed")
    ax.set_ylabel("RSS [MB]")
    ax2 = ax.twinx()
    ax2.plot(scans, points / 1e3, color="tab:green", alpha=0.6, label="local map")
    ax2.set_ylabel("local map points [thousand]", color="tab:green")
    lines = ax.get_legend_handles_labels()
    lines2 = ax2.get_legend_handles_labels()
    ax.legend(lines[0] + lines2[0], lines[1] + lines2[1], loc="lower right", fontsize=8)
    ax.set_title(f"{result['bag']}, method {args.method}: memory along the run")
    fig.tight_layout()
    RESULTS.mkdir(parents=True, exist_ok=True)
    fig.savefig(RESULTS / f"{section}_memory.png", dpi=110)

    save_results({section: result}, (section,))
    print(f"wrote {RESULTS / 'robustness.md'} and {RESULTS / (section + '_memory.png')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
