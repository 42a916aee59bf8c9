"""The suite's outputs: ``suite.json`` (written row by row), ``suite.md`` and one figure per
scenario.

``suite.json``::

    {"backend": "local", "command": "lili-odom suite ...", "preset": "full",
     "rpe_segment_m": 10.0, "wall_time_s": ..., "scenarios": {NAME: {split, kind, sensor, ...}},
     "rows": [{"scenario", "split", "kind", "seed", "method", "ate_m", "rpe_pct", "final_m",
               "distance_m", "scans_per_s", "degenerate_fraction", "scans", "wall_s",
               "error"?}, ...]}

``suite.md``: the command, then a summary table per split (ATE [m] of every method per
scenario; ``validation`` reported apart from ``tuning``, users' bags under ``user``), with
every run's ATE when a scenario has several seeds and where ``lili`` stands against the
LiDAR peers and the floors (:mod:`lili_odom.suite.standings`), then one
table per scenario (methods sorted by ATE, the best in bold; mean over seeds when there are
several) with its figure ``NAME.png`` (top view of the truth and every method's trajectory
after the same SE(3) alignment as the ATE, first seed).
"""
from __future__ import annotations

import json
import math
import os
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from lili_odom.suite.jobs import ROW_KEYS
from lili_odom.suite.standings import LIDAR_PEERS, markdown_lines, standings

SPLIT_ORDER = ("tuning", "validation", "user")


