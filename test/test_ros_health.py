"""The node's health statuses, the DDS defaults and the saved map, without ROS."""
from __future__ import annotations

import numpy as np
import pytest

from lili_odom.io.cloud_files import load_points
from lili_odom.io.map_file import MapAccumulator, save_points
from lili_odom.pipeline.types import OdometryOutput
from lili_odom.ros import dds
from lili_odom.ros.health import (ERROR, OK, WARN, HealthConfig, HealthMonitor, StampGapCounter,
                                  describe_direction)


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_stamp_gaps_count_missing_scans_not_pauses_or_restarts():
    g = StampGapCounter(0.1, max_gap_s=2.0)
    missing = [g.update(t) for t in (10.0, 10.1, 10.2, 10.5, 10.6, 10.7 + 0.04)]
    assert missing == [0, 0, 0, 2, 0, 0]  # 10.2 -> 10.5: two scans lost; jitter is not a loss
    assert g.update(15.0) == 0 and g.gaps == 1  # a pause
    assert g.update(3.0) == 0 and g.gaps == 2  # a restarted bag
    assert g.update(3.1) == 0 and g.missing == 2


def _output(basis=np.zeros((0, 6)), scale=1.0):
    return OdometryOutput(stamp=1.0, pose=np.eye(4), twist=np.zeros(6),
                          covariance=np.eye(6), degenerate_basis=np.asarray(basis),
                          details={"wheel_scale": scale, "used_imu": True, "used_wheel": True})


def _feed(monitor, clock, seconds, lidar_hz=10.0, imu_hz=100.0, wheel_hz=50.0, stamp0=100.0,
          skip_every=0, proc_s=0.02, output=None):
    """Advance the fake clock, feeding inputs at the given rates; every ``skip_every``-th scan
    is lost before the node (its stamp skipped)."""
    steps = int(round(seconds * 100))
    k = 0
    for i in range(steps):
        clock.t += 0.01
        if imu_hz and i % max(1, int(round(100 / imu_hz))) == 0:
            monitor.on_imu()
        if wheel_hz and i % max(1, int(round(100 / wheel_hz))) == 0:
            monitor.on_wheel()
        if lidar_hz and i % int(round(100 / lidar_hz)) == 0:
            k += 1
            if skip_every and k % skip_every == 0:
                continue
            monitor.on_scan(stamp0 + k / lidar_hz)
            monitor.on_processed(proc_s, output or _output())


def by_name(statuses):
    out = {s.name.removeprefix("lili_odom: "): s for s in statuses}
    assert all(s.name.startswith("lili_odom: ") for s in statuses)
    assert all(s.level in (OK, WARN, ERROR) and s.message and "\n" not in s.message
               for s in statuses)
    return out


def test_healthy_inputs_are_ok():
    clock = FakeClock()
    m = HealthMonitor(HealthConfig(), clock)
    _feed(m, clock, 8.0)
    s = by_name(m.statuses({"scans_dropped": 0}))
    assert set(s) == {"lidar input", "imu input", "wheel input", "scans dropped and missing",
                      "processing time", "degeneracy", "wheel scale", "fusion"}
    assert all(st.level == OK for st in s.values()), {k: v.message for k, v in s.items()}
    assert abs(float(s["lidar input"].values["rate_hz"]) - 10.0) < 0.5
    assert abs(float(s["imu input"].values["rate_hz"]) - 100.0) < 5.0


def test_missing_scans_and_silent_inputs_are_reported():
    clock = FakeClock()
    m = HealthMonitor(HealthConfig(), clock)
    _feed(m, clock, 8.0, wheel_hz=0.0, skip_every=3)  # a third of the scans lost upstream
    s = by_name(m.statuses({"scans_dropped": 0}))
    loss = s["scans dropped and missing"]
    assert loss.level == ERROR and "missing" in loss.message
    assert int(loss.values["scans_missing"]) >= 20
    assert s["wheel input"].level == WARN and "no wheel" in s["wheel input"].message
    assert s["lidar input"].level == WARN  # 6.7 Hz of 10 expected
    clock.t += 3.0  # the LiDAR falls silent
    assert by_name(m.statuses())["lidar input"].level == ERROR


def test_degeneracy_processing_wheel_scale_and_fusion_levels():
    clock = FakeClock()
    m = HealthMonitor(HealthConfig(), clock)
    out = _output(basis=[[1.0, 0, 0, 0, 0, 0]], scale=1.2)
    _feed(m, clock, 6.0, proc_s=0.09, output=out)
    m.on_pipeline_counters({"icp_failures": 0})
    m.on_pipeline_counters({"icp_failures": 2})
    s = by_name(m.statuses({"scan_errors": 0}))
    assert s["degeneracy"].level == WARN and s["degeneracy"].values["dimension"] == "1"
    assert "translation (+1.00, +0.00, +0.00)" in s["degeneracy"].message
    assert s["processing time"].level == WARN  # 90 ms of a 100 ms period
    assert s["wheel scale"].level == WARN and s["wheel scale"].values["scale"] == "1.2000"
    assert s["fusion"].level == WARN and "2 registration/fusion failures" in s["fusion"].message
    clock.t += 10.0  # the failures leave the window
    assert by_name(m.statuses())["fusion"].level == OK


