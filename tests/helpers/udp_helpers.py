"""Shared pieces of the UDP tests: a free loopback port, a bounded wait, a loopback receiver for what a run
sends and its drain (the ``udp_sender`` fixture is in tests/conftest.py)."""

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


@pytest.fixture
def udp_receiver():
    """A UDP socket bound on 127.0.0.1 (a free port) for what a test makes facepuppet send (a fixture of
    every test: tests/conftest.py loads this module as a plugin)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        s.settimeout(5.0)
        yield s


def drain(sock: socket.socket) -> list[bytes]:
    """Every datagram waiting on ``sock`` now, in arrival order (without waiting for more)."""
    sock.settimeout(0.0)
    out = []
    while True:
        try:
            out.append(sock.recv(65536))
        except BlockingIOError:
            return out
