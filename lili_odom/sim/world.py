"""Scene description (plain data, loaded from YAML) and its triangle mesh.

A world is a swept *tube* (tunnel or corridor; optional) along a planar centreline, an open
*outside* area (ground plane, portal wall, objects, random clutter) and sparse *features* inside
the tube. Everything is in the world frame ``world`` (REP-103: x forward, y left, z up), metres.

Conventions of the description:

* The centreline starts at the portal, the origin, heading +x. Arc length ``s`` along it; for
  ``s < 0`` (outside) it continues straight along -x, for ``s > length`` straight ahead.
  ``l`` is the lateral offset, positive to the left of the +s direction.
* The floor is ``z = floor_height(x, y)``: a sum of plane waves (small bumps) plus optional
  ramps (slopes, declines), defined in world x, y so that the mesh and the trajectory (wheel
  contacts) use exactly the same surface. The tube's walls and ceiling follow the ramps.
* ``tube: false`` keeps the centreline as the driven path but builds no tube (open areas,
  halls made of objects).
* Every triangle carries a material (reflectivity in [0, 1] as the Ouster reports it /100, and an
  ``outdoor`` flag used for the ambient channel).

A new world is a new YAML file, not new code: see ``config/worlds/tunnel.yaml``.
"""
from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
import yaml
from matplotlib.path import Path as PolyPath

__all__ = [
    "Material",
    "Segment",
    "CrossSection",
    "FloorWave",
    "Ramp",
    "Floor",
    "ObjectSpec",
    "ClutterSpec",
    "Outside",
    "FeatureSpec",
    "Features",
    "TrialPlan",
    "WorldDescription",
    "Centreline",
    "SceneMesh",
    "build_mesh",
    "load_world",
    "world_path",
]


# ---------------------------------------------------------------------------------------------
# description dataclasses
# ---------------------------------------------------------------------------------------------
@dataclass
class Material:
    """Surface material: ``reflectivity`` Lambertian albedo in [0, 1]; ``outdoor`` lit by day."""

    reflectivity: float = 0.3
    outdoor: bool = False


@dataclass
class Segment:
    """One centreline piece: ``straight`` or ``arc`` (``radius`` m, ``direction`` left|right)."""

    type: str = "straight"
    length: float = 10.0
    radius: float = 0.0
    direction: str = "left"


@dataclass
class CrossSection:
    """Tube profile in the (l, z) plane, z up from the nominal floor (z = 0).

    ``horseshoe``: vertical walls of ``wall_height`` then a half-circle arch of radius width/2
    (total height = wall_height + width/2). ``rectangle``: walls of ``height`` and a flat ceiling.
    ``circular``: a circle of radius ``radius`` whose chord at z = 0 is the floor (its centre is at
    ``height - radius``). ``resolution`` is the profile edge length, ``step`` the sweep step [m].
    """

    shape: str = "horseshoe"
    width: float = 6.0
    wall_height: float = 2.5
    height: float = 5.5
    radius: float = 3.0
    resolution: float = 0.3
    step: float = 0.25
    wall_material: str = "concrete"
    floor_material: str = "floor"
    end_wall: bool = True
    start_wall: bool = False
    end_material: str = "rock"


@dataclass
class FloorWave:
    """One plane wave of the floor: ``amplitude`` [m], ``wavelength`` [m], ``direction_deg``
    (of the wave vector, from world +x), ``phase`` [rad]."""

    amplitude: float = 0.01
    wavelength: float = 5.0
    direction_deg: float = 0.0
    phase: float = 0.0


@dataclass
class Ramp:
    """A slope of the floor along world direction ``direction_deg`` (from +x): with ``p`` the
    coordinate along that direction [m], the height changes by ``grade`` (dz/dp, e.g. -0.12 for
    a 12 % decline) between ``start`` and ``start + length``, flat before and after. The grade is
    blended in and out linearly over ``transition`` m (continuous pitch)."""

    direction_deg: float = 0.0
    start: float = 0.0
    length: float = 50.0
    grade: float = -0.1
    transition: float = 5.0


