"""Synthetic degenerate shapes: reference/local scan pairs with analytic degenerate subspaces.

The five scenarios of the paper's synthetic evaluation (Plane, Closed Cylinder, Sinusoidal
Cylinder, Open Cylinder, Rotating Tunnel) plus a well-constrained control (Box Room).

Frames
------
* ``S`` (shape frame): each surface is defined here with its symmetry axis along ``z_S``
  (the plane is ``z_S = 0``; the box room is centred at the origin with axes along ``S``).
* ``W`` (reference frame): ``p_W = T_W_S p_S`` with one fixed, generic rotation + translation
  ``T_WORLD_SHAPE`` shared by all shapes, so no shape axis is aligned with ``x-y-z``.
* ``C`` (sensor / local-scan frame): ``true_pose = T_W_C = T_W_S @ T_S_C``; the sensor sits at
  a scenario-specific position in ``S`` with a generic orientation.

Sampling
--------
Surfaces are sampled uniformly by area on a jittered grid of pitch ``GRID_PITCH`` = 0.063 m in
an area-preserving parametrisation (each point jittered by up to +-``JITTER`` = 0.25 pitch per
grid axis; the lattice origin is random), which puts the mean nearest-neighbour distance at
``SPACING`` = 0.05 m as in the paper.
The *reference* is the whole finite surface (reference frame ``W``). The *local scan* is an
independent second sampling of the same surface (different lattice offset and jitter),
cropped to the points within ``scan_radius`` of the sensor and expressed in ``C``. The sensor
always looks at the concave side of the surface (inside the tubes and the room, above the
plane) so no part of the cropped surface is occluded and no visibility test is needed.
Noisy variants add i.i.d. ``N(0, NOISE_SIGMA^2)`` per axis, ``NOISE_SIGMA`` = 0.02 m (the
paper's ``N(0, 0.02)`` read as a standard deviation), to every point of both clouds; the
clean and noisy variants of a scenario share the same underlying samples.

Geometry (shape frame, metres; sensor position p_S, crop radius r):

* plane: square ``|x|, |y| <= 4``; p_S = (0.2, -0.3, 1.2), r = 2.4.
* closed cylinder: R = 1, ``|z| <= 4`` (a full tube, open ends); p_S = (0.2, -0.15, 0.1), r = 2.
* sinusoidal cylinder: R = 1, A = 0.12, n = 5, ``|z| <= 4``; p_S = (0.15, -0.1, -0.1), r = 2.
* open cylinder: R = 2, ``|theta| <= 125 deg``, ``|z| <= 3.5``; p_S = (0.9, 0.15, 0.2)
  (0.9 m off the axis), r = 2; the scan covers about ``-66 < theta < 85 deg``.
* rotating tunnel: ellipse a = 1.3, b = 0.85, pitch p = 10, ``|z| <= 4``;
  p_S = (0.1, 0.15, 0), r = 2.
* box room: 3.6 x 3.0 x 2.4 box; p_S = (0.3, -0.2, 0.1), r = 2.2 (all six faces in range).

Each shape extends at least ~1.4 m beyond the local scan along every degenerate motion
(along the axis, around the open arc, across the plane), so that sliding the scan by the
benchmark range (``lili_odom.degeneracy.quality.QUALITY_RANGE`` = 0.5 m of scaled motion,
and the detectors' perturbations) keeps it on the surface and never shows it an end.

Analytic degenerate subspaces
-----------------------------
A rigid motion ``g`` of the reference frame that maps the surface onto itself moves the scan
pose to ``g @ T_W_C``. For a one-parameter symmetry ``g = T_W_S exp(t xi_S) T_S_W`` this is
``T_W_C @ exp(t Ad(T_C_S) xi_S)`` (``T exp(xi) T^-1 = exp(Ad_T xi)``), so a shape-frame
symmetry generator ``xi_S`` becomes the body-frame basis twist ``b = Ad(T_C_S) xi_S`` with
``T_C_S = T_W_C^-1 T_W_S``. Sums of the generators below are again symmetries of the
infinite surface, hence ``T_W_C exp(sum_j c_j b_j)`` keeps the scan on the surface exactly
(not only to first order). Generators in ``S``, order ``(v, w)``; a rotation about the line
through ``c`` with unit direction ``a`` is ``(v, w) = (c x a, a)`` since a point ``p`` moves
with velocity ``a x (p - c) = a x p + c x a``; all lines below pass through the ``S`` origin,
so ``v = 0`` in ``S`` and the coupling with translation appears only after the adjoint:

* plane ``z_S = 0``: translations ``e_x``, ``e_y`` and the rotation about the normal ``e_z``
  (any in-plane rigid motion). Dimension 3.
* closed cylinder ``x^2 + y^2 = R^2``: translation ``e_z`` and rotation about the axis
  (``w = e_z``); together they form all screws about the axis. Dimension 2.
* sinusoidal cylinder: the extrusion along ``z_S`` of the polar curve
  ``r(theta) = R + A sin(n theta)``. Only the extrusion direction ``e_z`` is continuous; the
  n-fold rotational symmetry is discrete, so rotation about the axis is constrained.
  Dimension 1.
* open cylinder: the part ``|theta| <= theta_max`` of the closed cylinder; the sensor is off
  the axis and sees only an arc well inside ``theta_max``, so locally the same two motions
  (axial translation, rotation about the axis line) are free. Because the axis does not pass
  through the sensor, the rotation is a coupled translation-rotation twist in ``C``.
  Dimension 2.
* rotating tunnel: an ellipse (semi-axes a > b) whose orientation turns by ``2 pi z / p``
  along the axis (pitch ``p``). Rotating by ``alpha`` and advancing by ``alpha p / (2 pi)``
  maps the surface onto itself, so the screw ``(v, w) = ((0, 0, p / (2 pi)), e_z)`` is free;
  pure translation and pure rotation are not (the ellipse is not a circle). Dimension 1.
* box room (closed box seen from inside, all six faces within range): no continuous
  symmetry. Dimension 0.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from lili_odom.geometry import adjoint, exp, transform_points

__all__ = [
    "SCENARIOS",
    "DISPLAY_NAMES",
    "SPACING",
    "JITTER",
    "GRID_PITCH",
    "NOISE_SIGMA",
    "INITIAL_OFFSET",
    "T_WORLD_SHAPE",
    "ShapeCase",
    "make_case",
    "all_cases",
    "characteristic_length",
    "sample_surface",
    "truth_dict",
    "write_case",
    "write_cases",
    "load_case",
]

SCENARIOS: tuple[str, ...] = (
    "plane",
    "closed_cylinder",
    "sinusoidal_cylinder",
    "open_cylinder",
    "rotating_tunnel",
    "box_room",
)
DISPLAY_NAMES: dict[str, str] = {
    "plane": "Plane",
    "closed_cylinder": "Closed Cylinder",
    "sinusoidal_cylinder": "Sinusoidal Cylinder",
    "open_cylinder": "Open Cylinder",
    "rotating_tunnel": "Rotating Tunnel",
    "box_room": "Box Room",
}

SPACING = 0.05
"""Target mean nearest-neighbour distance [m] between the points of one cloud (the paper's
"average distance between neighbouring points")."""
GRID_PITCH = 0.063
"""Pitch [m] of the jittered sampling grid (one point per GRID_PITCH^2 of surface). A jittered
grid's mean nearest-neighbour distance is ~0.80 pitch for JITTER = 0.25, hence ~SPACING."""
JITTER = 0.25
"""Uniform jitter of every sample, as a fraction of the pitch per grid axis (+-)."""
NOISE_SIGMA = 0.02
"""Standard deviation [m] of the per-axis Gaussian noise of the noisy variants."""
INITIAL_OFFSET = np.array([0.03, -0.02, 0.025, np.radians(0.6), np.radians(-0.5), np.radians(0.55)])
"""Body-frame twist ``(v [m], w [rad])``: ``initial_pose = true_pose @ exp(INITIAL_OFFSET)``
(4.1 cm, 0.95 deg)."""


