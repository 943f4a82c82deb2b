"""The ``filter`` stage of the live chain: filter, calibrate, gain/clamp, tracking loss.

For each accepted frame (finite: the frame loop rejects non-finite frames before any stage), in this order:

1. **Filter**: a One Euro filter per weight channel with its region's settings
   (eyes light, mouth heavier, see :mod:`~facepuppet.runtime.live.config`),
   and one for the head (quaternion components, kept in one hemisphere and
   renormalised; translation). ``dt`` is the difference of receive times.
2. **Calibrate**: subtract the neutral pose (weights and translation; the
   rotation is taken relative to the neutral rotation). The neutral is the mean
   of the raw frames over ``capture_s`` seconds after :meth:`request_calibration`
   (``--calibrate`` at start, the key C in a window) or after the session's count
   of calibrate messages (``/facepuppet/calibrate``) grows: the stage reads that
   count from the session's bus each tick; nothing calls into it from the receiver.
3. **Response** per channel (:mod:`~facepuppet.runtime.live.response`): mirror, gain, input range ->
   output range through a curve (linear, ease, threshold), clamp, blink linking; the head mirrored.
4. **Tracking loss**: with no frame for ``timeout_s`` the input is *lost* (an event, counted, published on
   the session's bus: the recorder, the OSC ``/facepuppet/tracking`` sender hear it); each region then eases over
   ``ease_out_s`` (smoothstep) to its loss target (``[tracking_loss]`` per region: hold, neutral, voice,
   idle; :mod:`~facepuppet.runtime.live.tracking_loss`); when frames return (event *found*) the output
   blends from wherever it was to the live value over ``ease_in_s``, so no tick jumps by more than the
   live motion plus ``|live - out| * max slope of the ramp * tick``.

**Live changes**: :meth:`LivePipeline.apply_config` (from any thread) hands over a new config; it takes
effect at the start of the next tick. The filters keep their state (new cutoffs apply from that sample on, so
the output moves no faster than the filter lets it), the response arrays are rebuilt, and the config's
``neutral`` becomes the neutral in force. :meth:`LivePipeline.current_config` is the config in force with the
captured neutral, what a profile saves. Each change is published on the session's bus (the recorder writes
it, the mix and the map follow it), and ``schedule`` replays recorded changes at their tick times. The state a
recording started mid-run carries is :mod:`~facepuppet.runtime.live.pipeline_state`.

Times ``t`` are the frame loop's tick times (seconds), so a replay on recorded
time gives the same output as the live run it came from.
"""

from __future__ import annotations

import collections
import logging
import math
import threading
from collections.abc import Callable, Iterable
from dataclasses import replace

import numpy as np

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.live.bus import SessionBus
from facepuppet.runtime.live.config import LiveConfig, Neutral
from facepuppet.runtime.live.one_euro import OneEuroFilter
from facepuppet.runtime.live.pipeline_state import RawState, read_snapshot, snapshot_doc
from facepuppet.runtime.live.response import Response
from facepuppet.runtime.live.tracking_loss import IdleMotion, LossTargets, voice_jaw
from facepuppet.runtime.mapping.channels import canonical, filter_region
from facepuppet.runtime.model.geometry import nlerp, quat_mul, smoothstep

logger = logging.getLogger(__name__)

_IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])
EVENTS_KEPT = 64  # the last tracking events kept for the panel (a ring: a show runs for hours)
TRACKING_STATES = ("waiting", "live", "lost", "easing")


def _conj(q: np.ndarray) -> np.ndarray:
    return np.array([-q[0], -q[1], -q[2], q[3]])