@dataclass
class Floor:
    """Floor bumps: explicit ``waves`` and/or ``random_waves`` random ones of RMS height ``rms``
    and wavelengths in ``wavelength_range``, drawn with ``seed``; ``ramps`` add slopes."""

    ramps: list[Ramp] = field(default_factory=list)
    waves: list[FloorWave] = field(default_factory=list)
    random_waves: int = 0
    rms: float = 0.015
    wavelength_range: tuple[float, float] = (3.0, 15.0)
    seed: int = 1


@dataclass
class ObjectSpec:
    """A placed object, standing on the floor at world ``position`` (x, y).

    kinds: ``box`` (``size`` = length, width, height), ``cylinder`` (``radius``, ``height``),
    ``vehicle`` (a body box plus a cab box), ``bush`` (a lumpy blob of ``radius``),
    ``wall`` (a box; same as box, named for readability). ``z_offset`` lifts it above the floor
    (a ceiling slab, a shelf). ``count`` copies are placed at ``position + k * step`` (k = 0..count-1),
    for rows of pillars or racks."""

    kind: str = "box"
    position: tuple[float, float] = (0.0, 0.0)
    yaw_deg: float = 0.0
    size: tuple[float, float, float] = (1.0, 1.0, 1.0)
    radius: float = 0.1
    height: float = 1.0
    z_offset: float = 0.0
    material: str = "metal"
    count: int = 1
    step: tuple[float, float] = (0.0, 0.0)


@dataclass
class ClutterSpec:
    """Random objects (bushes, rocks, poles) scattered over ``x_range`` x ``y_range`` keeping
    ``keep_out`` metres away from the line y = 0 (the approach path)."""

    kind: str = "bush"
    count: int = 0
    x_range: tuple[float, float] = (-50.0, -3.0)
    y_range: tuple[float, float] = (-30.0, 30.0)
    keep_out: float = 3.0
    size_range: tuple[float, float] = (0.3, 1.2)
    material: str = "vegetation"
    seed: int = 2


@dataclass
class Outside:
    """Open area at x < 0: ground grid, portal wall at x = 0 (with the tube opening) and objects."""

    ground: bool = True
    ground_x_range: tuple[float, float] = (-60.0, 0.0)
    ground_y_range: tuple[float, float] = (-40.0, 40.0)
    ground_step: float = 0.5
    ground_material: str = "gravel"
    portal: bool = True
    portal_width: float = 40.0
    portal_height: float = 14.0
    portal_cell: float = 0.25
    portal_material: str = "rock"
    objects: list[ObjectSpec] = field(default_factory=list)
    clutter: list[ClutterSpec] = field(default_factory=list)


@dataclass
class FeatureSpec:
    """Sparse features inside the tube, one every ``spacing`` metres at feature density 1
    (``spacing / density`` otherwise; none at density 0), positions jittered by ``jitter`` m.

    kinds: ``light`` (box of ``size`` hung at the crown, or at ``height`` on ``side``),
    ``tray`` (cable tray section of ``size`` on a wall at ``height``), ``niche`` (recess of
    ``size`` = length, depth, height cut into a wall; a deep one is a side gallery or a door).
    ``s_range`` limits this item to part of the tube (within ``Features.s_range``)."""

    kind: str = "light"
    spacing: float = 25.0
    jitter: float = 2.0
    size: tuple[float, float, float] = (1.2, 0.3, 0.12)
    height: float = 0.0
    side: str = "crown"  # crown | left | right | alternate
    material: str = "light"
    s_range: tuple[float, float] | None = None


@dataclass
class Features:
    """Inside features, placed for ``s`` in ``s_range`` (defaults to the whole tube)."""

    density: float = 1.0
    s_range: tuple[float, float] | None = None
    seed: int = 3
    items: list[FeatureSpec] = field(default_factory=list)


