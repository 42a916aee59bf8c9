"""Fault injection into a bag's message stream, and an offline run over the faulty stream.

:class:`FaultInjector` sits between :class:`~lili_odom.bagio.reader.BagReader` (messages in
header-stamp order) and the pipeline. It is pure Python and seeded, so a fault run is
reproducible. Faults (any combination, all off by default, see :class:`FaultSpec`):

* **IMU loss**: every IMU message is dropped independently with probability
  ``imu_drop_fraction``;
* **wheel outage**: every wheel message stamped inside ``wheel_outage`` is dropped;
* **LiDAR outage**: every cloud stamped inside ``lidar_outage`` is dropped;
* **reordering**: a fraction ``reorder_fraction`` of the messages on ``reorder_topics``
  (default IMU and wheels) is held back by a uniform random delay of up to
  ``reorder_max_delay_s`` of stamp order: it is emitted just before the first message
  stamped at or after its own stamp plus the delay (every message is still emitted).

Windows are ``(t0, t1)`` in seconds *after the first stamp of the stream* (so the same
options fit any bag or bag piece); :attr:`FaultInjector.stats` counts what was seen, dropped
and delayed per topic.

:func:`run_stream` runs the replay loop (:class:`~lili_odom.evaluation.replay.Replay`, as
:func:`lili_odom.evaluation.runner.run_bag` does) over any iterator of messages, without
writing output files, and returns the trajectory, the truth, the
counters and the scan accounting (:meth:`StreamRun.accounting`): every cloud that entered
the stream is either dropped by the injector, rejected by the reader, rejected by the parser
(``bad_clouds``), skipped by the pipeline (``skipped_*``, ``fusion_rejected``) or processed.
"""
from __future__ import annotations

import heapq
import random
import time
from dataclasses import asdict, dataclass, field
from typing import Any, Callable, Iterable, Iterator

import numpy as np

__all__ = ["FaultSpec", "FaultStats", "FaultInjector", "StreamItem", "StreamRun", "run_stream",
           "read_bag", "PIPELINE_SKIP_COUNTERS"]

#: Pipeline counters of scans handed to ``process_scan`` that produced no output.
PIPELINE_SKIP_COUNTERS = ("skipped_bad_stamp", "skipped_too_few_points", "skipped_stale_stamp",
                          "fusion_rejected")

IMU_TOPIC = "/ouster/imu"
WHEEL_TOPIC = "/platform/odom"
LIDAR_TOPIC = "/ouster/points"


@dataclass
class StreamItem:
    """A message of the stream (``BagReader`` yields objects with the same attributes)."""

    topic: str
    msg: Any
    stamp: float


def _stamp_of(item: Any) -> tuple[str, Any, float]:
    """(topic, msg, stamp) of a ``BagMessage``-like object or a ``(topic, msg)`` pair."""
    if isinstance(item, tuple):
        topic, msg = item[0], item[1]
        stamp = None
    else:
        topic, msg, stamp = item.topic, item.msg, getattr(item, "stamp", None)
    if stamp is None:
        header = getattr(msg, "header", None)
        st = getattr(header, "stamp", None)
        stamp = (float(st.sec) + 1e-9 * float(st.nanosec)) if st is not None else float("nan")
    return topic, msg, float(stamp)