class _ChannelState:
    """Filters, neutral and limits for one tuple of channel names."""

    def __init__(self, channels: tuple[str, ...], config: LiveConfig):
        n = len(channels)
        self.channels = channels
        self.weights = OneEuroFilter(n)
        self.rotation = OneEuroFilter(4)
        self.translation = OneEuroFilter(3)
        self.configure(config)
        self.last_q: np.ndarray | None = None

    def configure(self, config: LiveConfig) -> None:
        """Take the settings of ``config``, keeping the filters' state (a live change)."""
        settings = [config.filters[filter_region(c)] for c in self.channels]
        for f, values in ((self.weights, settings), (self.rotation, [config.filters["head"]] * 4),
                          (self.translation, [config.filters["head"]] * 3)):
            f.min_cutoff[:] = [s.min_cutoff for s in values]
            f.beta[:] = [s.beta for s in values]
            f.d_cutoff[:] = [s.d_cutoff for s in values]
        self.response = Response(self.channels, config)
        self.neutral_out = self.response(np.zeros(len(self.channels)))
        self.loss = LossTargets(self.channels, [filter_region(c) for c in self.channels], config.loss)

    def reset_filters(self) -> None:
        self.weights.reset()
        self.rotation.reset()
        self.translation.reset()
        self.last_q = None


