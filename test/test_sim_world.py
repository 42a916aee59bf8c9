"""Scene description, mesh and ray-cast geometry of the simulator."""
import numpy as np
import pytest

from lili_odom.sim.generator import SimRequest, Simulation
from lili_odom.sim.lidar import RayCaster
from lili_odom.sim.layout import Centreline
from lili_odom.sim.mesh import build_mesh
from lili_odom.sim.world import Segment, load_world


@pytest.mark.parametrize("name", ["tunnel", "corridor", "open_field", "orchard"])
def test_worlds_load_and_mesh(name):
    world = load_world(name)
    mesh = build_mesh(world)
    assert mesh.faces.shape[1] == 3 and len(mesh.faces) > 1000
    assert np.all(np.isfinite(mesh.vertices))
    assert len(mesh.material) == len(mesh.faces)
    assert set(np.unique(mesh.material)) <= set(range(len(mesh.materials)))
    assert world.trials, "every shipped world defines trials"


def test_feature_density_zero_removes_inside_features():
    world = load_world("tunnel")
    full = build_mesh(world, 1.0)
    none = build_mesh(world, 0.0)
    dense = build_mesh(world, 3.0)
    assert len(none.faces) < len(full.faces) < len(dense.faces)
    light = none.materials.index("light")
    assert not np.any(none.material == light)


def test_centreline_lengths_and_smoothness():
    line = Centreline([Segment("straight", 50.0), Segment("arc", 200.0, 300.0, "left")])
    s = np.linspace(-20, 260, 28001)
    xy, h, k = line.evaluate(s)
    step = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    assert np.allclose(step, s[1] - s[0], rtol=1e-6)  # unit speed parametrisation
    assert np.all(np.abs(np.diff(h)) < 1e-4)  # continuous heading
    assert np.allclose(xy[s <= 0][:, 1], 0.0) and np.isclose(h[-1], 200.0 / 300.0, atol=1e-9)


def test_ray_cast_hits_a_plane_exactly():
    world = load_world("open_field")
    world.floor.random_waves = 0
    world.outside.clutter = []
    world.outside.objects = []
    caster = RayCaster(build_mesh(world))
    o = np.array([[0.0, 0.0, 2.0], [10.0, 5.0, 1.0]])
    d = np.array([[0.0, 0.0, -1.0], [0.6, 0.0, -0.8]])
    dist, prim = caster.cast(o, d)
    assert np.all(prim >= 0)
    assert np.allclose(dist, [2.0, 1.25], atol=1e-4)
    dist, prim = caster.cast(o[:1], np.array([[0.0, 0.0, 1.0]]))
    assert np.isinf(dist[0]) and prim[0] == -1


def _to_world(sim, t, scan):
    T = sim.trajectory.pose(t + sim.lidar.column_times()) @ sim.sensors.extrinsics.base_to_lidar
    pts = np.einsum("jab,ijb->ija", T[:, :3, :3], scan.xyz.astype(float)) + T[None, :, :3, 3]
    return pts[scan.valid]


def test_cloud_lies_on_the_corridor_surfaces():
    """Every return of a moving scan, placed with its own column pose, is on a wall, the floor,
    the ceiling or an end wall of the featureless corridor, within the range noise."""
    sim = Simulation(SimRequest(world="corridor", trial=1, resolution=(32, 256), feature_density=0.0))
    t = 20.0
    scan = sim.scan(t)
    assert scan.valid.mean() > 0.95
    p = _to_world(sim, t, scan)
    cs = sim.world.cross_section
    floor_z = sim.trajectory.floor.height(p[:, :2])
    d = np.min(np.stack([
        np.abs(np.abs(p[:, 1]) - cs.width / 2),
        np.abs(p[:, 2] - cs.height),
        np.abs(p[:, 2] - floor_z),
        np.abs(p[:, 0]),
        np.abs(p[:, 0] - 80.0),
    ]), axis=0)
    sigma = sim.sensors.lidar.range_sigma
    assert np.percentile(d, 99) < 4 * sigma
    assert np.max(d) < 6 * sigma


def test_cloud_lies_on_the_tunnel_profile():
    """Same check in the straight part of the horseshoe tunnel (floor, walls, arch)."""
    sim = Simulation(SimRequest(world="tunnel", trial=1, resolution=(32, 256), feature_density=0.0))
    t = 45.0
    x = sim.trajectory.pose(t)[0, 0, 3]
    assert 8.0 < x < 30.0, "pose in the straight part"
    scan = sim.scan(t)
    p = _to_world(sim, t, scan)
    p = p[(p[:, 0] > 1.0) & (p[:, 0] < 40.0)]
    assert len(p) > 1000
    cs = sim.world.cross_section
    hw, wh = cs.width / 2, cs.wall_height
    floor_z = sim.trajectory.floor.height(p[:, :2])
    wall = np.where(p[:, 2] <= wh, np.abs(np.abs(p[:, 1]) - hw), np.inf)
    arch = np.where(p[:, 2] >= wh, np.abs(np.hypot(p[:, 1], p[:, 2] - wh) - hw), np.inf)
    d = np.min(np.stack([wall, arch, np.abs(p[:, 2] - floor_z)]), axis=0)
    # the mesh approximates the arch by 0.3 m chords (sagitta ~4 mm): noise dominates
    assert np.percentile(d, 99) < 4 * sim.sensors.lidar.range_sigma
