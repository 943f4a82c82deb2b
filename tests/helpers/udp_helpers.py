"""Shared pieces of the UDP receiver tests: a bounded wait (the ``udp_sender``
fixture is in tests/conftest.py)."""

from __future__ import annotations

import time

import pytest

DEADLINE_S = 10.0  # a spawned receiver on a loaded 2-core machine can take seconds to start


def wait_for(predicate, what: str):
    """Poll ``predicate`` until true; fail (not hang) after DEADLINE_S."""
    end = time.monotonic() + DEADLINE_S
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(0.002)
    pytest.fail(f"timed out after {DEADLINE_S} s waiting for {what}")


def poll_frame(source):
    """The next frame ``source.latest()`` hands out."""
    return wait_for(lambda: source.latest()[0], "a frame")
