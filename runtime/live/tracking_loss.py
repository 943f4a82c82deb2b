"""Tracking loss, defined per region: what the face does while the tracker is silent, and the lost/found events.

The ``[tracking_loss]`` section of the live config (:mod:`~facepuppet.runtime.live.config`)::

    [tracking_loss]
    timeout_s = 0.5          # no frame for this long: the input is lost (event "lost")
    ease_out_s = 0.6         # ...then each region eases to its loss target over this long
    ease_in_s = 0.25         # frames are back (event "found"): blend from where we are to live over this long
    eyes = "idle"            # per region: "hold", "neutral" (the default, also "ease"), "voice", "idle"
    brows = "neutral"
    mouth = "voice"
    head = "idle"
    other = "hold"
    voice_floor_db = -50.0   # "voice": this level (dBFS) or less closes the jaw ...
    voice_ceiling_db = -15.0 # ... this level or more opens it fully (jawOpen = 1, before the channel's clamp)
    idle_blink_s = 4.0       # "idle": mean seconds between blinks
    idle_seed = 0            # "idle": seed of the blink times and the head's sway phases

Modes (each region's weight channels, and ``head`` for the pose):

* ``hold``: keep the last output (the frozen face of older trackers; no ease).
* ``neutral``: ease to neutral (zero after calibration; identity head) over ``ease_out_s``.
* ``voice`` (``mouth`` only): ``jawOpen`` follows the voice level (``--audio`` / ``--audio-file``),
  linear in dB between ``voice_floor_db`` and ``voice_ceiling_db``; the other mouth channels ease to neutral.
  With ``--gestures`` the gesture layer's lips (Ju & Lee) take the place of that line (see
  :class:`~facepuppet.runtime.live.pipeline.LivePipeline`'s ``generator``), and with ``--voice`` the learned
  mouth (:mod:`facepuppet.runtime.voice.stage`: every mouth channel the voice table or vowel profile has, over
  the layer's). Without a level (no audio) it is ``neutral``.
* ``idle``: blinks (eyeBlink*) at seeded random intervals around ``idle_blink_s`` and, for ``head``, a small
  sway (a few degrees of yaw/pitch/roll as slow sums of sines); other channels of the region ease to neutral.
  With ``--gestures`` the gesture layer's blinks and head motion are used instead.

Every mode is a *target* that the output blends towards with the smoothstep of the ease-out (hold: the
target is the held value, so nothing moves). When frames return the output blends from wherever it was
(voice, idle, held) to the live value over ``ease_in_s``, so no tick steps by more than the live motion
plus ``|live - out| * max slope of the ramp (1.5 / ease_in_s) * tick``.

The idle generator is a function of the tick time alone (no state stepped per tick), so a replay on recorded
tick times gives the same idle face.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from facepuppet.runtime.mapping.channels import canonical
from facepuppet.runtime.model.geometry import euler_to_quat

LOSS_MODES = ("hold", "neutral", "voice", "idle")
LOSS_ALIASES = {"ease": "neutral"}
LOSS_REGIONS = ("eyes", "brows", "mouth", "other", "head")
VOICE_REGIONS = ("mouth",)
LOSS_KEYS = ("timeout_s", "ease_out_s", "ease_in_s", *LOSS_REGIONS, "voice_floor_db", "voice_ceiling_db",
             "idle_blink_s", "idle_seed")

BLINK_CLOSE_S = 0.06  # idle blink: close, hold, open (seconds)
BLINK_HOLD_S = 0.04
BLINK_OPEN_S = 0.12
SWAY_DEG = (2.0, 1.5, 1.0)  # idle head sway amplitude: yaw, pitch, roll (degrees)
SWAY_HZ = ((0.11, 0.23), (0.07, 0.19), (0.05, 0.13))  # two slow sines per axis


@dataclass(frozen=True)
class LossSettings:
    """The per-region tracking-loss modes and the voice/idle settings (see the module docstring).

    Attributes
    ----------
    modes : dict of region -> mode, one of LOSS_MODES, for every region of LOSS_REGIONS
    voice_floor_db, voice_ceiling_db : float, dBFS, the level range jawOpen 0..1 spans in ``voice``
    idle_blink_s : float, mean seconds between idle blinks
    idle_seed : int, seed of the idle generator
    """

    modes: dict = field(default_factory=lambda: {r: "neutral" for r in LOSS_REGIONS})
    voice_floor_db: float = -50.0
    voice_ceiling_db: float = -15.0
    idle_blink_s: float = 4.0
    idle_seed: int = 0

    def mode(self, region: str) -> str:
        return self.modes.get(region, "neutral")

    def to_toml(self) -> dict:
        """The keys of this (besides the times) as they are written in ``[tracking_loss]``."""
        return {**self.modes, "voice_floor_db": self.voice_floor_db, "voice_ceiling_db": self.voice_ceiling_db,
                "idle_blink_s": self.idle_blink_s, "idle_seed": self.idle_seed}


def parse_loss(where: str, table: dict, error: type[Exception]) -> LossSettings:
    """LossSettings from a ``[tracking_loss]`` table (its time keys are read by the config); ``error`` is
    raised with a message naming ``where`` and the key."""
    base = LossSettings()
    modes = dict(base.modes)
    for region in LOSS_REGIONS:
        if region not in table:
            continue
        value = table[region]
        mode = LOSS_ALIASES.get(value, value) if isinstance(value, str) else value
        if mode not in LOSS_MODES:
            raise error(f"{where}: key 'tracking_loss.{region}': expected one of "
                        f"{', '.join(repr(m) for m in (*LOSS_MODES, *LOSS_ALIASES))}, got {value!r}")
        if mode == "voice" and region not in VOICE_REGIONS:
            raise error(f"{where}: key 'tracking_loss.{region}': 'voice' drives the mouth only; "
                        f"for {region} use 'idle', 'hold' or 'neutral'")
        modes[region] = mode

    def number(key: str, default: float, positive: bool = False) -> float:
        v = table.get(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or (positive and v <= 0):
            raise error(f"{where}: key 'tracking_loss.{key}': expected a finite number"
                        + (" > 0" if positive else "") + f", got {v!r}")
        return float(v)

    floor = number("voice_floor_db", base.voice_floor_db)
    ceiling = number("voice_ceiling_db", base.voice_ceiling_db)
    if not floor < ceiling:
        raise error(f"{where}: key 'tracking_loss.voice_ceiling_db': expected more than voice_floor_db "
                    f"({floor:g}), got {ceiling:g}")
    seed = table.get("idle_seed", base.idle_seed)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise error(f"{where}: key 'tracking_loss.idle_seed': expected an integer >= 0, got {seed!r}")
    return LossSettings(modes, floor, ceiling, number("idle_blink_s", base.idle_blink_s, positive=True), seed)


def voice_jaw(level_db: float, settings: LossSettings) -> float:
    """jawOpen in [0, 1] of a voice level (dBFS): linear in dB from the floor to the ceiling; NaN gives NaN."""
    if not math.isfinite(level_db):
        return math.nan
    x = (level_db - settings.voice_floor_db) / (settings.voice_ceiling_db - settings.voice_floor_db)
    return min(max(x, 0.0), 1.0)


class IdleMotion:
    """Blinks and a small head sway as functions of time: the ``idle`` loss mode without gesture tables.

    Blink start times are a seeded renewal process: gaps uniform in [0.5, 1.5] x ``blink_s``, drawn in blocks as
    time advances (a few floats kept per block; nothing per frame). Each blink closes over BLINK_CLOSE_S, holds
    BLINK_HOLD_S and opens over BLINK_OPEN_S. The sway is two slow sines per axis with seeded phases.
    """

    BLOCK = 64

    def __init__(self, blink_s: float = 4.0, seed: int = 0) -> None:
        self.blink_s = float(blink_s)
        self._rng = np.random.default_rng(seed)
        self._phases = self._rng.uniform(0.0, 2 * math.pi, size=(3, 2))
        self._starts = np.zeros(0)
        self._end = 0.0  # blinks are drawn up to here
        self._t0 = 0.0  # first start time of the kept block

    def _extend(self, t: float) -> None:
        while self._end <= t + 1.0:
            gaps = self._rng.uniform(0.5, 1.5, size=self.BLOCK) * self.blink_s
            starts = self._end + np.cumsum(gaps)
            keep = self._starts[self._starts > t - 2.0]  # older blinks are over
            self._starts = np.concatenate([keep, starts])
            self._end = float(starts[-1])

    def blink(self, t: float) -> float:
        """Eyelid closure in [0, 1] at time ``t`` (s); ``t`` must not go back by more than 2 s."""
        self._extend(t)
        i = int(np.searchsorted(self._starts, t, side="right")) - 1
        if i < 0:
            return 0.0
        d = t - float(self._starts[i])
        if d < BLINK_CLOSE_S:
            return d / BLINK_CLOSE_S
        d -= BLINK_CLOSE_S
        if d < BLINK_HOLD_S:
            return 1.0
        d -= BLINK_HOLD_S
        return max(0.0, 1.0 - d / BLINK_OPEN_S)

    def sway(self, t: float) -> np.ndarray:
        """Head rotation quaternion (x, y, z, w) of the sway at ``t``."""
        angles = []
        for axis in range(3):
            s = sum(math.sin(2 * math.pi * hz * t + self._phases[axis, j]) for j, hz in enumerate(SWAY_HZ[axis]))
            angles.append(math.radians(SWAY_DEG[axis]) * 0.5 * s)
        return np.asarray(euler_to_quat(angles[0], angles[1], angles[2]), np.float64)


class LossTargets:
    """What each weight channel and the head go towards while tracking is lost, for one channel tuple.

    Parameters
    ----------
    channels : tuple of str
    regions : list of str, each channel's filter region
    settings : LossSettings
    """

    def __init__(self, channels: tuple[str, ...], regions: list[str], settings: LossSettings) -> None:
        self.settings = settings
        keys = [canonical(c) for c in channels]
        modes = np.array([settings.mode(r) for r in regions], dtype=object)
        self.keys = keys
        self.hold = np.array([m == "hold" for m in modes], bool)
        self.jaw = np.array([m == "voice" and k == "jawOpen" for m, k in zip(modes, keys)], bool)
        self.blink = np.array([m == "idle" and k.startswith("eyeBlink") for m, k in zip(modes, keys)], bool)
        self.voice = np.array([m == "voice" for m in modes], bool)
        self.idle = np.array([m == "idle" for m in modes], bool)
        self.head = settings.mode("head")

    @property
    def moving(self) -> bool:
        """Whether the targets change with time (voice or idle somewhere): the output must keep being emitted."""
        return bool(self.voice.any() or self.idle.any() or self.head == "idle")
