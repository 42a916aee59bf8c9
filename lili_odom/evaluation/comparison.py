"""Tables that compare parameter files over a set of runs: run names, per-run error tables,
paired differences and the reuse of stored runs.

A *run row* is a dict with ``config`` (the run's name, :func:`run_label`), its errors in
metres (``ate_m``, ``rpe_m``, ``final_m``) and the keys that identify it (``trial``, ``seed``,
``start`` [s], ``repeat``).
"""
from __future__ import annotations

import statistics
from pathlib import Path
from typing import Iterable

__all__ = ["run_label", "seeds_table", "paired_table", "matching_runs"]


def run_label(config: str, method: str = "lili") -> str:
    """A run's name: ``default`` or the parameter file's stem, with ``_<method>`` appended
    unless the method is ``lili``."""
    name = "default" if config == "default" else Path(config).stem
    return name if method == "lili" else f"{name}_{method}"


def seeds_table(rows: list[dict], trials: list[int], seeds: list[int], labels: list[str],
                targets: dict[int, dict[str, float]]) -> list[str]:
    """Markdown lines: per trial and run name, ATE / RPE [m] of each run in ``seeds``, their
    mean and worst, and how many are within ``targets[trial]`` (``{"ate_m": .., "rpe_m": ..}``,
    upper bounds)."""
    lines = ["| trial | configuration | " + " | ".join(f"seed {s}" for s in seeds)
             + " | mean | worst | target |", "|---|---|" + "---|" * (len(seeds) + 3)]
    for trial in trials:
        for config in labels:
            mine = {r["seed"]: r for r in rows if r["trial"] == trial and r["config"] == config}
            cells = [f"{mine[s]['ate_m']:.3f} / {mine[s]['rpe_m']:.3f}" for s in seeds]
            ate = [mine[s]["ate_m"] for s in seeds]
            rpe = [mine[s]["rpe_m"] for s in seeds]
            target = targets.get(trial, {})
            inf = float("inf")
            met = sum(a <= target.get("ate_m", inf) and r <= target.get("rpe_m", inf)
                      for a, r in zip(ate, rpe))
            goal = " and ".join(f"{k[:3].upper()} <= {v}" for k, v in target.items())
            lines.append(f"| {trial} | `{config}` | " + " | ".join(cells)
                         + f" | {sum(ate) / len(ate):.3f} / {sum(rpe) / len(rpe):.3f}"
                         f" | {max(ate):.3f} / {max(rpe):.3f} | {goal}: {met} of {len(seeds)} |")
    return lines


def paired_table(rows: list[dict], labels: list[str]) -> list[str]:
    """Markdown lines: each run name after the first against the first, window by window
    (``(seed, start)``; final error averaged over repeats): mean difference, windows where
    the first ends further off, and the Wilcoxon signed-rank p-value (scipy)."""
    from scipy.stats import wilcoxon

    def finals(config: str) -> dict[tuple, float]:
        out: dict[tuple, list[float]] = {}
        for r in rows:
            if r["config"] == config:
                out.setdefault((r["seed"], r["start"]), []).append(r["final_m"])
        return {w: statistics.mean(v) for w, v in out.items()}

    base = finals(labels[0])
    lines = [f"| against `{labels[0]}` | windows | mean difference [m] | `{labels[0]}` further "
             "off in | Wilcoxon p |", "|---|---|---|---|---|"]
    for config in labels[1:]:
        other = finals(config)
        common = sorted(set(base) & set(other))
        diff = [base[w] - other[w] for w in common]
        if not diff:
            continue
        p = float(wilcoxon(diff).pvalue) if any(diff) and len(diff) > 1 else float("nan")
        lines.append(f"| `{config}` | {len(diff)} | {statistics.mean(diff):+.2f} | "
                     f"{sum(d > 0 for d in diff)} of {len(diff)} | {p:.2f} |")
    return lines


def matching_runs(stored: dict, settings: dict, wanted: Iterable[tuple],
                  key: tuple[str, ...]) -> list[dict] | None:
    """The stored run rows (``stored["runs"]``) whose ``key`` fields are among ``wanted``,
    when ``stored`` was made with ``settings`` (equal values) and holds every wanted run;
    else None."""
    wanted = set(wanted)

    def ident(r: dict) -> tuple:
        return tuple(float(r[k]) if isinstance(r[k], float) else r[k] for k in key)

    rows = [r for r in stored.get("runs", []) if ident(r) in wanted]
    same = all(stored.get(k) == v for k, v in settings.items())
    return rows if same and len(rows) == len(wanted) else None