def test_no_output_at_all_is_an_error():
    m = HealthMonitor(HealthConfig(), FakeClock())
    m.on_scan(1.0)
    m.on_processed(0.01, None)
    assert by_name(m.statuses())["fusion"].level == ERROR


def test_describe_direction_names_the_dominant_part():
    assert describe_direction([0, 0, 0, 0, 0, 2.0]) == "rotation about (+0.00, +0.00, +1.00)"
    assert describe_direction([0, -3.0, 0, 0.1, 0, 0]).startswith("translation (+0.00, -1.00")


def test_dds_defaults_respect_user_choices(tmp_path):
    path = dds.profile_path()
    assert path is not None and path.name == "fastdds.xml"
    import xml.etree.ElementTree as ET

    root = ET.parse(path).getroot()
    seg = [e.text for e in root.iter() if e.tag.endswith("segment_size")]
    assert seg and int(seg[0]) >= 8 * 6291456 // 2  # several full OS1-128 clouds
    env: dict[str, str] = {}
    assert dds.apply_dds_defaults(env) == str(path) == env["FASTRTPS_DEFAULT_PROFILES_FILE"]
    for chosen in ({"FASTRTPS_DEFAULT_PROFILES_FILE": "mine.xml"},
                   {"FASTDDS_DEFAULT_PROFILES_FILE": "mine.xml"},
                   {"FASTDDS_BUILTIN_TRANSPORTS": "LARGE_DATA"},
                   {"RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"},
                   {"LILI_ODOM_DDS_PROFILE": "0"}):
        env = dict(chosen)
        assert dds.apply_dds_defaults(env) is None and env == chosen


def test_map_accumulator_keeps_one_point_per_voxel_and_stays_bounded():
    rng = np.random.default_rng(1)
    m = MapAccumulator(voxel_size=0.5, max_points=10**6)
    a = rng.uniform(-10, 10, (20000, 3))
    m.add(a)
    n = len(m)
    m.add(a + 1e-3)  # the same voxels (almost all): nothing new
    assert len(m) <= n * 1.01
    m.add(a + 100.0)  # a new place: the map grows
    assert len(m) >= 1.9 * n
    keys = np.floor(m.points() / 0.5).astype(int)
    assert len(np.unique(keys, axis=0)) == len(m)
    small = MapAccumulator(voxel_size=0.1, max_points=5000)
    small.add(a)
    assert len(small) <= 5000 and small.coarsened >= 1 and small.voxel_size > 0.1
    small.add([[np.nan, 0, 0]])  # non-finite rows are ignored
    assert np.isfinite(small.points()).all()


@pytest.mark.parametrize("suffix", [".pcd", ".ply"])
def test_saved_map_reads_back(tmp_path, suffix):
    pts = np.random.default_rng(2).uniform(-50, 50, (1000, 3))
    written = save_points(tmp_path / "sub" / f"map{suffix}", pts)
    assert written.is_absolute() and written.is_file()
    np.testing.assert_allclose(load_points(written), pts.astype(np.float32), atol=1e-5)
    with pytest.raises(ValueError, match="pcd or .ply"):
        save_points(tmp_path / "map.txt", pts)


def test_processing_status_reports_the_mean_time_of_each_pipeline_stage():
    clock = FakeClock()
    m = HealthMonitor(HealthConfig(), clock)
    assert m.stage_means() == {}
    slow = _output()
    slow.timings = {"deskew": 0.010, "icp": 0.004, "detector": 0.030, "total": 0.050}
    fast = _output()
    fast.timings = {"deskew": 0.010, "icp": 0.002, "detector": 0.010, "total": 0.030}
    for i in range(60):  # only the last 50 count: 10 slow ones fall out
        m.on_processed(0.05, slow if i < 35 else fast)
    means = m.stage_means()
    assert means["detector"] == pytest.approx((25 * 0.030 + 25 * 0.010) / 50)
    assert means["icp"] == pytest.approx(0.003)
    st = by_name(m.statuses())["processing time"]
    assert st.values["stage_detector_ms"] == "20.0" and st.values["stage_total_ms"] == "40.0"
    assert "(most in detector 20 ms, deskew 10 ms)" in st.message


def test_weakly_constrained_directions_are_ok_and_named():
    clock = FakeClock()
    m = HealthMonitor(HealthConfig(), clock)
    out = _output()
    out.weak_basis = np.array([[1.0, 0, 0, 0, 0, 0]])
    _feed(m, clock, 2.0, output=out)
    s = by_name(m.statuses({"scan_errors": 0}))["degeneracy"]
    assert s.level == OK and "1 weakly constrained" in s.message
    assert s.values["dimension"] == "0" and s.values["weakly_constrained"] == "1"
    assert s.values["weak_direction_0"].startswith("translation (+1.00")
