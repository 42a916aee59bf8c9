"""Scene description: plain dataclasses loaded from YAML.

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

A new world is a new YAML file, not new code: see ``config/worlds/tunnel.yaml``. The analytic
centreline and floor surface are in :mod:`lili_odom.sim.layout`, the triangle mesh in
:mod:`lili_odom.sim.mesh`.
"""
from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

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
