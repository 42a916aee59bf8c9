"""Where one of our methods stands against the others on every run of a suite.

A run is one (scenario, seed). For each run with a row of the method this gives its ATE, the
best LiDAR peer's ATE (KISS-ICP, GenZ-ICP, RKO-LIO: :data:`LIDAR_PEERS`), the better of the
two floors a fusion must beat (wheel odometry alone and our ``none``: :data:`FLOORS`) and the
ATE as a share of the distance driven. A peer or floor that failed on the run (no ATE) is
counted as behind; a failed run of the method is ahead of nothing.
"""
from __future__ import annotations

from dataclasses import dataclass

LIDAR_PEERS = ("kiss", "genz", "rko")
FLOORS = ("wheels", "none")


@dataclass(frozen=True)
class Standing:
    """One run: the method's ATE [m] and what it is compared with (None: no such row or it
    failed)."""

    scenario: str
    seed: int
    split: str
    distance_m: float | None
    ate_m: float | None
    best_peer: str | None
    best_peer_ate_m: float | None
    floor_ate_m: float | None

    @property
    def ahead_of_peers(self) -> bool:
        """ATE at most the best LiDAR peer's (ties count as ahead)."""
        return self.ate_m is not None and (self.best_peer_ate_m is None
                                           or self.ate_m <= self.best_peer_ate_m)

    @property
    def ahead_of_floors(self) -> bool:
        """ATE at most both wheel odometry alone's and ``none``'s."""
        return self.ate_m is not None and (self.floor_ate_m is None
                                           or self.ate_m <= self.floor_ate_m)

    @property
    def share_pct(self) -> float | None:
        """ATE as a share of the distance driven [%]."""
        if self.ate_m is None or not self.distance_m:
            return None
        return 100.0 * self.ate_m / self.distance_m


def _ate(row: dict | None) -> float | None:
    if row is None or row.get("error"):
        return None
    return row.get("ate_m")


def standings(rows: list[dict], method: str = "lili") -> list[Standing]:
    """One :class:`Standing` per run (scenario, seed) that has a row of ``method``, in the
    order the rows first name the runs."""
    runs: dict[tuple[str, int], dict[str, dict]] = {}
    for r in rows:
        runs.setdefault((r["scenario"], r["seed"]), {})[r["method"]] = r
    out = []
    for (scenario, seed), by_method in runs.items():
        own = by_method.get(method)
        if own is None:
            continue
        peers = {p: _ate(by_method.get(p)) for p in LIDAR_PEERS}
        peers = {p: v for p, v in peers.items() if v is not None}
        best = min(peers, key=peers.get) if peers else None
        floors = [v for v in (_ate(by_method.get(f)) for f in FLOORS) if v is not None]
        distances = [r.get("distance_m") for r in by_method.values() if r.get("distance_m")]
        out.append(Standing(
            scenario=scenario, seed=seed, split=own.get("split", ""),
            distance_m=distances[0] if distances else None, ate_m=_ate(own),
            best_peer=best, best_peer_ate_m=peers.get(best) if best else None,
            floor_ate_m=min(floors) if floors else None))
    return out


def _fmt(v: float | None, digits: int = 3) -> str:
    return "–" if v is None else f"{v:.{digits}f}"


def markdown_lines(items: list[Standing], method: str = "lili",
                   max_share_pct: float = 0.5) -> list[str]:
    """A Markdown table of ``items`` (one line per run) and a summary line counting the runs
    where ``method`` is ahead of the best LiDAR peer, within ``max_share_pct`` of the
    distance and ahead of both floors."""
    if not items:
        return []
    lines = [f"| scenario | seed | distance [m] | `{method}` | best LiDAR peer | "
             f"`{method}` / peer | % of distance | better floor | ahead of peers | "
             f"<= {max_share_pct:g} % | ahead of floors |",
             "|---|---:|---:|---:|---|---:|---:|---:|---|---|---|"]
    for s in items:
        ratio = (s.ate_m / s.best_peer_ate_m if s.ate_m is not None and s.best_peer_ate_m
                 else None)
        peer = f"{s.best_peer} {_fmt(s.best_peer_ate_m)}" if s.best_peer else "–"
        share = s.share_pct
        within = share is not None and share <= max_share_pct
        lines.append(
            f"| {s.scenario} | {s.seed} | {_fmt(s.distance_m, 1)} | {_fmt(s.ate_m)} | {peer} | "
            f"{_fmt(ratio, 2)} | {_fmt(share, 2)} | {_fmt(s.floor_ate_m)} | "
            f"{'yes' if s.ahead_of_peers else '**no**'} | {'yes' if within else '**no**'} | "
            f"{'yes' if s.ahead_of_floors else '**no**'} |")
    n = len(items)
    peers = sum(s.ahead_of_peers for s in items)
    within = sum(s.share_pct is not None and s.share_pct <= max_share_pct for s in items)
    floors = sum(s.ahead_of_floors for s in items)
    lines += ["", f"`{method}` is ahead of the best LiDAR peer on {peers} of {n} runs, within "
              f"{max_share_pct:g} % of the distance on {within} of {n} and ahead of wheel "
              f"odometry alone and `none` on {floors} of {n}."]
    return lines
