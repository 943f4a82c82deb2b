"""Pictures handed from the frame loop to a live consumer (a virtual camera, a network stream) that must never
slow the loop.

A live output's consumer (a camera driver, a video encoder, a socket) can stall for any reason: a codec's
slow frame, a kernel buffer full, a viewer not reading. The frame loop only reads the tick's pixels back (it
owns the GL context), as the framebuffer holds them (RGBA, bottom row first: the cheapest read, with no
conversion or copy), and puts them in a one-picture mailbox; one worker thread takes them out and does the
rest (the picture turned top row first by :func:`~facepuppet.runtime.render.readback.top_first`, RGBA with
colour x alpha, then the output's own work). When the worker is
still busy and a picture is already waiting, the waiting one is replaced by the new one and counted as
dropped: the viewer always gets the newest picture, late ones never pile up, and the loop's cost is the
read-back plus a lock, whatever the consumer does.

:class:`TickReadback` reads one tick's pixels once for every live output that wants them (a stream and a
virtual camera in one run cost one read); :func:`over_key` puts a picture with alpha over the key colour
of an output that carries none.

An output announced at a frame rate (a camera at ``--fps``) takes at most one picture per slot of that rate's
grid (``fps``): a live run drawing on arrival of a 120 Hz tracker draws 120 ticks a second, and the ticks
between slots are left out before their pixels are read (counted as ``over_rate``).

A consumer that raises is logged once and given nothing more: later pictures are counted as dropped, the
run goes on (a show does not stop because a viewer's network went away), and :attr:`FrameHandoff.failure`
says why.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.live.timing import DurationSketch
from facepuppet.runtime.render.readback import top_first

if TYPE_CHECKING:
    from facepuppet.runtime.live.loop import TickInfo

logger = logging.getLogger(__name__)


class TickReadback:
    """The pixels of the newest tick, read from the renderer once a tick for every output that wants them.

    :meth:`pixels` gives the finished picture (:meth:`~facepuppet.runtime.render.renderer.FaceRenderer.read_pixels`:
    top row first, RGB or straight RGBA; the video), :meth:`stored` the framebuffer's own RGBA with the
    function that turns it into what a live output takes (:func:`live_picture`), run in the output's
    thread. Outputs share the arrays and must not write into them.

    Attributes
    ----------
    reads : int, reads from the GPU
    """

    def __init__(self) -> None:
        self._pixels_key: tuple | None = None
        self._pixels: np.ndarray | None = None
        self._stored_key: tuple | None = None
        self._stored: tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]] | None = None
        self.reads = 0

    def pixels(self, info: TickInfo) -> np.ndarray:
        """The tick's finished picture: (h, w, 3) RGB or (h, w, 4) straight RGBA, top row first."""
        key = (id(info.renderer), info.k, info.stamps[4])
        if key != self._pixels_key:
            self._pixels_key, self._pixels = key, info.renderer.read_pixels()
            self.reads += 1
        return self._pixels

    def stored(self, info: TickInfo) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]:
        """The tick's picture as read, and the function that makes it a live picture (:func:`live_picture`)."""
        key = (id(info.renderer), info.k, info.stamps[4])
        if key != self._stored_key:
            if hasattr(info.renderer, "read_rgba"):
                self._stored = (info.renderer.read_rgba(), top_first)
                self.reads += 1
            else:  # a renderer that can only give the finished picture
                self._stored = (self.pixels(info), live_picture)
            self._stored_key = key
        return self._stored


def live_picture(pixels: np.ndarray) -> np.ndarray:
    """What a live output takes: (h, w, 4) RGBA, top row first, colour x alpha; from a finished picture ((h, w, 3)
    RGB, or (h, w, 4) straight RGBA: a renderer without ``read_rgba``)."""
    if pixels.shape[2] == 3:
        out = np.empty((*pixels.shape[:2], 4), np.uint8)
        out[:, :, :3] = pixels
        out[:, :, 3] = 255
        return out
    a = pixels[:, :, 3:4].astype(np.uint16)
    out = pixels.copy()
    out[:, :, :3] = (pixels[:, :, :3].astype(np.uint16) * a + 127) // 255
    return out


