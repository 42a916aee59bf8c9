"""Thread-safe hand-over between the node's ROS callbacks and its processing thread.

Policy (documented in the node): the LiDAR callback never processes; it puts the scan in a
:class:`LatestSlot` that holds at most ONE pending scan. A scan arriving while another is still
pending replaces it: the older pending scan is DROPPED and counted (``dropped``). So when
processing is slower than the LiDAR, the node always works on the newest data and its latency
stays bounded at about two scan periods, instead of a queue growing without bound.

IMU and wheel callbacks append to a :class:`SampleBuffer` (cheap; bounded so a stalled worker
cannot grow memory without limit; overflow is counted), drained by the worker before each scan.
"""
from __future__ import annotations

import threading
from collections import deque
from typing import Any, Generic, TypeVar

__all__ = ["LatestSlot", "SampleBuffer"]

T = TypeVar("T")


class LatestSlot(Generic[T]):
    """Single-item mailbox keeping only the newest item."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._item: T | None = None
        self._closed = False
        self.put_count = 0
        self.dropped = 0

    def put(self, item: T) -> bool:
        """Store ``item``; returns True when an older pending item was dropped."""
        with self._cond:
            self.put_count += 1
            replaced = self._item is not None
            if replaced:
                self.dropped += 1
            self._item = item
            self._cond.notify()
            return replaced

    def take(self, timeout: float | None = None) -> T | None:
        """Wait up to ``timeout`` s for an item and remove it; None on timeout or close."""
        with self._cond:
            if self._item is None and not self._closed:
                self._cond.wait(timeout)
            item, self._item = self._item, None
            return item

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
