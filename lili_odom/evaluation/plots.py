"""Plots of offline runs (matplotlib, Agg backend; PNG files)."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def trajectory_top_view(path: Path, truth: np.ndarray | None, estimates: dict[str, np.ndarray],
                        degenerate: dict[str, np.ndarray] | None = None, title: str = "") -> None:
    """Top view (x-y) of truth (n, 3) and estimates ``{label: (m, 3)}`` [m]; degenerate scans
    (boolean per estimate pose) are marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 7))
    if truth is not None and len(truth):
        ax.plot(truth[:, 0], truth[:, 1], "k-", lw=2, label="truth")
    for label, xyz in estimates.items():
        line, = ax.plot(xyz[:, 0], xyz[:, 1], "-", lw=1.2, label=label)
        mask = None if degenerate is None else degenerate.get(label)
        if mask is not None and np.any(mask):
            ax.plot(xyz[mask, 0], xyz[mask, 1], ".", ms=3, color=line.get_color(), alpha=0.5,
                    label=f"{label}: degenerate scans")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def comparison_figure(path: Path, truth: np.ndarray, estimates: dict[str, np.ndarray],
                      errors: dict[str, tuple[np.ndarray, np.ndarray]],
                      dimensions: dict[str, tuple[np.ndarray, np.ndarray]], title: str = "",
                      inset_half_width: float = 3.0) -> None:
    """Three panels for one trajectory and several methods (the paper's Fig. 6 and more).

    Args:
        truth: (n, 3) truth positions in the odometry frame [m].
        estimates: ``{method: (m, 3)}`` estimated positions [m] (same frame).
        errors: ``{method: (distance travelled [m], position error [m])}``.
        dimensions: ``{method: (distance travelled [m], detected dimension)}``.
        inset_half_width: half size of the end-point inset [m].
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(13, 9))
    grid = fig.add_gridspec(2, 2, height_ratios=[1.4, 1])
    ax = fig.add_subplot(grid[0, :])
    ax.plot(truth[:, 0], truth[:, 1], "k-", lw=2.5, label="truth")
    colors = {}
    for label, xyz in estimates.items():
        line, = ax.plot(xyz[:, 0], xyz[:, 1], "-", lw=1.2, label=label)
        colors[label] = line.get_color()
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(title or "top view")
    end = truth[-1]
    inset = ax.inset_axes([0.72, 0.05, 0.26, 0.5])
    inset.plot(truth[:, 0], truth[:, 1], "k-", lw=2.5)
    inset.plot(end[0], end[1], "k*", ms=12)
    for label, xyz in estimates.items():
        inset.plot(xyz[:, 0], xyz[:, 1], "-", lw=1.2, color=colors[label])
        inset.plot(xyz[-1, 0], xyz[-1, 1], "o", ms=5, color=colors[label])
    inset.set_xlim(end[0] - inset_half_width, end[0] + inset_half_width)
    inset.set_ylim(end[1] - inset_half_width, end[1] + inset_half_width)
    inset.set_aspect("equal")
    inset.set_title("end point", fontsize=8)
    inset.tick_params(labelsize=7)
    ax.indicate_inset_zoom(inset, edgecolor="0.4")

    ax_err = fig.add_subplot(grid[1, 0])
    for label, (dist, err) in errors.items():
        ax_err.plot(dist, err, "-", lw=1.2, color=colors.get(label), label=label)
    ax_err.set_yscale("log")
    ax_err.set_xlabel("distance travelled [m]")
    ax_err.set_ylabel("position error after SE(3) alignment [m]")
    ax_err.grid(True, which="both", alpha=0.3)
    ax_err.legend(fontsize=8)

    ax_dim = fig.add_subplot(grid[1, 1])
    labels = [k for k in dimensions]
    for j, label in enumerate(labels):
        dist, dim = dimensions[label]
        ax_dim.plot(dist, np.asarray(dim) + 0.08 * (j - (len(labels) - 1) / 2), ".", ms=2,
                    color=colors.get(label), label=label)
    ax_dim.set_xlabel("distance travelled [m]")
    ax_dim.set_ylabel("detected degenerate dimension")
    ax_dim.set_yticks(range(7))
    ax_dim.grid(True, alpha=0.3)
    ax_dim.legend(fontsize=8, markerscale=4)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
