"""Message conversion with rosbags-typed and rclpy-typed messages (no DDS)."""
from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lili_odom import messages as M
from lili_odom.bagio.factory import RosbagsFactory
from lili_odom.degeneracy.result import DegeneracyResult
from lili_odom.pipeline.types import OdometryOutput

rclpy_factory = pytest.importorskip("lili_odom.ros.factory")

ROSBAGS = RosbagsFactory()
RCLPY = rclpy_factory.RclpyFactory()
FACTORIES = [pytest.param(ROSBAGS, id="rosbags"), pytest.param(RCLPY, id="rclpy")]


def _pose(rotvec=(0.1, -0.2, 0.3), t=(1.0, -2.0, 0.5)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = t
    return T


def _output(basis=((1.0, 0, 0, 0, 0, 0),), stamp=1700000000.123456789) -> OdometryOutput:
    det = DegeneracyResult("lili", np.eye(4), np.asarray(basis, float), characteristic_length=8.0)
    return OdometryOutput(stamp=stamp, pose=_pose(), twist=np.arange(6.0),
                          covariance=np.diag([1.0, 2, 3, 4, 5, 6]), degeneracy=det,
                          degenerate_basis=np.asarray(basis, float))


def _deser(msg):
    """Message of either library -> rosbags object via CDR (checks serialisation too)."""
    data = ROSBAGS.serialize(msg) if hasattr(msg, "__msgtype__") else RCLPY.serialize(msg)
    typename = getattr(msg, "__msgtype__", None) or _rclpy_typename(msg)
    return ROSBAGS.typestore.deserialize_cdr(data, typename)


def _rclpy_typename(msg) -> str:
    module = type(msg).__module__.split(".")  # e.g. nav_msgs.msg._odometry
    return f"{module[0]}/msg/{type(msg).__name__}"


def test_stamp_split_round_trip():
    for t in (0.0, 1.5, 1700000000.123456789, 12.999999999):
        sec, ns = M.split_stamp(t)
        assert 0 <= ns < 1_000_000_000
        assert abs(sec + ns * 1e-9 - t) < 1e-6


@pytest.mark.parametrize("f", FACTORIES)
def test_imu_from_msg(f):
    msg = f.new("sensor_msgs/msg/Imu", header=M.header_msg(f, 12.25, "os_imu"),
                angular_velocity=f.new("geometry_msgs/msg/Vector3", x=0.1, y=0.2, z=0.3),
                linear_acceleration=f.new("geometry_msgs/msg/Vector3", x=0.0, y=0.5, z=9.81))
    s = M.imu_from_msg(msg)
    assert s.stamp == pytest.approx(12.25)
    np.testing.assert_allclose(s.angular_velocity, [0.1, 0.2, 0.3])
    np.testing.assert_allclose(s.linear_acceleration, [0.0, 0.5, 9.81])


@pytest.mark.parametrize("f", FACTORIES)
def test_odometry_round_trip_through_wheel_reader(f):
    out = _output()
    msg = M.odometry_msg(f, out, "lili_odom", "base_link")
    assert msg.header.frame_id == "lili_odom" and msg.child_frame_id == "base_link"
    w = M.wheel_from_msg(msg)
    assert w.stamp == pytest.approx(out.stamp, abs=1e-6)
    np.testing.assert_allclose(w.pose, out.pose, atol=1e-12)
    np.testing.assert_allclose(w.twist, out.twist)
    assert w.twist_covariance is None  # all zero = unknown
    # pose covariance is rotated into the parent frame: blockdiag(R, R) C blockdiag(R, R)^T
    R = out.pose[:3, :3]
    cov = np.asarray(msg.pose.covariance).reshape(6, 6)
    np.testing.assert_allclose(cov[:3, :3], R @ np.diag([1.0, 2, 3]) @ R.T, atol=1e-12)
    np.testing.assert_allclose(cov[3:, 3:], R @ np.diag([4.0, 5, 6]) @ R.T, atol=1e-12)


@pytest.mark.parametrize("f", FACTORIES)
def test_truth_sample_skips_malformed_and_non_finite(f):
    out = _output()
    stamp, T = M.truth_sample(M.odometry_msg(f, out, "map", "base_link"))
    assert stamp == pytest.approx(out.stamp, abs=1e-6)
    np.testing.assert_allclose(T, out.pose, atol=1e-12)
    bad = M.odometry_msg(f, out, "map", "base_link")
    bad.pose.pose.position.x = float("nan")
    assert M.truth_sample(bad) is None
    assert M.truth_sample(object()) is None  # not an Odometry at all


@pytest.mark.parametrize("f", FACTORIES)
def test_wheel_twist_covariance_kept_in_v_w_order(f):
    cov = np.diag([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    msg = f.new(
        "nav_msgs/msg/Odometry", header=M.header_msg(f, 3.0, "odom"), child_frame_id="base_link",
        pose=f.new("geometry_msgs/msg/PoseWithCovariance", pose=M.pose_msg(f, _pose())),
        twist=f.new("geometry_msgs/msg/TwistWithCovariance",
                    twist=f.new("geometry_msgs/msg/Twist",
                                linear=f.new("geometry_msgs/msg/Vector3", x=1.0),
                                angular=f.new("geometry_msgs/msg/Vector3", z=0.5)),
                    covariance=cov.reshape(36)))
    w = M.wheel_from_msg(msg)
    np.testing.assert_allclose(w.twist, [1, 0, 0, 0, 0, 0.5])
    np.testing.assert_allclose(w.twist_covariance, cov)
    np.testing.assert_allclose(w.pose, _pose(), atol=1e-12)


@pytest.mark.parametrize("build", ["odometry", "path", "markers", "basis", "cloud"])
def test_rclpy_and_rosbags_serialise_identically(build):
    out = _output(basis=((1.0, 0, 0, 0, 0, 0), (0, 0, 0.5, 0, 0, 1.0 / 8.0)))
    pts = np.random.default_rng(0).normal(size=(50, 3))

    def make(f):
        return {
            "odometry": lambda: M.odometry_msg(f, out, "lili_odom"),
            "path": lambda: M.path_msg(f, [(1.0, _pose()), (2.0, np.eye(4))], "lili_odom"),
            "markers": lambda: M.degeneracy_markers(f, out, "lili_odom"),
            "basis": lambda: M.degeneracy_json_msg(f, out),
            "cloud": lambda: M.pointcloud_xyz_msg(f, pts, 5.0, "lili_odom"),
        }[build]()

    from_rosbags = make(ROSBAGS)
    typename = from_rosbags.__msgtype__
    rclpy_bytes = RCLPY.serialize(make(RCLPY))
    # Same length and same content; fastcdr leaves alignment padding uninitialised, so the
    # bytes are compared after a rosbags decode/encode round trip.
    assert len(rclpy_bytes) == len(ROSBAGS.serialize(from_rosbags))
    decoded = ROSBAGS.typestore.deserialize_cdr(rclpy_bytes, typename)
    assert ROSBAGS.serialize(decoded) == ROSBAGS.serialize(from_rosbags)


@pytest.mark.parametrize("f", FACTORIES)
def test_scan_from_cloud_message(f):
    pts = np.array([[1.0, 2.0, 3.0], [np.nan, 0.0, 0.0], [0.0, 0.0, 0.0], [4.0, 5.0, 6.0]])
    msg = M.pointcloud_xyz_msg(f, pts, 42.5, "os_lidar")
    scan = M.scan_from_msg(msg)
    assert scan.stamp == pytest.approx(42.5) and scan.frame_id == "os_lidar"
    np.testing.assert_allclose(scan.points, pts[[0, 3]], rtol=1e-6)
    assert scan.times is None and scan.dropped == 2


def test_scan_parser_is_injectable():
    msg = M.pointcloud_xyz_msg(ROSBAGS, np.ones((3, 3)), 1.0, "x")
    scan = M.scan_from_msg(msg, lambda m, t: (np.zeros((2, 3)), np.array([0.0, 0.1]), 1))
    assert scan.points.shape == (2, 3) and scan.dropped == 1
    np.testing.assert_allclose(scan.times, [0.0, 0.1])


def test_transforms_from_tf_msg_rosbags():
    T = _pose()
    msg = M.tf_message(ROSBAGS, [(1.0, "os_sensor", "os_lidar", T), (1.0, "a", "b", np.eye(4))])
    msg = _deser(msg)
    out = M.transforms_from_tf_msg(msg)
    assert [(p, c) for p, c, _ in out] == [("os_sensor", "os_lidar"), ("a", "b")]
    np.testing.assert_allclose(out[0][2], T, atol=1e-12)


def test_classify_twist_rotation_axis_point_and_translation():
    q = np.array([0.0, 2.0, 0.0])
    w = np.array([0.0, 0.0, 1.0])
    v = -np.cross(w, q)  # pure rotation about the z axis through q
    info = M.classify_twist(np.r_[v, w], length=5.0)
    assert info["kind"] == "rotation"
    np.testing.assert_allclose(info["axis_point"], q, atol=1e-12)
    np.testing.assert_allclose(info["axis"], w)
    assert info["pitch"] == pytest.approx(0.0)
    assert M.classify_twist([0.0, 1.0, 0, 0, 0, 0.001], 5.0)["kind"] == "translation"


@pytest.mark.parametrize("f", FACTORIES)
def test_degeneracy_markers(f):
    out = _output(basis=((1.0, 0, 0, 0, 0, 0), (0, 0, 0, 0, 0, 1.0 / 8.0)))
    arr = _deser(M.degeneracy_markers(f, out, "lili_odom"))
    types = [(m.action, m.type) for m in arr.markers]
    assert types[0][0] == 3  # DELETEALL first
    # one translation arrow, one rotation = sphere + arrow
    assert sorted(types[1:]) == [(0, 0), (0, 0), (0, 2)]
    assert all(m.header.frame_id == "lili_odom" for m in arr.markers)
    arrow = arr.markers[1]
    start = np.array([arrow.points[0].x, arrow.points[0].y, arrow.points[0].z])
    end = np.array([arrow.points[1].x, arrow.points[1].y, arrow.points[1].z])
    np.testing.assert_allclose(start, out.pose[:3, 3])
    np.testing.assert_allclose((end - start) / 2.0, out.pose[:3, 0], atol=1e-12)  # body x


@pytest.mark.parametrize("f", FACTORIES)
def test_degeneracy_json(f):
    out = _output()
    data = json.loads(_deser(M.degeneracy_json_msg(f, out)).data)
    assert data["dimension"] == 1 and data["method"] == "lili"
    assert data["basis"][0]["translation"] == [1.0, 0.0, 0.0]
    assert data["basis"][0]["rotation"] == [0.0, 0.0, 0.0]
    assert data["frame_id"] == "base_link"
    assert data["stamp"] == pytest.approx(out.stamp)
    assert np.asarray(data["pose"]).shape == (4, 4)
    assert data["weak_dimension"] == 0 and data["weak_basis"] == []


@pytest.mark.parametrize("f", FACTORIES)
def test_weakly_constrained_directions_in_the_json_and_faint_markers(f):
    out = _output()
    out.weak_basis = np.array([[0.0, 1.0, 0.0, 0.0, 0.0, 0.0]])
    data = json.loads(_deser(M.degeneracy_json_msg(f, out)).data)
    assert data["dimension"] == 1 and data["weak_dimension"] == 1
    assert data["weak_basis"][0]["translation"] == [0.0, 1.0, 0.0]
    arr = _deser(M.degeneracy_markers(f, out, "lili_odom"))
    arrows = [m for m in arr.markers[1:] if m.type == 0]
    alphas = sorted(m.color.a for m in arrows)
    assert len(arrows) == len(out.degenerate_basis) + 1
    assert alphas[0] == pytest.approx(alphas[-1] / 3.0)


@pytest.mark.parametrize("f", FACTORIES)
def test_path_and_map(f):
    path = _deser(M.path_msg(f, [(1.0, _pose()), (2.0, np.eye(4))], "lili_odom"))
    assert len(path.poses) == 2 and path.header.frame_id == "lili_odom"
    assert M.stamp_seconds(path.header) == pytest.approx(2.0)
    np.testing.assert_allclose(M.pose_to_matrix(path.poses[0].pose), _pose(), atol=1e-12)
    cloud = _deser(M.pointcloud_xyz_msg(f, np.zeros((0, 3)), 1.0, "lili_odom"))
    assert cloud.width == 0 and cloud.point_step == 12
