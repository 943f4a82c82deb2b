"""``--vmc-out HOST:PORT``: the retargeted weights and head pose sent as VMC (PROTOCOLS.md §1).

Every tick sends, over one UDP socket:

* one bundle with ``/VMC/Ext/Bone/Pos s "Head" f px py pz qx qy qz qw``;
* the character's channels as ``/VMC/Ext/Blend/Val s Name f value``, names in
  PascalCase (:func:`~facepuppet.runtime.channels.pascal`: the perfect-sync
  spelling, case-sensitive), split over as many bundles as keep each under
  ``max_bundle`` bytes (1,500 by default; VirtualMotionCapture itself stays
  under 1,200), with one ``/VMC/Ext/Blend/Apply`` at the end of the last.

The bundles are built once with python-osc's builders (time tag "immediately")
and only the big-endian float32 argument bytes are patched per tick, so a tick
costs one ``struct.pack_into`` per value and one ``send`` per bundle.

**Socket.** Connected to the destination at start: the kernel binds it to the local address that
routes there (the loopback for 127.0.0.1), never to 0.0.0.0, and drops whatever comes from anyone else.

**Axes.** Ours are right-handed, x to the character's left; VMC's are Unity's
(left-handed, x to the avatar's right): a position (x, y, z) is sent as
(-x, y, z) and a rotation (x, y, z, w) as (x, -y, -z, w), the mirror the VMC
input applies the other way. Positions keep the character's units.
"""

from __future__ import annotations

import socket
import struct
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder

from facepuppet.runtime.channels import pascal

if TYPE_CHECKING:
    from facepuppet.runtime.live.loop import TickInfo

MAX_BUNDLE = 1500
_BUNDLE_HEAD = 16  # "#bundle\0" + 8-byte time tag
_F32 = struct.Struct(">f")


def _message(address: str, *args):
    builder = OscMessageBuilder(address)
    for value, type_ in args:
        builder.add_arg(value, type_)
    return builder.build()


def _bundle(messages: list) -> bytes:
    builder = OscBundleBuilder(IMMEDIATELY)
    for m in messages:
        builder.add_content(m)
    return builder.build().dgram


class VmcSender:
    """Send weights and the head pose as VMC bundles.

    Parameters
    ----------
    host, port : where to send (UDP)
    names : sequence of n str, the character's channel names (sent in PascalCase)
    max_bundle : int, bytes; every datagram stays strictly below this

    Attributes
    ----------
    datagrams : list of bytearray, the bundles sent each tick (head first, Apply in the last)
    counters : dict: ``bundles_sent``, ``send_errors``
    """

    def __init__(self, host: str, port: int, names: Sequence[str], max_bundle: int = MAX_BUNDLE) -> None:
        self.address = (host, int(port))
        self.names = tuple(pascal(n) for n in names)
        self.counters = {"bundles_sent": 0, "send_errors": 0}
        head = _message("/VMC/Ext/Bone/Pos", ("Head", "s"), *[(0.0, "f")] * 7)
        self._head = bytearray(_bundle([head]))
        self._head_at = len(self._head) - 7 * 4  # the 7 floats end the only message
        vals = [_message("/VMC/Ext/Blend/Val", (n, "s"), (0.0, "f")) for n in self.names]
        apply = _message("/VMC/Ext/Blend/Apply")
        # greedy split: each element costs 4 (size prefix) + its length
        groups, current, size = [], [], _BUNDLE_HEAD
        for m in vals + [apply]:
            if current and size + 4 + m.size >= max_bundle:
                groups.append(current)
                current, size = [], _BUNDLE_HEAD
            current.append(m)
            size += 4 + m.size
        groups.append(current)
        self.datagrams = [self._head] + [bytearray(_bundle(g)) for g in groups]
        if any(len(d) >= max_bundle for d in self.datagrams):
            raise ValueError(f"--vmc-out: a channel name is too long to fit a {max_bundle}-byte bundle")
        # (datagram index, byte offset of the value) of each channel, in order
        self._slots = []
        for gi, g in enumerate(groups, start=1):
            at = _BUNDLE_HEAD
            for m in g:
                if len(self._slots) < len(self.names):
                    self._slots.append((gi, at + m.size))  # the value is the message's last 4 bytes
                at += 4 + m.size
        # Connected, so the kernel binds it to the address that routes to the destination (the loopback
        # for 127.0.0.1), never to 0.0.0.0, and drops datagrams from anyone but the destination.
        self._sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.connect(self.address)
        except OSError as exc:
            self._sock.close()
            raise OSError(f"--vmc-out {host}:{port}: cannot send there: {exc.strerror or exc}") from exc

    def send(self, weights: np.ndarray, rotation: np.ndarray | None = None,
             translation: np.ndarray | None = None) -> None:
        """Send one tick: weights (n,) float, rotation (4,) (x, y, z, w) or None (identity),
        translation (3,) or None (zero). Send errors are counted, never raised."""
        w = np.nan_to_num(np.asarray(weights, dtype=np.float64), nan=0.0)
        for (gi, at), v in zip(self._slots, w):
            _F32.pack_into(self.datagrams[gi], at, v)
        px, py, pz = (0.0, 0.0, 0.0) if translation is None else (float(c) for c in translation)
        qx, qy, qz, qw = (0.0, 0.0, 0.0, 1.0) if rotation is None else (float(c) for c in rotation)
        struct.pack_into(">7f", self._head, self._head_at, -px, py, pz, qx, -qy, -qz, qw)  # mirror x
        for d in self.datagrams:
            try:
                self._sock.send(d)
                self.counters["bundles_sent"] += 1
            except OSError:
                self.counters["send_errors"] += 1

    def on_tick(self, info: TickInfo) -> None:
        """FrameLoop ``on_tick`` hook: send what this tick drew."""
        self.send(info.weights, info.rotation, info.translation)

    def close(self) -> None:
        self._sock.close()
