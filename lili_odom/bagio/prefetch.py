"""Read ahead: iterate a message source in a background thread, behind a bounded queue.

Reading a compressed bag is mostly decompression (zstd / lz4 release Python's GIL), so a
thread that reads the next messages while the caller processes the current ones takes that
time off the caller's loop. :class:`Prefetch` yields exactly the source's items, in the
source's order; an exception raised by the source (e.g. a corrupt chunk's
:class:`~lili_odom.errors.UserError`) is raised in the caller when it reaches that point.

    with BagReader(path) as reader, Prefetch(reader) as items:
        for item in items:
            ...

Leaving the ``with`` block early (a ``break``, an exception) stops the thread before the
source is closed. The source must not be used by anyone else while the thread reads it.
"""
from __future__ import annotations

import queue
import threading
from typing import Any, Iterable, Iterator

__all__ = ["Prefetch"]

_END = object()


class _Raised:
    """The exception the source raised, carried to the consumer."""

    def __init__(self, exc: BaseException) -> None:
        self.exc = exc


class Prefetch:
    """Iterate ``items`` in a daemon thread, at most ``depth`` items ahead of the consumer.

    Args:
        items: any iterable (e.g. a :class:`~lili_odom.bagio.reader.BagReader`).
        depth: items read ahead (default 64: about half a second of a LiDAR + IMU + wheel
            bag, four clouds).
    """

    def __init__(self, items: Iterable[Any], depth: int = 64) -> None:
        if depth < 1:
            raise ValueError(f"depth must be >= 1, got {depth}")
        self._items = items
        self._queue: queue.Queue = queue.Queue(maxsize=depth)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def __enter__(self) -> "Prefetch":
        self._thread = threading.Thread(target=self._read, name="lili_odom_prefetch",
                                        daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def _put(self, item: Any) -> bool:
        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def _read(self) -> None:
        try:
            for item in self._items:
                if not self._put(item):
                    return
        except BaseException as exc:  # noqa: BLE001 - handed to the consumer, raised there
            self._put(_Raised(exc))
            return
        self._put(_END)

    def __iter__(self) -> Iterator[Any]:
        if self._thread is None:
            raise RuntimeError("Prefetch is used as a context manager")
        while True:
            item = self._queue.get()
            if item is _END:
                return
            if isinstance(item, _Raised):
                raise item.exc
            yield item

    def close(self) -> None:
        """Stop reading ahead and wait for the thread (idempotent)."""
        self._stop.set()
        if self._thread is not None:
            while self._thread.is_alive():
                try:  # make room for a put the thread may be blocked in
                    self._queue.get(timeout=0.05)
                except queue.Empty:
                    pass
                self._thread.join(timeout=0.05)