class SuiteFile:
    """``suite.json``, rewritten (atomically) after every row."""

    def __init__(self, path: Path, *, backend: str, command: str, preset: str,
                 rpe_segment_m: float, scenarios: dict, resume: bool = False,
                 work_dir: Path | None = None) -> None:
        self.path = Path(path)
        rows: list[dict] = []
        old_scenarios: dict = {}
        if resume and self.path.exists():
            try:
                old = json.loads(self.path.read_text())
                rows = [r for r in old.get("rows", []) if not r.get("error")]
                old_scenarios = old.get("scenarios", {})
            except (OSError, ValueError):
                rows = []
        self.document = {
            "backend": backend,
            "command": command,
            "preset": preset,
            "rpe_segment_m": rpe_segment_m,
            "started_utc": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M:%S"),
            "wall_time_s": None,
            "work_dir": _relative(work_dir if work_dir is not None else self.path.parent / "runs",
                                  self.path.parent),
            "scenarios": {**old_scenarios, **scenarios},
            "rows": rows,
        }
        self._write()

    def finished_keys(self) -> set[tuple]:
        return {(r["scenario"], r["seed"], r["method"]) for r in self.document["rows"]}

    def add(self, row: dict) -> None:
        rows = self.document["rows"]
        key = (row["scenario"], row["seed"], row["method"])
        rows[:] = [r for r in rows if (r["scenario"], r["seed"], r["method"]) != key]
        rows.append(row)
        self._write()

    def set_wall_time(self, seconds: float) -> None:
        self.document["wall_time_s"] = round(float(seconds), 1)
        self._write()

    def _write(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(f".{self.path.name}.tmp")
        tmp.write_text(json.dumps(self.document, indent=1, allow_nan=False) + "\n")
        os.replace(tmp, self.path)


def _relative(path: Path, start: Path) -> str:
    """``path`` relative to ``start`` when it can be (keeps machine paths out of the file)."""
    try:
        return os.path.relpath(Path(path).resolve(), Path(start).resolve())
    except ValueError:
        return str(path)


def validate_row(row: dict) -> None:
    """Raise ValueError when a row lacks a key or holds a non-finite number."""
    missing = [k for k in ROW_KEYS if k not in row]
    if missing:
        raise ValueError(f"row misses {missing}")
    for k, v in row.items():
        if isinstance(v, float) and not math.isfinite(v):
            raise ValueError(f"row {k} is not finite")


# ---------------------------------------------------------------------------- markdown

def _fmt(v, digits: int = 3) -> str:
    if v is None:
        return "–"
    if isinstance(v, float):
        return f"{v:.{digits}f}"
    return str(v)


def _mean(values: list) -> float | None:
    vals = [v for v in values if v is not None]
    return float(np.mean(vals)) if vals else None


def aggregate(rows: list[dict]) -> dict[tuple[str, str], dict]:
    """(scenario, method) -> mean of each metric over the seeds that succeeded, ``seeds``,
    ``failed`` (count) and ``error`` (the first failure's reason)."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        groups.setdefault((r["scenario"], r["method"]), []).append(r)
    out = {}
    for key, rs in groups.items():
        ok = [r for r in rs if not r.get("error")]
        bad = [r for r in rs if r.get("error")]
        agg = {k: _mean([r.get(k) for r in ok]) for k in
               ("ate_m", "rpe_pct", "final_m", "distance_m", "scans_per_s", "degenerate_fraction")}
        agg.update(seeds=len(ok), failed=len(bad), error=bad[0]["error"] if bad else None,
                   split=rs[0]["split"])
        out[key] = agg
    return out


def markdown(document: dict) -> str:
    rows = document.get("rows", [])
    scenarios = document.get("scenarios", {})
    agg = aggregate(rows)
    methods: list[str] = []
    for r in rows:
        if r["method"] not in methods:
            methods.append(r["method"])
    order = [m for m in ("lili", "hessian", "zhang", "none", "genz", "rko", "kiss", "wheels")
             if m in methods] + [m for m in methods if m not in
                                 ("lili", "hessian", "zhang", "none", "genz", "rko", "kiss", "wheels")]
    names = list(dict.fromkeys(r["scenario"] for r in rows))
    lines = ["# Scenario suite", "",
             f"Command: `{document.get('command', '')}`  ",
             f"Backend: {document.get('backend')}, preset: {document.get('preset')}, "
             f"started {document.get('started_utc')} UTC, wall time "
             f"{_fmt(document.get('wall_time_s'), 0)} s.", "",
             "ATE: RMSE of the position error after an SE(3) alignment [m]; RPE: relative "
             f"translation error over {_fmt(document.get('rpe_segment_m'), 0)} m segments "
             "[% of the segment]; final: end-point error with the estimate anchored at the "
             "true start pose [m]; deg.: share of scans with a degenerate direction "
             "(our methods). `–`: failed or not applicable.", ""]
    split_of = {n: scenarios.get(n, {}).get("split") or next(
        r["split"] for r in rows if r["scenario"] == n) for n in names}
    splits = [s for s in SPLIT_ORDER if s in split_of.values()]
    splits += sorted(set(split_of.values()) - set(splits))
    for split in splits:
        in_split = [n for n in names if split_of[n] == split]
        lines += [f"## {split.capitalize()} scenarios: ATE [m]", "",
                  "| scenario | distance [m] | " + " | ".join(order) + " |",
                  "|---|---:|" + "---:|" * len(order)]
        for n in in_split:
            vals = {m: agg.get((n, m), {}).get("ate_m") for m in order}
            ok = [v for v in vals.values() if v is not None]
            best = min(ok) if ok else None
            dist = _mean([agg.get((n, m), {}).get("distance_m") for m in order])
            cells = [(f"**{_fmt(v)}**" if v is not None and v == best else _fmt(v)) for v in vals.values()]
            lines.append(f"| {n} | {_fmt(dist, 1)} | " + " | ".join(cells) + " |")
        lines.append("")
        in_rows = [r for r in rows if split_of[r["scenario"]] == split]
        if len({(r["scenario"], r["seed"]) for r in in_rows}) > len(in_split):
            lines += [f"### Every run ({split}): ATE [m]", ""] + _per_run_lines(in_rows, order) + [""]
        placed = standings(in_rows, "lili")
        if placed and any(r["method"] in LIDAR_PEERS for r in in_rows):
            lines += [f"### Where `lili` stands ({split})", ""] + markdown_lines(placed) + [""]
    lines += ["## Scenarios", ""]
    for n in names:
        info = scenarios.get(n, {})
        lines += [f"### {n} ({info.get('split', '')}, {info.get('kind', '')})", ""]
        if info.get("description"):
            lines += [info["description"], ""]
        details = ", ".join(x for x in (info.get("sensor"), info.get("errors")) if x)
        if details:
            lines += [f"Sensor and errors: {details}.", ""]
        ranked = sorted((m for m in order if (n, m) in agg),
                        key=lambda m: (agg[(n, m)]["ate_m"] is None, agg[(n, m)]["ate_m"] or 0.0))
        lines += ["| method | ATE [m] | RPE [%] | final [m] | scans/s | deg. | seeds |",
                  "|---|---:|---:|---:|---:|---:|---:|"]
        for i, m in enumerate(ranked):
            a = agg[(n, m)]
            name = f"**{m}**" if i == 0 and a["ate_m"] is not None else m
            seeds = f"{a['seeds']}" + (f" ({a['failed']} failed: {a['error']})" if a["failed"] else "")
            lines.append(f"| {name} | {_fmt(a['ate_m'])} | {_fmt(a['rpe_pct'], 2)} | "
                         f"{_fmt(a['final_m'], 2)} | {_fmt(a['scans_per_s'], 1)} | "
                         f"{_fmt(a['degenerate_fraction'], 2)} | {seeds} |")
        lines += ["", f"![{n}]({n}.png)", ""]
    return "\n".join(lines) + "\n"


def _per_run_lines(rows: list[dict], order: list[str]) -> list[str]:
    """A Markdown table of every run's (scenario, seed) ATE [m] per method, the best in bold."""
    runs: dict[tuple[str, int], dict[str, dict]] = {}
    for r in rows:
        runs.setdefault((r["scenario"], r["seed"]), {})[r["method"]] = r
    lines = ["| scenario | seed | distance [m] | " + " | ".join(order) + " |",
             "|---|---:|---:|" + "---:|" * len(order)]
    for (name, seed), by_method in runs.items():
        vals = [None if by_method.get(m) is None or by_method[m].get("error")
                else by_method[m].get("ate_m") for m in order]
        ok = [v for v in vals if v is not None]
        best = min(ok) if ok else None
        dist = _mean([r.get("distance_m") for r in by_method.values()])
        cells = [(f"**{_fmt(v)}**" if v is not None and v == best else _fmt(v)) for v in vals]
        lines.append(f"| {name} | {seed} | {_fmt(dist, 1)} | " + " | ".join(cells) + " |")
    return lines


# ---------------------------------------------------------------------------- figures

def _aligned_xy(est_path: Path, truth: tuple[np.ndarray, np.ndarray]) -> np.ndarray | None:
    """Positions (n, 2) of an estimate after the ATE's SE(3) alignment onto the truth."""
    from evo.core import sync
    from evo.core.trajectory import PoseTrajectory3D

    from lili_odom.bagio.tum import read_tum
    from lili_odom.suite.scoring import MAX_DT_S

    stamps, poses = read_tum(est_path)
    if len(stamps) < 2:
        return None
    ref = PoseTrajectory3D(poses_se3=list(truth[1]), timestamps=truth[0])
    est = PoseTrajectory3D(poses_se3=list(poses), timestamps=stamps)
    ref, est = sync.associate_trajectories(ref, est, max_diff=MAX_DT_S)
    est.align(ref, correct_scale=False)
    return est.positions_xyz[:, :2]


def figure(path: Path, title: str, run_dir: Path, methods: list[str]) -> bool:
    """Top view of the truth and every method's aligned trajectory of one run directory."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lili_odom.bagio.tum import read_tum

    truth_path = run_dir / "truth.tum"
    if not truth_path.exists():
        return False
    truth = read_tum(truth_path)
    fig, ax = plt.subplots(figsize=(8, 6))
    ax.plot(truth[1][:, 0, 3], truth[1][:, 1, 3], "k-", lw=3, alpha=0.35, label="truth")
    for m in methods:
        est = run_dir / m / "estimate_base.tum"
        if not est.exists():
            continue
        try:
            xy = _aligned_xy(est, truth)
        except Exception:  # noqa: BLE001 - a trajectory evo cannot align is left out
            xy = None
        if xy is not None:
            ax.plot(xy[:, 0], xy[:, 1], lw=1.2, label=m)
    # frame the truth: a method that runs away leaves the picture instead of shrinking it
    lo, hi = truth[1][:, :2, 3].min(axis=0), truth[1][:, :2, 3].max(axis=0)
    margin = max(5.0, 0.25 * float(np.max(hi - lo)))
    ax.set_xlim(lo[0] - margin, hi[0] + margin)
    ax.set_ylim(lo[1] - margin, hi[1] + margin)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def write_report(out: Path, document: dict) -> None:
    """``suite.md`` and the figures of a suite document (per-run files in its ``work_dir``,
    relative to ``out``)."""
    out = Path(out)
    rows = document.get("rows", [])
    work = out / document.get("work_dir", "runs")
    for name in dict.fromkeys(r["scenario"] for r in rows):
        seeds = sorted({r["seed"] for r in rows if r["scenario"] == name})
        methods = list(dict.fromkeys(r["method"] for r in rows if r["scenario"] == name))
        if seeds:
            figure(out / f"{name}.png", f"{name} (seed {seeds[0]}), aligned as for the ATE",
                   work / name / f"seed{seeds[0]}", methods)
    (out / "suite.md").write_text(markdown(document))
