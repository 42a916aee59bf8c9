"""Reading ahead in a thread (lili_odom.bagio.prefetch): same items, same order, errors
where they happened, and an early exit stops the producer."""
import threading

import pytest

from lili_odom.bagio.prefetch import prefetched
from lili_odom.errors import UserError


def test_items_come_out_in_order_for_every_depth():
    items = list(range(1000))
    for depth in (0, 1, 3, 128):
        assert list(prefetched(iter(items), depth=depth)) == items


def test_reading_runs_ahead_in_another_thread():
    producers = []

    def source():
        for i in range(5):
            producers.append(threading.current_thread().name)
            yield i

    assert list(prefetched(source(), depth=2)) == list(range(5))
    assert set(producers) == {"lili_odom_prefetch"}
    producers.clear()
    assert list(prefetched(source(), depth=0)) == list(range(5))
    assert set(producers) == {threading.current_thread().name}


def test_a_producer_error_is_raised_after_the_items_before_it():
    def source():
        yield 1
        yield 2
        raise UserError("bag.mcap: corrupt bag: bad chunk CRC")

    got = []
    with pytest.raises(UserError, match="corrupt bag"):
        for item in prefetched(source(), depth=8):
            got.append(item)
    assert got == [1, 2]


def test_leaving_early_stops_the_producer():
    produced = []

    def source():
        for i in range(10_000):
            produced.append(i)
            yield i

    for item in prefetched(source(), depth=4):
        if item == 2:
            break
    # the producer is joined when the consumer's generator closes: at most depth + a few
    # items beyond the last consumed one were read, and the source was not read to its end
    assert len(produced) <= 2 + 4 + 2
    assert not any(t.name == "lili_odom_prefetch" and t.is_alive() for t in threading.enumerate())