def _pose(rotvec: tuple[float, float, float], translation: tuple[float, float, float]) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = translation
    return T


T_WORLD_SHAPE = _pose((0.42, -0.57, 0.81), (1.3, -0.7, 0.45))
"""The fixed generic placement ``T_W_S`` of every shape in the reference frame."""

_E = np.eye(6)  # rows: unit twists vx, vy, vz, wx, wy, wz


@dataclass
class ShapeCase:
    """One reference / local-scan pair with its true degenerate subspace.

    Attributes:
        name: scenario id (one of ``SCENARIOS``).
        noise: per-axis noise standard deviation [m] added to both clouds (0.0 = clean).
        reference: (N, 3) reference points [m], reference frame ``W``.
        scan: (M, 3) local scan points [m], sensor frame ``C``.
        true_pose: 4x4 ``T_W_C`` mapping scan points into the reference frame.
        initial_pose: 4x4 starting guess ``true_pose @ exp(INITIAL_OFFSET)``.
        true_basis: (k, 6) plain twists ``(v [m], w [rad])`` in the scan's body frame at
            ``true_pose`` spanning the degenerate subspace (each row is the body-frame image
            of a unit shape-frame generator, not orthonormalised); (0, 6) for the box room.
        characteristic_length: L [m], median range of ``scan`` from the sensor origin.
        spacing: target mean nearest-neighbour distance [m] within a clean cloud.
        display_name: the paper's name of the scenario.
        shape_pose: 4x4 ``T_W_S`` placing the shape frame in the reference frame.
        sensor_radius: crop radius [m] of the local scan around the sensor.
        params: the scenario's geometric parameters [m, rad] (for logs and ``truth.json``).
    """

    name: str
    noise: float
    reference: np.ndarray
    scan: np.ndarray
    true_pose: np.ndarray
    initial_pose: np.ndarray
    true_basis: np.ndarray
    characteristic_length: float
    spacing: float
    display_name: str = ""
    shape_pose: np.ndarray = field(default_factory=lambda: np.eye(4))
    sensor_radius: float = 0.0
    params: dict[str, float] = field(default_factory=dict)

    @property
    def noisy(self) -> bool:
        return self.noise > 0.0

    @property
    def true_dimension(self) -> int:
        return int(self.true_basis.shape[0])

    @property
    def folder_name(self) -> str:
        """``<scenario>_<clean|noisy>``, the case's directory in ``write_cases``."""
        return f"{self.name}_{'noisy' if self.noisy else 'clean'}"

    @property
    def true_basis_scaled(self) -> np.ndarray:
        """(k, 6) orthonormal rows of the true subspace in the scaled space ``(v, L w)``."""
        from lili_odom.degeneracy.subspace import truth_scaled

        return truth_scaled(self.true_basis, self.characteristic_length)


