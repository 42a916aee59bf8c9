#!/usr/bin/env python3
"""What the vertical lines of the plane fits lie on: poles, box corners or flat faces.

Runs :func:`lili_odom.evaluation.runner.run_bag` without wheel odometry (so every scan's plane
fits use near-vertical lines, ``plane_refinement.vertical_lines_without_wheels``) over a
scenario's bag (default: the airfield, its first seed and own sensor) once per
``--line-neighbors`` value, records the centroid of every line a scan point got (odometry
frame), and places each against the world's objects (the scenario's world file, moved into
the odometry frame at the first scan's true pose): within ``--pole-distance`` of a cylinder's
axis ("pole"), within ``--corner-distance`` of a corner of a box-like object's footprint
("corner"), within ``--face-distance`` of a footprint edge ("flat face"), else "other".
A line on a flat face is a strip of points that a sparse sensor leaves on a wall it drives
towards, not a pole.

Writes ``benchmarks/results/line_sources.md`` and ``.json``.

Usage: ``python -m benchmarks.studies.line_sources [--scenario airfield] [--seed S]
[--line-neighbors 0 30]``
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import RESULTS, config_with, machine_info, write_results

CLASSES = ("pole", "corner", "flat face", "other")


def footprints(world: Any) -> tuple[np.ndarray, list[np.ndarray]]:
    """(axes (n, 2) of the cylinders, [corners (4, 2) of each box-like object]) in the world
    frame, every copy of a ``count``-ed object included."""
    axes, boxes = [], []
    for obj in world.outside.objects:
        for k in range(max(1, obj.count)):
            x = obj.position[0] + k * obj.step[0]
            y = obj.position[1] + k * obj.step[1]
            if obj.kind == "cylinder":
                axes.append((x, y))
            elif obj.kind in ("box", "wall", "vehicle"):
                a = np.deg2rad(obj.yaw_deg)
                R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
                half = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]]) * np.array(obj.size[:2]) / 2
                boxes.append(half @ R.T + (x, y))
    return np.array(axes).reshape(-1, 2), boxes


def _edge_distance(p: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Distance of the points ``p`` (m, 2) to the closed polygon ``corners`` (4, 2)."""
    best = np.full(len(p), np.inf)
    for a, b in zip(corners, np.roll(corners, -1, axis=0)):
        ab = b - a
        t = np.clip(((p - a) @ ab) / float(ab @ ab), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(p - (a + t[:, None] * ab), axis=1))
    return best


def classify(centroids: np.ndarray, axes: np.ndarray, boxes: list[np.ndarray],
             pole: float, corner: float, face: float) -> dict[str, int]:
    """How many of the line ``centroids`` (m, 2), world frame, are of each class."""
    p = np.asarray(centroids, dtype=float).reshape(-1, 2)
    left = np.ones(len(p), dtype=bool)
    out = {}
    near_pole = (np.min(np.linalg.norm(p[:, None] - axes[None], axis=2), axis=1) < pole
                 if len(axes) else np.zeros(len(p), dtype=bool))
    out["pole"] = int(np.count_nonzero(near_pole & left))
    left &= ~near_pole
    corners = np.vstack(boxes) if boxes else np.zeros((0, 2))
    near_corner = (np.min(np.linalg.norm(p[:, None] - corners[None], axis=2), axis=1) < corner
                   if len(corners) else np.zeros(len(p), dtype=bool))
    out["corner"] = int(np.count_nonzero(near_corner & left))
    left &= ~near_corner
    near_face = np.zeros(len(p), dtype=bool)
    for b in boxes:
        near_face |= _edge_distance(p, b) < face
    out["flat face"] = int(np.count_nonzero(near_face & left))
    left &= ~near_face
    out["other"] = int(np.count_nonzero(left))
    return out


