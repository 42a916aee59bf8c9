"""Read ahead: the items of an iterable produced in a background thread while the consumer
works on the ones before.

Reading a bag is mostly decompressing chunks and copying message bytes, which release the GIL,
so a thread reading ahead runs on the second core while the odometry processes a scan.
The items come out in the producer's order; an exception the producer raises is raised by the
consumer at the point where the item would have come. Leaving the loop early stops the
producer.
"""
from __future__ import annotations

import queue
import threading
from typing import Any, Iterable, Iterator

__all__ = ["prefetched"]

_END = object()


class _Failure:
    def __init__(self, exc: BaseException) -> None:
        self.exc = exc


def prefetched(items: Iterable[Any], depth: int = 128) -> Iterator[Any]:
    """Yield the items of ``items`` in order, read up to ``depth`` items ahead in a daemon
    thread (``depth`` <= 0: read in the caller's thread, no thread)."""
    if depth <= 0:
        yield from items
        return
    buffer: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()

    def put(item: Any) -> bool:
        while not stop.is_set():
            try:
                buffer.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        try:
            for item in items:
                if not put(item):
                    return
        except BaseException as exc:  # noqa: BLE001 - handed to the consumer, raised there
            put(_Failure(exc))
            return
        put(_END)

    thread = threading.Thread(target=produce, name="lili_odom_prefetch", daemon=True)
    thread.start()
    try:
        while True:
            item = buffer.get()
            if item is _END:
                return
            if isinstance(item, _Failure):
                raise item.exc
            yield item
    finally:
        stop.set()
        thread.join()