@dataclass
class TrialPlan:
    """Motion of one trial: ``legs`` as (s_start, s_end) along the centreline (a sign change of
    direction between legs means an in-place turn-around), lane offset (negative = right of the
    travel direction), speeds [m/s], accelerations [m/s^2], full stops inside the tube: ``stops``
    per leg at random places in ``stop_s_range``, or at the fixed arc lengths ``stop_s``."""

    legs: list[tuple[float, float]] = field(default_factory=lambda: [(-15.0, 100.0)])
    lane_offset: float = -0.8
    weave_amplitude: float = 0.25
    weave_wavelength: float = 35.0
    lane_change_length: float = 12.0
    speed_range: tuple[float, float] = (0.5, 1.2)
    cruise_duration_range: tuple[float, float] = (6.0, 20.0)
    max_accel: float = 0.4
    stops: int = 2
    stop_duration_range: tuple[float, float] = (3.0, 6.0)
    stop_s_range: tuple[float, float] | None = None
    stop_s: list[float] | None = None
    start_idle: float = 2.0
    end_idle: float = 2.0
    turn_rate: float = 0.5


@dataclass
class WorldDescription:
    """A whole world. ``segments`` empty means no tube (open field); ``tube`` false keeps the
    segments as the driven path only."""

    name: str = "world"
    description: str = ""
    segments: list[Segment] = field(default_factory=list)
    tube: bool = True
    cross_section: CrossSection = field(default_factory=CrossSection)
    floor: Floor = field(default_factory=Floor)
    materials: dict[str, Material] = field(default_factory=dict)
    outside: Outside = field(default_factory=Outside)
    features: Features = field(default_factory=Features)
    trials: dict[int, TrialPlan] = field(default_factory=dict)

    @property
    def tube_length(self) -> float:
        return float(sum(seg.length for seg in self.segments))

    def material_names(self) -> list[str]:
        return list(self.materials)


# ---------------------------------------------------------------------------------------------
# YAML loading
# ---------------------------------------------------------------------------------------------
def _build(cls: type, data: Any) -> Any:
    """Recursively build dataclass ``cls`` from plain YAML data (unknown keys are errors)."""
    if data is None:
        return cls()
    if isinstance(data, cls):
        return data
    if not isinstance(data, dict):
        raise ValueError(f"{cls.__name__}: expected a mapping, got {data!r}")
    hints = {f.name: f for f in dataclasses.fields(cls)}
    unknown = set(data) - set(hints)
    if unknown:
        raise ValueError(f"{cls.__name__}: unknown keys {sorted(unknown)}")
    kwargs = {}
    for key, value in data.items():
        kwargs[key] = _convert(hints[key].type, value)
    return cls(**kwargs)


_NESTED = {
    "Segment": Segment, "CrossSection": CrossSection, "Floor": Floor, "FloorWave": FloorWave,
    "ObjectSpec": ObjectSpec, "ClutterSpec": ClutterSpec, "Outside": Outside,
    "FeatureSpec": FeatureSpec, "Features": Features, "TrialPlan": TrialPlan,
    "Material": Material, "Ramp": Ramp,
}


def _convert(annotation: Any, value: Any) -> Any:
    text = annotation if isinstance(annotation, str) else getattr(annotation, "__name__", "")
    for name, cls in _NESTED.items():
        if text == name:
            return _build(cls, value)
        if text == f"list[{name}]":
            return [_build(cls, v) for v in (value or [])]
        if text == f"dict[str, {name}]":
            return {str(k): _build(cls, v) for k, v in (value or {}).items()}
        if text == f"dict[int, {name}]":
            return {int(k): _build(cls, v) for k, v in (value or {}).items()}
    if text.startswith("tuple") and value is not None:
        return tuple(value)
    if text.startswith("list[tuple") and value is not None:
        return [tuple(v) for v in value]
    return value


