"""The ``mix`` stage: several inputs at once, each channel (and the head) from the first live source in its order.

``run --input livelinkface --input audio`` or ``run --input vmc --input openseeface --listen A --listen B``:
the first tracker input is the frame loop's source; the others (and ``audio``, the voice) are *mix
sources* this stage polls once per tick. The ``[mix]`` section of the live config gives the order::

    [mix]
    order = ["livelinkface", "audio"]       # every channel and the head (default: the inputs as given)
    ease_s = 0.25                           # a channel whose source changes crossfades over this long
    [mix.regions]                           # per region (eyes, brows, mouth, other, head)
    head = ["openseeface", "livelinkface"]
    [mix.channels]                          # per channel (any spelling), before its region's order
    jawOpen = ["livelinkface", "audio"]

Sources are named by their input kind; a kind given twice is ``KIND`` then ``KIND#2``. A source is *live*
for a channel when its newest frame came less than ``timeout_s`` (``[tracking_loss]``) of tick time ago and
carries a finite value for that channel (a tracker that stops sending a channel, or sends NaN, is passed
over for it). ``audio`` offers one channel, ``jawOpen``, from the voice level (the line of
:func:`~facepuppet.runtime.live.tracking_loss.voice_jaw`), live while there is a level: it fills the jaw
while a tracker is live but sends no (finite) jaw. A channel that no source in its order offers eases to 0
(the head to identity); when no *tracker* is live the stage emits nothing and the ``filter`` stage's
tracking loss takes over (per region, as configured: ``[tracking_loss] mouth = "voice"`` takes the jaw
from the same voice), so the lost / found events mean "no tracker" / "a tracker again".

A tick emits a mixed frame when a source delivered a new frame this tick (or a crossfade or the voice is
moving); its channels are the union of what the sources sent, in order of first appearance. Each source
keeps its own counters (``NAME.frames``, ``NAME.lost``, ``NAME.found``, and ``NAME.served``, the
channel-ticks it supplied; one flat dict, as ``--stats`` prints counter groups). Everything works on tick
times, so a replay of a recording (which keeps each source's packets and, per tick, how many frames each
had completed) mixes as the live run did.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.live.tracking_loss import LossSettings, voice_jaw
from facepuppet.runtime.mapping.channels import canonical, filter_region
from facepuppet.runtime.model.geometry import nlerp, smoothstep

if TYPE_CHECKING:
    from facepuppet.runtime.voice.stage import VoiceStage

MIX_KEYS = ("order", "ease_s", "regions", "channels")
MIX_REGIONS = ("eyes", "brows", "mouth", "other", "head")
VOICE = "audio"
_IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


@dataclass(frozen=True)
class MixSettings:
    """The ``[mix]`` section: source orders (source names as :func:`source_names` gives them).

    Attributes
    ----------
    order : tuple of str or None, the default order (None: the inputs in the order given)
    regions : dict of region -> tuple of str
    channels : dict of canonical channel key -> tuple of str
    ease_s : float, crossfade seconds when a channel changes source
    """

    order: tuple | None = None
    regions: dict = field(default_factory=dict)
    channels: dict = field(default_factory=dict)
    ease_s: float = 0.25

    @property
    def empty(self) -> bool:
        return self.order is None and not self.regions and not self.channels

    def names(self) -> set[str]:
        """Every source name the orders mention."""
        out = set(self.order or ())
        for seq in (*self.regions.values(), *self.channels.values()):
            out.update(seq)
        return out


def parse_mix(where: str, table: dict, error: type[Exception], check_channel: Callable[[str], None]) -> MixSettings:
    """MixSettings from a ``[mix]`` table; ``error`` names ``where`` and the key; ``check_channel(name)`` raises
    for a channel name that is not known."""
    if not isinstance(table, dict):
        raise error(f"{where}: key 'mix': expected a table, got {table!r}")
    unknown = sorted(set(table) - set(MIX_KEYS))
    if unknown:
        raise error(f"{where}: key 'mix.{unknown[0]}': unknown key; expected one of {', '.join(MIX_KEYS)}")

    def order(key: str, value) -> tuple:
        if (not isinstance(value, list) or not value
                or not all(isinstance(v, str) and v.strip() for v in value)):
            raise error(f"{where}: key '{key}': expected a non-empty array of source names (input kinds such as "
                        f"\"livelinkface\", \"audio\", \"vmc#2\"), got {value!r}")
        names = tuple(v.strip() for v in value)
        if len(set(names)) != len(names):
            raise error(f"{where}: key '{key}': a source is named twice in {list(names)}")
        return names

    base = MixSettings()
    default = order("mix.order", table["order"]) if "order" in table else None
    ease = table.get("ease_s", base.ease_s)
    if isinstance(ease, bool) or not isinstance(ease, (int, float)) or not math.isfinite(ease) or ease <= 0:
        raise error(f"{where}: key 'mix.ease_s': expected a finite number > 0, got {ease!r}")
    regions = table.get("regions", {})
    if not isinstance(regions, dict):
        raise error(f"{where}: key 'mix.regions': expected a table, got {regions!r}")
    for region in regions:
        if region not in MIX_REGIONS:
            raise error(f"{where}: key 'mix.regions.{region}': unknown region; expected one of "
                        f"{', '.join(MIX_REGIONS)}")
    channels = table.get("channels", {})
    if not isinstance(channels, dict):
        raise error(f"{where}: key 'mix.channels': expected a table, got {channels!r}")
    for name in channels:
        check_channel(name)
    return MixSettings(default, {r: order(f"mix.regions.{r}", v) for r, v in regions.items()},
                       {canonical(n): order(f"mix.channels.{n}", v) for n, v in channels.items()}, float(ease))


def source_names(kinds: Sequence[str]) -> tuple[str, ...]:
    """Names of the inputs in the order given: the kind, then ``KIND#2``, ``KIND#3`` for repeats."""
    seen: dict[str, int] = {}
    out = []
    for kind in kinds:
        seen[kind] = seen.get(kind, 0) + 1
        out.append(kind if seen[kind] == 1 else f"{kind}#{seen[kind]}")
    return tuple(out)


