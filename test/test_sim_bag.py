"""Simulated rosbag2 MCAP bags: contents, layout, readers, CLI, cache, determinism."""
import hashlib
import json

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from lili_odom.cli import main as cli_main
from lili_odom.sim.generator import EPOCH_NS, SimRequest, ensure_trial_bag, simulate_bag

TS = get_typestore(Stores.ROS2_JAZZY)
TOPICS = {
    "/ouster/points": "sensor_msgs/msg/PointCloud2",
    "/ouster/imu": "sensor_msgs/msg/Imu",
    "/platform/odom": "nav_msgs/msg/Odometry",
    "/ground_truth/odom": "nav_msgs/msg/Odometry",
    "/tf_static": "tf2_msgs/msg/TFMessage",
}
_NP = {1: np.int8, 2: np.uint8, 3: np.int16, 4: np.uint16, 5: np.int32, 6: np.uint32, 7: np.float32, 8: np.float64}


def decode_cloud(msg) -> np.ndarray:
    """Organised (height, width) structured array from a PointCloud2, by its PointField layout."""
    dtype = np.dtype({
        "names": [f.name for f in msg.fields],
        "formats": [_NP[f.datatype] for f in msg.fields],
        "offsets": [f.offset for f in msg.fields],
        "itemsize": msg.point_step,
    })
    return np.frombuffer(bytes(msg.data), dtype=dtype).reshape(msg.height, msg.width)


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "piece"
    # 1.5 s crossing nothing special: outside the portal, reduced resolution
    summary = simulate_bag(SimRequest(trial=3, resolution=(16, 128), start=2.0, duration=1.5), out, progress=False)
    return out, summary


def _stamp(msg):
    h = msg.header if hasattr(msg, "header") else msg.transforms[0].header
    return h.stamp.sec * 1_000_000_000 + h.stamp.nanosec


def test_bag_topics_counts_and_order_with_rosbags(bag):
    path, summary = bag
    with Reader(path) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        assert types == TOPICS
        stamps, counts = [], {t: 0 for t in TOPICS}
        for conn, logtime, raw in reader.messages():
            msg = TS.deserialize_cdr(raw, conn.msgtype)
            st = _stamp(msg)
            stamps.append((conn.topic, st))
            counts[conn.topic] += 1
            if conn.topic == "/ouster/points":
                assert logtime == st + 100_000_000  # published one sweep after its stamp
            else:
                assert logtime == st
    for topic in TOPICS:
        mine = [st for tp, st in stamps if tp == topic]
        assert mine == sorted(mine)
    assert counts["/tf_static"] == 1
    assert counts["/ouster/points"] == 15  # scans starting at 2.0 .. 3.4 s end by 3.5 s
    assert counts["/ouster/imu"] == 151 and counts["/platform/odom"] == 76 and counts["/ground_truth/odom"] == 151
    assert counts == summary.counts
    assert min(st for _, st in stamps) == EPOCH_NS + 2_000_000_000
    meta = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["storage_identifier"] == "mcap"
    tf_qos = [t["topic_metadata"]["offered_qos_profiles"] for t in meta["topics_with_message_count"]
              if t["topic_metadata"]["name"] == "/tf_static"][0]
    assert tf_qos[0]["durability"] == "transient_local"