class LivePipeline:
    """The ``filter`` stage: filtering, calibration, gain/clamp and tracking-loss easing of live frames.

    Parameters
    ----------
    config : LiveConfig
    audio_level : callable taking the tick time (s) and returning dBFS (NaN for
        none), or None; its value is stamped on the frames this emits
    log : callable taking one str
    bus : SessionBus or None, the session's (None: one of its own, :attr:`bus`). The stage publishes on it each
        config taking effect (an applied config, a scheduled one, or a calibration capturing a neutral: the
        config then carries it) and each tracking event, and reads its count of calibration requests every
        tick (each increase requests a calibration)
    schedule : iterable of (tick time, LiveConfig), changes to apply at the first tick at or after each time
        (a replay of the changes a recording kept)
    keep_snapshots : bool, keep the state before each tick (:attr:`before_tick`): a run that may start a
        recording mid-run (its first recorded frame may be the very tick's)

    Call it once per tick as ``pipeline(frame, t)`` (the frame loop's
    ``pipeline`` hook): ``frame`` is the newest new frame or None; the return
    value is the frame to draw, or None to keep what is on screen.

    Attributes
    ----------
    counters : dict of str to int: ``tracking_lost`` (times the input went quiet past the timeout),
        ``tracking_found`` (times frames came back after a loss), ``calibrations``
    state : str, ``waiting`` (no frame yet), ``live``, ``lost``, ``returning``
    tracking_state : str, for the panel: ``waiting``, ``live``, ``lost`` or ``easing`` (frames are back and
        the output is still blending in)
    events : deque of (tick time s, found bool), the last EVENTS_KEPT tracking events
    generator : callable taking the tick time and returning a Frame (or None), or None: the voice/idle face
        of the gesture layer (:meth:`~facepuppet.runtime.gestures.layer.GestureLayer.compose` over nothing),
        used by the ``voice`` and ``idle`` loss modes instead of the built-in line and IdleMotion
    neutral_weights : ndarray of shape (n_channels,), float64, or None before calibration
    """

    name = "filter"

    def __init__(self, config: LiveConfig | None = None, audio_level: Callable[[float], float] | None = None,
                 log: Callable[[str], None] = logger.info, bus: SessionBus | None = None,
                 schedule: Iterable[tuple[float, LiveConfig]] = (), keep_snapshots: bool = False) -> None:
        self.config = config or LiveConfig()
        self.bus = bus if bus is not None else SessionBus()
        self.bus.config = self.config
        self._schedule = sorted(schedule, key=lambda item: item[0])
        self._pending: LiveConfig | None = None
        self._lock = threading.Lock()
        self.audio_level = audio_level
        self.log = log
        self._requests_seen = self.bus.calibration_requests()
        self.counters = {"tracking_lost": 0, "tracking_found": 0, "calibrations": 0}
        self.state = "waiting"
        self.events: collections.deque = collections.deque(maxlen=EVENTS_KEPT)
        self.generator: Callable[[float], Frame | None] | None = None
        self.idle = IdleMotion(self.config.loss.idle_blink_s, self.config.loss.idle_seed)
        self._channels: tuple[str, ...] | None = None
        self._cs: _ChannelState | None = None
        self._last_frame: Frame | None = None  # last accepted input frame
        self._last_tick = -math.inf  # tick time of the last accepted input frame
        self._live: tuple | None = None  # (weights, rotation, translation) of the last input, processed
        self._out: tuple | None = None  # what was last emitted
        self._held: tuple | None = None  # start of the current ease (out or in)
        self._ease_start = 0.0
        self._lost_done = False
        self._loss_from = 0.0  # tick time the ease to the loss targets runs from
        self.neutral_weights: np.ndarray | None = None
        self._neutral_rot = _IDENTITY.copy()
        self._neutral_trans: np.ndarray | None = None
        self._neutral_pose = self.config.neutral  # the neutral in force, by channel name (Neutral or None)
        self._take_neutral(self._neutral_pose)
        self._calib_pending = False
        self._capture: dict | None = None
        self.keep_snapshots = bool(keep_snapshots)
        self._before: RawState | None = None

    # -- the state a recording started mid-run carries (pipeline_state) -------------------------------

    def state_snapshot(self) -> dict | None:
        """What a replay of a recording started now needs to go on as this run does (JSON-able): the filters'
        state, the last input frame's times, the last processed and emitted values, an ease in or out and a
        neutral capture in progress; None while waiting for the first frame (a fresh stage is that state).
        The gesture layer's own state (``generator``) is not in it."""
        return snapshot_doc(self._raw_state())

    @property
    def before_tick(self) -> dict | None:
        """:meth:`state_snapshot` as it was before the newest tick (with ``keep_snapshots``; else None)."""
        return None if self._before is None else snapshot_doc(self._before)

    @property
    def before_tick_state(self) -> str | None:
        """The tracking state (``live``, ``returning``, ``lost``) of :attr:`before_tick`, None without one."""
        return None if self._before is None else self._before.state

    def _raw_state(self) -> RawState | None:
        """The parts of :meth:`state_snapshot`, copied where they change in place (cheap: every tick with
        ``keep_snapshots``; the capture's sums only while a neutral is captured)."""
        if self.state == "waiting" or self._cs is None or self._last_frame is None:
            return None
        cs, c = self._cs, self._capture
        capture = None if c is None else {k: v.copy() if isinstance(v, np.ndarray) else v for k, v in c.items()}
        return RawState(self.state, cs.channels,
                        tuple((f.x_hat.copy(), f.dx_hat.copy()) for f in (cs.weights, cs.rotation, cs.translation)),
                        cs.last_q, self._last_frame, self._last_tick, self._live, self._out,
                        (self._held, self._ease_start, self._loss_from, self._lost_done), capture,
                        self._calib_pending)

    def restore_state(self, doc: dict) -> None:
        """Go on from :meth:`state_snapshot`'s ``doc`` (before the first tick of a replay; a version 1 doc, live
        only, too). Raises ValueError naming what is wrong when ``doc`` is not such a snapshot (nothing is
        changed then)."""
        raw = read_snapshot(doc)
        channels = raw.channels
        cs = _ChannelState(channels, self.config)
        for f, (x_hat, dx_hat) in zip((cs.weights, cs.rotation, cs.translation), raw.filters):
            f.set_state(x_hat, dx_hat)
        cs.last_q = raw.last_q
        self._channels, self._cs = channels, cs
        self.neutral_weights = self._neutral_on(channels)
        self._last_frame, self._last_tick = raw.last_frame, raw.last_tick
        self._live, self._out, self.state = raw.live, raw.out, raw.state
        held, self._ease_start, self._loss_from, self._lost_done = raw.ease
        self._held = held if held is not None else raw.out
        self._capture, self._calib_pending = raw.capture, raw.calib_pending

    def apply_config(self, config: LiveConfig) -> None:
        """Hand over a new config (safe from any thread); it takes effect at the start of the next tick.

        Its ``neutral`` becomes the neutral in force (None clears it): edit a copy of :meth:`current_config`.
        Several calls before a tick: the last wins.
        """
        if not isinstance(config, LiveConfig):
            raise TypeError(f"apply_config: expected a LiveConfig, got {type(config).__name__}")
        with self._lock:
            self._pending = config

    def current_config(self) -> LiveConfig:
        """The config in force, with the neutral in force (captured or given): what a profile saves."""
        return replace(self.config, neutral=self._neutral_pose)

    def _switch(self, config: LiveConfig, t: float) -> None:
        # the config in force (with the neutral in force), apart from where it was read, again is no change
        changed = replace(config, path=None) != replace(self.current_config(), path=None)
        if (config.loss.idle_blink_s, config.loss.idle_seed) != (self.config.loss.idle_blink_s,
                                                                  self.config.loss.idle_seed):
            self.idle = IdleMotion(config.loss.idle_blink_s, config.loss.idle_seed)
        self.config = config
        if config.neutral != self._neutral_pose:
            self._neutral_pose = config.neutral
            self._take_neutral(config.neutral)
        if self._cs is not None:
            self._cs.configure(config)  # the response and the tracking-loss targets per channel, rebuilt
        if self.state == "lost" and self._out is not None and changed:
            # lost already: ease from what is shown to the new config's loss targets (a changed mode moves now;
            # the same config again, as a recording's first CONFIG record is, changes nothing)
            self._held, self._loss_from, self._lost_done = self._out, t, False
        self.bus.publish_config(t, config)

    def _take_neutral(self, neutral: Neutral | None) -> None:
        """Make ``neutral`` the neutral in force (the weights by name onto the current channels)."""
        if neutral is None:
            self.neutral_weights, self._neutral_rot, self._neutral_trans = None, _IDENTITY.copy(), None
            return
        self._neutral_rot = np.array(neutral.rotation, dtype=np.float64)
        self._neutral_rot /= np.linalg.norm(self._neutral_rot)
        self._neutral_trans = None if neutral.translation is None else np.array(neutral.translation, np.float64)
        self.neutral_weights = self._neutral_on(self._channels)

    def _neutral_on(self, channels: tuple[str, ...] | None) -> np.ndarray | None:
        if self._neutral_pose is None or channels is None:
            return None
        by_key = {canonical(c): w for c, w in zip(self._neutral_pose.channels, self._neutral_pose.weights)}
        return np.array([by_key.get(canonical(c), 0.0) for c in channels], dtype=np.float64)

    def request_calibration(self) -> None:
        """Capture the neutral from the next ``capture_s`` seconds of frames (safe from any thread)."""
        self._calib_pending = True

    @property
    def calibrating(self) -> bool:
        return self._calib_pending or self._capture is not None

    @property
    def tracking_state(self) -> str:
        """``waiting``, ``live``, ``lost`` or ``easing`` (see the class docstring)."""
        return "easing" if self.state == "returning" else self.state

    def _event(self, t: float, found: bool) -> None:
        self.counters["tracking_found" if found else "tracking_lost"] += 1
        self.events.append((t, found))
        self.bus.publish_tracking(t, found)

    def __call__(self, frame: Frame | None, t: float) -> Frame | None:
        if self.keep_snapshots:
            self._before = self._raw_state()
        while self._schedule and self._schedule[0][0] <= t:
            self._switch(self._schedule.pop(0)[1], t)
        if self._pending is not None:
            with self._lock:
                config, self._pending = self._pending, None
            self._switch(config, t)
        requests = self.bus.calibration_requests()
        if requests != self._requests_seen:
            self._requests_seen = requests
            self.request_calibration()
        if frame is None:
            return self._quiet(t)
        if frame.channels != self._channels:
            self._channels = frame.channels
            self._cs = _ChannelState(frame.channels or (), self.config)
            self.neutral_weights = self._neutral_on(frame.channels)
        dt = frame.t - self._last_frame.t if self._last_frame is not None else math.nan
        self._capture_step(frame, t)
        live = self._process(frame, dt)
        self._last_frame, self._last_tick, self._live = frame, t, live
        if self.state in ("lost", "returning"):
            if self.state == "lost":
                self.state, self._held, self._ease_start = "returning", self._out, t
                self._event(t, True)
            s = smoothstep(0.0, 1.0, (t - self._ease_start) / self.config.ease_in_s)
            out = self._blend(self._held, live, s)
            if s >= 1.0:
                self.state = "live"
        else:
            self.state = "live"
            out = live
        return self._emit(out, t)

    # -- stages -------------------------------------------------------------------------------------

    def _process(self, frame: Frame, dt: float) -> tuple:
        cs = self._cs
        weights = None
        if frame.weights is not None:
            w = cs.weights.filter(frame.weights, dt)
            if self.neutral_weights is not None:
                w = w - self.neutral_weights
            weights = cs.response(w)  # a new array; NaN (not sent) stays NaN
        rotation = None
        if frame.head_rotation is not None:
            q = frame.head_rotation.astype(np.float64)
            if cs.last_q is not None and float(np.dot(q, cs.last_q)) < 0:
                q = -q  # q and -q are one rotation: keep the filter on one hemisphere
            cs.last_q = q
            q = cs.rotation.filter(q, dt)
            q = q / max(float(np.linalg.norm(q)), 1e-12)
            rotation = cs.response.rotation(quat_mul(_conj(self._neutral_rot), q))
        translation = None
        if frame.head_translation is not None:
            translation = cs.translation.filter(frame.head_translation, dt).copy()
            if self._neutral_trans is not None:
                translation -= self._neutral_trans
            translation = cs.response.translation(translation)
        return weights, rotation, translation

    def _capture_step(self, frame: Frame, t: float) -> None:
        """Accumulate raw frames for the neutral; finish after ``capture_s`` seconds of tick time."""
        if self._calib_pending:
            self._calib_pending = False
            n = len(frame.channels or ())
            self._capture = {"t0": t, "n": 0, "w": np.zeros(n), "wn": np.zeros(n), "q": np.zeros(4),
                             "tr": np.zeros(3), "ntr": 0, "channels": frame.channels}
            self.log(f"calibration: capturing the neutral pose for {self.config.capture_s:g} s; hold still")
        c = self._capture
        if c is None:
            return
        if frame.channels != c["channels"]:
            self._capture = None
            self.log("calibration: the input's channels changed during capture; calibration abandoned")
            return
        if frame.weights is not None:
            finite = np.isfinite(frame.weights)
            c["w"][finite] += frame.weights[finite]
            c["wn"][finite] += 1
        if frame.head_rotation is not None:
            q = frame.head_rotation.astype(np.float64)
            c["q"] += q if float(np.dot(q, c["q"])) >= 0 else -q
        if frame.head_translation is not None:
            c["tr"] += frame.head_translation
            c["ntr"] += 1
        c["n"] += 1
        if t - c["t0"] >= self.config.capture_s:
            self.neutral_weights = np.where(c["wn"] > 0, c["w"] / np.maximum(c["wn"], 1), 0.0)
            norm = float(np.linalg.norm(c["q"]))
            self._neutral_rot = c["q"] / norm if norm > 0 else _IDENTITY.copy()
            self._neutral_trans = c["tr"] / c["ntr"] if c["ntr"] else None
            self._neutral_pose = Neutral(tuple(c["channels"] or ()), tuple(float(w) for w in self.neutral_weights),
                                    tuple(float(v) for v in self._neutral_rot),
                                    None if self._neutral_trans is None else
                                    tuple(float(v) for v in self._neutral_trans))
            self._capture = None
            self.counters["calibrations"] += 1
            self.log(f"calibration: neutral captured from {c['n']} frames")
            # the neutral in force changed: a recording keeps it like any change
            self.bus.publish_config(t, self.current_config())

    def _quiet(self, t: float) -> Frame | None:
        """A tick without a usable new frame: hold, keep blending in, or ease out to neutral."""
        if self.state == "waiting":
            return None
        idle = t - self._last_tick
        if idle <= self.config.timeout_s:
            if self.state == "returning":
                s = smoothstep(0.0, 1.0, (t - self._ease_start) / self.config.ease_in_s)
                if s >= 1.0:
                    self.state = "live"
                return self._emit(self._blend(self._held, self._live, s), t)
            return None
        if self.state != "lost":
            self.state, self._held, self._lost_done = "lost", self._out, False
            self._loss_from = self._last_tick + self.config.timeout_s
            self._event(t, False)
            self._cs.reset_filters()  # frames that come back start the filters afresh
        if self._lost_done:
            return None
        e = smoothstep(0.0, 1.0, (t - self._loss_from) / self.config.ease_out_s)
        self._lost_done = e >= 1.0 and not self._cs.loss.moving
        return self._emit(self._blend(self._held, self._loss_target(t), e), t)

    def _loss_target(self, t: float) -> tuple:
        """Where each part goes while tracking is lost, per region mode (hold, neutral, voice, idle)."""
        weights, rotation, translation = self._neutral()
        loss, held = self._cs.loss, self._held
        gen = self.generator(t) if self.generator is not None and loss.moving else None
        if weights is not None:
            weights = weights.copy()
            if held[0] is not None:
                weights[loss.hold] = np.nan_to_num(held[0][loss.hold])
            level = self.audio_level(t) if self.audio_level is not None else math.nan
            jaw = voice_jaw(level, self.config.loss)
            if math.isfinite(jaw):
                weights[loss.jaw] = jaw
            if loss.blink.any():
                weights[loss.blink] = self.idle.blink(t)
            if gen is not None and gen.weights is not None and gen.channels is not None:
                index = {canonical(c): i for i, c in enumerate(gen.channels)}
                for j in np.flatnonzero(loss.voice | loss.idle):
                    i = index.get(loss.keys[j])
                    if i is not None and math.isfinite(float(gen.weights[i])):
                        weights[j] = float(gen.weights[i])
            weights = np.clip(weights, self._cs.response.low, self._cs.response.high)
        if loss.head == "hold":
            rotation, translation = held[1], held[2]
        elif loss.head == "idle":
            sway = gen.head_rotation if gen is not None and gen.head_rotation is not None else self.idle.sway(t)
            rotation = np.asarray(sway, np.float64)
        return weights, rotation, translation

    def _neutral(self) -> tuple:
        weights = None if self._channels is None or self._last_frame.weights is None else self._cs.neutral_out
        translation = np.zeros(3) if self._neutral_trans is not None else None  # uncalibrated: hold it
        return weights, _IDENTITY, translation

    @staticmethod
    def _blend(a: tuple, b: tuple, s: float) -> tuple:
        """(1 - s) a + s b per part; a part missing on one side takes the other's; NaN counts as 0."""
        out = []
        for i, (x, y) in enumerate(zip(a, b)):
            if x is None or y is None:
                out.append(y if x is None else x)
            elif i == 1:
                out.append(nlerp(x, y, s))
            else:
                x, y = np.nan_to_num(x), np.nan_to_num(y)
                out.append(x + s * (y - x))
        return tuple(out)

    def _emit(self, out: tuple, t: float) -> Frame:
        self._out = out
        src = self._last_frame
        weights, rotation, translation = out
        return Frame(
            t=src.t, source=src.source, channels=src.channels if weights is not None else None,
            weights=weights, head_rotation=rotation, head_translation=translation,
            audio_level=self.audio_level(t) if self.audio_level is not None else math.nan,
            t_sender=src.t_sender, number=src.number,
        )