def characteristic_length(scan: np.ndarray) -> float:
    """Median range [m] of (M, 3) sensor-frame points from the sensor origin."""
    return float(np.median(np.linalg.norm(np.asarray(scan, dtype=float), axis=1)))


# --------------------------------------------------------------------------- sampling


def _jittered_grid(
    len_u: float, len_v: float, h: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Jittered grid on ``[0, len_u) x [0, len_v)`` with pitch ~``h``, random lattice origin.

    The pitch is adjusted to fit a whole number of cells; coordinates wrap around (exactly
    periodic in a periodic direction, and still area-uniform in an open one).
    """
    n_u, n_v = max(1, round(len_u / h)), max(1, round(len_v / h))
    p_u, p_v = len_u / n_u, len_v / n_v
    iu, iv = np.meshgrid(np.arange(n_u), np.arange(n_v), indexing="ij")
    iu, iv = iu.ravel().astype(float), iv.ravel().astype(float)
    u = (iu + 0.5 + rng.uniform(-JITTER, JITTER, iu.size) + rng.uniform()) * p_u
    v = (iv + 0.5 + rng.uniform(-JITTER, JITTER, iv.size) + rng.uniform()) * p_v
    return np.mod(u, len_u), np.mod(v, len_v)


def _sample_rectangle(
    origin: np.ndarray, e1: np.ndarray, e2: np.ndarray, h: float, rng: np.random.Generator
) -> np.ndarray:
    """Area-uniform samples of the parallelogram ``origin + s e1 + t e2``, s, t in [0, 1)."""
    l1, l2 = float(np.linalg.norm(e1)), float(np.linalg.norm(e2))
    s, t = _jittered_grid(l1, l2, h, rng)
    return origin + np.outer(s / l1, e1) + np.outer(t / l2, e2)


def _sample_twisted_extrusion(
    profile: Callable[[np.ndarray], np.ndarray],
    u_range: tuple[float, float],
    z_range: tuple[float, float],
    twist_rate: float,
    h: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """Area-uniform samples of ``F(u, z) = (Rz(twist_rate z) q(u), z)`` in the shape frame.

    ``q(u)`` (``profile``, (n,) -> (n, 2)) is the cross-section; ``u`` runs over ``u_range``
    (a closed curve when it spans a full period of ``q``). The area element is
    ``|F_u x F_z| = |q'| sqrt(1 + twist_rate^2 (q . t)^2)`` (t = unit tangent of q), which
    depends on ``u`` only, so a jittered grid in (cumulative area weight along u, z) is
    uniform by area.
    """
    u = np.linspace(u_range[0], u_range[1], 20001)
    q = profile(u)
    dq = np.gradient(q, u, axis=0)
    speed = np.linalg.norm(dq, axis=1)
    qt = np.einsum("ij,ij->i", q, dq) / speed
    weight = speed * np.sqrt(1.0 + twist_rate**2 * qt**2)
    W = np.concatenate([[0.0], np.cumsum(0.5 * (weight[1:] + weight[:-1]) * np.diff(u))])
    w_s, z_s = _jittered_grid(W[-1], z_range[1] - z_range[0], h, rng)
    uu = np.interp(w_s, W, u)
    zz = z_range[0] + z_s
    qq = profile(uu)
    ang = twist_rate * zz
    c, s = np.cos(ang), np.sin(ang)
    return np.column_stack([c * qq[:, 0] - s * qq[:, 1], s * qq[:, 0] + c * qq[:, 1], zz])


# --------------------------------------------------------------------------- scenarios


@dataclass(frozen=True)
class _Scenario:
    name: str
    params: dict[str, float]
    sampler: Callable[[np.random.Generator, float], np.ndarray]  # whole surface, frame S
    T_S_C: np.ndarray  # sensor pose in the shape frame
    scan_radius: float  # [m]
    generators: np.ndarray  # (k, 6) symmetry generators in S, (v, w)


def _circle(R: float) -> Callable[[np.ndarray], np.ndarray]:
    return lambda u: R * np.column_stack([np.cos(u), np.sin(u)])


def _sinusoid(R: float, A: float, n: int) -> Callable[[np.ndarray], np.ndarray]:
    def q(u: np.ndarray) -> np.ndarray:
        r = R + A * np.sin(n * u)
        return np.column_stack([r * np.cos(u), r * np.sin(u)])

    return q


def _ellipse(a: float, b: float) -> Callable[[np.ndarray], np.ndarray]:
    return lambda u: np.column_stack([a * np.cos(u), b * np.sin(u)])


def _box_sampler(half: tuple[float, float, float]) -> Callable[[np.random.Generator, float], np.ndarray]:
    hx, hy, hz = half

    def sample(rng: np.random.Generator, h: float) -> np.ndarray:
        ex, ey, ez = np.array([2 * hx, 0, 0]), np.array([0, 2 * hy, 0]), np.array([0, 0, 2 * hz])
        lo = np.array([-hx, -hy, -hz])
        faces = [
            _sample_rectangle(lo, ex, ey, h, rng),  # floor z = -hz
            _sample_rectangle(lo + ez, ex, ey, h, rng),  # ceiling z = +hz
            _sample_rectangle(lo, ex, ez, h, rng),  # wall y = -hy
            _sample_rectangle(lo + ey, ex, ez, h, rng),  # wall y = +hy
            _sample_rectangle(lo, ey, ez, h, rng),  # wall x = -hx
            _sample_rectangle(lo + ex, ey, ez, h, rng),  # wall x = +hx
        ]
        return np.vstack(faces)

    return sample


def _scenario(name: str) -> _Scenario:
    """Geometry, sensor placement and symmetry generators of one scenario (shape frame)."""
    if name == "plane":
        half = 4.0
        return _Scenario(
            name,
            {"half_size": half},
            lambda rng, h: _sample_rectangle(
                np.array([-half, -half, 0.0]), np.array([2 * half, 0, 0]), np.array([0, 2 * half, 0]), h, rng
            ),
            _pose((0.35, -0.25, 0.6), (0.2, -0.3, 1.2)),
            2.4,
            _E[[0, 1, 5]],
        )
    if name == "closed_cylinder":
        R, zh = 1.0, 4.0
        return _Scenario(
            name,
            {"radius": R, "half_length": zh},
            lambda rng, h: _sample_twisted_extrusion(_circle(R), (0.0, 2 * np.pi), (-zh, zh), 0.0, h, rng),
            _pose((-0.3, 0.45, 0.2), (0.2, -0.15, 0.1)),
            2.0,
            _E[[2, 5]],
        )
    if name == "sinusoidal_cylinder":
        R, A, n, zh = 1.0, 0.12, 5, 4.0
        return _Scenario(
            name,
            {"radius": R, "amplitude": A, "lobes": float(n), "half_length": zh},
            lambda rng, h: _sample_twisted_extrusion(_sinusoid(R, A, n), (0.0, 2 * np.pi), (-zh, zh), 0.0, h, rng),
            _pose((0.5, 0.2, -0.4), (0.15, -0.1, -0.1)),
            2.0,
            _E[[2]],
        )
    if name == "open_cylinder":
        R, th, zh = 2.0, np.radians(125.0), 3.5
        return _Scenario(
            name,
            {"radius": R, "half_arc_rad": float(th), "half_length": zh},
            lambda rng, h: _sample_twisted_extrusion(_circle(R), (-th, th), (-zh, zh), 0.0, h, rng),
            _pose((0.25, 0.4, 0.35), (0.9, 0.15, 0.2)),
            2.0,
            _E[[2, 5]],
        )
    if name == "rotating_tunnel":
        a, b, p, zh = 1.3, 0.85, 10.0, 4.0
        rate = 2 * np.pi / p
        screw = np.array([0.0, 0.0, p / (2 * np.pi), 0.0, 0.0, 1.0])
        return _Scenario(
            name,
            {"semi_axis_a": a, "semi_axis_b": b, "pitch": p, "half_length": zh},
            lambda rng, h: _sample_twisted_extrusion(_ellipse(a, b), (0.0, 2 * np.pi), (-zh, zh), rate, h, rng),
            _pose((-0.45, -0.2, 0.3), (0.1, 0.15, 0.0)),
            2.0,
            screw[None, :],
        )
    if name == "box_room":
        half = (1.8, 1.5, 1.2)
        return _Scenario(
            name,
            {"half_x": half[0], "half_y": half[1], "half_z": half[2]},
            _box_sampler(half),
            _pose((0.3, -0.35, 0.5), (0.3, -0.2, 0.1)),
            2.2,
            np.zeros((0, 6)),
        )
    raise ValueError(f"unknown scenario {name!r}; expected one of {', '.join(SCENARIOS)}")


def sample_surface(name: str, rng: np.random.Generator, pitch: float = GRID_PITCH) -> np.ndarray:
    """One area-uniform sampling of scenario ``name``'s whole surface, reference frame [m]."""
    return transform_points(T_WORLD_SHAPE, _scenario(name).sampler(rng, pitch))


def make_case(name: str, noisy: bool = False, seed: int = 0) -> ShapeCase:
    """Build one scenario (see the module docstring for frames, sampling and the truth).

    Args:
        name: scenario id from ``SCENARIOS``.
        noisy: add ``N(0, NOISE_SIGMA^2)`` per axis to every point of both clouds.
        seed: seeds the two independent samplings and the noise; the clean and noisy variants
            of the same (name, seed) share their noise-free samples.
    """
    sc = _scenario(name)
    index = SCENARIOS.index(name)
    ref_rng, scan_rng, noise_rng = (
        np.random.default_rng(s) for s in np.random.SeedSequence([int(seed), index]).spawn(3)
    )
    reference_s = sc.sampler(ref_rng, GRID_PITCH)
    scan_s = sc.sampler(scan_rng, GRID_PITCH)
    sensor = sc.T_S_C[:3, 3]
    scan_s = scan_s[np.linalg.norm(scan_s - sensor, axis=1) <= sc.scan_radius]

    true_pose = T_WORLD_SHAPE @ sc.T_S_C
    reference = transform_points(T_WORLD_SHAPE, reference_s)
    scan = transform_points(np.linalg.inv(sc.T_S_C), scan_s)
    sigma = NOISE_SIGMA if noisy else 0.0
    if noisy:
        reference = reference + noise_rng.normal(0.0, sigma, reference.shape)
        scan = scan + noise_rng.normal(0.0, sigma, scan.shape)

    T_C_S = np.linalg.inv(sc.T_S_C)
    true_basis = (adjoint(T_C_S) @ sc.generators.T).T.reshape(-1, 6)
    return ShapeCase(
        name=name,
        noise=sigma,
        reference=reference,
        scan=scan,
        true_pose=true_pose,
        initial_pose=true_pose @ exp(INITIAL_OFFSET),
        true_basis=true_basis,
        characteristic_length=characteristic_length(scan),
        spacing=SPACING,
        display_name=DISPLAY_NAMES[name],
        shape_pose=T_WORLD_SHAPE.copy(),
        sensor_radius=sc.scan_radius,
        params=dict(sc.params),
    )


def all_cases(seed: int = 0) -> list[ShapeCase]:
    """Every scenario, clean then noisy, in ``SCENARIOS`` order (12 cases)."""
    return [make_case(name, noisy, seed) for name in SCENARIOS for noisy in (False, True)]


# --------------------------------------------------------------------------- files


def truth_dict(case: ShapeCase, seed: int | None = None) -> dict[str, object]:
    """The ``truth.json`` object of a case (plain and scaled true basis, L, geometry)."""
    return {
        "scenario": case.name,
        "display_name": case.display_name,
        "noise": float(case.noise),
        "noisy": case.noisy,
        "seed": seed,
        "true_dimension": case.true_dimension,
        "true_basis": case.true_basis.tolist(),
        "true_basis_scaled": case.true_basis_scaled.tolist(),
        "characteristic_length": float(case.characteristic_length),
        "spacing": float(case.spacing),
        "sensor_radius": float(case.sensor_radius),
        "twist_order": "(v [m], w [rad]) in the scan's body frame at true_pose",
        "shape_pose": case.shape_pose.tolist(),
        "params": {k: float(v) for k, v in case.params.items()},
        "num_reference_points": int(len(case.reference)),
        "num_scan_points": int(len(case.scan)),
    }


def write_case(case: ShapeCase, out_dir: str | Path, seed: int | None = None) -> Path:
    """Write one case into ``out_dir/<scenario>_<clean|noisy>/`` and return that folder.

    Files: ``reference.npy`` (N, 3) reference frame, ``scan.npy`` (M, 3) sensor frame,
    ``initial_pose.txt`` and ``true_pose.txt`` (4x4, ``np.savetxt``), ``truth.json``.
    """
    folder = Path(out_dir) / case.folder_name
    folder.mkdir(parents=True, exist_ok=True)
    np.save(folder / "reference.npy", case.reference.astype(np.float64))
    np.save(folder / "scan.npy", case.scan.astype(np.float64))
    np.savetxt(folder / "initial_pose.txt", case.initial_pose)
    np.savetxt(folder / "true_pose.txt", case.true_pose)
    (folder / "truth.json").write_text(json.dumps(truth_dict(case, seed), indent=2) + "\n")
    return folder


def write_cases(out_dir: str | Path, seed: int = 0) -> list[Path]:
    """Write every case of ``all_cases(seed)`` below ``out_dir``; returns the case folders."""
    return [write_case(case, out_dir, seed) for case in all_cases(seed)]


def load_case(folder: str | Path) -> ShapeCase:
    """Read a folder written by ``write_case`` back into a ``ShapeCase``."""
    folder = Path(folder)
    truth = json.loads((folder / "truth.json").read_text())
    return ShapeCase(
        name=truth["scenario"],
        noise=float(truth["noise"]),
        reference=np.load(folder / "reference.npy"),
        scan=np.load(folder / "scan.npy"),
        true_pose=np.loadtxt(folder / "true_pose.txt"),
        initial_pose=np.loadtxt(folder / "initial_pose.txt"),
        true_basis=np.asarray(truth["true_basis"], dtype=float).reshape(-1, 6),
        characteristic_length=float(truth["characteristic_length"]),
        spacing=float(truth["spacing"]),
        display_name=truth.get("display_name", ""),
        shape_pose=np.asarray(truth.get("shape_pose", np.eye(4).tolist()), dtype=float),
        sensor_radius=float(truth.get("sensor_radius", 0.0)),
        params=dict(truth.get("params", {})),
    )
