"""Reading ahead in a thread (lili_odom.bagio.prefetch): same items, same order, errors where
the source raised them, and no thread left behind."""
import itertools
import threading
import time

import pytest

from lili_odom.bagio.prefetch import Prefetch
from lili_odom.errors import UserError


def _prefetch_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == "lili_odom_prefetch"]


def test_yields_every_item_in_order():
    with Prefetch(range(1000), depth=3) as items:
        assert list(items) == list(range(1000))
    assert not _prefetch_threads()


def test_an_error_of_the_source_is_raised_after_the_items_before_it():
    def source():
        yield from range(5)
        raise UserError("bag.mcap: corrupt bag: bad chunk")

    got = []
    with pytest.raises(UserError, match="corrupt bag"), Prefetch(source(), depth=2) as items:
        for item in items:
            got.append(item)
    assert got == [0, 1, 2, 3, 4]
    assert not _prefetch_threads()


def test_leaving_early_stops_the_thread_before_the_source_closes():
    read = []

    def endless():
        for i in itertools.count():
            read.append(i)
            yield i

    with Prefetch(endless(), depth=4) as items:
        for item in items:
            if item == 10:
                break
    assert not _prefetch_threads()
    n = len(read)
    assert 11 <= n <= 11 + 4 + 1  # read ahead by at most depth (+ the one being put)
    time.sleep(0.2)
    assert len(read) == n  # nothing is read after close


def test_is_a_context_manager_and_checks_its_depth():
    with pytest.raises(RuntimeError, match="context manager"):
        next(iter(Prefetch([1])))
    with pytest.raises(ValueError, match="depth"):
        Prefetch([1], depth=0)
