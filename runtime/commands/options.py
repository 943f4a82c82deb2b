"""Parsers of the option values the commands share: image size, host:port, sender allow lists.

Each raises ValueError naming the option and what it expected, so ``cli.main`` reports it as a usage error.
"""

from __future__ import annotations

import ipaddress
import re

from facepuppet.runtime.errors import UsageError


def parse_size(text: str) -> tuple[int, int]:
    """(width, height) of ``"1280x720"``; ValueError otherwise."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if m is None or int(m.group(1)) <= 0 or int(m.group(2)) <= 0:
        raise UsageError(f"--size: expected WIDTHxHEIGHT in pixels such as 1280x720, got {text!r}")
    return int(m.group(1)), int(m.group(2))


def parse_host_port(text: str, option: str = "--vmc-out") -> tuple[str, int]:
    """(host, port) of ``"HOST:PORT"``; ValueError naming the option otherwise."""
    m = re.fullmatch(r"\s*(\[[^\]]+\]|[^:\s]+):(\d+)\s*", text or "")
    if m is None or not 0 < int(m.group(2)) < 65536:
        raise UsageError(f"{option}: expected HOST:PORT such as 127.0.0.1:39539, got {text!r}")
    return m.group(1).strip("[]"), int(m.group(2))


def parse_allow(text: str | None) -> set[str] | None:
    """Sender IPs of ``--allow`` ("10.0.0.2,10.0.0.3"), or None; ValueError on a bad address."""
    if text is None:
        return None
    allow = set()
    for part in text.split(","):
        try:
            allow.add(str(ipaddress.ip_address(part.strip())))
        except ValueError:
            raise UsageError(f"--allow: expected comma-separated IP addresses, got {part.strip()!r}") from None
    return allow