def over_key(pixels: np.ndarray, key: tuple[int, int, int]) -> np.ndarray:
    """(h, w, 3) uint8: a live picture ((h, w, 4) RGBA, colour x alpha) over the colour ``key``; an (h, w, 3) RGB
    one as it is."""
    if pixels.shape[2] == 3:
        return pixels
    a = pixels[:, :, 3:4].astype(np.uint16)
    rgb = pixels[:, :, :3].astype(np.uint16) * 255 + np.asarray(key, np.uint16) * (255 - a)
    return ((rgb + 127) // 255).astype(np.uint8)


class FrameHandoff:
    """One worker thread consuming the pictures the frame loop offers, newest first, dropping what it cannot take.

    Parameters
    ----------
    consume : callable(k, t, stamp, pixels) run in the worker for each picture taken: ``k`` the tick, ``t`` its
        time (s), ``stamp`` its GPU-finished time (``time.perf_counter``), ``pixels`` the (h, w, 3|4) uint8 array
    name : str, the output's name (the thread's name and the log lines)
    fps : float or None, at most one picture per 1/fps slot of tick time (None: every tick)
    clock : callable, seconds on the loop's timer clock (``time.perf_counter``)

    Attributes
    ----------
    counters : dict: ``offered`` (pictures the loop handed over), ``sent`` (consumed), ``dropped`` (replaced
        while waiting, or offered after a failure), ``failed`` (1 once the consumer raised), ``over_rate``
        (ticks left out between two slots of ``fps``; their pixels were not read)
    loop : DurationSketch, seconds the loop spent per tick in :meth:`take` (the read-back, the lock, the mailbox)
    work : DurationSketch, seconds the worker spent per picture
    delay : DurationSketch, seconds from the tick's GPU-finished stamp to the consumer's return (what a
        viewer waits on top of the drawing, before its own transport and display)
    failure : str or None, why the consumer stopped
    """

    #: a tick up to this fraction of a slot early still takes that slot (tick times jitter on arrival)
    SLOT_SLACK = 0.1

    def __init__(self, consume: Callable[[int, float, float, np.ndarray], None], name: str,
                 fps: float | None = None, clock: Callable[[], float] = time.perf_counter) -> None:
        self._consume = consume
        self.name = name
        self._clock = clock
        self._cond = threading.Condition()
        self._waiting: tuple | None = None
        self._busy = False
        self._closing = False
        self.counters = {"offered": 0, "sent": 0, "dropped": 0, "failed": 0, "over_rate": 0}
        self._fps = None if fps is None else float(fps)
        self._slot = -math.inf
        self.loop = DurationSketch()
        self.work = DurationSketch()
        self.delay = DurationSketch()
        self.failure: str | None = None
        self._thread = threading.Thread(target=self._run, name=f"out-{name}", daemon=True)
        self._thread.start()

    def take(self, info: TickInfo, readback: TickReadback) -> None:
        """Tick observer's part: the tick's pixels read back (once for every output) and offered, unless the
        tick falls in a slot of ``fps`` already taken."""
        if self._fps is not None:
            slot = math.floor(info.t * self._fps + self.SLOT_SLACK)
            if slot <= self._slot:
                self.counters["over_rate"] += 1
                return
            self._slot = slot
        t0 = self._clock()
        pixels, finish = readback.stored(info)
        self.offer(info.k, info.t, info.stamps[4], pixels, finish)
        self.loop.add(self._clock() - t0)

    def offer(self, k: int, t: float, stamp: float, pixels: np.ndarray,
              finish: Callable[[np.ndarray], np.ndarray] | None = None) -> bool:
        """Hand a picture over without waiting (``finish``: what turns it into the consumer's picture, run in
        the worker); False when it (or the one it replaced) was dropped."""
        c = self.counters
        with self._cond:
            c["offered"] += 1
            if self.failure is not None or self._closing:
                c["dropped"] += 1
                kept = False
            else:
                kept = self._waiting is None
                if not kept:
                    c["dropped"] += 1  # the older waiting picture gives way to the newer one
                self._waiting = (k, t, stamp, pixels, finish)
                self._cond.notify()
        return kept

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._waiting is None and not self._closing:
                    self._cond.wait()
                item, self._waiting = self._waiting, None
                if item is None:  # closing, nothing left
                    return
                self._busy = True
            k, t, stamp, pixels, finish = item
            t0 = self._clock()
            try:
                self._consume(k, t, stamp, pixels if finish is None else finish(pixels))
            except Exception as exc:  # the run goes on; said once
                with self._cond:
                    self.failure = f"{type(exc).__name__}: {exc}"
                    self.counters["failed"] = 1
                    self.counters["dropped"] += 1
                    self._busy = False
                    if self._waiting is not None:
                        self._waiting = None
                        self.counters["dropped"] += 1
                    self._cond.notify_all()
                logger.warning("%s: stopped sending: %s (the run goes on without it)", self.name, self.failure)
                return
            t1 = self._clock()
            self.work.add(t1 - t0)
            self.delay.add(t1 - stamp)
            with self._cond:
                self.counters["sent"] += 1
                self._busy = False
                self._cond.notify_all()

    def drain(self) -> None:
        """Wait until the worker has taken and finished every picture offered so far (tests, the end of a run)."""
        with self._cond:
            while (self._waiting is not None or self._busy) and self.failure is None and self._thread.is_alive():
                self._cond.wait(0.1)

    #: seconds :meth:`close` waits for a consumer still busy (a device or a socket that blocks)
    CLOSE_WAIT_S = 5.0

    def close(self) -> bool:
        """Finish the waiting picture, then stop the worker; False when the consumer is still busy after
        ``CLOSE_WAIT_S`` (it is left behind, said once: the end of a run never hangs on a viewer)."""
        with self._cond:
            self._closing = True
            self._cond.notify_all()
        self._thread.join(self.CLOSE_WAIT_S)
        if self._thread.is_alive():
            logger.warning("%s: still busy %g s after the end of the run; left behind", self.name,
                           self.CLOSE_WAIT_S)
            return False
        return True

    def costs(self) -> dict:
        """The figures of :meth:`~facepuppet.runtime.live.stats.LiveStats`' kind, in ms: the loop's share, the
        worker's, the delay to the consumer; and the counts."""
        def q(sketch: DurationSketch) -> dict:
            if not sketch.n:
                return {"n": 0}
            return {"n": sketch.n, "p50": sketch.quantile(0.5) * 1e3, "p99": sketch.quantile(0.99) * 1e3,
                    "max": sketch.max * 1e3}
        return {"loop_ms": q(self.loop), "worker_ms": q(self.work), "delay_ms": q(self.delay),
                **self.counters, "failure": self.failure}
