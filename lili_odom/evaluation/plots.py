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
