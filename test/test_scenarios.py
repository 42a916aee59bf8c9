"""The scenario suite's data: every scenario loads and simulates what it says."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from lili_odom.sim.generator import Simulation, cache_key, sensors_for
from lili_odom.sim.wheels import simulate_wheel_odom
from lili_odom.sim.mesh import build_mesh
from lili_odom.sim.world import load_world
from lili_odom.suite.scenario import (
    SPLITS,
    ErrorProfile,
    SensorProfile,
    Slip,
    load_scenarios,
    scenario_bag,
    scenario_names,
    scenario_request,
    scenario_table,
)

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def scenarios():
    return load_scenarios()


def test_at_least_eight_scenarios_in_both_splits(scenarios):
    assert len(scenarios) >= 8
    assert [s.name for s in scenarios] == scenario_names()
    by_split = {split: [s for s in scenarios if s.split == split] for split in SPLITS}
    assert all(by_split.values()), by_split
    # every kind of difficulty has an instance in both splits, with a different sensor and seeds
    for kind in ("building", "open", "tunnel"):
        tuning = [s for s in by_split["tuning"] if s.kind == kind]
        validation = [s for s in by_split["validation"] if s.kind == kind]
        assert tuning and validation, kind
        assert {s.sensor.label for s in validation} - {s.sensor.label for s in tuning}, kind
        assert {s.world for s in validation} != {s.world for s in tuning} or kind == "tunnel", kind


def test_ci_pieces_are_short_and_inside_their_scenario(scenarios):
    ci = [s for s in scenarios if s.ci is not None]
    assert 2 <= len(ci) <= 3
    for sc in ci:
        assert 10.0 <= sc.ci.duration <= 30.0
        assert sc.ci.resolution[0] * sc.ci.resolution[1] <= 32 * 1024
        sim = Simulation(scenario_request(sc, sc.seeds[0], ci=True))
        t0, t1 = sim.window()
        assert t1 - t0 == pytest.approx(sc.ci.duration)
        # a CI piece starts at rest (the pipeline's start-up hold sees a standstill)
        v = np.linalg.norm(sim.trajectory.kinematics(np.array([t0])).velocity[0])
        assert v < 1e-3, (sc.name, v)


@pytest.mark.parametrize("name", scenario_names())
def test_scenario_world_and_trajectory(name):
    (sc,) = load_scenarios([name])
    assert sc.description and "Hard:" in sc.description
    world = load_world(sc.world)
    assert sc.trial in world.trials
    mesh = build_mesh(world)
    assert len(mesh.faces) > 1000
    sim = Simulation(scenario_request(sc, sc.seeds[0]))
    t0, t1 = sim.window()
    assert 40.0 <= t1 - t0 <= 350.0
    assert sc.duration_s == pytest.approx(t1 - t0)
    t = np.arange(t0, t1, 0.1)
    k = sim.trajectory.kinematics(t)
    speed = np.linalg.norm(k.velocity, axis=1)
    assert speed.max() <= 2.1
    assert 50.0 <= sc.distance <= 300.0
    assert sc.distance == pytest.approx(np.sum(speed) * 0.1, rel=0.02)
    # stops: a full standstill of at least 2 s between the first and the last motion
    moving = np.flatnonzero(speed > 0.05)
    still = (speed <= 0.05)[moving[0]:moving[-1]]
    runs = np.diff(np.flatnonzero(np.diff(np.r_[0, still.astype(int), 0])))[::2]
    assert runs.size and runs.max() * 0.1 >= 2.0, name
    # the robot stays on the floor: base_link height above the floor under it is the Husky's
    xy = k.position[:, :2]
    dz = k.position[:, 2] - sim.trajectory.floor.height(xy)
    assert np.all(np.abs(dz - sim.sensors.husky.base_height) < 0.1)


def test_sensor_profile_reaches_the_simulated_lidar(scenarios):
    office = next(s for s in scenarios if s.name == "office")
    assert office.sensor.model == "OS0-64"
    lidar = sensors_for(scenario_request(office, 3)).lidar
    assert (lidar.rows, lidar.cols) == (64, 1024)
    assert (lidar.elevation_max_deg, lidar.elevation_min_deg, lidar.max_range) == (45.0, -45.0, 50.0)
    sim = Simulation(scenario_request(office, 3, resolution=(16, 128)))
    scan = sim.scan(5.0)
    assert scan.xyz.shape == (16, 128, 3)
    ok = np.isfinite(scan.xyz[..., 0])
    el = np.degrees(np.arctan2(scan.xyz[..., 2], np.hypot(scan.xyz[..., 0], scan.xyz[..., 1])))
    # top and bottom rings return at +-45 deg in the lobby (ceiling 3.5 m, floor)
    assert np.nanmax(el[ok]) == pytest.approx(45.0, abs=0.2)
    assert np.nanmin(el[ok]) == pytest.approx(-45.0, abs=0.2)


def test_sensor_model_names():
    assert SensorProfile.from_data({"model": "OS1-32", "cols": 512}).resolution == (32, 512)
    os1 = SensorProfile.from_data({"model": "OS1-128"})
    assert (os1.elevation_max_deg, os1.max_range) == (22.5, 120.0)
    assert SensorProfile.from_data({"model": "OS0-64", "max_range": 35.0}).max_range == 35.0
    with pytest.raises(ValueError, match="OS1-64"):
        SensorProfile.from_data({"model": "VLP-16"})
    with pytest.raises(ValueError, match="unknown keys"):
        SensorProfile.from_data({"model": "OS1-64", "fov": 45})


def test_unknown_scenario_lists_the_known_ones():
    with pytest.raises(ValueError, match="building"):
        load_scenarios(["no_such_place"])


def test_cache_key_follows_the_profiles(scenarios):
    sc = next(s for s in scenarios if s.name == "building")
    base = cache_key(scenario_request(sc, 0))
    assert cache_key(scenario_request(sc, 0)) == base
    assert cache_key(scenario_request(sc, 1)) != base
    variants = [
        dataclasses.replace(sc, sensor=dataclasses.replace(sc.sensor, max_range=50.0)),
        dataclasses.replace(sc, sensor=dataclasses.replace(sc.sensor, elevation_max_deg=45.0)),
        dataclasses.replace(sc, errors=dataclasses.replace(sc.errors, wheel_scale_error=0.02)),
        dataclasses.replace(sc, errors=dataclasses.replace(sc.errors, wheel_outages=[(10.0, 12.0)])),
        dataclasses.replace(sc, errors=dataclasses.replace(sc.errors, imu={"gyro_noise_density": 1e-3})),
    ]
    keys = {cache_key(scenario_request(v, 0)) for v in variants}
    assert base not in keys and len(keys) == len(variants)
    assert cache_key(scenario_request(sc, 0, ci=True)) != base


def test_error_profile_reaches_the_wheels():
    (sc,) = load_scenarios(["building"], measure=False)
    errors = ErrorProfile(wheel_scale_error=-0.03, wheel_yaw_scale_error=0.05,
                          slips=[Slip(t=20.0, duration=1.0, gain=0.3)], wheel_outages=[(30.0, 33.5)])
    req = scenario_request(dataclasses.replace(sc, errors=errors), 0)
    sim = Simulation(req)
    wheels = simulate_wheel_odom(sim.trajectory, sim.sensors.wheels, seed=0, t_end=60.0)
    assert wheels.scale == pytest.approx(0.97) and wheels.yaw_scale == pytest.approx(1.05)
    fast = (np.abs(wheels.v_true) > 0.5) & ~wheels.slipping
    ratio = np.median(wheels.v[fast] / wheels.v_true[fast])
    assert ratio == pytest.approx(0.97, abs=0.003)
    slip = wheels.slipping
    assert np.all((wheels.t[slip] >= 20.0) & (wheels.t[slip] < 21.0)) and slip.sum() == 50
    assert np.median(wheels.v[slip] / wheels.v_true[slip]) == pytest.approx(0.97 * 1.3, abs=0.01)
    gap = (wheels.t >= 30.0) & (wheels.t < 33.5)
    assert not wheels.published[gap].any() and wheels.published[~gap].all()


def test_scenario_bag_has_the_topics_and_the_outage(tmp_path):
    from rosbags.highlevel import AnyReader

    (sc,) = load_scenarios(["mine"], measure=False)
    (t_out0, t_out1), = sc.errors.wheel_outages
    piece = dataclasses.replace(sc, start=t_out0 - 0.5, duration=t_out1 - t_out0 + 1.0)
    bag = scenario_bag(piece, 0, resolution=(4, 32), cache_dir=tmp_path, progress=False, jobs=1)
    assert bag.name.startswith("mine_4x32_seed0_")
    assert scenario_bag(piece, 0, resolution=(4, 32), cache_dir=tmp_path, progress=False, jobs=1) == bag
    stamps: dict[str, list[float]] = {}
    with AnyReader([bag]) as reader:
        for conn, _, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == "/tf_static":
                continue
            stamps.setdefault(conn.topic, []).append(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)
    assert set(stamps) == {"/ouster/points", "/ouster/imu", "/platform/odom", "/ground_truth/odom"}
    t0 = min(stamps["/ouster/imu"])
    wheel_t = np.array(stamps["/platform/odom"]) - t0 + piece.start
    assert len(wheel_t) == pytest.approx(0.5 * 50 * 2, abs=2)  # only the 0.5 s either side
    assert not np.any((wheel_t >= t_out0 + 1e-6) & (wheel_t < t_out1 - 1e-6))
    assert len(stamps["/ouster/imu"]) == pytest.approx((t_out1 - t_out0 + 1.0) * 100, abs=2)


def test_sensor_mount_reaches_tf_static_and_the_imu(tmp_path):
    from rosbags.highlevel import AnyReader

    from lili_odom.extrinsics import HUSKY_BASE_TO_SENSOR, pose_from_xyz_rpy
    from lili_odom.messages import transforms_from_tf_msg

    (sc,) = load_scenarios(["office_tilted"], measure=False)
    x, y, z, roll, pitch, yaw = sc.sensor.mount
    assert (pitch, yaw) == (12.0, 90.0)
    req = scenario_request(sc, 5)
    assert req.base_to_sensor == pytest.approx((x, y, z, 0.0, np.radians(12.0), np.radians(90.0)))
    T_mount = pose_from_xyz_rpy(req.base_to_sensor)
    assert np.allclose(sensors_for(req).extrinsics.base_to_sensor, T_mount)
    # the Husky's mast without a mount, and its cache key as before a mount existed
    plain = dataclasses.replace(sc, sensor=dataclasses.replace(sc.sensor, mount=None))
    assert scenario_request(plain, 5).base_to_sensor is None
    assert np.allclose(sensors_for(scenario_request(plain, 5)).extrinsics.base_to_sensor,
                       pose_from_xyz_rpy(HUSKY_BASE_TO_SENSOR))
    assert cache_key(scenario_request(plain, 5)) != cache_key(req)
    assert "(own mount)" in sc.sensor.label and "(own mount)" not in plain.sensor.label

    piece = dataclasses.replace(sc, start=0.5, duration=1.0)  # inside the 2 s standstill
    bag = scenario_bag(piece, 5, resolution=(4, 32), cache_dir=tmp_path, progress=False, jobs=1)
    edges, acc = {}, []
    with AnyReader([bag]) as reader:
        for conn, _, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == "/tf_static":
                edges.update({(p, c): T for p, c, T in transforms_from_tf_msg(msg)})
            elif conn.topic == "/ouster/imu":
                a = msg.linear_acceleration
                acc.append((a.x, a.y, a.z))
    assert np.allclose(edges[("base_link", "os_sensor")], T_mount, atol=1e-9)
    # at rest on a level floor the IMU, turned with the sensor, feels gravity in its own frame
    g_imu = T_mount[:3, :3].T @ np.array([0.0, 0.0, 9.81])
    assert np.allclose(np.mean(acc, axis=0), g_imu, atol=0.3)


def test_sensor_mount_must_be_six_numbers():
    for bad in ([0.0, 0.0, 0.5], [0, 0, 0.5, 0, "12", 0], [0, 0, float("nan"), 0, 0, 0]):
        with pytest.raises(ValueError, match="mount"):
            SensorProfile.from_data({"model": "OS1-32", "mount": bad})


def test_docs_table_is_current(scenarios):
    doc = (ROOT / "docs" / "scenarios.md").read_text()
    assert scenario_table(scenarios) in doc, "regenerate: lili-odom simulate scenario --list --markdown"
