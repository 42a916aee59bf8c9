"""The replay loop: a stream of recorded messages through the node's feeder and pipeline.

Every offline consumer of a bag (``lili-odom run``, the fault runs, the benchmarks) drives the
pipeline through :class:`Replay`, so they all see exactly what the node does: messages go to a
:class:`~lili_odom.pipeline.feeder.MessageFeeder` (scans wait for the IMU / wheel data of their
sweep), ground truth is collected on the side, and every output passes through the hooks:

* ``on_output(output, pipeline)``: after every processed scan;
* ``on_timings(output, timings)``: per-stage times of that scan [s]: ``parse`` (PointCloud2 to
  points, measured as the cloud's feed call minus the processing inside it), the pipeline's
  own stages (``predict``, ``deskew``, ``icp``, ``detector``, ``remap``, ``fusion``, ``map``)
  and ``total`` (parse plus the pipeline's total);
* ``on_call(seconds)``: the wall time of every ``feed`` / ``flush`` call (IMU / wheel
  buffering included), e.g. to measure throughput after a warm-up.

Items are objects with ``topic`` and ``msg`` attributes (``BagReader`` messages,
:class:`~lili_odom.evaluation.faults.StreamItem`) or ``(topic, msg)`` pairs, in header-stamp
order. Topics other than the LiDAR, IMU, wheel and ``/tf_static`` ones are not fed.
"""
from __future__ import annotations

import time
from collections import deque
from typing import Any, Callable, Iterable

from lili_odom.pipeline.types import OdometryOutput

__all__ = ["Replay", "OutputHook", "TimingsHook"]

OutputHook = Callable[[OdometryOutput, Any], None]
TimingsHook = Callable[[OdometryOutput, dict], None]


class _TimedPipeline:
    """The pipeline as the feeder sees it, with ``process_scan`` timed (everything else is the
    pipeline's own attribute)."""

    def __init__(self, pipeline: Any) -> None:
        self._pipeline = pipeline
        self.processed: list[tuple[OdometryOutput | None, float]] = []

    def __getattr__(self, name: str) -> Any:
        return getattr(self._pipeline, name)

    def process_scan(self, scan: Any) -> OdometryOutput | None:
        t0 = time.perf_counter()
        out = self._pipeline.process_scan(scan)
        self.processed.append((out, time.perf_counter() - t0))
        return out


class Replay:
    """One replay: a pipeline built from ``config`` (or the given one), its feeder and hooks.

    Attributes:
        pipeline: the :class:`~lili_odom.pipeline.odometry.OdometryPipeline`.
        feeder: the :class:`~lili_odom.pipeline.feeder.MessageFeeder` in front of it.
        truth: ``(stamp, 4x4 pose)`` of every usable ground-truth message seen.
        clouds_in: LiDAR messages handed to the feeder.
        outputs: outputs produced so far (count).
    """

    def __init__(self, config: Any, *, pipeline: Any = None,
                 on_output: OutputHook | None = None,
                 on_timings: TimingsHook | None = None,
                 on_call: Callable[[float], None] | None = None) -> None:
        from lili_odom.pipeline.feeder import MessageFeeder
        from lili_odom.pipeline.odometry import OdometryPipeline

        self.config = config
        self.pipeline = pipeline if pipeline is not None else OdometryPipeline(config.pipeline)
        self._timed = _TimedPipeline(self.pipeline) if on_timings is not None else None
        self.feeder = MessageFeeder(self._timed or self.pipeline, config)
        self.on_output = on_output
        self.on_timings = on_timings
        self.on_call = on_call
        self.truth: list[tuple[float, Any]] = []
        self.clouds_in = 0
        self.outputs = 0
        self._parse_times: deque[float] = deque()
        self._fed_topics = {config.lidar_topic, config.imu_topic, config.wheel_topic,
                            "/tf_static"}

    # ------------------------------------------------------------------ one message at a time

    def feed(self, topic: str, msg: Any) -> list[OdometryOutput]:
        """Hand one message over; returns the outputs it released (oldest first)."""
        if topic == self.config.ground_truth_topic:
            from lili_odom.messages import truth_sample

            sample = truth_sample(msg)
            if sample is not None:
                self.truth.append(sample)
            return []
        if topic not in self._fed_topics:
            return []
        lidar = topic == self.config.lidar_topic
        if lidar:
            self.clouds_in += 1
        pending = self.feeder.pending
        t0 = time.perf_counter()
        outs = self.feeder.feed(topic, msg)
        self._after_call(time.perf_counter() - t0, pending if lidar else None)
        self._emit(outs)
        return outs

    def flush(self) -> list[OdometryOutput]:
        """Process every waiting scan now (end of the stream)."""
        t0 = time.perf_counter()
        outs = self.feeder.flush()
        self._after_call(time.perf_counter() - t0, None)
        self._emit(outs)
        return outs

    # ------------------------------------------------------------------ a whole stream

    def run(self, items: Iterable[Any], *, max_scans: int = 0, flush: bool = True) -> "Replay":
        """Feed every item, then (``flush``) process the scans still waiting.

        ``max_scans`` > 0: after that many clouds, further clouds are skipped and the other
        messages fed only until the last cloud has been processed.
        """
        for item in items:
            topic, msg = (item[0], item[1]) if isinstance(item, tuple) else (item.topic, item.msg)
            if topic == self.config.ground_truth_topic:
                self.feed(topic, msg)
                continue
            done = bool(max_scans) and self.clouds_in >= max_scans
            if done and topic == self.config.lidar_topic:
                continue
            self.feed(topic, msg)
            if done and not self.feeder.pending:
                break
        if flush:
            self.flush()
        return self

    # ------------------------------------------------------------------ hooks

    def _after_call(self, seconds: float, pending_before: int | None) -> None:
        if self.on_call is not None:
            self.on_call(seconds)
        if self._timed is None:
            return
        processed, self._timed.processed = self._timed.processed, []
        if pending_before is not None:
            queued = self.feeder.pending - pending_before + len(processed)
            if queued > 0:  # the cloud parsed (a bad cloud is counted, not queued)
                self._parse_times.append(seconds - sum(s for _, s in processed))
        for out, _ in processed:
            parse = self._parse_times.popleft() if self._parse_times else float("nan")
            if out is not None:
                timings = {k: v for k, v in out.timings.items() if k != "total"}
                timings["parse"] = parse
                timings["total"] = parse + out.timings.get("total", float("nan"))
                self.on_timings(out, timings)

    def _emit(self, outs: list[OdometryOutput]) -> None:
        self.outputs += len(outs)
        if self.on_output is not None:
            for out in outs:
                self.on_output(out, self.pipeline)
