"""Where the offline benchmarks find the real data kit (ICT head, takes, speech).

The kit is the user's, not the package's: ``--data DIR`` names it, or the
``FACEPUPPET_DATA`` environment variable (``make bench`` sets it). A bench
that needs it and finds neither stops with a message saying so.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from facepuppet.runtime.errors import UsageError

ENV = "FACEPUPPET_DATA"


def add_data_argument(parser: argparse.ArgumentParser) -> None:
    """``--data DIR``, defaulting to $FACEPUPPET_DATA."""
    parser.add_argument("--data", type=Path, default=None,
                        help=f"the data kit folder (default: ${ENV})")


def data_dir(value: str | os.PathLike | None) -> Path:
    """The data kit folder from ``--data`` or $FACEPUPPET_DATA; ValueError when neither names a folder."""
    chosen = value if value is not None else os.environ.get(ENV)
    if not chosen:
        raise UsageError(f"this benchmark needs the data kit: pass --data DIR or set {ENV}")
    path = Path(chosen)
    if not path.is_dir():
        raise UsageError(f"data kit folder {path} does not exist (from {'--data' if value is not None else ENV})")
    return path
