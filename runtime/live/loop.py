"""The frame loop: one snapshot, the stage chain, one map, one draw per tick, on a clock it is given.

Tick ``k`` happens at time ``t_k = k / fps`` (seconds since the source's first
frame). Each tick takes the newest frame the source has by ``t_k`` (older ones
are dropped and counted, never queued), rejects it if it is not finite, runs
the stages (:func:`~facepuppet.runtime.live.stages.build_chain`), maps the last
stage's channels onto the renderer's by name with a
:class:`~facepuppet.runtime.mapping.channels.ChannelMap` cached per channel tuple (an
:class:`~facepuppet.runtime.mapping.expressions.ExpressionMap` for a character with VRM
expressions: channels onto morphs and expressions),
draws, waits for the GPU, and hands the tick to its observers (one interface,
:class:`~facepuppet.runtime.protocols.TickObserver`: PNG frames, the weight log, video, OSC
outputs, the recorder, the live stats).

The clock only paces the ticks; it never decides what is drawn. With a
:class:`RecordedClock` (headless replay) ticks follow one another at once; with
a :class:`WallClock` (a window) each tick waits for its real time, and a tick
that is late is counted but still drawn at its recorded time, so the same
recording gives the same frames either way (DESIGN.md, Determinism).

A live run draws *on arrival* instead (``idle_fps``): the loop sleeps in the
source's ``wait_for_frame`` until a new frame arrives (or ``1 / idle_fps``
passes, so easing and gestures keep moving), and the tick is labelled with
the first index of the ``fps`` grid at or after that moment. With a fine grid
(the live run uses 1 kHz) a frame waits for nothing but the previous draw, and
the labels still replay tick for tick.
"""

from __future__ import annotations

import gc
import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.live.mapper import Mapper
from facepuppet.runtime.live.timing import StageTimer

if TYPE_CHECKING:
    from facepuppet.runtime.mapping.channels import ChannelMap
    from facepuppet.runtime.mapping.expressions import ExpressionDrive, ExpressionMap
    from facepuppet.runtime.protocols import FrameSource, Renderer, Stage, TickObserver
    from facepuppet.runtime.render.gl_context import GLTarget

logger = logging.getLogger(__name__)

STAGES = ("snapshot", "map", "draw_submit", "gpu_finish", "sink")
ARRIVAL_GRID_HZ = 1000.0  # tick-label grid of a run that draws on arrival (see the module docstring)


class RecordedClock:
    """Recorded time that advances at once: ``wait_until(t)`` never sleeps."""

    def __init__(self) -> None:
        self._now = 0.0

    def start(self) -> None:
        self._now = 0.0

    def now(self) -> float:
        """Seconds since :meth:`start` on recorded time."""
        return self._now

    def wait_until(self, t: float) -> float:
        """Advance to ``t``; returns the lateness (always 0.0)."""
        self._now = max(self._now, t)
        return 0.0


