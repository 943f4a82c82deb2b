"""Shared pieces of the OSC adapter tests: crafted messages, bundles and datagrams, counter checks."""

from __future__ import annotations

from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder


def msg(address, *args):
    """One OSC message (built); an argument given as a tuple is (value, type tag)."""
    b = OscMessageBuilder(address)
    for a in args:
        b.add_arg(*a) if isinstance(a, tuple) else b.add_arg(a)
    return b.build()


def osc(address, *args) -> bytes:
    """The datagram of :func:`msg`."""
    return msg(address, *args).dgram


def bundle(*messages) -> bytes:
    """The datagram of one bundle (timetag: immediately) holding ``messages``."""
    b = OscBundleBuilder(IMMEDIATELY)
    for m in messages:
        b.add_content(m)
    return b.build().dgram


def vmc_frame(value: float) -> bytes:
    """One VMC bundle: JawOpen = ``value``, then Apply."""
    return bundle(msg("/VMC/Ext/Blend/Val", "JawOpen", value), msg("/VMC/Ext/Blend/Apply"))


def counts(adapter, **expected):
    """Assert the adapter's counters: those named as given, every other one 0."""
    want = {k: 0 for k in adapter.counters}
    want.update(expected)
    assert adapter.counters == want