@dataclass
class FaultSpec:
    """What to break (see the module docstring). Windows: seconds after the first stamp."""

    imu_drop_fraction: float = 0.0
    wheel_outage: tuple[float, float] | None = None
    lidar_outage: tuple[float, float] | None = None
    reorder_fraction: float = 0.0
    reorder_max_delay_s: float = 0.05
    reorder_topics: tuple[str, ...] = (IMU_TOPIC, WHEEL_TOPIC)
    imu_topic: str = IMU_TOPIC
    wheel_topic: str = WHEEL_TOPIC
    lidar_topic: str = LIDAR_TOPIC
    seed: int = 0

    def validate(self) -> None:
        if not 0.0 <= self.imu_drop_fraction <= 1.0:
            raise ValueError(f"imu_drop_fraction must be in [0, 1], got {self.imu_drop_fraction}")
        if not 0.0 <= self.reorder_fraction <= 1.0:
            raise ValueError(f"reorder_fraction must be in [0, 1], got {self.reorder_fraction}")
        if not self.reorder_max_delay_s >= 0.0:
            raise ValueError(f"reorder_max_delay_s must be >= 0, got {self.reorder_max_delay_s}")
        for name in ("wheel_outage", "lidar_outage"):
            w = getattr(self, name)
            if w is not None and not (len(w) == 2 and float(w[0]) <= float(w[1])):
                raise ValueError(f"{name} must be (t0, t1) with t0 <= t1, got {w}")

    @property
    def active(self) -> bool:
        return bool(self.imu_drop_fraction or self.wheel_outage or self.lidar_outage
                    or (self.reorder_fraction and self.reorder_max_delay_s))

    def describe(self) -> str:
        parts = []
        if self.imu_drop_fraction:
            parts.append(f"drop {100 * self.imu_drop_fraction:.0f} % of IMU")
        if self.wheel_outage:
            a, b = self.wheel_outage
            parts.append(f"no wheels {a:g}-{b:g} s")
        if self.lidar_outage:
            a, b = self.lidar_outage
            parts.append(f"no LiDAR {a:g}-{b:g} s")
        if self.reorder_fraction and self.reorder_max_delay_s:
            parts.append(f"delay {100 * self.reorder_fraction:.0f} % of "
                         f"{'/'.join(t.rsplit('/', 1)[-1] for t in self.reorder_topics)} "
                         f"by <= {1e3 * self.reorder_max_delay_s:.0f} ms")
        return ", ".join(parts) or "clean"


@dataclass
class FaultStats:
    """Per-topic message counts of one injection."""

    seen: dict[str, int] = field(default_factory=dict)
    emitted: dict[str, int] = field(default_factory=dict)
    dropped: dict[str, int] = field(default_factory=dict)
    delayed: dict[str, int] = field(default_factory=dict)
    max_delay_s: float = 0.0
    first_stamp: float | None = None

    def to_dict(self) -> dict:
        return asdict(self)


def _inc(d: dict[str, int], key: str) -> None:
    d[key] = d.get(key, 0) + 1


class FaultInjector:
    """Apply a :class:`FaultSpec` to a message stream: ``for item in injector(items): ...``.

    Items are passed through unchanged (the same objects), so anything that reads a
    ``BagReader`` can read the injector's output. Items without a finite stamp (e.g.
    ``/tf_static``) are never dropped or delayed.
    """

    def __init__(self, spec: FaultSpec | None = None) -> None:
        self.spec = spec or FaultSpec()
        self.spec.validate()
        self.stats = FaultStats()

    def __call__(self, items: Iterable[Any]) -> Iterator[Any]:
        spec, st = self.spec, self.stats
        rng = random.Random(spec.seed)
        held: list[tuple[float, int, str, Any]] = []  # (release stamp, seq, topic, item)
        seq = 0
        t_first: float | None = None

        def inside(window, t: float) -> bool:
            return window is not None and t_first is not None and \
                float(window[0]) <= t - t_first <= float(window[1])

        for item in items:
            topic, _, stamp = _stamp_of(item)
            _inc(st.seen, topic)
            finite = np.isfinite(stamp)
            if finite and t_first is None:
                t_first = st.first_stamp = stamp
            # release the held messages whose delay has passed, in release order
            while held and finite and held[0][0] <= stamp:
                _, _, htopic, hitem = heapq.heappop(held)
                _inc(st.emitted, htopic)
                yield hitem
            if finite:
                # one random draw per message and fault, whatever the outcome, so enabling
                # one fault does not change which messages another fault hits
                u_drop, u_reorder, u_delay = rng.random(), rng.random(), rng.random()
                if topic == spec.imu_topic and u_drop < spec.imu_drop_fraction:
                    _inc(st.dropped, topic)
                    continue
                if (topic == spec.wheel_topic and inside(spec.wheel_outage, stamp)) or \
                        (topic == spec.lidar_topic and inside(spec.lidar_outage, stamp)):
                    _inc(st.dropped, topic)
                    continue
                if (topic in spec.reorder_topics and spec.reorder_max_delay_s > 0
                        and u_reorder < spec.reorder_fraction):
                    delay = u_delay * spec.reorder_max_delay_s
                    heapq.heappush(held, (stamp + delay, seq, topic, item))
                    seq += 1
                    _inc(st.delayed, topic)
                    st.max_delay_s = max(st.max_delay_s, delay)
                    continue
            _inc(st.emitted, topic)
            yield item
        while held:
            _, _, htopic, hitem = heapq.heappop(held)
            _inc(st.emitted, htopic)
            yield hitem


