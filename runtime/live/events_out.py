"""Tracking lost / found as OSC ``/facepuppet/tracking i`` (1 found, 0 lost), for show control.

``run`` sends each event of the ``filter`` stage
(:attr:`~facepuppet.runtime.live.pipeline.LivePipeline.listeners`) to ``--events-out HOST:PORT`` as one
plain OSC message per datagram, and to ``--vmc-out`` (next to the VMC stream, which a show-control patch
often already listens to) as a bundle holding that one message, as every datagram of a VMC stream is a
bundle; each sent from the frame-loop thread on a non-blocking socket (a full
send buffer drops the message and counts it, the show goes on).
"""

from __future__ import annotations

import socket
from collections.abc import Sequence

from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder

TRACKING_ADDRESS = "/facepuppet/tracking"


def tracking_message(found: bool, bundle: bool = False) -> bytes:
    """The datagram of one event: ``/facepuppet/tracking`` with one int32, 1 found, 0 lost (in a bundle
    with ``bundle``)."""
    builder = OscMessageBuilder(TRACKING_ADDRESS)
    builder.add_arg(1 if found else 0, "i")
    message = builder.build()
    if not bundle:
        return message.dgram
    b = OscBundleBuilder(IMMEDIATELY)
    b.add_content(message)
    return b.build().dgram


class TrackingEventSender:
    """Send tracking events to one or more (host, port) over UDP.

    Parameters
    ----------
    targets : sequence of (host, port), sent plain messages
    bundle_targets : sequence of (host, port), sent the message in a bundle (``--vmc-out``)

    Attributes
    ----------
    counters : dict: ``events_sent`` (datagrams sent, all targets), ``events_send_errors``
    """

    def __init__(self, targets: Sequence[tuple[str, int]] = (),
                 bundle_targets: Sequence[tuple[str, int]] = ()) -> None:
        self.targets = tuple((str(h), int(p), False) for h, p in targets) + tuple(
            (str(h), int(p), True) for h, p in bundle_targets)
        if not self.targets:
            raise ValueError("TrackingEventSender: expected at least one HOST:PORT to send to")
        family = socket.AF_INET6 if any(":" in h for h, _, _ in self.targets) else socket.AF_INET
        self._sock = socket.socket(family, socket.SOCK_DGRAM)
        self._sock.setblocking(False)
        self.counters = {"events_sent": 0, "events_send_errors": 0}

    def __call__(self, t: float, found: bool) -> None:
        """A pipeline listener: send the event to every target."""
        data = (tracking_message(found), tracking_message(found, bundle=True))
        for host, port, bundle in self.targets:
            try:
                self._sock.sendto(data[bundle], (host, port))
                self.counters["events_sent"] += 1
            except OSError:
                self.counters["events_send_errors"] += 1

    def describe(self) -> str:
        return "events: tracking lost/found as OSC /facepuppet/tracking to " + ", ".join(
            f"{h}:{p}" + (" (in a bundle)" if b else "") for h, p, b in self.targets)

    def close(self) -> None:
        self._sock.close()
