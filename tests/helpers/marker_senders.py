"""A sender of the facepuppet markers protocol over OSC/UDP for the ``run --input markers`` tests."""

from __future__ import annotations

import time

from pythonosc.osc_message_builder import OscMessageBuilder


def marker_sender(names, pose_at, units=None):
    """A ``send(client, stop)`` (a pythonosc UDP client, a threading.Event) to run on a thread: the markers
    layout about every 0.2 s (with ``/facepuppet/markers/units`` when ``units``) and, every 10 ms, a marker
    frame of ``pose_at(seconds since the start)``, (n_markers, 3) float32."""

    def send(client, stop):
        layout = OscMessageBuilder("/facepuppet/markers/layout")
        layout.add_arg(1)
        for name in names:
            layout.add_arg(name, "s")
        declare = OscMessageBuilder("/facepuppet/markers/units")
        declare.add_arg(1)
        declare.add_arg(units or "", "s")
        start, n = time.monotonic(), 0
        while not stop.is_set():
            if n % 20 == 0:
                client.send(layout.build())
                if units:
                    client.send(declare.build())
            m = OscMessageBuilder("/facepuppet/markers/frame")
            m.add_arg(1)
            m.add_arg(n)
            m.add_arg(time.time(), "d")
            m.add_arg(pose_at(time.monotonic() - start).astype("<f4").tobytes(), "b")
            client.send(m.build())
            n += 1
            time.sleep(0.01)

    return send