class WallClock:
    """Real time: ``wait_until(t)`` sleeps until ``t`` seconds after :meth:`start`.

    Parameters
    ----------
    monotonic : callable returning seconds (default ``time.monotonic``)
    sleep : callable taking seconds (default ``time.sleep``)
    """

    def __init__(self, monotonic: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        self._monotonic = monotonic
        self._sleep = sleep
        self._origin = monotonic()

    def start(self) -> None:
        self._origin = self._monotonic()

    def now(self) -> float:
        return self._monotonic() - self._origin

    def wait_until(self, t: float) -> float:
        """Sleep until ``t``; returns how late we already were (seconds, 0.0 when on time)."""
        ahead = t - self.now()
        if ahead > 0:
            self._sleep(ahead)
            return 0.0
        return -ahead


class TickInfo:
    """What one tick did, handed to the tick observers and overlays (one object, reused every tick).

    Attributes
    ----------
    k : int, tick index
    t : float, tick time (s)
    raw : Frame or None, the new frame the snapshot returned this tick (before the stages)
    frame : Frame or None, the frame on screen (after the stages)
    weights : ndarray of shape (n_shapes,), float32, the rig weights drawn (the loop's buffer: copy to keep)
    rotation, translation : ndarray or None, the head pose drawn
    expressions : ndarray of shape (n_expressions,), float32, or None: the values of the character's VRM
        expressions drawn (after isBinary and overrides; the map's buffer), None when the map drives none
    stamps : tuple of 5 floats on the loop's timer clock (``time.perf_counter``, which is the
        monotonic clock on Linux): snapshot start, snapshot end, map end, draw submitted, GPU finished
        (for the overlays, which run before the GPU wait: the previous tick's)
    renderer : Renderer, what drew the tick (``read_pixels()`` for its picture)
    """

    __slots__ = ("k", "t", "raw", "frame", "weights", "rotation", "translation", "expressions", "stamps",
                 "renderer")

    def __init__(self, renderer: Renderer | None = None) -> None:
        self.k, self.t, self.raw, self.frame, self.weights = 0, 0.0, None, None, None
        self.rotation = self.translation = self.expressions = None
        self.stamps = (0.0,) * 5
        self.renderer = renderer


@dataclass
class LoopResult:
    """What one :meth:`FrameLoop.run` did.

    Attributes
    ----------
    n_ticks : int, ticks drawn
    counters : dict of str to int: ``frames_received`` (frames the source
        delivered, stale ones included), ``stale_dropped``,
        ``nonfinite_rejected``, ``ticks_without_new_frame``, ``late_ticks``,
        ``skipped_ticks`` (late ticks skipped with ``catch_up``)
    timings : dict, :meth:`StageTimer.summary` of the stages in ``STAGES``
    timer : StageTimer, the raw durations
    closed_by_window : bool, the window asked to close before the end
    """

    n_ticks: int
    counters: dict[str, int]
    timings: dict[str, dict[str, float]]
    timer: StageTimer
    closed_by_window: bool = False


class FrameLoop:
    """Drive a renderer from a frame source, tick by tick, through a chain of stages.

    Parameters
    ----------
    names : sequence of str, the channels the renderer draws, in order (the map's targets)
    renderer : Renderer (:class:`~facepuppet.runtime.protocols.Renderer`): ``draw(weights, head_rotation,
        head_translation)``, ``finish()`` and ``read_pixels()``
    clock : RecordedClock or WallClock (anything with start/now/wait_until)
    observers : sequence of TickObserver (callables taking a :class:`TickInfo`), called in order after the
        GPU wait on every tick (PNG frames, the weight log, video, OSC outputs, the recorder, live stats)
    fps : float, ticks per second of recorded time
    log : callable taking one str; the channel-map report goes here, once per distinct channel tuple
        (the :class:`~facepuppet.runtime.live.mapper.Mapper` caches the last MAX_CHANNEL_MAPS tuples' maps;
        an older tuple seen again is reported again)
    target : GLTarget or None; when it has a window (``headless`` False) each
        tick polls events, stops on ``should_close()`` and swaps buffers
    stages : sequence of Stage (:func:`~facepuppet.runtime.live.stages.build_chain`), run in order every
        tick on the new finite frame (None when there is none); the last one's frame, when not None,
        is mapped by channel name onto ``names`` and drawn
    stop : callable returning bool or None; checked before each tick, True ends the run
    catch_up : bool; a tick later than one period skips the ticks it missed
        (live runs: never fall behind real time) instead of drawing each one
    idle_fps : float or None; draw on arrival (see the module docstring) when the
        source has ``wait_for_frame(timeout_s) -> bool``, redrawing at least this
        often without new frames; ``fps`` is then the grid of the tick labels
    drive : ExpressionDrive or None (:func:`~facepuppet.runtime.mapping.expressions.make_drive`): maps each channel
        tuple onto the character's morphs and VRM expressions; None: a plain ChannelMap by name, as for an OBJ rig
    mapper : Mapper or None, the map step to use (a session's, shared with its panel); None: one of its own
        from ``names`` and ``drive``
    overlays : sequence of callables taking a :class:`TickInfo`, called every tick right after the
        renderer's draw call and before the GPU wait, to draw over the character into the same framebuffer
        (the panel, :mod:`~facepuppet.runtime.panel`); their time counts in ``draw_submit``
    wake : callable(timeout_s) -> bool or None; with ``idle_fps``, what the loop sleeps in instead of the
        source's ``wait_for_frame`` (several inputs: :class:`~facepuppet.runtime.inputs.arrival.ArrivalWaiter`,
        so a frame of any of them is drawn on arrival)

    A frame with an infinite weight or a non-finite head pose is rejected here, once, before the
    stages (``counters["nonfinite_rejected"]``; NaN weights mean "not sent" and pass).
    """

    def __init__(self, names: Sequence[str], renderer: Renderer, clock: RecordedClock | WallClock,
                 observers: Sequence[TickObserver] = (), fps: float = 60.0,
                 log: Callable[[str], None] = logger.info, target: GLTarget | None = None,
                 stages: Sequence[Stage] = (), stop: Callable[[], bool] | None = None,
                 catch_up: bool = False, idle_fps: float | None = None,
                 drive: ExpressionDrive | None = None,
                 overlays: Sequence[Callable[[TickInfo], None]] = (),
                 wake: Callable[[float], bool] | None = None, mapper: Mapper | None = None) -> None:
        if not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
            raise ValueError(f"FrameLoop fps: expected a positive finite number, got {fps!r}")
        if idle_fps is not None and not (isinstance(idle_fps, (int, float)) and 0 < idle_fps <= fps):
            raise ValueError(f"FrameLoop idle_fps: expected a number in (0, fps = {fps:g}], got {idle_fps!r}")
        if isinstance(names, str) or not all(isinstance(n, str) for n in names):
            raise ValueError(f"FrameLoop names: expected a sequence of channel names, got {names!r}")
        self.idle_fps = None if idle_fps is None else float(idle_fps)
        self.wake = wake
        self.shape_names = tuple(names)
        self.renderer = renderer
        # MToon's UV animation runs on the tick's time (recorded time on replay, so a replay draws the same)
        self._material_time = getattr(renderer, "set_material_time", None)
        self.clock = clock
        self.observers = tuple(observers)
        self.fps = float(fps)
        self.log = log
        self.target = target
        self.stages = tuple(stages)
        self.overlays = tuple(overlays)
        self.stop = stop
        self.catch_up = bool(catch_up)
        self.counters: dict[str, int] = {}
        if mapper is None:
            if drive is not None and tuple(drive.shape_names) != self.shape_names:
                raise ValueError("FrameLoop drive: its shapes are not the renderer's channels")
            mapper = Mapper(self.shape_names, drive, log=log)
        elif mapper.names != self.shape_names:
            raise ValueError("FrameLoop mapper: its channels are not the renderer's")
        self.mapper = mapper
        self._expressions: np.ndarray | None = None
        self._weights = np.zeros(len(self.shape_names), dtype=np.float32)
        self._rotation: np.ndarray | None = None
        self._translation: np.ndarray | None = None
        self._frame: Frame | None = None
        # the renderer's clock for what moves on its own (spring bones) and the eyes' channels, when it has one
        self._advance = getattr(renderer, "advance", None)

    @property
    def drive(self) -> ExpressionDrive | None:
        return self.mapper.drive

    def channel_map(self, channels: tuple[str, ...], source: str = "") -> ChannelMap | ExpressionMap:
        """The cached map for a channel tuple; built (and its report logged) on first sight."""
        return self.mapper.map_for(channels, source)

    def run(self, source: FrameSource, duration: float | None = None,
            ticks: Sequence[int] | None = None) -> LoopResult:
        """Tick from t = 0 until the first tick at or after ``duration`` (default: the source's ``duration``).

        With neither, runs until the window closes. ``ticks``, a sequence of
        increasing tick indices, draws exactly those ticks (``t = k / fps``)
        instead, ignoring ``duration`` and ``catch_up``: a replay ticking as a
        recorded live run did.
        """
        schedule, last = self._plan(source, duration, ticks)
        window = self.target is not None and not getattr(self.target, "headless", True)
        timer = StageTimer(STAGES)
        counters = self.counters  # updated in place: hooks may hold it
        counters.clear()
        counters.update(dict.fromkeys(
            ("frames_received", "stale_dropped", "nonfinite_rejected", "ticks_without_new_frame", "late_ticks",
             "skipped_ticks"), 0))
        info = TickInfo(self.renderer)
        wait = self.wake if self.wake is not None else getattr(source, "wait_for_frame", None)
        arrival = schedule is None and self.idle_fps is not None and wait is not None
        idle_s = 0.0 if self.idle_fps is None else 1.0 / self.idle_fps
        # What the session built before its first tick lives as long as the loop: frozen, a full collection
        # (which a long show's ticks eventually trigger) does not scan it. With a character, the tables, the
        # GL objects and the modules loaded, that scan took ~10 ms on the CI machine: a dropped frame each time.
        gc.collect()
        gc.freeze()
        try:
            return self._ticks(source, schedule, last, window, timer, info, wait, arrival, idle_s)
        finally:
            gc.unfreeze()  # the next session's objects, not this one's, are frozen by its own loop

    def _ticks(self, source: FrameSource, schedule: list[int] | None, last: float, window: bool, timer: StageTimer,
               info: TickInfo, wait: Callable[[float], object] | None, arrival: bool, idle_s: float) -> LoopResult:
        """The ticks of :meth:`run`, from the clock's start."""
        counters = self.counters
        n_ticks = 0
        closed = False
        self.clock.start()
        k = i = 0
        drawn_at = -math.inf
        while (k if schedule is None else i) <= last:
            if self.stop is not None and self.stop():
                break
            if schedule is not None:
                k, i = schedule[i], i + 1
            if arrival:
                # sleep until a frame arrives or the idle redraw is due; label: the next grid index
                wait(max(0.0, drawn_at + idle_s - self.clock.now()))
                k = max(k, math.ceil(self.clock.now() * self.fps - 1e-9))
                if k > last:
                    break
                drawn_at = self.clock.now()
            else:
                k = self._wait_for_tick(k, last, schedule is None)
            if window:
                self.target.poll()
                if self.target.should_close():
                    closed = True
                    break
            self._tick(k, k / self.fps, source, timer, info)
            if window:
                self.target.swap()
            n_ticks += 1
            k += 1
        return LoopResult(n_ticks, counters, timer.summary(), timer, closed)

    def _plan(self, source, duration: float | None, ticks) -> tuple[list[int] | None, float]:
        """(the explicit tick schedule or None, index of the last tick)."""
        if duration is None:
            duration = getattr(source, "duration", None)
        # the last tick is the first at or after ``duration``, so the last recorded frame is shown
        last = math.inf if duration is None else max(0, math.ceil(duration * self.fps - 1e-6))
        if ticks is None:
            return None, last
        schedule = [int(k) for k in ticks]
        if any(b <= a for a, b in zip(schedule, schedule[1:])) or (schedule and schedule[0] < 0):
            raise ValueError("FrameLoop.run ticks: expected increasing non-negative tick indices")
        return schedule, len(schedule) - 1

    def _wait_for_tick(self, k: int, last: float, may_skip: bool) -> int:
        """Wait for tick ``k``'s time; a late tick is counted and, with ``catch_up``, skips the ticks it missed."""
        late = self.clock.wait_until(k / self.fps)
        if late > 0:
            self.counters["late_ticks"] += 1
            if self.catch_up and may_skip and late * self.fps >= 1.0:
                skip = min(int(late * self.fps), last - k)
                self.counters["skipped_ticks"] += skip
                k += skip
        return k

    def _tick(self, k: int, t: float, source, timer: StageTimer, info: TickInfo) -> None:
        """One tick: snapshot, the stages and the map, draw, wait for the GPU, the observers."""
        now, add, counters = timer.now, timer.add, self.counters
        t0 = now()
        frame, stale = source.latest(t)
        t1 = now()
        add("snapshot", t1 - t0)
        raw = frame
        if frame is None:
            counters["ticks_without_new_frame"] += 1
        else:
            counters["frames_received"] += 1 + stale
            counters["stale_dropped"] += stale
            if not frame.is_finite():
                counters["nonfinite_rejected"] += 1
                frame = None
        for stage in self.stages:
            frame = stage(frame, t)
        if frame is not None:
            self._accept(frame)
        t2 = now()
        add("map", t2 - t1)

        if self._advance is not None:
            self._advance(t, frame)
        if self._material_time is not None:
            self._material_time(t)
        self.renderer.draw(self._weights, self._rotation, self._translation)
        if self.overlays:  # drawn over the character (the panel), with this tick's frames; stamps: last tick's
            info.k, info.t, info.raw, info.frame, info.weights = k, t, raw, self._frame, self._weights
            info.rotation, info.translation, info.expressions = self._rotation, self._translation, self._expressions
            for overlay in self.overlays:
                overlay(info)
        t3 = now()
        add("draw_submit", t3 - t2)
        self.renderer.finish()
        t4 = now()
        add("gpu_finish", t4 - t3)
        if self.observers:
            info.k, info.t, info.raw, info.frame, info.weights = k, t, raw, self._frame, self._weights
            info.rotation, info.translation, info.expressions = self._rotation, self._translation, self._expressions
            info.stamps = (t0, t1, t2, t3, t4)
            for observer in self.observers:
                observer(info)
        add("sink", now() - t4)

    def _accept(self, frame: Frame) -> None:
        """Make ``frame`` the current one: its weights mapped by name, its pose kept where it has one."""
        if frame.weights is not None:
            cmap = self.channel_map(frame.channels, frame.source)
            cmap.apply(frame.weights, out=self._weights)
            self._expressions = cmap.expression_values if getattr(cmap, "drives_expressions", False) else None
        if frame.head_rotation is not None:
            self._rotation = frame.head_rotation
        if frame.head_translation is not None:
            self._translation = frame.head_translation
        self._frame = frame
