"""The travel-bias study measures each pose's step along the true direction of travel."""
import numpy as np

from benchmarks.studies.travel_bias import distance_gap, step_errors, summary


def _pose(x: float, y: float = 0.0, yaw: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    c, s = np.cos(yaw), np.sin(yaw)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = [x, y]
    return T


def _scan(stamp, fused_x, measured_x, info, T_bl, yaw=0.0):
    to_lidar = T_bl  # the log's prediction and registration are LiDAR poses
    return {"stamp": stamp, "fused": _pose(fused_x, yaw=yaw),
            "prediction": _pose(fused_x, yaw=yaw) @ to_lidar,
            "registration": _pose(measured_x - 0.05, yaw=yaw) @ to_lidar,
            "measurement": _pose(measured_x, yaw=yaw),
            "information": None if info is None else np.diag([info, 0, 0, 0, 0, 0.0]),
            "T_base_lidar": T_bl}


def test_steps_along_the_true_travel_in_the_previous_fused_frame():
    T_bl = np.eye(4)
    T_bl[:3, 3] = [0.3, 0.0, 0.8]  # the LiDAR ahead of and above base_link
    truth_t = np.array([0.0, 0.1, 0.2, 0.3])
    truth = np.array([_pose(0.0), _pose(0.2), _pose(0.4), _pose(0.4)])  # then standing
    log = [_scan(0.0, 0.0, 0.0, None, T_bl),
           _scan(0.1, 0.15, 0.18, 100.0, T_bl),   # fused 5 cm short, measured 2 cm short
           _scan(0.2, 0.30, 0.40, 300.0, T_bl),   # steps of 0.15 and 0.25 from 0.15
           _scan(0.3, 0.30, 0.30, 100.0, T_bl)]   # standing: not compared
    e = step_errors(log, truth_t, truth)
    assert np.allclose(e["fused"], [-0.05, -0.05])
    assert np.allclose(e["measurement"], [-0.02, +0.05])
    assert np.allclose(e["registration"], [-0.07, 0.0])
    assert np.allclose(e["prediction"], [-0.05, -0.05])
    assert np.allclose(e["information"], [100.0, 300.0])
    s = summary(e)
    assert s["scans"] == 2
    assert np.isclose(s["measurement"]["mean_cm"], 1.5)
    assert np.isclose(s["measurement"]["weighted_mean_cm"], (-2.0 * 100 + 5.0 * 300) / 400)


def test_a_turned_robot_projects_on_its_own_travel():
    T_bl = np.eye(4)
    yaw = np.pi / 2  # heading +y in the odometry frame
    truth_t = np.array([0.0, 0.1])
    truth = np.array([_pose(0.0, 0.0, yaw), _pose(0.0, 0.2, yaw)])
    fused = [_pose(0.0, 0.0, yaw), _pose(0.0, 0.17, yaw)]
    log = [{"stamp": 0.0, "fused": fused[0], "T_base_lidar": T_bl},
           {"stamp": 0.1, "fused": fused[1], "prediction": fused[1], "registration": fused[1],
            "measurement": fused[1], "information": np.eye(6), "T_base_lidar": T_bl}]
    e = step_errors(log, truth_t, truth)
    assert np.allclose(e["fused"], [-0.03])


def test_distance_gap_counts_the_extra_distance_travelled():
    stamps = np.array([0.0, 1.0, 2.0])
    est = [_pose(0.0), _pose(1.1), _pose(2.2)]
    truth_t = np.array([0.0, 1.0, 2.0])
    truth = np.array([_pose(0.0), _pose(1.0), _pose(2.0)])
    t, gap = distance_gap(stamps, est, truth_t, truth)
    assert np.allclose(t, [0.0, 1.0, 2.0])
    assert np.allclose(gap, [0.0, 0.1, 0.2])
