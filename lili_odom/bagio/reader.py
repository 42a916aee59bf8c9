"""Read a rosbag2 bag (directory or single ``.mcap``) in header-stamp order.

A real driver publishes a finished Ouster sweep about 0.1 s after its ``header.stamp``, and IMU
and wheel messages can be logged slightly out of order between topics, so the bag's log order is
not the order the pipeline needs. :class:`BagReader` decodes the requested topics and releases
them through a bounded reorder buffer keyed by header stamp: a message is released once a
message stamped ``reorder_window`` seconds later has been read (or at the end of the bag).

Messages whose stamp is older than the last released one ("late", i.e. more than the window out
of order) cannot be released in order: they are skipped and counted in ``stats.late``.
Messages without a ``header`` (``tf2_msgs/TFMessage``, ``rosgraph_msgs/Clock``) carry no
stamp; they are released as soon as they are read, with the log time as their stamp.

Every problem a user can cause (missing path, not a bag, corrupt or truncated file, missing
required topic, undecodable or unexpected message type) is raised as a one-line
:class:`lili_odom.errors.UserError`.
"""
from __future__ import annotations

import heapq
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

from lili_odom.errors import UserError

__all__ = ["BagMessage", "RawBagMessage", "ReaderStats", "BagReader", "DEFAULT_TOPIC_TYPES"]

#: Default input topics and the message type each must have.
DEFAULT_TOPIC_TYPES: dict[str, str] = {
    "/ouster/points": "sensor_msgs/msg/PointCloud2",
    "/ouster/imu": "sensor_msgs/msg/Imu",
    "/platform/odom": "nav_msgs/msg/Odometry",
    "/ground_truth/odom": "nav_msgs/msg/Odometry",
    "/tf_static": "tf2_msgs/msg/TFMessage",
}


@dataclass
class BagMessage:
    """One decoded message.

    Attributes:
        topic: topic name.
        stamp: ``header.stamp`` [s] (log time for messages without a header).
        log_time: the bag's log (receive) time [s].
        msgtype: ``pkg/msg/Name``.
        msg: the rosbags message object.
    """

    topic: str
    stamp: float
    log_time: float
    msgtype: str
    msg: Any


@dataclass
class RawBagMessage:
    """One undecoded message in log-time order: CDR bytes as rosbag2 stores them."""

    topic: str
    msgtype: str
    log_time_ns: int
    data: bytes


@dataclass
class ReaderStats:
    read: int = 0  # decoded messages
    released: int = 0  # yielded messages
    late: int = 0  # skipped: more than the reorder window out of order
    max_buffered: int = 0
    per_topic: dict[str, int] = field(default_factory=dict)


def _one_line(exc: BaseException, limit: int = 200) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


