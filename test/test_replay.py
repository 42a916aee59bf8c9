"""The replay loop: hooks see every output, stage timings add up, timing changes nothing."""
from pathlib import Path

import numpy as np
import pytest

from lili_odom.bagio.reader import BagReader
from lili_odom.config import load_config
from lili_odom.evaluation.replay import Replay

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / "bags" / "tunnel_entrance_32x256"
SCANS = 12


def _items(config):
    topics = [config.lidar_topic, config.imu_topic, config.wheel_topic,
              config.ground_truth_topic, "/tf_static"]
    with BagReader(BAG, topics=topics) as reader:
        yield from reader


@pytest.fixture(scope="module")
def config():
    if not BAG.exists():
        pytest.skip("CI bag missing")
    return load_config(ROOT / "config" / "deterministic.yaml")


def test_hooks_see_every_output_with_stage_timings_that_add_up(config):
    outputs, timings, calls = [], [], []
    replay = Replay(config, on_output=lambda out, pipe: outputs.append(out),
                    on_timings=lambda out, t: timings.append((out.stamp, t)),
                    on_call=calls.append)
    replay.run(_items(config), max_scans=SCANS)
    assert replay.clouds_in == SCANS and len(outputs) == replay.outputs == SCANS
    assert [s for s, _ in timings] == [o.stamp for o in outputs]
    assert replay.truth and all(np.shape(T) == (4, 4) for _, T in replay.truth)
    for (_, t), out in zip(timings, outputs):
        assert t["parse"] > 0 and np.isfinite(t["parse"])
        assert t["total"] == pytest.approx(t["parse"] + out.timings["total"])
        assert {"deskew", "icp", "fusion"} <= set(t)
    busy = sum(calls)
    assert busy >= sum(t["total"] for _, t in timings) * 0.99


def test_timing_hook_does_not_change_the_trajectory(config):
    plain = Replay(config).run(_items(config), max_scans=SCANS)
    poses_plain = []
    plain_again = Replay(config, on_output=lambda o, p: poses_plain.append(o.pose))
    plain_again.run(_items(config), max_scans=SCANS)
    poses_timed = []
    timed = Replay(config, on_output=lambda o, p: poses_timed.append(o.pose),
                   on_timings=lambda o, t: None)
    timed.run(((i.topic, i.msg) for i in _items(config)), max_scans=SCANS)  # pairs work too
    assert len(poses_timed) == len(poses_plain) == plain.outputs == SCANS
    # equal up to the last bits: one thread per native call makes repeats bit-identical only
    # in a fresh process (a multi-threaded run earlier in the process, e.g. another test,
    # leaves TBB's reductions summing in another order)
    assert all(np.allclose(a, b, rtol=0, atol=1e-9) for a, b in zip(poses_plain, poses_timed))
    assert timed.pipeline.counters == plain.pipeline.counters
