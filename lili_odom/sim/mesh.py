"""Triangle mesh of a world description (tube, outside area, features, objects, clutter).

World frame ``world`` (REP-103: x forward, y left, z up), metres. Every triangle carries a
material index (reflectivity in [0, 1], ``outdoor`` flag for the ambient channel).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import trimesh
from matplotlib.path import Path as PolyPath

from lili_odom.sim.layout import Centreline, FloorField
from lili_odom.sim.world import CrossSection, FeatureSpec, Material, ObjectSpec, WorldDescription

__all__ = ["SceneMesh", "build_mesh", "profile_points"]


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
