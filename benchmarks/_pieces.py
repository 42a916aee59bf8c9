"""One window of a suite scenario at any resolution, for the benchmarks that compare resolutions.

:func:`suite_resolutions` lists the Ouster modes (rows x cols) the shipped scenarios use (their
sensor and their CI piece); :func:`default_resolutions` adds :data:`DEFAULT_RESOLUTIONS`.
:func:`piece_bag` simulates a window of one scenario with the suite's own scenario code (its
world, trial, sensor family, error profile and seed; only rows x cols replaced) and caches
the bag in the simulator cache (``data/sim`` or ``$LILI_ODOM_SIM_CACHE``), as the suite does.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

__all__ = ["DEFAULT_RESOLUTIONS", "format_resolution", "parse_resolution", "suite_resolutions",
           "default_resolutions", "piece_bag", "warm_file_cache"]

#: Resolutions measured besides the suite's own: 32, 64 and 128 beams, 512 to 2048 columns.
DEFAULT_RESOLUTIONS: tuple[tuple[int, int], ...] = (
    (32, 512), (32, 1024), (64, 1024), (64, 2048), (128, 1024), (128, 2048))


def format_resolution(resolution: tuple[int, int]) -> str:
    """``(rows, cols)`` as ``"ROWSxCOLS"``."""
    return f"{int(resolution[0])}x{int(resolution[1])}"


def parse_resolution(text: str) -> tuple[int, int]:
    """``"ROWSxCOLS"`` as ``(rows, cols)``; ValueError when malformed."""
    from lili_odom.sim.sensors import parse_resolution as parse

    return tuple(int(v) for v in parse(text))  # type: ignore[return-value]


def suite_resolutions() -> dict[tuple[int, int], list[str]]:
    """Every resolution a shipped scenario uses -> the scenarios using it (a CI piece is
    listed as ``NAME (CI)``), sorted by points per scan, then rows."""
    from lili_odom.suite.scenario import load_scenarios

    users: dict[tuple[int, int], list[str]] = {}
    for sc in load_scenarios(measure=False):
        users.setdefault(tuple(sc.sensor.resolution), []).append(sc.name)
        if sc.ci is not None:
            users.setdefault(tuple(sc.ci.resolution), []).append(f"{sc.name} (CI)")
    return {r: users[r] for r in sorted(users, key=lambda r: (r[0] * r[1], r[0]))}


def default_resolutions() -> list[tuple[int, int]]:
    """:data:`DEFAULT_RESOLUTIONS` and every resolution of :func:`suite_resolutions`, sorted
    by points per scan, then rows."""
    return sorted(set(DEFAULT_RESOLUTIONS) | set(suite_resolutions()),
                  key=lambda r: (r[0] * r[1], r[0]))


def piece_bag(scenario: str, start: float, duration: float, resolution: tuple[int, int],
              seed: int = 0, *, progress: bool = True, cache_dir: Path | str | None = None
              ) -> Path:
    """The cached bag of ``scenario`` from ``start`` [s of trial time, as the scenario's own
    ``start``] for ``duration`` [s] at ``resolution`` (rows, cols) with ``seed``; simulated on
    first use. The directory is ``<cache>/<scenario>_t<start>-<end>_<rows>x<cols>_seed<seed>_<key>``."""
    from lili_odom.sim.generator import ensure_bag
    from lili_odom.suite.scenario import load_scenarios, scenario_request

    (sc,) = load_scenarios([scenario], measure=False)
    req = dataclasses.replace(scenario_request(sc, seed, resolution=tuple(resolution)),
                              start=float(start), duration=float(duration))
    name = (f"{sc.name}_t{start:g}-{start + duration:g}_{format_resolution(resolution)}"
            f"_seed{seed}")
    return ensure_bag(req, cache_dir, name, progress=progress)


def warm_file_cache(bag: Path | str, chunk: int = 1 << 24) -> int:
    """Read every file of ``bag`` (a directory or a file) once, so the timed runs that follow
    all find it in the page cache; returns the bytes read."""
    bag = Path(bag)
    total = 0
    for path in ([bag] if bag.is_file() else sorted(p for p in bag.rglob("*") if p.is_file())):
        with open(path, "rb") as f:
            while block := f.read(chunk):
                total += len(block)
    return total
