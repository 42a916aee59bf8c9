"""World description extensions: floor ramps, object arrays, per-feature ranges, path-only worlds,
fixed stops; and the request-level sensor overrides."""
from __future__ import annotations

import numpy as np
import pytest

from lili_odom.sim.generator import SimRequest, sensors_for
from lili_odom.sim.trajectory import Trajectory
from lili_odom.sim.layout import Centreline, FloorField
from lili_odom.sim.mesh import build_mesh
from lili_odom.sim.world import (
    CrossSection,
    FeatureSpec,
    Features,
    Floor,
    ObjectSpec,
    Outside,
    Ramp,
    Segment,
    TrialPlan,
    WorldDescription,
)


def _tube_world(**kw) -> WorldDescription:
    base = dict(
        name="t",
        segments=[Segment("straight", 60.0)],
        cross_section=CrossSection(shape="rectangle", width=3.0, height=3.0, resolution=0.5, step=0.5),
        outside=Outside(ground=False, portal=False),
        features=Features(density=0.0),
        trials={1: TrialPlan(legs=[(2.0, 58.0)], stops=0, weave_amplitude=0.0)},
    )
    base.update(kw)
    return WorldDescription(**base)


def test_ramp_height_is_smooth_and_drops_grade_times_length():
    field = FloorField(Floor(ramps=[Ramp(direction_deg=0.0, start=10.0, length=20.0, grade=-0.1, transition=4.0)]))
    x = np.linspace(-5.0, 45.0, 5001)
    z = field.height(np.stack([x, np.zeros_like(x)], -1))
    assert z[0] == 0.0 and z[-1] == pytest.approx(-2.0)
    slope = np.gradient(z, x)
    assert slope.min() == pytest.approx(-0.1, abs=1e-3)
    assert np.abs(np.diff(slope)).max() < 2 * 0.1 * (x[1] - x[0]) / 4.0  # continuous pitch
    # along the other horizontal direction the ramp does not change the height
    z_y = field.height(np.stack([np.full(50, 20.0), np.linspace(-10, 10, 50)], -1))
    assert np.ptp(z_y) < 1e-12


def test_tube_walls_and_trajectory_follow_a_ramp():
    world = _tube_world(floor=Floor(ramps=[Ramp(start=20.0, length=20.0, grade=-0.15, transition=4.0)]))
    mesh = build_mesh(world)
    v = mesh.vertices
    far = v[:, 0] > 45.0
    assert v[far, 2].max() == pytest.approx(3.0 - 3.0, abs=0.05)  # the ceiling came down 3 m
    assert v[far, 2].min() == pytest.approx(-3.0, abs=0.05)
    traj = Trajectory(world, world.trials[1], seed=0)
    k = traj.kinematics(np.linspace(0.0, traj.duration, 400))
    z_floor = FloorField(world.floor).height(k.position[:, :2])
    assert np.allclose(k.position[:, 2] - z_floor, 0.1323, atol=0.02)
    pitch = -np.degrees(np.arcsin(k.rotation[:, 2, 0]))  # REP-103: positive pitch = nose down
    assert pitch.max() == pytest.approx(np.degrees(np.arctan(0.15)), abs=0.3)
    assert pitch.min() > -0.5


def test_object_arrays_place_count_copies():
    one = _tube_world(segments=[], outside=Outside(ground=False, portal=False, objects=[
        ObjectSpec(kind="box", position=(0.0, 0.0), size=(1.0, 1.0, 1.0))]))
    row = _tube_world(segments=[], outside=Outside(ground=False, portal=False, objects=[
        ObjectSpec(kind="box", position=(0.0, 0.0), size=(1.0, 1.0, 1.0), count=5, step=(3.0, 0.5))]))
    m1, m5 = build_mesh(one), build_mesh(row)
    assert len(m5.faces) == 5 * len(m1.faces)
    assert m5.vertices[:, 0].max() == pytest.approx(12.5)
    assert m5.vertices[:, 1].max() == pytest.approx(2.5)


def test_feature_s_range_limits_an_item():
    niche = FeatureSpec(kind="niche", spacing=4.0, jitter=0.0, size=(1.0, 0.5, 2.0), side="left", material="wood",
                        s_range=(40.0, 55.0))
    world = _tube_world(features=Features(density=1.0, items=[niche]))
    mesh = build_mesh(world)
    wood = mesh.material == mesh.materials.index("wood")
    x = mesh.triangles[wood][..., 0]
    assert wood.any() and x.min() >= 40.0 and x.max() <= 55.0


def test_path_only_world_builds_no_tube_but_drives_the_curve():
    world = _tube_world(tube=False, segments=[Segment("straight", 20.0), Segment("arc", 15.7, 10.0, "left")],
                        outside=Outside(ground=True, ground_x_range=(-5, 35), ground_y_range=(-5, 25), portal=False),
                        trials={1: TrialPlan(legs=[(0.0, 45.0)], stops=0, weave_amplitude=0.0, lane_offset=0.0)})
    mesh = build_mesh(world)
    assert np.abs(mesh.vertices[:, 2]).max() < 0.1  # the ground only
    traj = Trajectory(world, world.trials[1], seed=0)
    end = traj.pose(traj.duration)[0]
    heading = np.degrees(np.arctan2(end[1, 0], end[0, 0]))
    assert heading == pytest.approx(90.0, abs=1.0)


def test_fixed_stops_are_where_the_plan_says():
    world = _tube_world(trials={1: TrialPlan(legs=[(2.0, 58.0)], stop_s=[20.0, 45.0], stop_duration_range=(3.0, 3.0),
                                             weave_amplitude=0.0)})
    traj = Trajectory(world, world.trials[1], seed=4)
    holds = [p for p in traj.phases if p.kind == "hold"][1:-1]
    assert [round(p.d0 + 2.0, 6) for p in holds] == [20.0, 45.0]
    assert all(p.T == 3.0 for p in holds)
    line = Centreline(world.segments)
    for p in holds:
        x = traj.pose(p.t0 + 1.5)[0, 0, 3]
        assert x == pytest.approx(line.evaluate(p.d0 + 2.0)[0][0, 0], abs=1e-6)


def test_request_overrides_reach_the_sensor_models():
    req = SimRequest(resolution=(32, 512), lidar={"elevation_max_deg": 45.0, "max_range": 50.0},
                     imu={"gyro_noise_density": 1e-3}, wheels={"scale_error": 0.02, "outages": [[1.0, 2.0]]})
    s = sensors_for(req)
    assert (s.lidar.rows, s.lidar.cols, s.lidar.elevation_max_deg, s.lidar.max_range) == (32, 512, 45.0, 50.0)
    assert s.imu.gyro_noise_density == 1e-3 and s.wheels.scale_error == 0.02
    assert s.wheels.outages == ((1.0, 2.0),)
    with pytest.raises(ValueError, match="rows"):
        sensors_for(SimRequest(lidar={"rows": 64}))
    with pytest.raises(ValueError, match="no settable field"):
        sensors_for(SimRequest(wheels={"scale": 1.0}))