def world_path(name_or_file: str | Path) -> Path:
    """Resolve a world: an existing file path, or a name looked up in ``config/worlds/`` of the
    source tree, then in the installed share directory."""
    p = Path(name_or_file)
    if p.suffix in (".yaml", ".yml") and p.exists():
        return p
    candidates = [
        Path(__file__).resolve().parents[2] / "config" / "worlds" / f"{p.name}.yaml",
        Path(sys.prefix) / "share" / "lili_odom" / "config" / "worlds" / f"{p.name}.yaml",
    ]
    for c in candidates:
        if c.exists():
            return c
    raise FileNotFoundError(f"world {name_or_file!s} not found (looked in {[str(c) for c in candidates]})")


def load_world(name_or_file: str | Path) -> WorldDescription:
    """Load a world description from YAML (a path or a name under ``config/worlds``)."""
    path = world_path(name_or_file)
    data = yaml.safe_load(path.read_text())
    world = _build(WorldDescription, data)
    if "floor" not in world.materials:
        world.materials.setdefault("floor", Material(0.25))
    return world


# ---------------------------------------------------------------------------------------------
# centreline and floor
# ---------------------------------------------------------------------------------------------
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


# ---------------------------------------------------------------------------------------------
# mesh building
# ---------------------------------------------------------------------------------------------
@dataclass
class SceneMesh:
    """Triangle soup of a world: ``vertices`` (V, 3) float64, ``faces`` (F, 3) int, ``material``
    (F,) index into ``materials`` (list of names) with ``reflectivity`` / ``outdoor`` per material."""

    vertices: np.ndarray
    faces: np.ndarray
    material: np.ndarray
    materials: list[str]
    reflectivity: np.ndarray
    outdoor: np.ndarray

    def trimesh(self) -> trimesh.Trimesh:
        return trimesh.Trimesh(self.vertices, self.faces, process=False)

    @property
    def triangles(self) -> np.ndarray:
        return self.vertices[self.faces]

    @property
    def face_normals(self) -> np.ndarray:
        tri = self.triangles
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


class _Builder:
    def __init__(self, materials: dict[str, Material]):
        self.names = list(materials)
        self.materials = materials
        self.parts: list[tuple[np.ndarray, np.ndarray, int]] = []

    def mat(self, name: str) -> int:
        if name not in self.materials:
            self.materials[name] = Material()
            self.names.append(name)
        return self.names.index(name)

    def add(self, vertices: np.ndarray, faces: np.ndarray, material: str) -> None:
        if len(faces):
            self.parts.append((np.asarray(vertices, float), np.asarray(faces, int), self.mat(material)))

    def add_mesh(self, mesh: trimesh.Trimesh, material: str) -> None:
        self.add(mesh.vertices, mesh.faces, material)

    def finish(self) -> SceneMesh:
        verts, faces, mats, offset = [], [], [], 0
        for v, f, m in self.parts:
            verts.append(v)
            faces.append(f + offset)
            mats.append(np.full(len(f), m))
            offset += len(v)
        return SceneMesh(
            vertices=np.concatenate(verts),
            faces=np.concatenate(faces),
            material=np.concatenate(mats),
            materials=list(self.names),
            reflectivity=np.array([self.materials[n].reflectivity for n in self.names]),
            outdoor=np.array([self.materials[n].outdoor for n in self.names]),
        )


def _grid_faces(nu: int, nv: int, closed_v: bool = False) -> np.ndarray:
    """Faces of a (nu x nv) vertex grid, index i * nv + j; ``closed_v`` wraps j."""
    jmax = nv if closed_v else nv - 1
    i, j = np.meshgrid(np.arange(nu - 1), np.arange(jmax), indexing="ij")
    a = i * nv + j
    b = i * nv + (j + 1) % nv
    c = (i + 1) * nv + j
    d = (i + 1) * nv + (j + 1) % nv
    return np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3), np.stack([b, c, d], -1).reshape(-1, 3)])


