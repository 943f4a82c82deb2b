"""What the phone trackers share: the periodic request to the phone, its address, eye angles to gaze weights.

Some phone apps stream only after being asked: iFacialMocap on a start payload
(PROTOCOLS.md §7), VTube Studio's phone protocol on a JSON request that must be
repeated before its ``time`` runs out (§8). :class:`PhoneRequester` sends such a
payload from its own UDP socket to the one address the user gave (``--phone
HOST``: an IP address, never a name to look up, never guessed, never a
broadcast), at once and then every ``every_s`` seconds, from a daemon thread
that sleeps on an event: it never touches the frame loop, and :meth:`stop`
ends it (the run stops it with everything else). A send that fails (no route,
an ICMP "port unreachable" from an earlier one) is counted in
``counters["send_errors"]``, never raised; ``counters["sent"]`` counts the
payloads that left.

The adapters of these kinds say what to send: ``phone_port`` (the phone's
port), ``phone_every_s`` and ``phone_request(listen_port) -> bytes``.
"""

from __future__ import annotations

import ipaddress
import math
import re
import socket
import threading
from collections.abc import Callable

import numpy as np

from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.mapping.channels import ARKIT_NAMES

#: gaze angle (degrees) that gives an eyeLook* weight of 1 (as for Face Cap's eye rotations)
EYE_RANGE_DEG = 30.0

_INDEX = {name: i for i, name in enumerate(ARKIT_NAMES)}
_EYE = {  # side -> ARKit indices of (down, up, towards the face's own left, towards its right)
    "Left": tuple(_INDEX[f"eyeLook{d}Left"] for d in ("Down", "Up", "Out", "In")),
    "Right": tuple(_INDEX[f"eyeLook{d}Right"] for d in ("Down", "Up", "In", "Out")),
}


def eyes_into(weights: np.ndarray, side: str, pitch_deg: float, yaw_deg: float) -> None:
    """Fill the eyeLook* weights of ``side`` ("Left"/"Right") that are NaN (not sent) from an eye's angles.

    Pitch > 0 looks down, yaw > 0 turns the gaze to the face's own left; EYE_RANGE_DEG gives 1,
    clamped to [0, 1]. Weights the tracker sent are left as they are.
    """
    pitch, yaw = pitch_deg / EYE_RANGE_DEG, yaw_deg / EYE_RANGE_DEG
    down, up, to_left, to_right = _EYE[side]
    for index, value in ((down, pitch), (up, -pitch), (to_left, yaw), (to_right, -yaw)):
        if math.isnan(weights[index]):
            weights[index] = min(max(value, 0.0), 1.0)


def parse_phone(text: str, default_port: int, option: str = "--phone") -> tuple[str, int]:
    """(ip, port) of ``--phone``: ``IP``, ``IP:PORT`` or ``[IPv6]:PORT``; the port defaults to ``default_port``.

    Raises
    ------
    ValueError
        naming the option when the text is not an IP address (host names are refused, not looked up:
        the request goes only to an address the user wrote) or the port is out of range, and for
        broadcast or multicast addresses and ``0.0.0.0``/``::``.
    """
    text = (text or "").strip()
    m = re.fullmatch(r"\[([^\]]+)\](?::(\d+))?|([^:\s]+)(?::(\d+))?|([0-9A-Fa-f:]+)", text)
    if m is None:
        raise UsageError(f"{option}: expected the phone's IP address, optionally :PORT (e.g. 192.168.1.20), "
                         f"got {text!r}")
    host = m.group(1) or m.group(3) or m.group(5)
    port_text = m.group(2) or m.group(4)
    try:
        ip = ipaddress.ip_address(host)
    except ValueError:
        raise UsageError(f"{option}: {host!r} is not an IP address; give the phone's address as the app shows it "
                         "(names are not looked up)") from None
    if ip.is_multicast or ip.is_unspecified or (ip.version == 4 and ip == ipaddress.IPv4Address("255.255.255.255")):
        raise UsageError(f"{option}: {host} is not one phone's address (broadcast, multicast or unspecified); "
                         "give the phone's own IP address")
    port = default_port if port_text is None else int(port_text)
    if not 0 < port < 65536:
        raise UsageError(f"{option}: port {port} is out of range 1-65535")
    return str(ip), port


class PhoneRequester:
    """Sends ``payload(listen_port)`` to (host, port) now and every ``every_s`` seconds until :meth:`stop`.

    Parameters
    ----------
    host : str, an IP address (see :func:`parse_phone`)
    port : int, the phone's port
    payload : bytes, what to send
    every_s : float > 0, seconds between sends
    log : callable(str), told once about the first failed send
    """

    def __init__(self, host: str, port: int, payload: bytes, every_s: float,
                 log: Callable[[str], None] = lambda s: None) -> None:
        if not every_s > 0:
            raise ValueError(f"PhoneRequester every_s: expected a positive number of seconds, got {every_s!r}")
        self.host, self.port, self.payload, self.every_s, self.log = host, int(port), bytes(payload), float(every_s), \
            log
        self.counters: dict[str, int] = {"sent": 0, "send_errors": 0}
        self.last_error: BaseException | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._sock: socket.socket | None = None

    def start(self) -> PhoneRequester:
        """Open the socket and start the thread (the first payload goes out at once)."""
        if self._thread is not None:
            raise RuntimeError("PhoneRequester.start: already started")
        self._sock = socket.socket(socket.AF_INET6 if ":" in self.host else socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.setblocking(False)  # a full send buffer drops this payload (counted), never waits
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="phone-request", daemon=True)
        self._thread.start()
        return self

    def _run(self) -> None:
        while True:
            self.send_once()
            if self._stop.wait(self.every_s):
                return

    def send_once(self) -> bool:
        """Send the payload now; False (counted) when the send failed."""
        sock = self._sock
        if sock is None:
            return False
        try:
            sock.sendto(self.payload, (self.host, self.port))
        except OSError as exc:
            self.counters["send_errors"] += 1
            if self.last_error is None:
                self.log(f"phone: cannot send the request to {self.host}:{self.port}: {exc} (retrying every "
                         f"{self.every_s:g} s)")
            self.last_error = exc
            return False
        self.counters["sent"] += 1
        return True

    def stop(self) -> None:
        """End the thread and close the socket (no more payloads after this returns)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self) -> PhoneRequester:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