def check_mix_sources(settings: MixSettings, names: Sequence[str], where: str) -> None:
    """ValueError naming the config when an order names a source the run does not have."""
    missing = sorted(settings.names() - set(names))
    if missing:
        raise InputFileError(f"--config {where}: [mix] names the source {missing[0]!r}, which this run does not have; "
                             f"its sources are {', '.join(names)} (one per --input, a repeated kind as KIND#2)")


def follow_config(stage: MixStage, default_order: Sequence[str],
                  log: Callable[[str], None]) -> Callable[[float, object], None]:
    """An ``on_config`` hook for the filter stage (``LivePipeline.on_config``): a config applied live (the panel,
    a recording's schedule) hands its ``[mix]`` orders, its ``timeout_s`` and its voice line to ``stage``,
    from the next tick on. An order naming a source the run does not have is refused with a warning (the mix
    keeps its orders)."""
    def hook(t: float, config) -> None:
        settings = config.mix if config.mix.order is not None else replace(config.mix, order=tuple(default_order))
        try:
            check_mix_sources(settings, stage.names, config.path or "(the config applied)")
        except ValueError as exc:
            log(f"mix: warning: {exc}; the mix keeps its orders")
            return
        stage.configure(settings, config.timeout_s)
        for name in stage.names[1:]:
            source = stage.source(name)
            if isinstance(source, VoiceMixSource):
                source.loss = config.loss
    return hook


class VoiceMixSource:
    """The ``audio`` mix source: ``jawOpen`` from the voice level, a new value every tick while there is one.

    Parameters
    ----------
    level : callable t -> dBFS (the audio tap's level: the value the recording keeps)
    loss : LossSettings, its voice_floor_db / voice_ceiling_db give the line from level to jaw
    voice : VoiceStage or None (``--voice``): its learned mouth channels instead of the level's jaw
    """

    channels = ("jawOpen",)

    def __init__(self, level: Callable[[float], float], loss: LossSettings, voice: VoiceStage | None = None) -> None:
        self.level = level
        self.loss = loss
        self.voice = voice
        if voice is not None:
            self.channels = tuple(voice.outputs)
        self.counters: dict = {}
        self.frames_taken = 0

    def latest(self, t: float) -> tuple[Frame | None, int]:
        if self.voice is not None:
            frame = self.voice.frame(t)
            if frame is not None:
                self.frames_taken += 1
            return frame, 0
        jaw = voice_jaw(float(self.level(t)), self.loss)
        if not math.isfinite(jaw):
            return None, 0
        self.frames_taken += 1
        return Frame(t=t, source=VOICE, channels=self.channels, weights=np.array([jaw], np.float32)), 0


class _Source:
    """One source's newest frame and its state in the mix."""

    def __init__(self, name: str, source):
        self.name, self.source = name, source
        self.frame: Frame | None = None
        self.t_frame = -math.inf  # tick time the newest frame arrived
        self.live = False
        self.tracker = not isinstance(source, VoiceMixSource)


