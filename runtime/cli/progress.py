"""Progress of long work: one line on stderr, rewritten in place, with an estimate.

Every long command (replay of a long take, ``fit-retarget``, rig import, the
longer benchmarks) reports through :class:`Progress`, so they all read alike::

    fit-retarget: 37/120 folds (31%), 2.4/s, ~35 s left  components 12

The line is drawn only on a terminal and at most every ``interval_s``; piped
or redirected output stays clean (the command's own summary lines are what
land in a log). Work long enough that a log would otherwise sit silent for
minutes (a replay of a long take) asks for ``piped_every_s``: off a terminal it
then writes the same text as a whole line every that many seconds, never a
carriage return, so a log shows it is alive and how far it got without
filling with redraws. The clock is injectable so the arithmetic is testable.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO


def _duration(seconds: float) -> str:
    if seconds < 60:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{seconds // 60:.0f} min {seconds % 60:02.0f} s"
    return f"{seconds // 3600:.0f} h {seconds % 3600 // 60:02.0f} min"


class Progress:
    """Count of ``total`` steps done, drawn as a line with rate and time left.

    ``enabled`` defaults to whether ``stream`` (stderr) is a terminal. ``total``
    may be None (unknown length): the line then shows the count and rate only.
    ``piped_every_s``: when not enabled (not a terminal), write the line as a plain line of its own every
    this many seconds (None: nothing, the default). Use as a context manager or call :meth:`close`; closing
    ends the line.
    """

    def __init__(
        self,
        label: str,
        total: float | None = None,
        *,
        unit: str = "",
        stream: TextIO | None = None,
        enabled: bool | None = None,
        interval_s: float = 0.25,
        clock: Callable[[], float] = time.monotonic,
        piped_every_s: float | None = None,
    ) -> None:
        self.label = label
        self.total = total
        self.unit = unit
        self.stream = stream if stream is not None else sys.stderr
        if enabled is None:
            isatty = getattr(self.stream, "isatty", None)
            enabled = bool(isatty and isatty())
        self.enabled = enabled
        self.interval_s = interval_s
        self.piped_every_s = piped_every_s
        self.clock = clock
        self.done: float = 0
        self._start = clock()
        self._drawn_at: float | None = None
        self._width = 0
        self._closed = False

    def line(self, note: str = "") -> str:
        """The text of the progress line now (without the carriage return)."""
        elapsed = max(self.clock() - self._start, 1e-9)
        unit = f" {self.unit}" if self.unit else ""
        rate = self.done / elapsed
        if self.total:
            fraction = min(self.done / self.total, 1.0)
            text = f"{self.label}: {self.done:g}/{self.total:g}{unit} ({100 * fraction:.0f}%)"
        else:
            text = f"{self.label}: {self.done:g}{unit}"
        text += f", {rate:.3g}/s" if self.done else ""
        if self.total and 0 < self.done < self.total:
            text += f", ~{_duration((self.total - self.done) / rate)} left"
        elif self.total and self.done >= self.total:
            text += f", {_duration(elapsed)}"
        return f"{text}  {note}" if note else text

    def update(self, done: float, note: str = "") -> None:
        """Set the count done; redraws when enabled and ``interval_s`` has passed."""
        self.done = done
        if self._closed:
            return
        if not self.enabled:
            if self.piped_every_s is not None:
                self._log_line(note)
            return
        now = self.clock()
        if self._drawn_at is not None and now - self._drawn_at < self.interval_s:
            return
        self._drawn_at = now
        self._draw(note, end="")

    def step(self, done: float, total: float, note: str = "") -> None:
        """:meth:`update` with the total as well: the ``progress(i, n, name)`` callback that long work (a
        reader, an exporter, a comparison) reports through, when the total is known only as it goes."""
        self.total = total
        self.update(done, note=note)

    def advance(self, n: float = 1, note: str = "") -> None:
        """Add ``n`` steps done."""
        self.update(self.done + n, note)

    def write(self, text: str) -> None:
        """Print ``text`` as a line of its own (always, terminal or not: a result, not progress); a drawn
        progress line is cleared first and drawn again below it."""
        if self.enabled and self._drawn_at is not None and not self._closed:
            self.stream.write("\r" + " " * self._width + "\r" + text + "\n")
            self._width = 0
            self._draw("", end="")
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def close(self, note: str = "") -> None:
        """Draw the final line and end it (once); nothing when disabled."""
        if self._closed:
            return
        self._closed = True
        if self.enabled and (self._drawn_at is not None or note):
            self._draw(note, end="\n")

    def _log_line(self, note: str) -> None:
        """Off a terminal: the line as a plain line of its own, once ``piped_every_s`` has passed since the
        start or the last one."""
        now = self.clock()
        since = self._start if self._drawn_at is None else self._drawn_at
        if now - since < self.piped_every_s:
            return
        self._drawn_at = now
        self.stream.write(self.line(note) + "\n")
        self.stream.flush()

    def _draw(self, note: str, end: str) -> None:
        text = self.line(note)
        pad = max(self._width - len(text), 0)
        self._width = len(text)
        self.stream.write("\r" + text + " " * pad + end)
        self.stream.flush()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
