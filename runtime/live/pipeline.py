"""The ``filter`` stage of the live chain: filter, calibrate, gain/clamp, tracking loss.

For each accepted frame (finite: the frame loop rejects non-finite frames before any stage), in this order:

1. **Filter**: a One Euro filter per weight channel with its region's settings
   (eyes light, mouth heavier, see :mod:`~facepuppet.runtime.live.config`),
   and one for the head (quaternion components, kept in one hemisphere and
   renormalised; translation). ``dt`` is the difference of receive times.
2. **Calibrate**: subtract the neutral pose (weights and translation; the
   rotation is taken relative to the neutral rotation). The neutral is the mean
   of the raw frames over ``capture_s`` seconds after :meth:`request_calibration`
   (``--calibrate`` at start, the key C in a window) or after the source's count
   of calibrate messages (``/facepuppet/calibrate``) grows: the stage reads that
   count each tick (``calibrate_requests``); nothing calls into it from the receiver.
3. **Response** per channel (:mod:`~facepuppet.runtime.live.response`): mirror, gain, input range ->
   output range through a curve (linear, ease, threshold), clamp, blink linking; the head mirrored.
4. **Tracking loss**: with no frame for ``timeout_s`` the input is *lost* (an event, counted, handed to the
   ``listeners``: the recorder, the OSC ``/facepuppet/tracking`` sender); each region then eases over
   ``ease_out_s`` (smoothstep) to its loss target (``[tracking_loss]`` per region: hold, neutral, voice,
   idle; :mod:`~facepuppet.runtime.live.tracking_loss`); when frames return (event *found*) the output
   blends from wherever it was to the live value over ``ease_in_s``, so no tick jumps by more than the
   live motion plus ``|live - out| * max slope of the ramp * tick``.

**Live changes**: :meth:`LivePipeline.apply_config` (from any thread) hands over a new config; it takes
effect at the start of the next tick. The filters keep their state (new cutoffs apply from that sample on, so
the output moves no faster than the filter lets it), the response arrays are rebuilt, and the config's
``neutral`` becomes the neutral in force. :meth:`LivePipeline.current_config` is the config in force with the
captured neutral, what a profile saves. ``on_config`` callables hear each change (the recorder writes it), and
``schedule`` replays recorded changes at their tick times.

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

from facepuppet.runtime.channels import canonical, filter_region
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.geometry import quat_mul, smoothstep
from facepuppet.runtime.live.config import LiveConfig, Neutral
from facepuppet.runtime.live.one_euro import OneEuroFilter
from facepuppet.runtime.live.response import Response
from facepuppet.runtime.live.tracking_loss import IdleMotion, LossTargets, voice_jaw

logger = logging.getLogger(__name__)

_IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])
EVENTS_KEPT = 64  # the last tracking events kept for the panel (a ring: a show runs for hours)
TRACKING_STATES = ("waiting", "live", "lost", "easing")


def nlerp(a: np.ndarray, b: np.ndarray, s: float) -> np.ndarray:
    """Normalised linear interpolation of quaternions (x, y, z, w), shortest way round."""
    if float(np.dot(a, b)) < 0:
        b = -b
    q = (1.0 - s) * a + s * b
    return q / max(float(np.linalg.norm(q)), 1e-12)


def _conj(q: np.ndarray) -> np.ndarray:
    return np.array([-q[0], -q[1], -q[2], q[3]])


def _float(x) -> float | None:
    """A float for JSON: None for NaN and infinities."""
    x = float(x)
    return x if math.isfinite(x) else None


def _floats(a: np.ndarray) -> list:
    return [_float(x) for x in np.asarray(a, np.float64).ravel()]


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _array(values, n: int, where: str) -> np.ndarray:
    """(n,) float64 from a JSON list (None: NaN); ValueError naming ``where`` otherwise."""
    if not isinstance(values, list) or len(values) != n or not all(v is None or _finite(v) for v in values):
        raise ValueError(f"pipeline state: '{where}' is not a list of {n} numbers")
    return np.array([math.nan if v is None else float(v) for v in values], np.float64)


def _parts(parts: tuple | None) -> list | None:
    """(weights, rotation, translation), each an array or None, for JSON."""
    return None if parts is None else [None if p is None else _floats(p) for p in parts]


def _snapshot_doc(raw: tuple | None) -> dict | None:
    """The JSON-able :meth:`LivePipeline.state_snapshot` of a :meth:`LivePipeline._raw_state`."""
    if raw is None:
        return None
    state, channels, filters, last_q, last, last_tick, live, out, ease, capture, calib_pending = raw
    held, ease_start, loss_from, lost_done = ease
    return {
        "version": 2, "state": state, "channels": list(channels),
        "filters": {name: [_floats(x), _floats(dx)] for name, (x, dx) in zip(("weights", "rotation",
                                                                             "translation"), filters)},
        "last_q": None if last_q is None else _floats(last_q),
        "last_frame": {"t": float(last.t), "t_sender": _float(last.t_sender), "number": int(last.number),
                       "source": str(last.source), "weights": last.weights is not None},
        "last_tick": float(last_tick), "live": _parts(live), "out": _parts(out),
        "held": _parts(held), "ease_start": float(ease_start), "loss_from": float(loss_from),
        "lost_done": bool(lost_done), "calib_pending": bool(calib_pending),
        "capture": None if capture is None else {
            "t0": float(capture["t0"]), "n": int(capture["n"]), "ntr": int(capture["ntr"]),
            "channels": None if capture["channels"] is None else list(capture["channels"]),
            **{k: _floats(capture[k]) for k in ("w", "wn", "q", "tr")}},
    }


def _unparts(doc, n: int, where: str) -> tuple | None:
    if doc is None:
        return None
    if not isinstance(doc, list) or len(doc) != 3:
        raise ValueError(f"pipeline state: '{where}' is not [weights, rotation, translation]")
    return tuple(None if p is None else _array(p, k, f"{where}[{i}]") for i, (p, k) in enumerate(zip(doc, (n, 4, 3))))


def _capture_of(doc) -> dict | None:
    """A neutral capture in progress from its snapshot (None: none)."""
    if doc is None:
        return None
    if not isinstance(doc, dict) or not _finite(doc.get("t0")) or not isinstance(doc.get("n"), int) or \
            not isinstance(doc.get("ntr"), int):
        raise ValueError("pipeline state: 'capture' lacks its start, frame count or head count")
    names = doc.get("channels")
    if names is not None and (not isinstance(names, list) or not all(isinstance(c, str) for c in names)):
        raise ValueError("pipeline state: 'capture.channels' is not a list of names")
    k = len(names or ())
    return {"t0": float(doc["t0"]), "n": doc["n"], "ntr": doc["ntr"],
            "channels": None if names is None else tuple(names),
            **{key: _array(doc.get(key), m, f"capture.{key}") for key, m in (("w", k), ("wn", k), ("q", 4), ("tr", 3))}}


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
    calibrate_requests : callable returning an int or None: a count of calibration requests that only
        grows (the source's calibrate messages); read every tick, each increase requests a calibration
    on_config : callables taking (tick time, LiveConfig), called when the config in force changes: an applied
        config takes effect, or a calibration captures a neutral (the config then carries it)
    schedule : iterable of (tick time, LiveConfig), changes to apply at the first tick at or after each time
        (a replay of the changes a recording kept)

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
    listeners : list of callables ``(t, found)`` called on each event (tick thread; must not block)
    generator : callable taking the tick time and returning a Frame (or None), or None: the voice/idle face
        of the gesture layer (:meth:`~facepuppet.runtime.gestures.layer.GestureLayer.compose` over nothing),
        used by the ``voice`` and ``idle`` loss modes instead of the built-in line and IdleMotion
    neutral_weights : ndarray of shape (n_channels,), float64, or None before calibration
    """

    name = "filter"

    def __init__(self, config: LiveConfig | None = None, audio_level: Callable[[float], float] | None = None,
                 log: Callable[[str], None] = logger.info,
                 calibrate_requests: Callable[[], int] | None = None,
                 on_config: Iterable[Callable[[float, LiveConfig], None]] = (),
                 schedule: Iterable[tuple[float, LiveConfig]] = ()) -> None:
        self.config = config or LiveConfig()
        self.on_config = list(on_config)
        self._schedule = sorted(schedule, key=lambda item: item[0])
        self._pending: LiveConfig | None = None
        self._lock = threading.Lock()
        self.audio_level = audio_level
        self.log = log
        self.calibrate_requests = calibrate_requests
        self._requests_seen = 0 if calibrate_requests is None else int(calibrate_requests())
        self.counters = {"tracking_lost": 0, "tracking_found": 0, "calibrations": 0}
        self.state = "waiting"
        self.events: collections.deque = collections.deque(maxlen=EVENTS_KEPT)
        self.listeners: list[Callable[[float, bool], None]] = []
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
        self.keep_snapshots = False  # keep :meth:`before_tick` (a run that may start a recording mid-run)
        self._before: tuple | None = None

    # -- the state a recording started mid-run carries ----------------------------------------------

    def state_snapshot(self) -> dict | None:
        """What a replay of a recording started now needs to go on as this run does (JSON-able): the filters'
        state, the last input frame's times, the last processed and emitted values, an ease in or out and a
        neutral capture in progress; None while waiting for the first frame (a fresh stage is that state).
        The gesture layer's own state (``generator``) is not in it."""
        return _snapshot_doc(self._raw_state())

    @property
    def before_tick(self) -> dict | None:
        """:meth:`state_snapshot` as it was before the newest tick (with ``keep_snapshots``; else None)."""
        return None if self._before is None else _snapshot_doc(self._before)

    @property
    def before_tick_state(self) -> str | None:
        """The tracking state (``live``, ``returning``, ``lost``) of :attr:`before_tick`, None without one."""
        return None if self._before is None else self._before[0]

    def _raw_state(self) -> tuple | None:
        """The parts of :meth:`state_snapshot`, copied where they change in place (cheap: every tick with
        ``keep_snapshots``; the capture's sums only while a neutral is captured)."""
        if self.state == "waiting" or self._cs is None or self._last_frame is None:
            return None
        cs, c = self._cs, self._capture
        capture = None if c is None else {k: v.copy() if isinstance(v, np.ndarray) else v for k, v in c.items()}
        return (self.state, cs.channels,
                tuple((f.x_hat.copy(), f.dx_hat.copy()) for f in (cs.weights, cs.rotation, cs.translation)),
                cs.last_q, self._last_frame, self._last_tick, self._live, self._out,
                (self._held, self._ease_start, self._loss_from, self._lost_done), capture, self._calib_pending)

    def restore_state(self, doc: dict) -> None:
        """Go on from :meth:`state_snapshot`'s ``doc`` (before the first tick of a replay; a version 1 doc, live
        only, too). Raises ValueError naming what is wrong when ``doc`` is not such a snapshot (nothing is
        changed then)."""
        if not isinstance(doc, dict) or doc.get("version") not in (1, 2):
            raise ValueError("pipeline state: expected a version 1 or 2 snapshot")
        v2 = doc["version"] == 2
        state = doc.get("state") if v2 else "live"
        if state not in ("live", "returning", "lost"):
            raise ValueError("pipeline state: 'state' is not live, returning or lost")
        channels = doc.get("channels")
        if not isinstance(channels, list) or not all(isinstance(c, str) for c in channels):
            raise ValueError("pipeline state: 'channels' is not a list of names")
        channels = tuple(channels)
        n = len(channels)
        cs = _ChannelState(channels, self.config)
        filters = doc.get("filters")
        if not isinstance(filters, dict):
            raise ValueError("pipeline state: 'filters' missing")
        for name, f in (("weights", cs.weights), ("rotation", cs.rotation), ("translation", cs.translation)):
            pair = filters.get(name)
            if not isinstance(pair, list) or len(pair) != 2:
                raise ValueError(f"pipeline state: 'filters.{name}' is not [x_hat, dx_hat]")
            f.set_state(_array(pair[0], f.n, f"filters.{name}"), _array(pair[1], f.n, f"filters.{name}"))
        last_q = None if doc.get("last_q") is None else _array(doc["last_q"], 4, "last_q")
        last = doc.get("last_frame")
        if not isinstance(last, dict) or not _finite(last.get("t")) or not isinstance(last.get("number"), int):
            raise ValueError("pipeline state: 'last_frame' lacks its time and number")
        if not _finite(doc.get("last_tick")):
            raise ValueError("pipeline state: 'last_tick' is not a number")
        live = _unparts(doc.get("live"), n, "live")
        out = _unparts(doc.get("out"), n, "out")
        held, ease, capture, pending = None, (0.0, 0.0, False), None, False
        if v2:
            held = _unparts(doc.get("held"), n, "held")
            for key in ("ease_start", "loss_from"):
                if not _finite(doc.get(key)):
                    raise ValueError(f"pipeline state: '{key}' is not a number")
            if not isinstance(doc.get("lost_done"), bool) or not isinstance(doc.get("calib_pending"), bool):
                raise ValueError("pipeline state: 'lost_done' and 'calib_pending' must be true or false")
            if state != "live" and out is None:
                raise ValueError(f"pipeline state: '{state}' needs 'out', what was shown")
            ease = (float(doc["ease_start"]), float(doc["loss_from"]), doc["lost_done"])
            capture, pending = _capture_of(doc.get("capture")), doc["calib_pending"]
        frame = Frame(t=float(last["t"]), source=str(last.get("source", "")),
                      channels=channels if last.get("weights") else None,
                      weights=np.full(n, np.nan) if last.get("weights") else None,
                      t_sender=float(last["t_sender"]) if _finite(last.get("t_sender")) else math.nan,
                      number=int(last["number"]))
        cs.last_q = last_q
        self._channels, self._cs = channels, cs
        self.neutral_weights = self._neutral_on(channels)
        self._last_frame, self._last_tick = frame, float(doc["last_tick"])
        self._live, self._out, self.state = live, out, state
        self._held = held if held is not None else out
        self._ease_start, self._loss_from, self._lost_done = ease
        self._capture, self._calib_pending = capture, pending

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
        for hook in self.on_config:
            hook(t, config)

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
        for listener in self.listeners:
            listener(t, found)

    def __call__(self, frame: Frame | None, t: float) -> Frame | None:
        if self.keep_snapshots:
            self._before = self._raw_state()
        while self._schedule and self._schedule[0][0] <= t:
            self._switch(self._schedule.pop(0)[1], t)
        if self._pending is not None:
            with self._lock:
                config, self._pending = self._pending, None
            self._switch(config, t)
        if self.calibrate_requests is not None:
            requests = int(self.calibrate_requests())
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
            config = self.current_config()
            for hook in self.on_config:  # the neutral in force changed: a recording keeps it like any change
                hook(t, config)

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
