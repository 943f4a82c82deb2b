"""The bounds the control servers hold every client to, and the rate limiter they share.

A control server is reachable by anything on the machine (and, with a token, the LAN): every size and rate a
client controls is bounded here, once.
"""

from __future__ import annotations

MAX_MESSAGE_BYTES = 64 << 10  # a command is a few hundred bytes; over this the WebSocket closes with 1009
MAX_QUEUE = 8  # incoming messages buffered per connection before the reader stops reading the socket
MAX_CLIENTS = 32  # connections at once; more are answered 503
RATE_PER_S = 30.0  # commands per second a client may send, sustained
RATE_BURST = 60.0  # ... and at once
MAX_REFUSED = 200  # refused (rate-limited or malformed) messages in a row before the connection is closed
STALL_S = 2.0  # a send that waits longer than this on a client (it does not read): the client is dropped
WRITE_LIMIT = 256 << 10  # bytes buffered for a client before a send waits for it to read
VIEW_MAX_BYTES = 16 << 20  # the largest view frame sent (4K RGBA before compression is 33 MB: halved first)
OSC_RATE_PER_S = 60.0  # OSC datagrams per second over all senders
OSC_BURST = 120.0


class RateLimit:
    """A token bucket: :meth:`take` is True while the client is within ``rate`` per second (``burst`` at once).

    Time is the caller's (seconds, monotonic), so a test can drive it without sleeping."""

    def __init__(self, rate: float = RATE_PER_S, burst: float = RATE_BURST) -> None:
        self.rate, self.burst = float(rate), float(burst)
        self.tokens = self.burst
        self.at: float | None = None

    def take(self, now: float) -> bool:
        if self.at is not None:
            self.tokens = min(self.burst, self.tokens + (now - self.at) * self.rate)
        self.at = now
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return True
        return False