def profile_points(cs: CrossSection) -> tuple[np.ndarray, np.ndarray]:
    """Closed tube profile as (M, 2) points (l, z), counter-clockwise seen along +s starting at
    the right end of the floor, and a boolean mask of the points that belong to the floor."""
    res = cs.resolution
    hw = cs.width / 2.0

    def line(a, b):
        a, b = np.asarray(a, float), np.asarray(b, float)
        n = max(int(np.ceil(np.linalg.norm(b - a) / res)), 1)
        return a + (b - a) * (np.arange(n) / n)[:, None]

    if cs.shape == "circular":
        r = cs.radius
        zc = cs.height - r
        half = np.sqrt(max(r * r - zc * zc, 1e-6))
        a0 = np.arctan2(-zc, half)
        a1 = np.pi - a0
        n = max(int(np.ceil(r * (a1 - a0) / res)), 8)
        ang = a0 + (a1 - a0) * np.arange(n) / n
        wall = np.stack([r * np.cos(ang), zc + r * np.sin(ang)], -1)
        floor = line((-half, 0.0), (half, 0.0))
        pts = np.concatenate([wall, floor])
        is_floor = np.r_[np.zeros(len(wall), bool), np.ones(len(floor), bool)]
        is_floor[0] = True
    else:
        if cs.shape == "horseshoe":
            wh = cs.wall_height
            n = max(int(np.ceil(np.pi * hw / res)), 8)
            ang = np.pi * np.arange(n) / n
            top = np.stack([hw * np.cos(ang), wh + hw * np.sin(ang)], -1)
        elif cs.shape == "rectangle":
            wh = cs.height
            top = line((hw, wh), (-hw, wh))
        else:
            raise ValueError(f"unknown cross-section shape {cs.shape!r}")
        right = line((hw, 0.0), (hw, wh))
        left = line((-hw, wh), (-hw, 0.0))
        floor = line((-hw, 0.0), (hw, 0.0))
        pts = np.concatenate([right, top, left, floor])
        is_floor = np.zeros(len(pts), bool)
        is_floor[len(right) + len(top) + len(left):] = True
        is_floor[0] = True
    return pts, is_floor


def _feature_positions(spec: FeatureSpec, density: float, s_lo: float, s_hi: float,
                       rng: np.random.Generator) -> np.ndarray:
    if density <= 0 or spacing_is_bad(spec.spacing):
        return np.zeros(0)
    step = spec.spacing / density
    s = np.arange(s_lo + rng.uniform(0, step), s_hi, step)
    s = s + rng.uniform(-spec.jitter, spec.jitter, len(s))
    return s[(s > s_lo) & (s < s_hi)]


def spacing_is_bad(spacing: float) -> bool:
    return not np.isfinite(spacing) or spacing <= 0


def build_mesh(world: WorldDescription, feature_density: float | None = None) -> SceneMesh:
    """Triangulate ``world``. ``feature_density`` overrides ``world.features.density``
    (0 = a perfectly featureless tube; the floor bumps stay, they are part of the floor)."""
    density = world.features.density if feature_density is None else float(feature_density)
    b = _Builder(dict(world.materials))
    floor = FloorField(world.floor)
    if world.segments and world.tube:
        _build_tube(b, world, floor, density)
    _build_outside(b, world, floor)
    return b.finish()