class BagReader:
    """Open a bag and iterate its messages (use as a context manager).

    Args:
        path: rosbag2 directory (with ``metadata.yaml``) or a single ``.mcap`` file.
        topics: topics to read; None = every topic in the bag.
        required: topics that must be in the bag (default ``/ouster/points``).
        expected_types: ``{topic: msgtype}`` checked for the topics present (default
            :data:`DEFAULT_TOPIC_TYPES`).
        reorder_window: reorder buffer span [s] of header stamps.
        max_buffered: hard cap on buffered messages (memory guard); beyond it the oldest is
            released even if the window has not passed.
        progress: optional ``callback(read, total)`` called after every decoded message.

    Raises:
        UserError: see module docstring.
    """

    def __init__(
        self,
        path: str | Path,
        topics: Sequence[str] | None = None,
        required: Sequence[str] = ("/ouster/points",),
        expected_types: Mapping[str, str] | None = None,
        reorder_window: float = 0.5,
        max_buffered: int = 20000,
        progress: Callable[[int, int], None] | None = None,
    ) -> None:
        self.path = Path(path)
        self.requested = list(topics) if topics is not None else None
        self.required = list(required)
        self.expected_types = dict(DEFAULT_TOPIC_TYPES if expected_types is None
                                   else expected_types)
        self.reorder_window = float(reorder_window)
        self.max_buffered = int(max_buffered)
        self.progress = progress
        self.stats = ReaderStats()
        self._reader: Any = None

    # -- opening -------------------------------------------------------------------------

    def open(self) -> "BagReader":
        from rosbags.highlevel import AnyReader, AnyReaderError

        from lili_odom.bagio.factory import jazzy_typestore

        if not self.path.exists():
            raise UserError(f"{self.path}: no such file or directory")
        if self.path.is_dir() and not (self.path / "metadata.yaml").exists():
            raise UserError(f"{self.path}: not a rosbag2 bag (directory without metadata.yaml)")
        if self.path.is_file() and self.path.suffix not in (".mcap", ".db3"):
            raise UserError(f"{self.path}: not a rosbag2 bag (expected a bag directory or "
                            f"an .mcap file)")
        try:
            reader = AnyReader([self.path], default_typestore=jazzy_typestore())
            reader.open()
        except (AnyReaderError, FileNotFoundError) as exc:
            raise UserError(f"{self.path}: cannot open bag: {_one_line(exc)}") from None
        except Exception as exc:  # noqa: BLE001 - any decoder failure means a corrupt file
            raise UserError(f"{self.path}: corrupt bag: {_one_line(exc)}") from None
        self._reader = reader
        try:
            self._check_topics()
        except UserError:
            self.close()
            raise
        return self

    def _check_topics(self) -> None:
        available = self.topic_types
        missing = [t for t in self.required if t not in available]
        if missing:
            have = ", ".join(sorted(available)) or "none"
            raise UserError(f"{self.path}: required topic {missing[0]} not in bag "
                            f"(topics: {have})")
        for topic in self.selected_topics:
            want = self.expected_types.get(topic)
            have_type = available[topic]
            if want is not None and have_type != want:
                raise UserError(f"{self.path}: topic {topic} has type {have_type}, "
                                f"expected {want}")
            if have_type not in self._reader.typestore.types:
                raise UserError(f"{self.path}: topic {topic} has unknown message type "
                                f"{have_type} (no definition in the bag)")

    def close(self) -> None:
        if self._reader is not None:
            try:
                self._reader.close()
            finally:
                self._reader = None

    def __enter__(self) -> "BagReader":
        return self.open()

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- metadata ------------------------------------------------------------------------

    @property
    def topic_types(self) -> dict[str, str]:
        """``{topic: msgtype}`` of every topic in the bag."""
        return {c.topic: c.msgtype for c in self._connections_all()}

    @property
    def selected_topics(self) -> list[str]:
        """Requested topics that are in the bag (all topics when none were requested)."""
        have = self.topic_types
        if self.requested is None:
            return sorted(have)
        return [t for t in self.requested if t in have]

    @property
    def missing_topics(self) -> list[str]:
        """Requested topics the bag does not have."""
        have = self.topic_types
        return [t for t in (self.requested or []) if t not in have]

    @property
    def latched_topics(self) -> set[str]:
        """Topics recorded from a transient-local (latched) publisher, plus ``/tf_static``."""
        out = {"/tf_static"}
        for c in self._connections_all():
            for qos in getattr(getattr(c, "ext", None), "offered_qos_profiles", None) or []:
                durability = getattr(qos, "durability", None)
                if getattr(durability, "name", "") == "TRANSIENT_LOCAL":
                    out.add(c.topic)
        return out & set(self.topic_types)

    @property
    def message_count(self) -> int:
        """Messages on the selected topics."""
        sel = set(self.selected_topics)
        return sum(c.msgcount for c in self._connections_all() if c.topic in sel)

    @property
    def start_time(self) -> float:
        """Earliest log time [s]."""
        return self._open_reader().start_time * 1e-9

    @property
    def end_time(self) -> float:
        return self._open_reader().end_time * 1e-9

    def _open_reader(self) -> Any:
        if self._reader is None:
            raise RuntimeError("BagReader is not open")
        return self._reader

    def _connections_all(self) -> list[Any]:
        return list(self._open_reader().connections)

    def _connections(self) -> list[Any]:
        sel = set(self.selected_topics)
        return [c for c in self._connections_all() if c.topic in sel]

    # -- iteration -----------------------------------------------------------------------

    def raw_messages(self, start: float | None = None) -> Iterator[RawBagMessage]:
        """Undecoded messages of the selected topics in log-time order (for ``play``).

        Args:
            start: skip messages logged before this absolute log time [s].
        """
        reader = self._open_reader()
        start_ns = None if start is None else int(start * 1e9)
        it = reader.messages(connections=self._connections(), start=start_ns)
        while True:
            try:
                conn, t_ns, data = next(it)
            except StopIteration:
                return
            except Exception as exc:  # noqa: BLE001 - corrupt chunk, bad CRC, truncation
                raise UserError(f"{self.path}: corrupt bag: {_one_line(exc)}") from None
            yield RawBagMessage(conn.topic, conn.msgtype, int(t_ns), bytes(data))

    def decode(self, raw: RawBagMessage) -> Any:
        """Deserialize one raw message with the bag's own definitions."""
        try:
            return self._open_reader().deserialize(raw.data, raw.msgtype)
        except Exception as exc:  # noqa: BLE001
            raise UserError(f"{self.path}: cannot decode a {raw.msgtype} message on "
                            f"{raw.topic}: {_one_line(exc)}") from None

    def _decoded(self) -> Iterator[BagMessage]:
        total = self.message_count
        for raw in self.raw_messages():
            msg = self.decode(raw)
            log_time = raw.log_time_ns * 1e-9
            header = getattr(msg, "header", None)
            stamp = log_time
            if header is not None and hasattr(header, "stamp"):
                stamp = float(header.stamp.sec) + 1e-9 * float(header.stamp.nanosec)
            self.stats.read += 1
            self.stats.per_topic[raw.topic] = self.stats.per_topic.get(raw.topic, 0) + 1
            if self.progress is not None:
                self.progress(self.stats.read, total)
            yield BagMessage(raw.topic, stamp, log_time, raw.msgtype, msg)

    def __iter__(self) -> Iterator[BagMessage]:
        """Decoded messages of the selected topics in header-stamp order (see module doc)."""
        heap: list[tuple[float, int, BagMessage]] = []
        seq = 0
        newest = -float("inf")
        last_out = -float("inf")
        for item in self._decoded():
            if not hasattr(item.msg, "header"):
                self.stats.released += 1
                yield item
                continue
            if item.stamp < last_out:
                self.stats.late += 1
                continue
            heapq.heappush(heap, (item.stamp, seq, item))
            seq += 1
            newest = max(newest, item.stamp)
            self.stats.max_buffered = max(self.stats.max_buffered, len(heap))
            horizon = newest - self.reorder_window
            while heap and (heap[0][0] <= horizon or len(heap) > self.max_buffered):
                stamp, _, out = heapq.heappop(heap)
                last_out = stamp
                self.stats.released += 1
                yield out
        while heap:
            _, _, out = heapq.heappop(heap)
            self.stats.released += 1
            yield out
