"""Node plumbing without DDS: the scan hand-over policy and its buffers."""
from __future__ import annotations

import threading
import time

import numpy as np

from lili_odom.ros.queues import SampleBuffer, ScanQueue


def test_scan_queue_of_one_keeps_newest_and_counts_drops():
    slot = ScanQueue(1)
    assert slot.put(1) is False
    assert slot.put(2) is True and slot.put(3) is True
    assert slot.take(0.0) == 3 and slot.dropped == 2
    assert slot.take(0.01) is None


def test_scan_queue_absorbs_a_burst_then_drops_the_oldest_in_order():
    q = ScanQueue(3)
    assert [q.put(i) for i in range(3)] == [False, False, False] and len(q) == 3
    assert q.put(3) is True and q.dropped == 1  # 0 pushed out
    assert [q.take(0.0) for _ in range(4)] == [1, 2, 3, None]


def test_scan_queue_rejects_a_size_below_one():
    import pytest

    with pytest.raises(ValueError, match="maxlen"):
        ScanQueue(0)


def test_scan_queue_slow_consumer_processes_newest():
    slot = ScanQueue(1)
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


def test_scan_queue_wake_ends_a_wait_without_an_item():
    q = ScanQueue(2)
    q.wake()  # before the wait: the next take returns at once
    t0 = time.monotonic()
    assert q.take(5.0) is None and time.monotonic() - t0 < 2.0
    got = []
    waiter = threading.Thread(target=lambda: got.append(q.take(5.0)))
    waiter.start()
    threading.Event().wait(0.05)
    t0 = time.monotonic()
    q.wake()
    waiter.join(5.0)
    assert got == [None] and time.monotonic() - t0 < 2.0
    q.put(7)
    q.wake()  # an item waiting is taken, and the wake is used up
    assert q.take(0.0) == 7
    t0 = time.monotonic()
    assert q.take(0.2) is None and time.monotonic() - t0 >= 0.15


def test_sample_buffer_bounded():
    buf = SampleBuffer(maxlen=3)
    for i in range(5):
        buf.append(i)
    assert buf.drain() == [2, 3, 4] and buf.overflow == 2 and len(buf) == 0
