"""Smooth ground-vehicle trajectory through a world: pose of ``base_link`` in ``world`` vs time.

The plan (``TrialPlan``) is a list of legs along the centreline. Inside a leg the robot follows
the lane ``l(s)`` (lane offset + a slow weave) with a speed profile made of smooth ramps
(``3u^2 - 2u^3``, so acceleration is continuous and bounded by ``max_accel``), cruises at random
Husky-like speeds, and makes full stops. Between legs of opposite direction it turns in place
(quintic yaw blend). Heading is the tangent of the driven path (no side slip), z / roll / pitch
follow the floor under the four wheels, so bumps and ramps give vertical, roll and pitch motion.

Time ``t`` [s] runs from 0 at the trial start. Everything is vectorised over arrays of ``t`` and
analytic in ``t``, so derivatives by central differences (``kinematics``) are accurate to ~1e-6.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from lili_odom.sim.layout import Centreline, FloorField
from lili_odom.sim.sensors import HuskyConfig
from lili_odom.sim.world import TrialPlan, WorldDescription

__all__ = ["Trajectory", "Kinematics"]


def _smooth(u):
    """Cubic smoothstep on [0, 1] (velocity ramp shape)."""
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def _smooth_int(u):
    """Integral of ``_smooth`` from 0 to u (u in [0, 1])."""
    u = np.clip(u, 0.0, 1.0)
    return u**3 - 0.5 * u**4


def _quintic(u):
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10.0 - 15.0 * u + 6.0 * u * u)


@dataclass
class _Phase:
    t0: float
    T: float
    kind: str  # move | hold | turn
    leg: int
    d0: float  # distance along the leg at the start
    v0: float
    v1: float


@dataclass
class Kinematics:
    """Kinematics of a frame X rigidly attached to base_link, at times t (N,).

    ``position`` (N,3) and ``velocity`` / ``acceleration`` (N,3) of X's origin in ``world``;
    ``rotation`` (N,3,3) = R_world_X; ``omega`` (N,3) angular velocity in X (body) [rad/s]."""

    position: np.ndarray
    rotation: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    omega: np.ndarray


class _Leg:
    def __init__(self, line: Centreline, s_start: float, s_end: float, plan: TrialPlan,
                 prev: "_Leg | None", phase: float):
        self.line = line
        self.s_start, self.s_end = float(s_start), float(s_end)
        self.dir = 1.0 if s_end >= s_start else -1.0
        self.length = abs(s_end - s_start)
        self.plan = plan
        self.prev = prev
        self.phase = phase

    def _target(self, s):
        p = self.plan
        return self.dir * p.lane_offset + p.weave_amplitude * np.sin(2 * np.pi * s / p.weave_wavelength + self.phase)

    def lateral(self, s):
        s = np.asarray(s, dtype=float)
        if self.prev is None:
            return self._target(s)
        d = self.dir * (s - self.s_start)
        w = _quintic(d / max(self.plan.lane_change_length, 1e-6))
        return (1 - w) * self.prev.lateral(s) + w * self._target(s)

    def xy(self, s):
        xy, _ = self.line.frame(s, self.lateral(s))
        return xy

    def heading(self, s):
        e = 1e-4
        dp = self.xy(np.asarray(s) + e) - self.xy(np.asarray(s) - e)
        dp *= self.dir
        return np.arctan2(dp[..., 1], dp[..., 0])


class Trajectory:
    """Trajectory of ``base_link`` in ``world`` for ``plan`` (random parts drawn from ``seed``)."""

    def __init__(self, world: WorldDescription, plan: TrialPlan, seed: int = 0,
                 husky: HuskyConfig | None = None):
        self.world = world
        self.plan = plan
        self.husky = husky or HuskyConfig()
        self.line = Centreline(world.segments)
        self.floor = FloorField(world.floor)
        rng = np.random.default_rng([seed, 7001])
        self.legs: list[_Leg] = []
        prev = None
        for s0, s1 in plan.legs:
            leg = _Leg(self.line, s0, s1, plan, prev, rng.uniform(0, 2 * np.pi))
            self.legs.append(leg)
            prev = leg
        self.phases: list[_Phase] = []
        self.turns: dict[int, tuple[float, float]] = {}  # phase index -> (yaw0, dyaw)
        self._plan_phases(rng)
        self._t0 = np.array([p.t0 for p in self.phases])
        self.duration = self.phases[-1].t0 + self.phases[-1].T

    # ------------------------------------------------------------------ planning
    def _add(self, T, kind, leg, d0, v0=0.0, v1=0.0):
        t0 = self.phases[-1].t0 + self.phases[-1].T if self.phases else 0.0
        self.phases.append(_Phase(t0, float(T), kind, leg, float(d0), float(v0), float(v1)))

    def _plan_phases(self, rng: np.random.Generator) -> None:
        p = self.plan
        self._add(p.start_idle, "hold", 0, 0.0)
        for k, leg in enumerate(self.legs):
            if k > 0:
                prev = self.legs[k - 1]
                yaw0 = float(np.ravel(prev.heading(prev.s_end))[0])
                yaw1 = float(np.ravel(leg.heading(leg.s_start))[0])
                dyaw = (yaw1 - yaw0) % (2 * np.pi)
                if dyaw > 0.05:
                    self._add(1.0, "hold", k - 1, prev.length)
                    self.turns[len(self.phases)] = (yaw0, dyaw)
                    self._add(1.875 * dyaw / p.turn_rate, "turn", k - 1, prev.length)
                    self._add(1.0, "hold", k, 0.0)
            # stops inside this leg
            lo, hi = p.stop_s_range or (min(leg.s_start, leg.s_end), max(leg.s_start, leg.s_end))
            stops = []
            if p.stop_s is not None:  # fixed places: those inside this leg
                stops = [leg.dir * (s - leg.s_start) for s in p.stop_s]
                stops = [d for d in stops if 1.0 < d < leg.length - 1.0]
            for _ in range(200 if p.stop_s is None else 0):
                if len(stops) >= p.stops:
                    break
                s = rng.uniform(lo, hi)
                d = leg.dir * (s - leg.s_start)
                if 10.0 < d < leg.length - 10.0 and all(abs(d - x) > 25.0 for x in stops):
                    stops.append(d)
            marks = [0.0] + sorted(stops) + [leg.length]
            for i in range(len(marks) - 1):
                self._segment(k, marks[i], marks[i + 1] - marks[i], rng)
                if i < len(marks) - 2:
                    self._add(rng.uniform(*p.stop_duration_range), "hold", k, marks[i + 1])
        self._add(p.end_idle, "hold", len(self.legs) - 1, self.legs[-1].length)

    def _segment(self, leg: int, d0: float, D: float, rng: np.random.Generator) -> None:
        """Rest-to-rest motion over distance D with random cruise speeds."""
        p = self.plan
        a = p.max_accel
        vmin, vmax = p.speed_range

        def ramp(v0, v1):
            T = 1.5 * abs(v1 - v0) / a
            return T, T * (v0 + v1) / 2

        mean_tau = np.mean(p.cruise_duration_range)
        m = max(1, int(round(D / (0.5 * (vmin + vmax) * mean_tau))))
        for _ in range(20):
            v = rng.uniform(vmin, vmax, m)
            tau = rng.uniform(*p.cruise_duration_range, m)
            speeds = np.r_[0.0, v, 0.0]
            R = sum(ramp(speeds[i], speeds[i + 1])[1] for i in range(m + 1))
            C = D - R
            if C > 0.05 * D:
                break
            m = max(1, m - 1)
        else:  # very short segment: one slow bump of speed
            v = np.array([min(vmin, np.sqrt(D * a / 1.5) * 0.7)])
            tau = np.array([1.0])
            speeds = np.r_[0.0, v, 0.0]
            R = 2 * ramp(0.0, v[0])[1]
            C = max(D - R, 1e-6)
        tau = tau * C / float(np.sum(v * tau))
        d = d0
        for i in range(m + 1):
            T, dist = ramp(speeds[i], speeds[i + 1])
            self._add(T, "move", leg, d, speeds[i], speeds[i + 1])
            d += dist
            if i < m:
                self._add(tau[i], "move", leg, d, v[i], v[i])
                d += v[i] * tau[i]

    # ------------------------------------------------------------------ evaluation
    def _planar(self, t: np.ndarray):
        """(xy (N,2), yaw (N,)) of base_link's ground point."""
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        idx = np.clip(np.searchsorted(self._t0, t, side="right") - 1, 0, len(self.phases) - 1)
        leg_i = np.array([self.phases[i].leg for i in idx])
        d = np.zeros_like(t)
        xy = np.zeros((len(t), 2))
        yaw = np.zeros(len(t))
        for i in np.unique(idx):
            ph = self.phases[i]
            m = idx == i
            tau = t[m] - ph.t0
            if ph.kind == "move" and ph.T > 0:
                u = tau / ph.T
                d[m] = ph.d0 + ph.v0 * tau + (ph.v1 - ph.v0) * ph.T * _smooth_int(u)
            else:
                d[m] = ph.d0
        for k in np.unique(leg_i):
            leg = self.legs[k]
            m = leg_i == k
            s = leg.s_start + leg.dir * np.clip(d[m], 0.0, leg.length)
            xy[m] = leg.xy(s)
            yaw[m] = leg.heading(s)
        for i, (yaw0, dyaw) in self.turns.items():
            m = idx == i
            if np.any(m):
                ph = self.phases[i]
                yaw[m] = yaw0 + dyaw * _quintic((t[m] - ph.t0) / ph.T)
        return xy, yaw

    def pose(self, t: np.ndarray | float) -> np.ndarray:
        """T_world_base (N, 4, 4) at times ``t`` [s] (clamped to [0, duration])."""
        xy, yaw = self._planar(t)
        h = self.husky
        c, s = np.cos(yaw), np.sin(yaw)
        fwd = np.stack([c, s], -1)
        left = np.stack([-s, c], -1)
        z = {}
        for a, sa in (("f", 0.5), ("r", -0.5)):
            for b, sb in (("l", 0.5), ("r", -0.5)):
                z[a + b] = self.floor.height(xy + sa * h.wheelbase * fwd + sb * h.track * left)
        zc = 0.25 * (z["fl"] + z["fr"] + z["rl"] + z["rr"])
        pitch = -np.arctan2(0.5 * (z["fl"] + z["fr"] - z["rl"] - z["rr"]), h.wheelbase)
        roll = np.arctan2(0.5 * (z["fl"] + z["rl"] - z["fr"] - z["rr"]), h.track)
        R = Rotation.from_euler("ZYX", np.stack([yaw, pitch, roll], -1)).as_matrix()
        T = np.tile(np.eye(4), (len(yaw), 1, 1))
        T[:, :3, :3] = R
        T[:, :3, 3] = np.concatenate([xy, zc[:, None]], -1) + R[:, :, 2] * h.base_height
        return T

    def kinematics(self, t: np.ndarray | float, T_base_x: np.ndarray | None = None,
                   h: float = 1e-3) -> Kinematics:
        """Position, rotation, world velocity/acceleration and body angular rate of the frame
        ``X`` (``T_base_x``, default base_link itself) by central differences of step ``h``."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        X = np.eye(4) if T_base_x is None else np.asarray(T_base_x)
        n = len(t)
        T = self.pose(np.concatenate([t - h, t, t + h])) @ X
        T0, T1, T2 = T[:n], T[n:2 * n], T[2 * n:]
        p0, p1, p2 = T0[:, :3, 3], T1[:, :3, 3], T2[:, :3, 3]
        R1 = T1[:, :3, :3]
        rp = Rotation.from_matrix(np.einsum("nji,njk->nik", R1, T2[:, :3, :3])).as_rotvec()
        rm = Rotation.from_matrix(np.einsum("nji,njk->nik", R1, T0[:, :3, :3])).as_rotvec()
        return Kinematics(
            position=p1,
            rotation=R1,
            velocity=(p2 - p0) / (2 * h),
            acceleration=(p2 - 2 * p1 + p0) / (h * h),
            omega=(rp - rm) / (2 * h),
        )

    def phase_kinds(self, t: np.ndarray) -> list[str]:
        """Kind of motion ('move', 'hold', 'turn') at times t (for diagnostics / tests)."""
        idx = np.clip(np.searchsorted(self._t0, np.atleast_1d(t), side="right") - 1, 0, len(self.phases) - 1)
        return [self.phases[i].kind for i in idx]

    def path_length(self) -> float:
        return float(sum(leg.length for leg in self.legs))
