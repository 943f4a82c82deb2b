"""``run``'s control options: ``--web [HOST:PORT]`` (the control API, its pages, its OSC port) and its token.

``--web`` alone listens on 127.0.0.1:8765: the WebSocket and the two pages over TCP, the same verbs as OSC over
UDP, both on that port. Another host (a tablet on the LAN) needs a token: ``--web-token`` gives one, else one is
generated and printed once; every page URL and WebSocket then carries ``?token=...`` and every OSC message
starts with it.
"""

from __future__ import annotations

import argparse
import ipaddress
import re
import secrets
from dataclasses import dataclass

from facepuppet.runtime.errors import UsageError

DEFAULT_WEB = "127.0.0.1:8765"
DEFAULT_VIEW_FPS = 30.0
_TOKEN = re.compile(r"[A-Za-z0-9_.~-]{16,128}")


def is_loopback(host: str) -> bool:
    """Whether ``host`` is a loopback address (``localhost`` counts)."""
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def parse_web_address(text: str) -> tuple[str, int]:
    """(host, port) of ``--web HOST:PORT`` (port 0: any free port, said in the log); UsageError otherwise."""
    m = re.fullmatch(r"\s*(\[[^\]]+\]|[^:\s]+):(\d+)\s*", text or "")
    if m is None or not 0 <= int(m.group(2)) < 65536:
        raise UsageError(f"--web: expected HOST:PORT such as {DEFAULT_WEB}, got {text!r}")
    host = m.group(1).strip("[]")
    if host != "localhost":
        try:
            ipaddress.ip_address(host)
        except ValueError:
            raise UsageError(f"--web: the host is an IP address (or localhost), got {host!r}") from None
    return host, int(m.group(2))


@dataclass(frozen=True)
class ControlOptions:
    """``--web``, ``--web-token``, ``--web-view-fps``.

    Attributes
    ----------
    web : (host, port) or None, where the control API listens (None: no control API)
    token : str or None, what every client must give (always set for a non-loopback host)
    generated : bool, the token was generated here (the run prints it once)
    view_fps : float, the most frames per second the view page is sent
    """

    web: tuple[str, int] | None = None
    token: str | None = None
    generated: bool = False
    view_fps: float = DEFAULT_VIEW_FPS

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        group = parser.add_argument_group("control", "steer the show from a browser, a Stream Deck or a script")
        group.add_argument("--web", nargs="?", const=DEFAULT_WEB, default=None, metavar="HOST:PORT",
                           help=f"serve the control API (JSON over WebSocket; the same verbs as OSC over UDP on the "
                                f"same port), the remote panel page and the OBS view page (default {DEFAULT_WEB}; "
                                "another host than loopback needs a token)")
        group.add_argument("--web-token", default=None, metavar="TOKEN",
                           help="the token clients give (?token= in the URL, OSC's first argument); generated and "
                                "printed once for a non-loopback --web without one")
        group.add_argument("--web-view-fps", type=float, default=DEFAULT_VIEW_FPS, metavar="FPS",
                           help=f"the most frames per second sent to the view page (default {DEFAULT_VIEW_FPS:g})")

    @classmethod
    def from_args(cls, ns: argparse.Namespace) -> ControlOptions:
        text = getattr(ns, "web", None)
        token = getattr(ns, "web_token", None)
        fps = getattr(ns, "web_view_fps", DEFAULT_VIEW_FPS)
        if text is None:
            if token is not None:
                raise UsageError("--web-token: only with --web")
            return cls()
        web = parse_web_address(text)
        if token is not None and not _TOKEN.fullmatch(token):
            raise UsageError("--web-token: 16 to 128 characters of letters, digits and -._~ (it goes in URLs)")
        if not (isinstance(fps, (int, float)) and 0 < fps <= 60):
            raise UsageError(f"--web-view-fps: expected a number in (0, 60], got {fps!r}")
        generated = token is None and not is_loopback(web[0])
        if generated:
            token = secrets.token_urlsafe(18)
        return cls(web, token, generated, float(fps))
