"""The control verbs as OSC addresses (TouchOSC, Stream Deck OSC plugins, a chat bot's script), over UDP.

A receive thread on the ``--web`` host and port (UDP and TCP ports are separate: the same number serves both)
decodes each datagram with the strict reader (:func:`~facepuppet.runtime.inputs.osc.decode`), checks each
message into a :class:`~facepuppet.runtime.control.commands.Command` and hands the show verbs to the control
stage. OSC has no replies: what is refused is counted (malformed, unknown address, bad arguments, wrong token,
over the rate) and logged at most once a second. With a token in force each message's first argument is it.
"""

from __future__ import annotations

import hmac
import logging
import socket
import threading
import time
from collections.abc import Callable

from facepuppet.runtime.control.commands import SHOW_VERBS, Command, CommandError, parse_osc, split_token
from facepuppet.runtime.control.limits import OSC_BURST, OSC_RATE_PER_S, RateLimit
from facepuppet.runtime.inputs.osc import MAX_UDP_PAYLOAD, decode

logger = logging.getLogger(__name__)


class OscControl:
    """A UDP receive thread for the control verbs (see the module docstring).

    Parameters
    ----------
    host, port : where to listen (the ``--web`` address; port as the WebSocket server bound it)
    token : str or None
    submit : callable(Command) -> bool, hands a show command to the control stage
    """

    def __init__(self, host: str, port: int, *, token: str | None, submit: Callable[[Command], bool],
                 log: Callable[[str], None] = logger.info) -> None:
        self.token = token
        self.submit = submit
        self.log = log
        self.counters = dict.fromkeys(("datagrams", "commands", "malformed", "bad_commands", "refused_token",
                                       "rate_limited", "dropped"), 0)
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self.sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            self.sock.bind((host, port))
        except OSError:
            self.sock.close()
            raise
        self.sock.settimeout(0.2)
        self.address = self.sock.getsockname()[:2]
        self.limit = RateLimit(OSC_RATE_PER_S, OSC_BURST)
        self._said = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._receive, name="control-osc", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.sock.close()

    def _receive(self) -> None:
        while not self._stop.is_set():
            try:
                data = self.sock.recv(MAX_UDP_PAYLOAD + 1)
            except TimeoutError:
                continue
            except OSError:
                return
            self.handle(data, time.monotonic())

    def handle(self, data: bytes, now: float) -> None:
        """One datagram (never raises)."""
        c = self.counters
        c["datagrams"] += 1
        if not self.limit.take(now):
            c["rate_limited"] += 1
            return
        messages = decode(data)
        if messages is None:
            c["malformed"] += 1
            self._say(now, "OSC control: a malformed datagram (counted)")
            return
        for address, params in messages:
            if self.token is not None:
                given, params = split_token(params)
                if given is None or not hmac.compare_digest(given.encode(), self.token.encode()):
                    c["refused_token"] += 1
                    self._say(now, f"OSC control: {address} without the token (counted)")
                    continue
            try:
                command = parse_osc(address, params)
            except CommandError as exc:
                c["bad_commands"] += 1
                self._say(now, f"OSC control: {exc}")
                continue
            if command.verb not in SHOW_VERBS:
                continue
            if self.submit(command):
                c["commands"] += 1
            else:
                c["dropped"] += 1

    def _say(self, now: float, line: str) -> None:
        if now - self._said >= 1.0:
            self._said = now
            self.log(line)
