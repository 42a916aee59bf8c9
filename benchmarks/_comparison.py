"""Markdown tables that compare odometry configurations run on the same bags.

Input everywhere is a list of *run rows*: dicts with ``config`` (the configuration's name,
:func:`run_label`), errors in metres (``ate_m``, ``rpe_m``, ``final_m``) and the fields that
identify the bag window (``trial``, ``seed``, ``start`` [s], ``repeat``). The functions only
format and compare rows; running the odometry is the caller's job.
"""
from __future__ import annotations

import statistics
from pathlib import Path
from typing import Iterable

__all__ = ["run_label", "seeds_table", "paired_table", "matching_runs"]


def run_label(config: str, method: str = "lili") -> str:
    """Name of a configuration: ``"default"`` for ``config == "default"``, else the stem of
    the parameter file path; ``_<method>`` is appended for every method but ``lili``."""
    name = "default" if config == "default" else Path(config).stem
    return name if method == "lili" else f"{name}_{method}"


def seeds_table(rows: list[dict], trials: list[int], seeds: list[int], labels: list[str],
                targets: dict[int, dict[str, float]]) -> list[str]:
    """Markdown table lines, one row per (trial, configuration name in ``labels``): ATE / RPE
    [m] for each value of ``seeds``, their mean and maximum, and the count of rows within
    ``targets[trial]`` (upper bounds ``{"ate_m": .., "rpe_m": ..}``; missing keys: no
    bound)."""
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
    """Markdown table lines comparing each configuration in ``labels[1:]`` with
    ``labels[0]`` on the windows both have (a window is ``(seed, start)``; its final error
    [m] is the mean over repeats): mean difference, the number of windows where ``labels[0]``
    ends further off, and the Wilcoxon signed-rank p-value (scipy; NaN for fewer than two or
    all-zero differences). Configurations with no common window get no row."""
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
    """Rows of ``stored["runs"]`` whose ``key`` fields form a tuple in ``wanted``, when every
    ``settings`` item equals ``stored``'s value for it and every wanted tuple is present;
    None otherwise (the caller runs them afresh)."""
    wanted = set(wanted)

    def ident(r: dict) -> tuple:
        return tuple(float(r[k]) if isinstance(r[k], float) else r[k] for k in key)

    rows = [r for r in stored.get("runs", []) if ident(r) in wanted]
    same = all(stored.get(k) == v for k, v in settings.items())
    return rows if same and len(rows) == len(wanted) else None
