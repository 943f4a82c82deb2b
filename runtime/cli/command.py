"""The ``facepuppet`` command.

Runtime commands live in runtime modules, each with ``register(subparsers)``;
offline commands arrive through the ``facepuppet.commands`` entry-point group
(see pyproject.toml), so this module never imports ``offline``.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
import traceback
from importlib.metadata import entry_points

from facepuppet.runtime.errors import FacepuppetError, RecordingFailed
from facepuppet.runtime.files.outputs import add_output_policy, check_outputs
from facepuppet.runtime.render.blas_threads import BlasThreads
from facepuppet.runtime.render.gl_context import GLUnavailable  # building the parser imports GL anyway

from facepuppet import __version__

# Runtime modules that add subcommands, in the order --help lists them. Each
# must exist and import: a missing one is an error, never a silently dropped command.
_COMMAND_MODULES = (
    "facepuppet.runtime.commands.run",
    "facepuppet.runtime.commands.manipulate",
    "facepuppet.runtime.commands.demo",
    "facepuppet.runtime.commands.replay",
    "facepuppet.runtime.commands.contact_sheet",
    "facepuppet.runtime.bench.registry",
)


def build_parser() -> argparse.ArgumentParser:

    parser = argparse.ArgumentParser(
        prog="facepuppet",
        description="Realtime facial puppetry: trackers in, a retargeted character out.",
    )
    parser.add_argument("--version", action="version", version=f"facepuppet {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in _COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    for ep in entry_points(group="facepuppet.commands"):
        ep.load()(sub)
    for command in sub.choices.values():   # one policy for every command's outputs (runtime/files/outputs.py)
        add_output_policy(command)
    return parser


# Commands that draw every frame. They run with one BLAS thread: the CPU
# deformation path's saxpy, split over OpenBLAS workers that compete with
# llvmpipe's rasteriser threads, stalled for 100-600 ms now and then on a
# 2-core machine (see runtime/render/blas_threads.py).
_RENDERING_COMMANDS = frozenset({"run", "replay", "demo", "manipulate", "contact-sheet", "bench"})


def main(argv: list[str] | None = None) -> int:
    """Run one command; every refusal a user can cause becomes one line and an exit code here, in one place.

    A refusal is a :class:`FacepuppetError` (a bad option, a file that cannot be used, a table that does not
    fit, a missing device) or an ``OSError`` (a file missing or unreadable, an address that cannot be bound):
    ``facepuppet COMMAND: error: MESSAGE`` on stderr, no traceback. argparse refuses its own usage errors
    before this (exit 2). Anything else is a bug in facepuppet, not the user's fault: it is not caught, so
    Python shows its traceback and exits 1. ``FACEPUPPET_DEBUG=1`` in the environment shows the traceback of
    a refusal too, then its line, with the same exit code.

    Exit codes: 0 done; 2 refused (an option, a file, a table, an output, an address); 3 no OpenGL context;
    130 interrupted (also a replay stopped by Ctrl-C, after its summary; 143 one stopped by SIGTERM); 1 a run
    whose recording could not be written to its end (:class:`RecordingFailed`, one line), or a bug (a
    traceback).
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    _configure_logging()
    try:
        check_outputs(args)   # an output that exists (without --force) is refused before any work
        if args.command in _RENDERING_COMMANDS:
            with BlasThreads(1):
                return int(args.func(args) or 0)
        return int(args.func(args) or 0)
    except GLUnavailable as exc:
        return _error(args.command, exc, 3)
    except RecordingFailed as exc:
        return _error(args.command, exc, 1)
    except (FacepuppetError, OSError) as exc:
        return _error(args.command, exc, 2)
    except KeyboardInterrupt:
        print(f"facepuppet {args.command}: interrupted", file=sys.stderr)
        return 130


class _Stderr(logging.StreamHandler):
    """A handler writing to whatever ``sys.stderr`` is when a line is logged (not the stream of the moment it
    was made: a caller that swaps stderr, as a test's capture does, gets the lines)."""

    def __init__(self) -> None:
        super().__init__(sys.stderr)

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:
        pass


def _configure_logging() -> None:
    """Library modules log through ``logging.getLogger(__name__)``; the command shows facepuppet's INFO
    lines as plain text on stderr (other libraries' only from WARNING up); what a command finds, it prints
    on stdout."""
    ours = logging.getLogger("facepuppet")
    if not any(isinstance(h, _Stderr) for h in ours.handlers):
        handler = _Stderr()
        handler.setFormatter(logging.Formatter("%(message)s"))
        ours.addHandler(handler)
        ours.propagate = False
    if ours.level in (logging.NOTSET,) or ours.level > logging.INFO:  # put back, whoever changed it since
        ours.setLevel(logging.INFO)


def _error(command: str, exc: BaseException, code: int) -> int:
    """The one line of a refusal (after its traceback with ``FACEPUPPET_DEBUG=1``); ``code`` back."""
    if os.environ.get("FACEPUPPET_DEBUG", "") not in ("", "0"):
        traceback.print_exception(exc, file=sys.stderr)
    print(f"facepuppet {command}: error: {exc}", file=sys.stderr)
    return code


if __name__ == "__main__":
    raise SystemExit(main())
