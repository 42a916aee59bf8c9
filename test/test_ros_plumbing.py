"""Node plumbing without DDS: static transform chains and the scan hand-over policy."""
from __future__ import annotations

import threading

import numpy as np

from lili_odom.ros.queues import LatestSlot, SampleBuffer
from lili_odom.ros.static_tf import lookup


def _T(t=(0.0, 0.0, 0.0), yaw=0.0) -> np.ndarray:
    T = np.eye(4)
    c, s_ = np.cos(yaw), np.sin(yaw)
    T[:3, :3] = [[c, -s_, 0], [s_, c, 0], [0, 0, 1]]
    T[:3, 3] = t
    return T


def test_static_tf_lookup_composes_chain_both_directions():
    tfs = {("base_link", "os_sensor"): _T((0.1, 0, 0.65)),
           ("os_sensor", "os_lidar"): _T((0, 0, 0.036), np.pi),
           ("os_sensor", "os_imu"): _T((0.006, -0.012, 0.008))}
    T = lookup(tfs, "base_link", "os_lidar")
    np.testing.assert_allclose(T, tfs[("base_link", "os_sensor")] @ tfs[("os_sensor", "os_lidar")])
    back = lookup(tfs, "os_lidar", "os_imu")
    np.testing.assert_allclose(T @ back, lookup(tfs, "base_link", "os_imu"), atol=1e-12)
    assert lookup(tfs, "base_link", "camera") is None
    np.testing.assert_allclose(lookup({}, "a", "a"), np.eye(4))


def test_latest_slot_keeps_newest_and_counts_drops():
    slot = LatestSlot()
    assert slot.put(1) is False
    assert slot.put(2) is True and slot.put(3) is True
    assert slot.take(0.0) == 3 and slot.dropped == 2
    assert slot.take(0.01) is None


def test_latest_slot_slow_consumer_processes_newest():
    slot = LatestSlot()
    done = []

    def consumer():
        while not slot.closed:
            item = slot.take(0.5)
            if item is not None:
                done.append(item)
                threading.Event().wait(0.02)

    th = threading.Thread(target=consumer)
    th.start()
    for i in range(50):
        slot.put(i)
        threading.Event().wait(0.001)
    threading.Event().wait(0.1)
    slot.close()
    th.join(2.0)
    assert done[-1] == 49
    assert len(done) + slot.dropped == 50 and slot.dropped > 0


def test_sample_buffer_bounded():
    buf = SampleBuffer(maxlen=3)
    for i in range(5):
        buf.append(i)
    assert buf.drain() == [2, 3, 4] and buf.overflow == 2 and len(buf) == 0