def _build_tube(b: _Builder, world: WorldDescription, floor: FloorField, density: float) -> None:
    cs = world.cross_section
    line = Centreline(world.segments)
    L = line.length
    ns = max(int(np.ceil(L / cs.step)), 1) + 1
    s = np.linspace(0.0, L, ns)
    prof, is_floor = profile_points(cs)
    M = len(prof)
    xy, n = line.frame(s)
    # vertices: ring i, profile j
    P = xy[:, None, :] + prof[None, :, 0, None] * n[:, None, :]
    z = np.broadcast_to(prof[None, :, 1], (ns, M)).copy()
    z += floor.grade_height(P)
    z[:, is_floor] += floor.bumps(P[:, is_floor])
    V = np.concatenate([P, z[..., None]], -1)  # (ns, M, 3)

    # niches: recesses cut into the walls; mark the quads to drop
    keep = np.ones((ns - 1, M), bool)  # quad (i, j) between rings i,i+1 and profile j,j+1
    rng = np.random.default_rng(world.features.seed)
    s_lo, s_hi = world.features.s_range or (0.0, L)
    s_lo, s_hi = max(s_lo, 0.0), min(s_hi, L)
    extra = []
    for k, spec in enumerate(world.features.items):
        lo, hi = s_lo, s_hi
        if spec.s_range is not None:
            lo, hi = max(lo, spec.s_range[0]), min(hi, spec.s_range[1])
        for idx, sf in enumerate(_feature_positions(spec, density, lo + 1, hi - 1, rng)):
            side = spec.side
            if side == "alternate":
                side = "left" if idx % 2 == 0 else "right"
            if spec.kind == "niche":
                _cut_niche(b, V, keep, s, prof, is_floor, line, sf, spec, side)
            else:
                extra.append((spec, sf, side))
    # wall/ceiling quads and floor quads with their own materials
    F = _grid_faces(ns, M, closed_v=True).reshape(2, ns - 1, M, 3)
    floor_quad = is_floor & np.roll(is_floor, -1)
    flat_v = V.reshape(-1, 3)
    for mask, mat in ((~floor_quad, cs.wall_material), (floor_quad, cs.floor_material)):
        sel = keep & mask[None, :]
        b.add(flat_v, F[:, sel].reshape(-1, 3), mat)
    for flag, ring in ((cs.end_wall, V[-1]), (cs.start_wall, V[0])):
        if flag:
            verts = np.vstack([ring, ring.mean(0)])
            j = np.arange(M)
            b.add(verts, np.stack([np.full(M, M), j, (j + 1) % M], -1), cs.end_material)
    for spec, sf, side in extra:
        _add_feature(b, line, floor, cs, spec, sf, side)


def _wall_index(prof: np.ndarray, is_floor: np.ndarray, side: str, z0: float, z1: float) -> tuple[int, int]:
    """Profile indices j0 < j1 spanning heights [z0, z1] on the ``side`` wall."""
    sign = 1.0 if side == "left" else -1.0
    cand = np.where((~is_floor) & (np.sign(prof[:, 0]) == sign))[0]
    zc = prof[cand, 1]
    inside = cand[(zc >= z0) & (zc <= z1)]
    if len(inside) < 2:
        inside = cand[np.argsort(np.abs(zc - 0.5 * (z0 + z1)))[:2]]
    return int(inside.min()), int(inside.max())


def _cut_niche(b, V, keep, s, prof, is_floor, line, sf, spec, side) -> None:
    length, depth, height = spec.size
    i0 = int(np.searchsorted(s, sf - length / 2))
    i1 = int(np.searchsorted(s, sf + length / 2))
    if i1 - i0 < 1 or i0 < 1 or i1 >= len(s) - 1:
        return
    z0 = max(spec.height, 0.3)
    j0, j1 = _wall_index(prof, is_floor, side, z0, z0 + height)
    if j1 <= j0:
        return
    keep[i0:i1, j0:j1] = False
    # outward direction: away from the centreline, horizontal
    _, n = line.frame(s[i0:i1 + 1])
    out = (1.0 if side == "left" else -1.0) * n
    front = V[i0:i1 + 1, j0:j1 + 1]  # (a, c, 3)
    back = front.copy()
    back[..., :2] += depth * out[:, None, :]
    a, c = front.shape[:2]
    # back face grid
    b.add(back.reshape(-1, 3), _grid_faces(a, c), spec.material)
    # four rims: strips between front and back along the boundary
    rims = [front[0, :], back[0, :]], [front[-1, :], back[-1, :]], [front[:, 0], back[:, 0]], [front[:, -1], back[:, -1]]
    for f_line, b_line in rims:
        grid = np.stack([f_line, b_line], 1)  # (k, 2, 3)
        b.add(grid.reshape(-1, 3), _grid_faces(len(f_line), 2), spec.material)


