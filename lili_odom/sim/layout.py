"""Analytic layout of a world description: the planar centreline and the floor surface.

World frame ``world`` (REP-103: x forward, y left, z up), metres. The mesh
(:mod:`lili_odom.sim.mesh`) and the driven trajectory (:mod:`lili_odom.sim.trajectory`) both
evaluate these, so walls, floor and wheel contacts agree exactly.
"""
from __future__ import annotations

import numpy as np

from lili_odom.sim.world import Floor, FloorWave, Segment

__all__ = ["Centreline", "FloorField"]


class Centreline:
    """Planar centreline: ``s`` [m] -> position (x, y), heading [rad], curvature [1/m].

    Curvature changes between segments are spread linearly over ``transition`` metres (a
    clothoid-like easement), so position is C2 and a vehicle following a lane offset from the
    centreline has continuous velocity and acceleration. Heading is integrated analytically;
    position by Gauss-Legendre quadrature from grid points every ``grid`` metres.
    """

    _GL_X, _GL_W = np.polynomial.legendre.leggauss(8)

    def __init__(self, segments: list[Segment], transition: float = 10.0, grid: float = 1.0):
        ks, bounds, s = [], [0.0], 0.0
        for seg in segments:
            if seg.type == "arc":
                ks.append((1.0 if seg.direction == "left" else -1.0) / float(seg.radius))
            elif seg.type == "straight":
                ks.append(0.0)
            else:
                raise ValueError(f"unknown segment type {seg.type!r}")
            s += float(seg.length)
            bounds.append(s)
        self.length = s
        ks = [0.0] + ks + [0.0]
        lengths = [seg.length for seg in segments] or [1.0]
        w = min(transition, 0.5 * min(lengths))
        knots_s, knots_k = [-1e9], [0.0]
        for j, sb in enumerate(bounds):  # junction j between ks[j] and ks[j+1]
            if ks[j] == ks[j + 1]:
                continue
            knots_s += [sb - w / 2, sb + w / 2]
            knots_k += [ks[j], ks[j + 1]]
        knots_s.append(1e9)
        knots_k.append(0.0)
        self._ks = np.array(knots_s)
        self._kk = np.array(knots_k)
        # heading at each knot (integral of the piecewise-linear curvature from s = 0)
        seg_int = np.diff(self._ks) * 0.5 * (self._kk[1:] + self._kk[:-1])
        cum = np.r_[0.0, np.cumsum(seg_int)]
        i0 = np.searchsorted(self._ks, 0.0, side="right") - 1
        self._kh = cum - (cum[i0] + self._partial(i0, 0.0))
        # position grid
        lo, hi = -200.0, self.length + 200.0
        self._gs = np.arange(lo, hi + grid, grid)
        steps = self._quad(self._gs[:-1], self._gs[1:])
        gp = np.r_[np.zeros((1, 2)), np.cumsum(steps, 0)]
        gp -= self._interp_grid_zero(gp)
        self._gp = gp
        self._grid = grid

    def _partial(self, i, s):
        """Integral of curvature from knot i to s (s inside knot interval i)."""
        s0, s1 = self._ks[i], self._ks[i + 1]
        k0, k1 = self._kk[i], self._kk[i + 1]
        u = s - s0
        slope = (k1 - k0) / (s1 - s0)
        return k0 * u + 0.5 * slope * u * u

    def _interp_grid_zero(self, gp):
        i = int(np.searchsorted(self._gs, 0.0, side="right") - 1)
        return gp[i] + self._quad(np.array([self._gs[i]]), np.array([0.0]))[0]

    def heading(self, s: np.ndarray) -> np.ndarray:
        s = np.asarray(s, dtype=float)
        i = np.clip(np.searchsorted(self._ks, s, side="right") - 1, 0, len(self._ks) - 2)
        return self._kh[i] + self._partial(i, s)

    def curvature(self, s: np.ndarray) -> np.ndarray:
        return np.interp(np.asarray(s, dtype=float), self._ks, self._kk)

    def _quad(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Integral of (cos h, sin h) ds from a to b, (N, 2)."""
        half = 0.5 * (b - a)
        mid = 0.5 * (b + a)
        x = mid[:, None] + half[:, None] * self._GL_X[None, :]
        h = self.heading(x)
        return np.stack([(np.cos(h) @ self._GL_W) * half, (np.sin(h) @ self._GL_W) * half], -1)

    def evaluate(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return (xy (N, 2), heading (N,), curvature (N,)) at arc lengths ``s``."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        i = np.clip(((s - self._gs[0]) // self._grid).astype(int), 0, len(self._gs) - 2)
        xy = self._gp[i] + self._quad(self._gs[i], s)
        return xy, self.heading(s), self.curvature(s)

    def frame(self, s: np.ndarray, l: np.ndarray | float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """World xy of the point (s, l) and the unit left normal n(s), both (N, 2)."""
        xy, h, _ = self.evaluate(s)
        n = np.stack([-np.sin(h), np.cos(h)], -1)
        return xy + np.asarray(l, dtype=float)[..., None] * n, n


class FloorField:
    """Floor height ``z = sum a sin(k . (x, y) + phase) + ramps`` [m] in world coordinates."""

    def __init__(self, floor: Floor):
        self.ramps = list(floor.ramps)
        waves = list(floor.waves)
        if floor.random_waves > 0:
            rng = np.random.default_rng(floor.seed)
            n = floor.random_waves
            amp = floor.rms * np.sqrt(2.0 / n)
            lo, hi = floor.wavelength_range
            for _ in range(n):
                waves.append(FloorWave(
                    amplitude=amp * rng.uniform(0.6, 1.4),
                    wavelength=float(np.exp(rng.uniform(np.log(lo), np.log(hi)))),
                    direction_deg=float(rng.uniform(-60, 60) + 180 * rng.integers(0, 2)),
                    phase=float(rng.uniform(0, 2 * np.pi)),
                ))
        self.amp = np.array([w.amplitude for w in waves])
        ang = np.deg2rad([w.direction_deg for w in waves])
        kk = 2 * np.pi / np.array([w.wavelength for w in waves]) if waves else np.zeros(0)
        self.kvec = np.stack([kk * np.cos(ang), kk * np.sin(ang)], -1) if waves else np.zeros((0, 2))
        self.phase = np.array([w.phase for w in waves])

    def height(self, xy: np.ndarray) -> np.ndarray:
        """Floor height at world (x, y) points of shape (..., 2)."""
        return self.bumps(xy) + self.grade_height(xy)

    def bumps(self, xy: np.ndarray) -> np.ndarray:
        """The plane-wave part of the floor height (only the floor itself has it)."""
        xy = np.asarray(xy, dtype=float)
        if len(self.amp) == 0:
            return np.zeros(xy.shape[:-1])
        arg = xy @ self.kvec.T + self.phase
        return np.sin(arg) @ self.amp

    def grade_height(self, xy: np.ndarray) -> np.ndarray:
        """The ramp part of the floor height (walls and ceilings of a tube follow it)."""
        xy = np.asarray(xy, dtype=float)
        z = np.zeros(xy.shape[:-1])
        for r in self.ramps:
            a = np.deg2rad(r.direction_deg)
            p = xy[..., 0] * np.cos(a) + xy[..., 1] * np.sin(a)
            w = float(np.clip(r.transition, 1e-6, 0.5 * r.length))
            z += r.grade * (_ramp_integral(p - r.start + 0.5 * w, w) - _ramp_integral(p - r.start - r.length + 0.5 * w, w))
        return z


def _ramp_integral(u: np.ndarray, w: float) -> np.ndarray:
    """Integral of a unit step blended linearly over [0, w]: 0 before, u^2 / 2w, then u - w/2."""
    u = np.asarray(u, dtype=float)
    return np.where(u <= 0, 0.0, np.where(u < w, u * u / (2 * w), u - 0.5 * w))
