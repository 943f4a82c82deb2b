"""Receive times never go back: a datagram stamped at its read (the kernel's timestamping switched on a
moment late) is not dated after the ones that arrived after it."""

from __future__ import annotations

import math

from facepuppet.runtime.inputs.udp import ArrivalOrder


def test_a_time_before_the_previous_one_is_raised_to_it_and_later_ones_pass():
    order = ArrivalOrder()
    # two datagrams dated at their read (0.44 s), then the true arrival stamps of those queued behind them
    assert [order(t) for t in (0.444, 0.4443, 0.2001, 0.21, 0.45, 0.46)] == [0.444, 0.4443, 0.4443, 0.4443,
                                                                             0.45, 0.46]
    assert order.last == 0.46


def test_a_new_order_starts_from_nothing():
    assert ArrivalOrder().last == -math.inf and ArrivalOrder()(-5.0) == -5.0