def _box(size, T) -> trimesh.Trimesh:
    return trimesh.creation.box(extents=size, transform=T)


def _pose(x, y, z, yaw) -> np.ndarray:
    T = np.eye(4)
    c, s_ = np.cos(yaw), np.sin(yaw)
    T[:3, :3] = [[c, -s_, 0], [s_, c, 0], [0, 0, 1]]
    T[:3, 3] = (x, y, z)
    return T


def _add_feature(b: _Builder, line: Centreline, floor: FloorField, cs: CrossSection,
                 spec: FeatureSpec, sf: float, side: str) -> None:
    xy, h, _ = line.evaluate(sf)
    xy, h = xy[0], float(h[0])
    n = np.array([-np.sin(h), np.cos(h)])
    dz = float(floor.grade_height(xy))
    L, W, H = spec.size
    hw = cs.width / 2.0 if cs.shape != "circular" else np.sqrt(max(cs.radius**2 - (cs.height - cs.radius) ** 2, 0))
    if side == "crown":
        top = cs.height if cs.shape != "horseshoe" else cs.wall_height + cs.width / 2
        c = np.r_[xy, top - 0.15 - H / 2 + dz]
        b.add_mesh(_box((L, W, H), _pose(*c, h)), spec.material)
        return
    sign = 1.0 if side == "left" else -1.0
    z = spec.height
    if cs.shape == "circular":  # wall l at height z on the circle
        zc = cs.height - cs.radius
        hw = np.sqrt(max(cs.radius**2 - (z - zc) ** 2, 0.0))
    elif cs.shape == "horseshoe" and z > cs.wall_height:
        hw = np.sqrt(max(hw**2 - (z - cs.wall_height) ** 2, 0.0))
    lat = sign * (hw - 0.02 - W / 2)
    c = np.r_[xy + lat * n, z + dz]
    b.add_mesh(_box((L, W, H), _pose(*c, h)), spec.material)
    if spec.kind == "tray":  # a few brackets down to the wall make it look like a tray
        for u in (-L / 2 + 0.1, L / 2 - 0.1):
            p = xy + lat * n + u * np.array([np.cos(h), np.sin(h)])
            b.add_mesh(_box((0.05, W, 0.05), _pose(p[0], p[1], z + dz - H / 2 - 0.05, h)), "metal")


