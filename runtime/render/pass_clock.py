"""Time each draw pass of a frame: where a frame's GPU time goes, pass by pass.

A frame's passes (clear, opaque surfaces, blended layers, label, MSAA
resolve) are queued by the CPU and run later by the GPU, so the CPU time of
a draw call says nothing about what the pass costs. Two ways to see it:

* ``"finish"``: wait for the GPU (``ctx.finish()``) after every pass and take
  the wall time between waits. Exact on a software rasteriser (llvmpipe runs
  the queued work at the wait), and close on a real GPU, but it stops the
  CPU and GPU from overlapping, so the frame as a whole is slower than
  unprofiled: use it to compare passes, not to measure the frame.
* ``"query"``: an OpenGL timer query (``GL_TIME_ELAPSED``) around each pass,
  read after the frame. What a real GPU reports as its own time, without
  stalling; llvmpipe answers timer queries without measuring (about 1 ns),
  so on a software rasteriser only ``"finish"`` is meaningful.

A renderer calls :meth:`PassClock.mark` after each pass; a frame with no
clock calls nothing (:data:`NO_CLOCK`), so the live loop pays nothing.
"""

from __future__ import annotations

import time

import moderngl

MODES = ("finish", "query")


class PassClock:
    """Milliseconds per named pass, frame by frame.

    Parameters
    ----------
    ctx : moderngl.Context
    mode : "finish" or "query" (see the module doc)

    Attributes
    ----------
    frames : list of dict, one per frame: pass name -> ms, in pass order
    """

    def __init__(self, ctx: moderngl.Context, mode: str = "finish") -> None:
        if mode not in MODES:
            raise ValueError(f"mode: expected one of {MODES}, got {mode!r}")
        self.ctx, self.mode = ctx, mode
        self.frames: list[dict[str, float]] = []
        self._queries: list[moderngl.Query] = []  # query mode: one per pass position, reused every frame
        self._names: list[str] = []
        self._current: dict[str, float] = {}
        self._t = 0.0

    def start(self) -> None:
        """Begin a frame: the GPU is idle (what came before is not counted) and the first pass's clock runs."""
        self.ctx.finish()
        self._names, self._current = [], {}
        if self.mode == "query":
            self._begin(0)
        self._t = time.perf_counter()

    def mark(self, name: str) -> None:
        """The pass ``name`` has been issued: its time is the time since the previous mark (or the start)."""
        if self.mode == "finish":
            self.ctx.finish()
            now = time.perf_counter()
            self._add(name, (now - self._t) * 1e3)
            self._t = now
        else:
            self._queries[len(self._names)].__exit__(None, None, None)
            self._names.append(name)
            self._begin(len(self._names))

    def stop(self) -> dict[str, float]:
        """End the frame; returns (and keeps in :attr:`frames`) ms per pass, in pass order."""
        if self.mode == "query":
            self._queries[len(self._names)].__exit__(None, None, None)  # the empty tail after the last mark
            self.ctx.finish()
            for name, query in zip(self._names, self._queries):
                self._add(name, query.elapsed / 1e6)
        self.frames.append(self._current)
        return self._current

    def _add(self, name: str, ms: float) -> None:
        self._current[name] = self._current.get(name, 0.0) + ms

    def _begin(self, i: int) -> None:
        if i == len(self._queries):
            self._queries.append(self.ctx.query(time=True))
        self._queries[i].__enter__()


class NoClock:
    """Marks nothing: a frame drawn without a clock."""

    @staticmethod
    def mark(name: str) -> None:
        return None


NO_CLOCK = NoClock()
