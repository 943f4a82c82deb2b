"""Offline subcommands of ``facepuppet``, registered through an entry point."""

from __future__ import annotations


def register(subparsers) -> None:
    """Add the offline commands to the ``facepuppet`` parser."""
