"""Shared pieces of the UDP receiver tests: crafted datagrams and a bounded wait (the ``udp_sender``
fixture is in tests/conftest.py)."""

from __future__ import annotations

import time

import pytest
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder

DEADLINE_S = 10.0  # a spawned receiver on a loaded 2-core machine can take seconds to start


def vmc_frame(value: float) -> bytes:
    """One VMC bundle: JawOpen = ``value``, then Apply."""
    b = OscBundleBuilder(IMMEDIATELY)
    m = OscMessageBuilder("/VMC/Ext/Blend/Val")
    m.add_arg("JawOpen")
    m.add_arg(value)
    b.add_content(m.build())
    b.add_content(OscMessageBuilder("/VMC/Ext/Blend/Apply").build())
    return b.build().dgram


def osc(address, *args) -> bytes:
    """One OSC message; an argument given as a tuple is (value, type tag)."""
    b = OscMessageBuilder(address)
    for a in args:
        b.add_arg(*a) if isinstance(a, tuple) else b.add_arg(a)
    return b.build().dgram


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
