"""Memory and CPU of this process together with its descendants (Linux ``/proc``).

``getrusage`` misses the odometry's background detector process, a child of a
``multiprocessing`` forkserver that the run's process does not wait for: ``ProcessTreeRss``
samples the resident set of this process and of every process descending from it in a
background thread and keeps the peak of their sum [MB]; ``descendants_cpu_s`` is the CPU time
of the descendants (with what they reaped). Elsewhere than Linux: NaN / 0.
"""
from __future__ import annotations

import os
import threading
from pathlib import Path

PAGE_MB = os.sysconf("SC_PAGE_SIZE") / 2**20 if hasattr(os, "sysconf") else float("nan")


def _parents() -> dict[int, int]:
    out = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
        except OSError:
            continue
        out[int(d.name)] = int(stat[stat.rindex(")") + 2:].split()[1])
    return out


def _tree(root: int) -> set[int]:
    parents = _parents()
    tree, frontier = {root}, [root]
    while frontier:
        p = frontier.pop()
        kids = [c for c, pp in parents.items() if pp == p and c not in tree]
        tree.update(kids)
        frontier.extend(kids)
    return tree


def descendants_cpu_s() -> float:
    """CPU time [s] used so far by this process's living descendants and the processes they
    reaped (user + system)."""
    if not Path("/proc/self/stat").exists():
        return 0.0
    tick = os.sysconf("SC_CLK_TCK")
    total = 0
    for pid in _tree(os.getpid()) - {os.getpid()}:
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()
        total += sum(int(x) for x in fields[11:15])  # utime stime cutime cstime
    return total / tick


def tree_rss_mb(root: int | None = None) -> float:
    """Resident memory [MB] of process ``root`` (default: this one) and its descendants now."""
    root = os.getpid() if root is None else root
    total = 0
    for pid in _tree(root):
        try:
            total += int(Path(f"/proc/{pid}/statm").read_text().split()[1])
        except (OSError, IndexError, ValueError):
            continue
    return total * PAGE_MB


class ProcessTreeRss:
    """Context manager sampling :func:`tree_rss_mb` every ``every_s`` seconds; ``peak_mb``."""

    def __init__(self, every_s: float = 0.25) -> None:
        self.every_s = float(every_s)
        self.peak_mb = float("nan")
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample, daemon=True)

    def _sample(self) -> None:
        while True:
            try:
                now = tree_rss_mb()
            except OSError:
                return
            self.peak_mb = now if not self.peak_mb >= now else self.peak_mb
            if self._stop.wait(self.every_s):
                return

    def __enter__(self) -> "ProcessTreeRss":
        if Path("/proc/self/statm").exists():
            self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()