class MixStage:
    """The ``mix`` stage (see the module docstring).

    Parameters
    ----------
    names : sequence of str, every source's name in input order (the first is the frame loop's source)
    sources : dict of name -> source with ``latest(t) -> (frame or None, stale)``, for every source but the first
    settings : MixSettings
    timeout_s : float, a source with no frame for this long is lost (for every channel)

    Attributes
    ----------
    counters : dict of str to int: ``NAME.frames`` (new frames taken), ``NAME.lost``, ``NAME.found`` (times the
        source went quiet past the timeout / came back), ``NAME.served`` (channel-ticks it supplied) for each
        source, and ``handovers`` (channel and head source changes)
    chosen : dict of canonical channel key -> source name (None: no source) of the last tick, and ``head``
    """

    name = "mix"

    def __init__(self, names: Sequence[str], sources: dict, settings: MixSettings, timeout_s: float = 0.5) -> None:
        self.names = tuple(names)
        if not self.names or set(sources) != set(self.names[1:]):
            raise ValueError(f"MixStage: expected a source for each of {self.names[1:]}, got {sorted(sources)}")
        self.settings = settings
        self.timeout_s = float(timeout_s)
        self._sources = [_Source(self.names[0], None)] + [_Source(n, sources[n]) for n in self.names[1:]]
        self._rank = {n: i for i, n in enumerate(self.names)}
        self.counters: dict = {"handovers": 0}
        for n in self.names:
            self.counters.update({f"{n}.frames": 0, f"{n}.lost": 0, f"{n}.found": 0, f"{n}.served": 0})
        self.chosen: dict = {}
        self._channels: tuple[str, ...] = ()
        self._keys: list[str] = []
        self._orders: list[list[int]] = []
        self._head_order = self._order_of(None, "head")
        self._choice = np.zeros(0, np.int64)  # per channel: source index, -1 none
        self._out = np.zeros(0)
        self._from = np.zeros(0)
        self._switch_t = np.zeros(0)
        self._head = (-1, _IDENTITY.copy(), None)  # source, rotation, translation last emitted
        self._head_from: tuple = (_IDENTITY.copy(), None)
        self._head_switch_t = -math.inf

    def configure(self, settings: MixSettings, timeout_s: float) -> None:
        """Take a changed ``[mix]`` (a live config change): the orders are rebuilt; a channel whose first live
        source changes crossfades over ``ease_s`` as on any hand-over."""
        self.settings = settings
        self.timeout_s = float(timeout_s)
        self._head_order = self._order_of(None, "head")
        self._orders = [self._order_of(k, filter_region(k)) for k in self._keys]

    def _order_of(self, key: str | None, region: str) -> list[int]:
        s = self.settings
        seq = (s.channels.get(key) if key is not None else None) or s.regions.get(region) or s.order or self.names
        return [self._rank[n] for n in seq if n in self._rank]

    def source(self, name: str) -> object:
        """The source object of a mix source by name (None for the first, the loop's own)."""
        return self._sources[self._rank[name]].source

    def tracker_sources(self) -> list[tuple[str, object]]:
        """(name, source) of the tracker mix sources (all but the loop's own and the voice), in input order."""
        return [(s.name, s.source) for s in self._sources[1:] if s.tracker]

    @property
    def source_states(self) -> dict[str, str]:
        """Each source's state for the panel: ``live`` or ``lost``."""
        return {s.name: "live" if s.live else "lost" for s in self._sources}

    def __call__(self, frame: Frame | None, t: float) -> Frame | None:
        fresh = False
        for i, s in enumerate(self._sources):
            new = frame if i == 0 else s.source.latest(t)[0]
            if new is not None:
                s.frame, s.t_frame = new, t
                self.counters[f"{s.name}.frames"] += 1
                fresh = fresh or s.tracker
            live = s.frame is not None and t - s.t_frame <= self.timeout_s
            if live != s.live:
                self.counters[f"{s.name}.found" if live else f"{s.name}.lost"] += 1
                s.live = live
        self._grow_channels()
        if not any(s.live and s.tracker for s in self._sources):
            return None  # every tracker is quiet: the filter stage's tracking loss takes over
        choice, values = self._choose()
        fresh = fresh or any(not self._sources[i].tracker for i in set(choice.tolist()) if i >= 0)
        ease = self.settings.ease_s
        switched = choice != self._choice
        if switched.any():
            self.counters["handovers"] += int(switched.sum())
            self._from = np.where(switched, self._out, self._from)
            self._switch_t = np.where(switched, t, self._switch_t)
            self._choice = choice
        s = smoothstep(0.0, 1.0, (t - self._switch_t) / ease)
        out = self._from + s * (values - self._from)
        moving = bool(np.any(s < 1.0))
        self._out = out
        for i in choice[choice >= 0]:
            self.counters[f"{self.names[i]}.served"] += 1
        rotation, translation, head_moving = self._mix_head(t)
        self.chosen = {k: (self.names[c] if c >= 0 else None) for k, c in zip(self._keys, choice)}
        self.chosen["head"] = self.names[self._head[0]] if self._head[0] >= 0 else None
        if not (fresh or moving or head_moving):
            return None
        newest = max((x for x in self._sources if x.frame is not None), key=lambda x: x.t_frame)
        src = newest.frame
        # a tick without a new frame (a crossfade moving) is stamped as if received now, on the frames' clock
        # (the newest frame's receive time + the tick time since it came): the filter's dt stays the tick's
        return Frame(t=src.t + (t - newest.t_frame), source="mix", channels=self._channels,
                     weights=out.astype(np.float32),
                     head_rotation=rotation, head_translation=translation, audio_level=src.audio_level,
                     t_sender=src.t_sender, number=src.number)

    def _grow_channels(self) -> None:
        """The union of the sources' channels, in order of first appearance (grows, never shrinks)."""
        known = set(self._keys)
        added = []
        for s in self._sources:
            if s.frame is not None and s.frame.channels is not None:
                for c in s.frame.channels:
                    k = canonical(c)
                    if k not in known:
                        known.add(k)
                        added.append((c, k))
        if not added:
            return
        self._channels = self._channels + tuple(c for c, _ in added)
        self._keys += [k for _, k in added]
        self._orders += [self._order_of(k, filter_region(k)) for _, k in added]
        n = len(added)
        self._choice = np.concatenate([self._choice, np.full(n, -2, np.int64)])  # -2: not chosen yet
        self._out = np.concatenate([self._out, np.zeros(n)])
        self._from = np.concatenate([self._from, np.zeros(n)])
        self._switch_t = np.concatenate([self._switch_t, np.full(n, -math.inf)])
        self._index_cache: dict = {}

    def _index(self, frame: Frame) -> dict:
        cache = self.__dict__.setdefault("_index_cache", {})
        hit = cache.get(frame.channels)
        if hit is None:
            if len(cache) > 64:
                cache.clear()
            hit = cache[frame.channels] = {canonical(c): j for j, c in enumerate(frame.channels)}
        return hit

    def _choose(self) -> tuple[np.ndarray, np.ndarray]:
        n = len(self._keys)
        choice = np.full(n, -1, np.int64)
        values = np.zeros(n)
        for j, (key, order) in enumerate(zip(self._keys, self._orders)):
            for i in order:
                s = self._sources[i]
                if not s.live or s.frame.weights is None or s.frame.channels is None:
                    continue
                at = self._index(s.frame).get(key)
                if at is None:
                    continue
                v = float(s.frame.weights[at])
                if math.isfinite(v):
                    choice[j], values[j] = i, v
                    break
        first = self._choice == -2  # a channel's first source: no crossfade from 0
        if first.any():
            self._out = np.where(first, values, self._out)
            self._from = np.where(first, values, self._from)
            self._choice = np.where(first, choice, self._choice)
        return choice, values

    def _mix_head(self, t: float) -> tuple:
        pick, rot, trans = -1, _IDENTITY, None
        for i in self._head_order:
            s = self._sources[i]
            if s.live and s.frame.head_rotation is not None and np.isfinite(s.frame.head_rotation).all():
                pick, rot, trans = i, s.frame.head_rotation.astype(np.float64), s.frame.head_translation
                break
        if pick != self._head[0]:
            if self._head[0] != -1 or self._head_switch_t != -math.inf:
                self.counters["handovers"] += 1
                self._head_from, self._head_switch_t = (self._head[1], self._head[2]), t
            else:  # the first head: no crossfade
                self._head_switch_t = -math.inf
        s = smoothstep(0.0, 1.0, (t - self._head_switch_t) / self.settings.ease_s)
        out_rot = nlerp(self._head_from[0], rot, s) if s < 1.0 else rot
        a, b = self._head_from[1], trans
        out_trans = b if (s >= 1.0 or a is None or b is None) else a + s * (np.asarray(b) - a)
        self._head = (pick, out_rot, out_trans)
        return (out_rot if pick >= 0 or s < 1.0 else None), out_trans, bool(s < 1.0)