def measure(bag: Path, line_neighbors: int) -> dict[str, Any]:
    """One run without wheels with ``line_neighbors``; the lines' centroids (odometry frame)
    and the transform from the world to the odometry frame."""
    from lili_odom.evaluation.runner import run_bag
    from lili_odom.pipeline import plane_refinement

    fits = plane_refinement._planes
    centroids: list[np.ndarray] = []

    def recording(reference, q, cfg):
        out = fits(reference, q, cfg)
        rows = out[4]
        if len(rows):
            centroids.append(out[2][rows].copy())
        return out

    config = config_with({"plane_refinement.line_neighbors": int(line_neighbors)},
                         path="benchmarks/configs/no_wheels.yaml", prog="line_sources")
    plane_refinement._planes = recording
    try:
        with tempfile.TemporaryDirectory(prefix="lili_line_sources_") as tmp:
            run = run_bag(bag, config, Path(tmp) / "run", progress=False)
    finally:
        plane_refinement._planes = fits
    stamps = np.array([s for s, _ in run.truth])
    i = int(np.argmin(np.abs(stamps - run.estimates[0][0])))
    T_odom_world = run.estimates[0][1] @ np.linalg.inv(run.truth[i][1])
    return {"centroids": np.vstack(centroids) if centroids else np.zeros((0, 3)),
            "T_odom_world": T_odom_world,
            "ate_m": (run.summary.get("metrics") or {}).get("ate_rmse_m"),
            "scans": len(run.estimates)}


def main(argv: list[str] | None = None) -> int:
    from lili_odom.sim.world import load_world
    from lili_odom.suite.scenario import load_scenarios, scenario_bag

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="airfield")
    ap.add_argument("--seed", type=int, help="default: the scenario's first seed")
    ap.add_argument("--line-neighbors", type=int, nargs="+", default=[0, 30])
    ap.add_argument("--pole-distance", type=float, default=1.0, help="[m] (default 1)")
    ap.add_argument("--corner-distance", type=float, default=1.5, help="[m] (default 1.5)")
    ap.add_argument("--face-distance", type=float, default=1.0, help="[m] (default 1)")
    ap.add_argument("--out", type=Path, default=RESULTS)
    ap.add_argument("--name", default="line_sources")
    args = ap.parse_args(argv)
    try:
        (scenario,) = load_scenarios([args.scenario], measure=False)
    except ValueError as exc:
        ap.error(str(exc))
    seed = scenario.seeds[0] if args.seed is None else args.seed
    bag = scenario_bag(scenario, seed)
    axes, boxes = footprints(load_world(scenario.world))
    rows = {}
    for n in args.line_neighbors:
        print(f"line_neighbors {n} ...", flush=True)
        m = measure(bag, n)
        T = m["T_odom_world"]
        to_world = np.linalg.inv(T)
        c = m["centroids"]
        world = c @ to_world[:3, :3].T + to_world[:3, 3] if len(c) else c
        counts = classify(world[:, :2], axes, boxes, args.pole_distance, args.corner_distance,
                          args.face_distance)
        rows[str(n)] = {"lines": int(len(c)), "classes": counts, "ate_m": m["ate_m"],
                        "scans": m["scans"]}
    command = (f"python -m benchmarks.studies.line_sources --scenario {args.scenario} "
               f"--seed {seed} --line-neighbors {' '.join(map(str, args.line_neighbors))}")
    machine = machine_info()
    lines = ["# What the vertical lines lie on", "",
             f"`{command}`: `{scenario.name}` seed {seed} at its own sensor, without wheel "
             "odometry, one run per `line_neighbors` (0: no check of the wider neighbourhood); "
             "every line a scan point got, placed against the world's objects (module docstring "
             f"of `benchmarks/studies/line_sources.py`; pole within {args.pole_distance:g} m of "
             f"a cylinder's axis, corner within {args.corner_distance:g} m of a box's footprint "
             f"corner, flat face within {args.face_distance:g} m of its edge). "
             f"Commit `{machine['commit']}`.", "",
             "| `line_neighbors` | lines | " + " | ".join(CLASSES) + " | ATE [m] |",
             "|---:|---:|" + "---:|" * len(CLASSES) + "---:|"]
    for n, r in rows.items():
        total = max(r["lines"], 1)
        cells = " | ".join(f"{r['classes'][k]} ({100 * r['classes'][k] / total:.0f} %)"
                           for k in CLASSES)
        ate = f"{r['ate_m']:.3f}" if r["ate_m"] is not None else "–"
        lines.append(f"| {n} | {r['lines']} | {cells} | {ate} |")
    path = write_results(args.out, args.name, "\n".join(lines) + "\n",
                         {"machine": machine, "command": command, "runs": rows})
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