def _build_outside(b: _Builder, world: WorldDescription, floor: FloorField) -> None:
    out = world.outside
    if out.ground:
        x0, x1 = out.ground_x_range
        y0, y1 = out.ground_y_range
        xs = np.arange(x0, x1 + 1e-9, out.ground_step)
        ys = np.arange(y0, y1 + 1e-9, out.ground_step)
        X, Y = np.meshgrid(xs, ys, indexing="ij")
        XY = np.stack([X, Y], -1)
        V = np.concatenate([XY, floor.height(XY)[..., None]], -1).reshape(-1, 3)
        b.add(V, _grid_faces(len(xs), len(ys)), out.ground_material)
    if out.portal and world.segments and world.tube:
        prof, _ = profile_points(world.cross_section)
        c = out.portal_cell
        ys = np.arange(-out.portal_width / 2, out.portal_width / 2 + 1e-9, c)
        zs = np.arange(-0.5, out.portal_height + 1e-9, c)
        Y, Z = np.meshgrid(ys, zs, indexing="ij")
        centres = np.stack([Y[:-1, :-1] + c / 2, Z[:-1, :-1] + c / 2], -1).reshape(-1, 2)
        opening = PolyPath(prof).contains_points(centres) | (centres[:, 1] < 0)
        V = np.stack([np.zeros_like(Y), Y, Z], -1).reshape(-1, 3)
        F = _grid_faces(len(ys), len(zs)).reshape(2, -1, 3)
        b.add(V, F[:, ~opening].reshape(-1, 3), out.portal_material)
    for obj in out.objects:
        for k in range(max(int(obj.count), 0)):
            x, y = obj.position
            placed = dataclasses.replace(obj, position=(x + k * obj.step[0], y + k * obj.step[1]))
            _add_object(b, floor, placed, None)
    for spec in out.clutter:
        rng = np.random.default_rng(spec.seed)
        placed = 0
        while placed < spec.count:
            x = rng.uniform(*spec.x_range)
            y = rng.uniform(*spec.y_range)
            if abs(y) < spec.keep_out:
                continue
            size = rng.uniform(*spec.size_range)
            obj = ObjectSpec(kind=spec.kind, position=(x, y), yaw_deg=rng.uniform(0, 360),
                             radius=size, size=(size, size * rng.uniform(0.5, 1.0), size * rng.uniform(0.4, 1.0)),
                             height=size * rng.uniform(4, 8), material=spec.material)
            _add_object(b, floor, obj, rng)
            placed += 1


def _add_object(b: _Builder, floor: FloorField, obj: ObjectSpec, rng: np.random.Generator | None) -> None:
    x, y = obj.position
    z = float(floor.height(np.array([x, y]))) + obj.z_offset
    yaw = np.deg2rad(obj.yaw_deg)
    if obj.kind in ("box", "wall"):
        L, W, H = obj.size
        b.add_mesh(_box((L, W, H), _pose(x, y, z + H / 2 - 0.05, yaw)), obj.material)
    elif obj.kind == "vehicle":
        L, W, H = obj.size
        b.add_mesh(_box((L, W, 0.55 * H), _pose(x, y, z + 0.25 + 0.55 * H / 2, yaw)), obj.material)
        cab = _pose(x, y, z + 0.25 + 0.55 * H + 0.45 * H / 2 - 0.25, yaw) @ _pose(-0.1 * L, 0, 0, 0)
        b.add_mesh(_box((0.5 * L, 0.92 * W, 0.45 * H), cab), obj.material)
        for u in (-0.35 * L, 0.35 * L):  # wheels as short cylinders
            for v in (-W / 2, W / 2):
                T = _pose(x, y, z, yaw) @ _pose(u, v, 0.35, 0)
                R = trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0])
                b.add_mesh(trimesh.creation.cylinder(radius=0.35, height=0.25, sections=10, transform=T @ R), "rubber")
    elif obj.kind == "cylinder":
        T = _pose(x, y, z + obj.height / 2 - 0.05, yaw)
        b.add_mesh(trimesh.creation.cylinder(radius=obj.radius, height=obj.height, sections=12, transform=T), obj.material)
    elif obj.kind in ("bush", "rock"):
        rng = rng or np.random.default_rng(int(abs(x * 1000 + y * 7)))
        m = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
        v = m.vertices * rng.uniform(0.7, 1.3, (len(m.vertices), 1))
        scale = np.array([1.0, rng.uniform(0.6, 1.0), rng.uniform(0.5, 0.9) if obj.kind == "rock" else rng.uniform(0.8, 1.3)])
        v = v * obj.radius * scale
        v = v @ _pose(0, 0, 0, yaw)[:3, :3].T + [x, y, z + 0.6 * obj.radius * scale[2]]
        b.add(v, m.faces, obj.material)
    else:
        raise ValueError(f"unknown object kind {obj.kind!r}")