def test_cloud_layout_nan_and_t_with_the_mcap_reader(bag):
    path, _ = bag
    clouds, imus, odoms, tfs, stamps = [], [], [], [], []
    with open(next(path.glob("*.mcap")), "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            msg = TS.deserialize_cdr(message.data, schema.name)
            stamps.append(_stamp(msg))
            {"/ouster/points": clouds, "/ouster/imu": imus, "/platform/odom": odoms,
             "/tf_static": tfs}.get(channel.topic, []).append(msg)
    assert stamps == sorted(stamps), "messages are written in header-stamp order"
    c = clouds[0]
    assert c.header.frame_id == "os_lidar"
    assert (c.height, c.width, c.point_step, c.row_step, c.is_dense) == (16, 128, 48, 48 * 128, False)
    layout = {f.name: (f.offset, f.datatype, f.count) for f in c.fields}
    assert layout == {"x": (0, 7, 1), "y": (4, 7, 1), "z": (8, 7, 1), "intensity": (16, 7, 1), "t": (20, 6, 1),
                      "reflectivity": (24, 4, 1), "ring": (26, 4, 1), "ambient": (28, 4, 1), "range": (32, 6, 1)}
    a = decode_cloud(c)
    none = a["range"] == 0
    assert none.any() and (~none).any(), "outside the portal some beams see the sky"
    assert np.all(np.isnan(a["x"][none])) and np.all(np.isnan(a["z"][none]))
    assert np.all(np.isfinite(a["x"][~none]))
    r = np.sqrt(a["x"] ** 2 + a["y"] ** 2 + a["z"] ** 2)
    assert np.allclose(r[~none], a["range"][~none] / 1000.0, atol=1e-4)
    assert np.array_equal(a["t"], np.broadcast_to(np.round(np.arange(128) * 1e8 / 128).astype(np.uint32), (16, 128)))
    assert np.array_equal(a["ring"][:, 0], np.arange(16))
    # ring 0 is the top beam: +22.5 deg
    el = np.degrees(np.arcsin(a["z"] / np.where(r > 0, r, np.nan)))
    assert np.nanmedian(el[0]) == pytest.approx(22.5, abs=0.01) and np.nanmedian(el[-1]) == pytest.approx(-22.5, abs=0.01)
    imu = imus[0]
    assert imu.header.frame_id == "os_imu" and imu.orientation_covariance[0] == -1.0
    assert imu.angular_velocity_covariance[0] > 0 and imu.linear_acceleration_covariance[8] > 0
    assert 9.0 < np.linalg.norm([imu.linear_acceleration.x, imu.linear_acceleration.y, imu.linear_acceleration.z]) < 10.6
    assert odoms[0].header.frame_id == "odom" and odoms[0].child_frame_id == "base_link"
    frames = {(t.header.frame_id, t.child_frame_id): t.transform for t in tfs[0].transforms}
    assert set(frames) == {("base_link", "os_sensor"), ("os_sensor", "os_lidar"), ("os_sensor", "os_imu")}
    lid = frames[("os_sensor", "os_lidar")]
    assert lid.translation.z == pytest.approx(0.03618) and abs(lid.rotation.z) == pytest.approx(1.0)
    imu_tf = frames[("os_sensor", "os_imu")].translation
    assert (imu_tf.x, imu_tf.y, imu_tf.z) == pytest.approx((0.006253, -0.011775, 0.007645))


def test_truth_odometry_is_the_trajectory(bag):
    path, _ = bag
    with Reader(path) as reader:
        conn = [c for c in reader.connections if c.topic == "/ground_truth/odom"]
        msgs = [TS.deserialize_cdr(raw, c.msgtype) for c, _, raw in reader.messages(connections=conn)]
    assert msgs[0].header.frame_id == "world" and msgs[0].child_frame_id == "base_link"
    x = np.array([m.pose.pose.position.x for m in msgs])
    v = np.array([m.twist.twist.linear.x for m in msgs])
    assert np.all(x < 0.0)  # trial 3 starts outside the portal
    dx = np.diff(x) / 0.01
    assert np.allclose(0.5 * (v[1:] + v[:-1]), dx, atol=0.02)


def _digest(path):
    h = hashlib.sha256()
    with Reader(path) as reader:
        for conn, t, raw in reader.messages():
            h.update(conn.topic.encode() + t.to_bytes(8, "little") + bytes(raw))
    return h.hexdigest()


def test_determinism_for_a_seed(tmp_path):
    req = SimRequest(trial=3, resolution=(8, 64), start=10.0, duration=0.35, seed=7)
    a = simulate_bag(req, tmp_path / "a", progress=False)
    b = simulate_bag(req, tmp_path / "b", progress=False)
    req.seed = 8
    c = simulate_bag(req, tmp_path / "c", progress=False)
    assert a.counts["/ouster/points"] == 3
    assert _digest(a.path) == _digest(b.path) != _digest(c.path)


def test_cli_and_cache(tmp_path, capsys):
    rc = cli_main(["simulate", "tunnel", "--trial", "3", "--resolution", "8x64", "--duration", "0.3",
                   "--out", str(tmp_path / "cli"), "--no-progress", "--jobs", "1"])
    assert rc == 0 and (tmp_path / "cli" / "metadata.yaml").exists()
    assert cli_main(["simulate", "tunnel", "--trial", "3", "--out", str(tmp_path / "cli"), "--no-progress"]) == 2
    assert cli_main(["simulate", "tunnel", "--trial", "9", "--out", str(tmp_path / "x"), "--no-progress"]) == 2
    kw = dict(resolution="8x64", duration=0.3, progress=False, jobs=1)
    p1 = ensure_trial_bag(3, tmp_path / "cache", **kw)
    mtime = (p1 / "metadata.yaml").stat().st_mtime_ns
    p2 = ensure_trial_bag(3, tmp_path / "cache", **kw)
    assert p1 == p2 and (p2 / "metadata.yaml").stat().st_mtime_ns == mtime
    assert ensure_trial_bag(3, tmp_path / "cache", seed=1, **kw) != p1
    side = json.loads((tmp_path / "cache" / f"{p1.name}.json").read_text())
    assert side["request"]["trial"] == 3 and side["counts"]["/ouster/points"] == 3
    with Reader(p1) as reader:
        assert reader.message_count > 0
    assert len(list(p1.glob("*.mcap"))) == 1 and (p1 / f"{p1.name}.mcap").exists()


def _messages(path, t0_ns, t1_ns):
    out = {}
    with Reader(path) as reader:
        for conn, _, raw in reader.messages():
            if conn.topic == "/tf_static":
                continue
            st = _stamp(TS.deserialize_cdr(raw, conn.msgtype))
            if t0_ns <= st <= t1_ns:
                out[(conn.topic, st)] = bytes(raw)
    return out


def test_a_piece_equals_the_same_window_of_a_longer_run(tmp_path):
    long = simulate_bag(SimRequest(trial=3, resolution=(8, 64), start=0.0, duration=1.6), tmp_path / "long", progress=False)
    piece = simulate_bag(SimRequest(trial=3, resolution=(8, 64), start=1.2, duration=0.3), tmp_path / "piece", progress=False)
    lo, hi = EPOCH_NS + 1_200_000_000, EPOCH_NS + 1_500_000_000
    a, b = _messages(long.path, lo, hi), _messages(piece.path, lo, hi)
    a = {k: v for k, v in a.items() if not (k[0] == "/ouster/points" and k[1] + 100_000_000 > hi)}
    assert len(b) == 3 + 31 + 16 + 31 and a == b


def test_committed_ci_bag_is_complete_and_reproducible(tmp_path):
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "bags" / "tunnel_entrance_32x256"
    with Reader(path) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        types = {c.topic: c.msgtype for c in reader.connections}
    assert types == TOPICS
    assert counts["/ouster/points"] == 150 and counts["/tf_static"] == 1
    assert counts["/ground_truth/odom"] >= 1500 and counts["/ouster/imu"] >= 1500 and counts["/platform/odom"] >= 750
    # the bag is what its README command makes: regenerate the first 0.4 s and compare
    req = SimRequest(trial=3, resolution=(32, 256), duration=0.4, seed=0)
    fresh = simulate_bag(req, tmp_path / "fresh", progress=False)
    lo, hi = EPOCH_NS, EPOCH_NS + 300_000_000
    committed, regenerated = _messages(path, lo, hi), _messages(fresh.path, lo, hi)
    assert len(committed) == 4 + 31 + 16 + 31 and committed.keys() == regenerated.keys()
    hint = "simulator changed: regenerate bags/ with the command in bags/README.md"
    for key, raw in committed.items():
        if key[0] != "/ouster/points":  # IMU, wheels, truth: plain arithmetic, bit-exact
            assert raw == regenerated[key], (key, hint)
            continue
        # Clouds: Embree's ray hits differ in the last float bits between CPUs (SIMD width),
        # which can flip a range across a millimetre; anything else is a simulator change.
        a = decode_cloud(TS.deserialize_cdr(raw, TOPICS[key[0]]))
        b = decode_cloud(TS.deserialize_cdr(regenerated[key], TOPICS[key[0]]))
        xyz_a = np.stack([a[c] for c in "xyz"], -1)
        xyz_b = np.stack([b[c] for c in "xyz"], -1)
        assert np.array_equal(np.isnan(xyz_a), np.isnan(xyz_b)), (key, hint)
        assert np.allclose(xyz_a, xyz_b, atol=2e-3, equal_nan=True), (key, hint)
        assert np.array_equal(a["t"], b["t"]) and np.array_equal(a["ring"], b["ring"]), (key, hint)
        assert np.abs(a["range"].astype(np.int64) - b["range"]).max() <= 2, (key, hint)
        assert np.mean(a["intensity"] != b["intensity"]) < 0.01, (key, hint)
