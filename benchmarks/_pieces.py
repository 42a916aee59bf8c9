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

__all__ = ["DEFAULT_RESOLUTIONS", "DEFAULT_PIECE", "format_resolution", "parse_resolution",
           "suite_resolutions", "default_resolutions", "piece_bag", "warm_file_cache",
           "add_piece_arguments", "piece_bags", "piece_command", "add_window_arguments",
           "window_bag", "window_command"]

#: Resolutions measured besides the suite's own: 32, 64 and 128 beams, 512 to 2048 columns.
DEFAULT_RESOLUTIONS: tuple[tuple[int, int], ...] = (
    (32, 512), (32, 1024), (64, 1024), (64, 2048), (128, 1024), (128, 2048))


#: The window the resolution benchmarks time by default: (scenario, start [s], duration [s]).
DEFAULT_PIECE: tuple[str, float, float] = ("building", 0.0, 30.0)


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


def add_piece_arguments(ap) -> None:
    """Add ``--scenario --start --duration --seed --resolutions`` (the window and the
    resolutions a resolution benchmark measures) to the argparse parser ``ap``."""
    scenario, start, duration = DEFAULT_PIECE
    ap.add_argument("--scenario", default=scenario,
                    help=f"scenario of the suite (default {scenario})")
    ap.add_argument("--start", type=float, default=start,
                    help=f"window start [s of the scenario's trial] (default {start:g})")
    ap.add_argument("--duration", type=float, default=duration,
                    help=f"window length [s] (default {duration:g})")
    ap.add_argument("--seed", type=int, default=0, help="simulator seed (default 0)")
    ap.add_argument("--resolutions", nargs="+", metavar="ROWSxCOLS",
                    help="default: " + " ".join(format_resolution(r) for r in DEFAULT_RESOLUTIONS)
                    + " and every other resolution a scenario of the suite uses")


def piece_bags(ap, args, progress: bool = True):
    """The scenario and the cached bag per resolution (``{"RxC": path}``) that the arguments of
    :func:`add_piece_arguments` name; a bad value ends the program through ``ap.error``."""
    from lili_odom.suite.scenario import load_scenarios

    if not args.duration > 0:
        ap.error("--duration must be positive")
    try:
        resolutions = ([parse_resolution(r) for r in args.resolutions] if args.resolutions
                       else default_resolutions())
        (scenario,) = load_scenarios([args.scenario], measure=False)
    except ValueError as exc:
        ap.error(str(exc))
    bags = {}
    for res in resolutions:
        if progress:
            print(f"[{format_resolution(res)}] bag of {scenario.name} "
                  f"{args.start:g}-{args.start + args.duration:g} s", flush=True)
        bags[format_resolution(res)] = piece_bag(scenario.name, args.start, args.duration, res,
                                                 args.seed, progress=progress)
    return scenario, bags


def piece_command(module: str, args, extra: str = "") -> str:
    """The command line that reproduces a run: ``python -m MODULE`` with the piece options of
    :func:`add_piece_arguments` that differ from their defaults, then ``extra``."""
    scenario, start, duration = DEFAULT_PIECE
    return (f"python -m {module}"
            + (f" --scenario {args.scenario}" if args.scenario != scenario else "")
            + (f" --start {args.start:g}" if args.start != start else "")
            + (f" --duration {args.duration:g}" if args.duration != duration else "")
            + (f" --seed {args.seed}" if args.seed else "")
            + (" --resolutions " + " ".join(args.resolutions) if args.resolutions else "")
            + extra)


def add_window_arguments(ap, scenario: str, duration: float, resolution: str = "32x512") -> None:
    """Add ``--scenario --start --duration --seed --resolution`` (one window of a scenario at
    one resolution, for a study) with these defaults to the argparse parser ``ap``."""
    ap.add_argument("--scenario", default=scenario, help=f"scenario of the suite (default {scenario})")
    ap.add_argument("--start", type=float, default=0.0, help="window start [s of the trial]")
    ap.add_argument("--duration", type=float, default=duration,
                    help=f"window length [s] (default {duration:g})")
    ap.add_argument("--seed", type=int, default=0, help="simulator seed (default 0)")
    ap.add_argument("--resolution", default=resolution,
                    help=f"ROWSxCOLS (default {resolution})")


def window_bag(ap, args):
    """The scenario, the resolution (rows, cols) and the cached bag that the arguments of
    :func:`add_window_arguments` name; a bad value ends the program through ``ap.error``."""
    from lili_odom.suite.scenario import load_scenarios

    if not args.duration > 0:
        ap.error("--duration must be positive")
    try:
        res = parse_resolution(args.resolution)
        (scenario,) = load_scenarios([args.scenario], measure=False)
        bag = piece_bag(args.scenario, args.start, args.duration, res, args.seed)
    except ValueError as exc:
        ap.error(str(exc))
    return scenario, res, bag


def window_command(module: str, args, scenario: str, duration: float,
                   resolution: str = "32x512") -> str:
    """``python -m MODULE`` with the options of :func:`add_window_arguments` that differ from
    the given defaults."""
    return (f"python -m {module}"
            + (f" --scenario {args.scenario}" if args.scenario != scenario else "")
            + (f" --start {args.start:g}" if args.start else "")
            + (f" --duration {args.duration:g}" if args.duration != duration else "")
            + (f" --seed {args.seed}" if args.seed else "")
            + (f" --resolution {args.resolution}" if args.resolution != resolution else ""))
