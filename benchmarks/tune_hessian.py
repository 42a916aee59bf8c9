"""Tune the ``hessian`` detector's single threshold once, on the clean synthetic shapes.

Procedure (the value found is frozen as ``lili_odom.degeneracy.hessian.HESSIAN_THRESHOLD``):

1. For every clean (noise-free) scenario of ``lili_odom.sim.shapes`` and each seed, run
   ``HessianDetector.detect`` from the case's initial pose against
   ``reference_for_detection(case.reference)`` and take the per-correspondence eigenvalues of
   the scaled body-frame Hessian at P_opt (they do not depend on the threshold).
2. With ``k`` = the case's true degenerate dimension, the ``k`` smallest eigenvalues should fall
   below the threshold and the other ``6 - k`` above it. Collect ``lo`` = the largest of the
   "should be degenerate" eigenvalues and ``hi`` = the smallest of the "should be constrained"
   ones over all cases.
3. When ``lo < hi`` every case is separable; the threshold is the geometric mean
   ``sqrt(lo * hi)`` (the middle of the gap on the log scale, since eigenvalues span decades),
   rounded to one significant digit.

Noisy cases are reported for information only and take no part in the tuning.

Usage: ``python -m benchmarks.tune_hessian [--seeds 0 1 2] [--json OUT]``.
"""
from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np

from lili_odom.degeneracy.factory import reference_for_detection
from lili_odom.degeneracy.hessian import HESSIAN_THRESHOLD, HessianDetector
from lili_odom.sim.shapes import SCENARIOS, make_case


def spectra(seeds: list[int], noisy: bool) -> list[dict]:
    det = HessianDetector()
    rows = []
    for seed in seeds:
        for name in SCENARIOS:
            case = make_case(name, noisy=noisy, seed=seed)
            res = det.detect(reference_for_detection(case.reference), case.scan, case.initial_pose)
            k = case.true_dimension
            ev = np.sort(np.asarray(res.eigenvalues))  # ascending
            rows.append(
                {
                    "scenario": name,
                    "seed": seed,
                    "noise": case.noise,
                    "ok": res.ok,
                    "true_dimension": k,
                    "eigenvalues_ascending": ev.tolist(),
                    "largest_degenerate": float(ev[k - 1]) if k else None,
                    "smallest_constrained": float(ev[k]) if k < 6 else None,
                    "n_correspondences": res.details.get("n_correspondences"),
                    "runtime_s": res.runtime_s,
                }
            )
    return rows


def one_digit(x: float) -> float:
    e = math.floor(math.log10(x))
    return round(x / 10**e) * 10**e


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--json", help="write the spectra and the tuned value to this file")
    args = ap.parse_args(argv)

    clean = spectra(args.seeds, noisy=False)
    if not all(r["ok"] for r in clean):
        print("some clean case failed to run", file=sys.stderr)
        return 1
    lo = max(r["largest_degenerate"] for r in clean if r["largest_degenerate"] is not None)
    hi = min(r["smallest_constrained"] for r in clean if r["smallest_constrained"] is not None)
    tuned = one_digit(math.sqrt(lo * hi)) if lo < hi else float("nan")

    noisy = spectra(args.seeds, noisy=True)
    print(f"{'case':28s} {'k':>2s} {'largest degen.':>15s} {'smallest constr.':>17s}")
    for r in clean + noisy:
        tag = f"{r['scenario']}{' (noisy)' if r['noise'] else ''} s{r['seed']}"
        a = r["largest_degenerate"]
        b = r["smallest_constrained"]
        print(f"{tag:28s} {r['true_dimension']:2d} {a if a is not None else float('nan'):15.3e} "
              f"{b if b is not None else float('nan'):17.3e}")
    print(f"clean: largest degenerate eigenvalue {lo:.3e}, smallest constrained {hi:.3e}")
    print(f"tuned threshold sqrt(lo*hi) -> {tuned:g}   (frozen HESSIAN_THRESHOLD = {HESSIAN_THRESHOLD:g})")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(
                {"lo": lo, "hi": hi, "tuned": tuned, "frozen": HESSIAN_THRESHOLD, "seeds": args.seeds,
                 "clean": clean, "noisy_info_only": noisy},
                fh,
                indent=1,
            )
    return 0 if lo < hi else 2


if __name__ == "__main__":
    sys.exit(main())
