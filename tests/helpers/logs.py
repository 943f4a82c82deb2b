"""What a command says, captured for a test to read: its log lines (``logging``, under the ``facepuppet``
logger) and what it prints."""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator


class _Lines(logging.Handler):
    def __init__(self, lines: list[str]) -> None:
        super().__init__(logging.DEBUG)
        self.lines = lines

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(record.getMessage())


class _Printed:
    """A text stream that appends each complete printed line to ``lines``."""

    def __init__(self, lines: list[str]) -> None:
        self.lines = lines
        self._tail = ""

    def write(self, text: str) -> int:
        *done, self._tail = (self._tail + text).split("\n")
        self.lines.extend(done)
        return len(text)

    def flush(self) -> None:
        pass


@contextlib.contextmanager
def session_log(lines: list[str] | None = None, name: str = "facepuppet") -> Iterator[list[str]]:
    """Within the block, every INFO line (and above) of ``name``'s loggers is appended to ``lines`` (a new
    list when None), which is yielded, whatever the command line's logging set-up."""
    lines = [] if lines is None else lines
    logger = logging.getLogger(name)
    handler, level = _Lines(lines), logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    try:
        yield lines
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)


@contextlib.contextmanager
def logged(lines: list[str] | None = None) -> Iterator[list[str]]:
    """Within the block, what a command says in order, its log lines and what it prints, appended to
    ``lines`` (a new list when None), which is yielded."""
    with session_log(lines) as lines, contextlib.redirect_stdout(_Printed(lines)):
        yield lines


def said(capsys) -> str:
    """Everything a command run in this test said, as one text: what it printed (its results, on stdout)
    followed by what it logged (on stderr)."""
    captured = capsys.readouterr()
    return captured.out + captured.err
