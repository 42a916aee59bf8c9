"""Node plumbing without DDS: parameter flattening and the scan hand-over policy."""
from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np
import pytest

from lili_odom.ros.params import build_config, coerce_like, flatten_config
from lili_odom.ros.queues import LatestSlot, SampleBuffer


@dataclass
class Inner:
    max_range: float = 100.0
    voxel_size: float | None = None
    deskew: bool = True


@dataclass
class Outer:
    method: str = "lili"
    iterations: int = 5
    extrinsic: np.ndarray = field(default_factory=lambda: np.eye(4))
    matcher: Inner = field(default_factory=Inner)


def test_flatten_and_build_round_trip():
    flat = flatten_config(Outer())
    assert flat["matcher.max_range"] == 100.0 and flat["matcher.voxel_size"] is None
    assert len(flat["extrinsic"]) == 16
    cfg = build_config(Outer, {"matcher.max_range": 80, "iterations": 7.0, "method": "zhang",
                               "matcher.voxel_size": 0.5, "extrinsic": list(range(16)),
                               "unknown.name": 1})
    assert cfg.matcher.max_range == 80.0 and isinstance(cfg.matcher.max_range, float)
    assert cfg.iterations == 7 and cfg.method == "zhang" and cfg.matcher.voxel_size == 0.5
    assert cfg.extrinsic.shape == (4, 4) and cfg.extrinsic[3, 3] == 15


def test_coerce_errors_name_the_parameter():
    with pytest.raises(ValueError, match="matcher.max_range"):
        coerce_like("far", 1.0, "matcher.max_range")
    with pytest.raises(ValueError):
        coerce_like(2.5, 3, "iterations")
    assert coerce_like("false", True) is False


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
