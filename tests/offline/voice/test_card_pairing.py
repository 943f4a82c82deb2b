"""The card latency's pairing of onsets: each start takes the first event at or after it and before the next
start that exists, so an onset whose blocks the microphone dropped (nan) neither steals nor hides another's."""

from __future__ import annotations

import math

from facepuppet.offline.voice.card_latency import after


def test_each_start_takes_the_first_event_before_the_next_start():
    assert after([0.5, 1.2, 1.3, 2.9], [0.0, 1.0, 2.0]) == [0.5, 1.2, 2.9]


def test_a_missing_start_gives_nan_and_the_one_before_still_finds_its_event():
    got = after([0.5, 2.5], [0.0, math.nan, 2.0])
    assert got[0] == 0.5 and math.isnan(got[1]) and got[2] == 2.5


def test_a_start_with_no_event_before_the_next_is_nan():
    got = after([1.5], [0.0, 1.0])
    assert math.isnan(got[0]) and got[1] == 1.5
