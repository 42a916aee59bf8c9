"""Solution remapping: the registration keeps the prediction along the degenerate subspace."""
from __future__ import annotations

import numpy as np
import pytest

from lili_odom import geometry as g
from lili_odom.degeneracy.reference import GuardedRegistration, ReferenceMap
from lili_odom.fusion.subspace import remap_pose
from lili_odom.pipeline.remap import constrained_registration, project_out

L = 5.0


def _scaled_rows(rows) -> np.ndarray:
    B = g.scale_twist(np.asarray(rows, dtype=float), L)
    return B / np.linalg.norm(B, axis=1, keepdims=True)


def test_project_out_leaves_nothing_along_the_subspace() -> None:
    rng = np.random.default_rng(0)
    B = np.linalg.qr(rng.normal(size=(6, 2)))[0].T  # two orthonormal scaled rows
    xi = rng.normal(size=6)
    kept = project_out(xi, B, L)
    assert np.allclose(B @ g.scale_twist(kept, L), 0.0, atol=1e-12)
    # what is removed lies inside the subspace
    removed = g.scale_twist(xi - kept, L)
    assert np.allclose(removed, B.T @ (B @ removed), atol=1e-12)


def test_remap_pose_takes_the_degenerate_components_of_the_reference() -> None:
    axis = _scaled_rows([[1, 0, 0, 0, 0, 0.02]])  # the axis of a gently curved tunnel
    T = g.exp(np.array([0.3, -0.1, 0.05, 0.01, -0.02, 0.03]))
    slide = g.unscale_twist(1.7 * axis[0], L)
    T_ref = T @ g.exp(slide) @ g.exp(np.array([0.0, 0.2, 0.0, 0.0, 0.0, -0.01]))
    out = remap_pose(T, T_ref, axis, L)
    # no difference left along the subspace ...
    s = g.scale_twist(g.log(np.linalg.inv(out) @ T_ref), L)
    assert abs(float(axis[0] @ s)) < 1e-6
    # ... and T only moved along it
    moved = g.scale_twist(g.log(np.linalg.inv(T) @ out), L)
    assert np.allclose(moved, axis[0] * (axis[0] @ moved), atol=1e-6)
    assert remap_pose(T, T_ref, np.zeros((0, 6)), L) == pytest.approx(T)


def _corridor(rng: np.random.Generator) -> np.ndarray:
    """Points on the floor, walls and ceiling of a 4 x 3 m corridor along x, 60 m long, with
    a 0.4 m pillar at x = 4 against the left wall (something for ICP to slide towards)."""
    n = 30000
    x = rng.uniform(-30.0, 30.0, n)
    side = rng.integers(0, 4, n)
    u = rng.uniform(0.0, 1.0, n)
    y = np.where(side == 0, -2.0, np.where(side == 1, 2.0, -2.0 + 4.0 * u))
    z = np.where(side == 2, 0.0, np.where(side == 3, 3.0, 3.0 * u))
    m = 1500
    face = rng.integers(0, 2, m)
    v = rng.uniform(0.0, 0.4, m)
    pillar = np.c_[np.where(face == 0, 4.0, 3.6 + v), np.where(face == 0, 1.6 + v, 1.6),
                   rng.uniform(0.0, 3.0, m)]
    return np.r_[np.c_[x, y, z], pillar]


def test_constrained_registration_keeps_the_prediction_along_the_axis() -> None:
    rng = np.random.default_rng(1)
    world = _corridor(rng)
    reference = ReferenceMap.from_points(world, 0.5, 50)
    T_true = g.exp(np.array([2.0, 0.3, 1.2, 0.0, 0.0, 0.05]))
    scan = g.transform_points(np.linalg.inv(T_true), _corridor(rng))
    scan = scan[np.linalg.norm(scan, axis=1) < 15.0]
    icp = GuardedRegistration(max_iterations=1, convergence=1e-6)

    def step(pose):
        res = icp.align(scan, reference, pose, 1.0, 0.3)
        return res.pose if res.ok else None

    # the unconstrained optimum slid 0.4 m along the axis and picked up the slide's leak
    # into the other directions (here: 3 cm sideways, 0.5 deg of yaw)
    registered = T_true @ g.exp(np.array([0.4, 0.03, 0.0, 0.0, 0.0, 0.009]))
    prediction = T_true @ g.exp(np.array([-0.25, 0.2, -0.1, 0.0, 0.0, -0.02]))
    axis = _scaled_rows([[1, 0, 0, 0, 0, 0]])
    out = constrained_registration(step, registered, prediction, axis, L, max_iterations=30,
                                   tolerance=1e-5)
    assert out.ok and out.converged
    err = g.log(np.linalg.inv(T_true) @ out.pose)
    # along the axis: the prediction's position; everything else: the truth
    assert err[0] == pytest.approx(-0.25, abs=0.01)
    # (to the centimetres point-to-point ICP resolves on this sampling)
    assert np.abs(err[1:3]).max() < 0.03 and np.abs(err[3:]).max() < 0.003, err
    # the registration itself would have slid back to the truth along the axis (the pillar)
    free = g.log(np.linalg.inv(T_true) @ GuardedRegistration(100, 1e-6).align(
        scan, reference, prediction, 1.0, 0.3).pose)
    assert abs(free[0]) < 0.05, free
    # nothing degenerate: the registration is returned unchanged, no ICP run
    none = constrained_registration(lambda pose: None, registered, prediction,
                                    np.zeros((0, 6)), L)
    assert none.ok and none.iterations == 0 and np.allclose(none.pose, registered)
    # a failing ICP step is reported, with the last good pose
    failed = constrained_registration(lambda pose: None, registered, prediction, axis, L)
    assert not failed.ok and np.all(np.isfinite(failed.pose))


def test_the_pipeline_remaps_to_the_wheels_only_and_keeps_the_registration_without_them():
    """Held at the IMU's prediction, the measurement would only confirm the fused velocity
    that made the prediction: without wheel data the registration itself is the measurement."""
    from lili_odom.degeneracy.result import DegeneracyResult
    from lili_odom.pipeline.odometry import OdometryPipeline, PipelineConfig

    rng = np.random.default_rng(2)
    cfg = PipelineConfig()
    cfg.detection_schedule.background = False
    p = OdometryPipeline(cfg)
    p._matcher.insert(_corridor(rng), np.eye(4))
    p.estimator.initialize(10.0, pose=np.linalg.inv(p.T_base_lidar))  # LiDAR at the origin
    source = _corridor(rng)
    source = source[np.linalg.norm(source, axis=1) < 15.0]
    registered = g.exp(np.array([0.4, 0.0, 0.0, 0.0, 0.0, 0.0]))  # slid 0.4 m along x
    axis = DegeneracyResult("lili", registered, _scaled_rows([[1, 0, 0, 0, 0, 0]]), L)
    out = p._remap(source, registered, p.estimator.wheel_prediction(10.1), axis)
    assert out is registered and p.counters["remap_without_wheels"] == 1
    for t in (9.9, 10.0, 10.1):  # the wheels report standing still
        p.estimator.add_wheel(t, np.eye(4))
    out = p._remap(source, registered, p.estimator.wheel_prediction(10.1), axis)
    assert abs(g.log(out)[0]) < 0.02  # held at the wheels' prediction: the origin
    assert p.counters["remap_without_wheels"] == 1
