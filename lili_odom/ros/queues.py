"""Thread-safe hand-over between the node's ROS callbacks and its processing thread.

Policy (documented in the node): the LiDAR callback never processes; it puts the scan in a
:class:`ScanQueue` that holds at most ``maxlen`` pending scans (the node's
``scan_queue_size``). The queue absorbs a short hiccup of the worker (a slow scan, a garbage
collection, a busy core) without losing anything; when it is full, a new scan pushes out the
OLDEST pending one, which is DROPPED and counted (``dropped``). So when processing is
persistently slower than the LiDAR, the node keeps working on recent data and its latency stays
bounded at about ``maxlen + 1`` scan periods, instead of a queue growing without bound.

IMU and wheel callbacks append to a :class:`SampleBuffer` (cheap; bounded so a stalled worker
cannot grow memory without limit; overflow is counted), drained by the worker before each scan.
While a scan waits for the IMU and wheel samples that cover its sweep, they also
:meth:`ScanQueue.wake` the worker, so it feeds them as they arrive.
"""
from __future__ import annotations

import threading
from collections import deque
from typing import Any, Generic, TypeVar

__all__ = ["ScanQueue", "SampleBuffer"]

T = TypeVar("T")


class ScanQueue(Generic[T]):
    """Bounded FIFO mailbox: when full, a new item pushes out (drops) the oldest.

    Args:
        maxlen: items kept at most (1: only the newest pending item).
    """

    def __init__(self, maxlen: int = 1) -> None:
        if int(maxlen) < 1:
            raise ValueError(f"maxlen must be >= 1, got {maxlen}")
        self.maxlen = int(maxlen)
        self._cond = threading.Condition()
        self._items: deque[T] = deque()
        self._closed = False
        self._woken = False
        self.put_count = 0
        self.dropped = 0

    def put(self, item: T) -> bool:
        """Append ``item``; returns True when the oldest pending item was dropped for it."""
        with self._cond:
            self.put_count += 1
            dropped = len(self._items) >= self.maxlen
            if dropped:
                self._items.popleft()
                self.dropped += 1
            self._items.append(item)
            self._cond.notify()
            return dropped

    def take(self, timeout: float | None = None) -> T | None:
        """Wait up to ``timeout`` s for an item and remove the oldest; None on timeout, close or
        :meth:`wake`."""
        with self._cond:
            if not self._items and not self._closed and not self._woken:
                self._cond.wait(timeout)
            self._woken = False
            return self._items.popleft() if self._items else None

    def wake(self) -> None:
        """End the current (or next) wait of :meth:`take` without an item: the waiter has
        something else to do (new IMU or wheel samples for a scan that waits for them)."""
        with self._cond:
            self._woken = True
            self._cond.notify()

    def __len__(self) -> int:
        with self._cond:
            return len(self._items)

    def close(self) -> None:
        """Wake every waiter; later ``take`` calls return immediately."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    @property
    def closed(self) -> bool:
        return self._closed


class SampleBuffer(Generic[T]):
    """Bounded FIFO filled by callbacks and drained by the worker."""

    def __init__(self, maxlen: int = 10000) -> None:
        self._lock = threading.Lock()
        self._items: deque[Any] = deque()
        self.maxlen = int(maxlen)
        self.overflow = 0
        self.received = 0

    def append(self, item: T) -> None:
        with self._lock:
            self.received += 1
            if len(self._items) >= self.maxlen:
                self._items.popleft()
                self.overflow += 1
            self._items.append(item)

    def drain(self) -> list[T]:
        with self._lock:
            items = list(self._items)
            self._items.clear()
            return items

    def clear(self) -> None:
        with self._lock:
            self._items.clear()

    def __len__(self) -> int:
        with self._lock:
            return len(self._items)