def read_bag(reader: Any, window: tuple[float, float] | None = None) -> Iterator[Any]:
    """The items of an open ``BagReader`` whose stamp lies in ``window`` = (t0, t1) seconds
    after the bag's first stamp (all items when None; items without a header always pass).
    Stops reading once past the window."""
    t_first = None
    for item in reader:
        if window is None or not hasattr(item.msg, "header"):
            yield item
            continue
        if t_first is None:
            t_first = item.stamp
        rel = item.stamp - t_first
        if rel < window[0]:
            continue
        if rel > window[1]:
            return
        yield item


@dataclass
class StreamRun:
    """What :func:`run_stream` produced (poses: base_link in the odometry frame, 4x4)."""

    method: str
    estimates: list[tuple[float, np.ndarray]] = field(default_factory=list)
    truth: list[tuple[float, np.ndarray]] = field(default_factory=list)
    dimensions: list[int] = field(default_factory=list)
    counters: dict[str, int] = field(default_factory=dict)
    clouds_in: int = 0  # clouds that reached the feeder
    wall_time_s: float = 0.0

    @property
    def stamps(self) -> np.ndarray:
        return np.array([s for s, _ in self.estimates])

    @property
    def poses(self) -> np.ndarray:
        return np.array([T for _, T in self.estimates]).reshape(-1, 4, 4)

    def accounting(self) -> dict[str, int]:
        """Where every cloud that reached the feeder went. ``balanced`` is 1 when
        ``clouds_in == processed + skipped + bad_clouds == scans_to_pipeline + bad_clouds``
        and every processed scan gave an output (nothing lost silently)."""
        c = self.counters
        skipped = {k: int(c.get(k, 0)) for k in PIPELINE_SKIP_COUNTERS}
        out = {"clouds_in": self.clouds_in, "bad_clouds": int(c.get("bad_clouds", 0)),
               "scans_to_pipeline": int(c.get("scans", 0)),
               "processed": int(c.get("processed", 0)), "outputs": len(self.estimates),
               "skipped": sum(skipped.values()), **skipped}
        out["balanced"] = int(out["clouds_in"] == out["processed"] + out["skipped"]
                              + out["bad_clouds"]
                              and out["clouds_in"] == out["scans_to_pipeline"] + out["bad_clouds"]
                              and out["processed"] == out["outputs"])
        return out

    def metrics(self, segment_m: float = 100.0):
        """ATE/RPE against the truth (:func:`lili_odom.evaluation.metrics.evaluate`)."""
        from lili_odom.evaluation.metrics import evaluate

        if not self.truth or len(self.estimates) < 2:
            return None
        truth = sorted(self.truth, key=lambda x: x[0])
        return evaluate(self.stamps, self.poses, np.array([s for s, _ in truth]),
                        np.array([T for _, T in truth]), segment_m=segment_m)


def run_stream(items: Iterable[Any], config: Any, *,
               on_output: Callable[[Any, Any], None] | None = None) -> StreamRun:
    """Run the odometry over ``items`` (``BagReader``-like, header-stamp order), as
    :func:`lili_odom.evaluation.runner.run_bag` does, without writing files.

    Args:
        config: a :class:`lili_odom.config.NodeConfig`.
        on_output: called as ``on_output(output, pipeline)`` after every processed scan
            (e.g. to sample memory).
    """
    from lili_odom.evaluation.replay import Replay

    run = StreamRun(method=config.pipeline.method)

    def record(out, pipeline) -> None:
        run.estimates.append((out.stamp, np.asarray(out.pose, dtype=np.float64)))
        run.dimensions.append(len(out.degenerate_basis))
        if on_output is not None:
            on_output(out, pipeline)

    replay = Replay(config, on_output=record)
    t0 = time.perf_counter()
    try:
        replay.pipeline.start()  # the background detector process, before the first scan
        replay.run((_stamp_of(item)[:2] for item in items))
    finally:
        replay.pipeline.close()
    run.wall_time_s = time.perf_counter() - t0
    run.truth = replay.truth
    run.clouds_in = replay.clouds_in
    run.counters = dict(replay.pipeline.counters)
    return run
