"""facepuppet.runtime.cli: the ``facepuppet`` command. The parser and ``main`` (:mod:`.command`), the
commands reference written from it (:mod:`.reference`), the progress line of long work (:mod:`.progress`).
The commands themselves live in :mod:`facepuppet.runtime.commands` and the offline entry points.
"""

from facepuppet.runtime.cli.command import build_parser, main

__all__ = ["build_parser", "main"]
