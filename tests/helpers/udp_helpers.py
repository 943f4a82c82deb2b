"""Shared pieces of the UDP tests: a free loopback port, a bounded wait (the ``udp_sender``
fixture is in tests/conftest.py)."""

from __future__ import annotations

import socket
import time

import pytest

DEADLINE_S = 10.0  # a spawned receiver on a loaded 2-core machine can take seconds to start



def free_udp_port() -> int:
    """A UDP port free on 127.0.0.1 just now (bound and released)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


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
