"""The live run's small TOML config: filtering per region, the response per channel, tracking loss, neutral.

Every key is optional; what is left out keeps its default. Example::

    [filter.eyes]            # eyeBlink*, eyeLook*, eyeSquint*, eyeWide*: light smoothing
    min_cutoff = 3.0         # Hz
    beta = 1.5               # Hz per (weight / s)
    d_cutoff = 1.0           # Hz
    [filter.mouth]           # mouth*, jaw*, tongue*, cheek*: heavier
    min_cutoff = 1.2
    [filter.head]            # head rotation (quaternion components) and translation
    min_cutoff = 1.0
    beta = 0.5

    [tracking_loss]
    timeout_s = 0.5          # no frame for this long: ease to neutral
    ease_out_s = 0.6         # ...over this long
    ease_in_s = 0.25         # frames are back: blend from where we are to live over this long
    mouth = "voice"          # per region: hold / neutral / voice (mouth) / idle (runtime.live.tracking_loss)

    [calibration]
    capture_s = 0.5          # --calibrate / OSC /facepuppet/calibrate / key C: neutral = mean of this window

    [channels.jawOpen]       # any spelling of a channel name (JawOpen, jawOpen, ...): its response
    gain = 1.3               # v = gain * (filtered value - neutral)
    input_range = [0.05, 0.8]   # v over this range ...
    output_range = [0.0, 1.0]   # ... maps onto this one (either given: v outside the input range is held at its ends)
    curve = "threshold"      # linear (default), ease (smoothstep over the range) or threshold
    threshold = 0.1          # threshold curve: v below this (the input's units) gives the output range's low end
    clamp = [0.0, 1.0]       # last: the value is clamped to this

    [face]
    link_blinks = true       # both eyeBlink channels take the stronger of the two (default false)
    mirror = true            # swap left and right channels, negate head yaw and roll and x (default false)

    [neutral]                # the calibrated neutral (written by profiles; key C / --calibrate capture one)
    channels = ["jawOpen", "eyeBlinkLeft"]   # the input's channel names
    weights = [0.06, 0.1]
    rotation = [0.0, 0.0, 0.0, 1.0]          # x, y, z, w
    translation = [0.0, 0.0, 0.0]            # optional

    [profile]                # written by profiles (runtime.live.profiles): what the profile was made for
    character = "ict.npz"
    input = "livelinkface"

    [mix]                    # several inputs at once (run --input A --input B): runtime.live.mix
    order = ["livelinkface", "audio"]

    [mapping]                # a character with VRM expressions (runtime.expressions)
    emotions = true          # the default ARKit -> VRM mapping also drives Joy, Angry, Sorrow, Fun (default false)
    [mapping.channels]       # per input channel (any spelling): exactly these targets, nothing else
    jawOpen = { to = "A", weight = 1.2 }                 # an expression (any VRM spelling) or else a shape
    mouthSmileLeft = [{ to = "Joy", weight = 0.5 }, { to = "smile_l" }]   # several; weight defaults to 1
    tongueOut = "tongue_out"                             # a name alone: that target at weight 1
    eyeLookInLeft = false                                # drive nothing (turn a default off)

The per-channel response runs after the filter and calibration, in this order: gain, input range -> output
range through the curve, clamp; then blink linking. Mirroring swaps the channels before their response, so a
``[channels.NAME]`` names what the character gets. Regions are ``eyes``, ``brows``, ``mouth``, ``other``
(weights) and ``head`` (pose). Errors (:class:`LiveConfigError`) name the file, the key, the type
or range expected and what was found; unknown keys are errors too (a typo
must not pass silently).
"""

from __future__ import annotations

import difflib
import math
import tomllib
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

from facepuppet.runtime.control.hotkeys import parse_hotkeys
from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.files.input_files import regular_file
from facepuppet.runtime.live.mix import MixSettings, parse_mix
from facepuppet.runtime.live.tracking_loss import LOSS_KEYS, LossSettings, parse_loss
from facepuppet.runtime.mapping.channels import ARKIT_NAMES, canonical, split_side
from facepuppet.runtime.mapping.expressions import MappingSettings, MappingTarget

if TYPE_CHECKING:
    import os

REGIONS = ("eyes", "brows", "mouth", "other", "head")
CURVES = ("linear", "ease", "threshold")


class LiveConfigError(InputFileError):
    """A config file that cannot be used: the message names the file, the key and the problem."""


@dataclass(frozen=True)
class FilterSettings:
    """One Euro settings of one region (Hz, Hz per unit/s, Hz)."""

    min_cutoff: float
    beta: float
    d_cutoff: float = 1.0


@dataclass(frozen=True)
class ChannelSettings:
    """The response of one channel (see the module docstring for the order).

    Attributes
    ----------
    gain : float, applied to the value after offset (neutral) removal
    clamp : (low, high), the last step
    input_range, output_range : (low, high) or None; either given: the gained value maps linearly from the input
        range onto the output range (held at the ends), through ``curve``; both None and a linear curve: no remap
    curve : str, ``linear``, ``ease`` (smoothstep) or ``threshold`` (below ``threshold``: the output's low end,
        at or above it: linear)
    threshold : float, in the input's units (the gained value)
    """

    gain: float = 1.0
    clamp: tuple[float, float] = (0.0, 1.0)
    input_range: tuple[float, float] | None = None
    output_range: tuple[float, float] | None = None
    curve: str = "linear"
    threshold: float = 0.1

    @property
    def shaped(self) -> bool:
        """Whether the value is remapped (a range or a curve other than linear)."""
        return self.input_range is not None or self.output_range is not None or self.curve != "linear"


@dataclass(frozen=True)
class Neutral:
    """A calibrated neutral pose: raw input values subtracted before the response.

    Attributes
    ----------
    channels : tuple of str, the input's channel names (matched by any spelling)
    weights : tuple of float, one per channel
    rotation : (x, y, z, w), the neutral head rotation (unit quaternion)
    translation : (x, y, z) or None (None: translation is not offset)
    """

    channels: tuple[str, ...]
    weights: tuple[float, ...]
    rotation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    translation: tuple[float, float, float] | None = None


DEFAULT_FILTERS = {
    "eyes": FilterSettings(min_cutoff=3.0, beta=1.5),  # blinks must stay crisp
    "brows": FilterSettings(min_cutoff=2.0, beta=0.7),
    "mouth": FilterSettings(min_cutoff=1.2, beta=0.4),  # steadier, lip jitter shows most
    "other": FilterSettings(min_cutoff=1.5, beta=0.5),
    "head": FilterSettings(min_cutoff=1.0, beta=0.5),
}


@dataclass(frozen=True)
class LiveConfig:
    """Settings of the live pipeline (see the module docstring for the file format).

    Attributes
    ----------
    filters : dict of region -> FilterSettings
    channels : dict of canonical channel key -> ChannelSettings
    default_channel : ChannelSettings, for channels not listed
    timeout_s, ease_out_s, ease_in_s : float, seconds (tracking loss)
    capture_s : float, seconds of frames averaged into the neutral pose
    link_blinks : bool, both eyeBlink channels take the stronger of the two
    mirror : bool, left and right channels swapped, head yaw and roll (and x) negated
    neutral : Neutral or None, the calibrated neutral in force (None: none)
    mapping : MappingSettings, the ``[mapping]`` (channels onto a character's expressions and shapes)
    loss : LossSettings, the per-region tracking-loss modes of ``[tracking_loss]``
        (:mod:`~facepuppet.runtime.live.tracking_loss`)
    mix : MixSettings, the ``[mix]`` source orders of a run with several inputs (:mod:`~facepuppet.runtime.live.mix`)
    hotkeys : tuple of (key, command object), the window's ``[hotkeys]``
        (:mod:`~facepuppet.runtime.control.hotkeys`)
    path : str, the file it came from ("" for defaults)
    """

    filters: dict = field(default_factory=lambda: dict(DEFAULT_FILTERS))
    channels: dict = field(default_factory=dict)
    default_channel: ChannelSettings = ChannelSettings()
    timeout_s: float = 0.5
    ease_out_s: float = 0.6
    ease_in_s: float = 0.25
    capture_s: float = 0.5
    link_blinks: bool = False
    mirror: bool = False
    neutral: Neutral | None = None
    mapping: MappingSettings = MappingSettings()
    loss: LossSettings = LossSettings()
    mix: MixSettings = MixSettings()
    hotkeys: tuple = ()
    path: str = ""

    def channel(self, name: str) -> ChannelSettings:
        """Settings of a channel by any spelling of its name."""
        return self.channels.get(canonical(name), self.default_channel)


def _number(where: str, key: str, value, positive: bool = False, non_negative: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise LiveConfigError(f"{where}: key '{key}': expected a finite number, got {value!r} "
                              f"({type(value).__name__})")
    if positive and value <= 0:
        raise LiveConfigError(f"{where}: key '{key}': expected a number > 0, got {value!r}")
    if non_negative and value < 0:
        raise LiveConfigError(f"{where}: key '{key}': expected a number >= 0, got {value!r}")
    return float(value)


def _table(where: str, key: str, value, allowed: tuple[str, ...] | None) -> dict:
    if not isinstance(value, dict):
        raise LiveConfigError(f"{where}: key '{key}': expected a table, got {value!r} ({type(value).__name__})")
    if allowed is not None:
        unknown = sorted(set(value) - set(allowed))
        if unknown:
            raise LiveConfigError(f"{where}: key '{key}.{unknown[0]}': unknown key; expected one of "
                                  f"{', '.join(allowed)}")
    return value


def _pair(where: str, key: str, c, strict: bool = False) -> tuple[float, float]:
    if not isinstance(c, list) or len(c) != 2:
        raise LiveConfigError(f"{where}: key '{key}': expected an array of two numbers [low, high], "
                              f"got {c!r} ({type(c).__name__})")
    lo, hi = (_number(where, key, v) for v in c)
    if lo > hi or (strict and lo == hi):
        raise LiveConfigError(f"{where}: key '{key}': expected low {'<' if strict else '<='} high, got [{lo}, {hi}]")
    return lo, hi


def _channel(where: str, key: str, value: dict, base: ChannelSettings) -> ChannelSettings:
    _table(where, key, value, ("gain", "clamp", "input_range", "output_range", "curve", "threshold"))
    gain = _number(where, f"{key}.gain", value["gain"]) if "gain" in value else base.gain
    clamp = _pair(where, f"{key}.clamp", value["clamp"]) if "clamp" in value else base.clamp
    in_range = _pair(where, f"{key}.input_range", value["input_range"], strict=True) if "input_range" in value \
        else base.input_range
    out = value.get("output_range")
    if out is not None and not (isinstance(out, list) and len(out) == 2):
        raise LiveConfigError(f"{where}: key '{key}.output_range': expected an array of two numbers [from, to], "
                              f"got {out!r} ({type(out).__name__})")
    out_range = tuple(_number(where, f"{key}.output_range", v) for v in out) if out is not None else base.output_range
    curve = value.get("curve", base.curve)
    if curve not in CURVES:
        raise LiveConfigError(f"{where}: key '{key}.curve': expected one of {', '.join(CURVES)}, got {curve!r}")
    threshold = _number(where, f"{key}.threshold", value["threshold"]) if "threshold" in value else base.threshold
    return ChannelSettings(gain, clamp, in_range, out_range, curve, threshold)


def _flag(where: str, key: str, value) -> bool:
    if not isinstance(value, bool):
        raise LiveConfigError(f"{where}: key '{key}': expected true or false, got {value!r} ({type(value).__name__})")
    return value


def _numbers(where: str, key: str, value, n: int | None = None) -> tuple[float, ...]:
    if not isinstance(value, list) or (n is not None and len(value) != n):
        what = f"an array of {n} numbers" if n is not None else "an array of numbers"
        raise LiveConfigError(f"{where}: key '{key}': expected {what}, got {value!r} ({type(value).__name__})")
    return tuple(_number(where, key, v) for v in value)


def _neutral(where: str, value) -> Neutral:
    table = _table(where, "neutral", value, ("channels", "weights", "rotation", "translation"))
    names = table.get("channels", [])
    if not isinstance(names, list) or not all(isinstance(n, str) and n.strip() for n in names):
        raise LiveConfigError(f"{where}: key 'neutral.channels': expected an array of channel names, got {names!r}")
    weights = _numbers(where, "neutral.weights", table.get("weights", []))
    if len(weights) != len(names):
        raise LiveConfigError(f"{where}: key 'neutral.weights': expected {len(names)} numbers (one per "
                              f"neutral.channels), got {len(weights)}")
    rotation = _numbers(where, "neutral.rotation", table.get("rotation", [0.0, 0.0, 0.0, 1.0]), 4)
    if math.hypot(*rotation) < 1e-6:
        raise LiveConfigError(f"{where}: key 'neutral.rotation': expected a unit quaternion [x, y, z, w], "
                              f"got {list(rotation)}")
    translation = _numbers(where, "neutral.translation", table["translation"], 3) if "translation" in table \
        else None
    return Neutral(tuple(names), weights, rotation, translation)


def _profile_table(where: str, value) -> None:
    table = _table(where, "profile", value, ("character", "input", "saved"))
    for k, v in table.items():
        if not isinstance(v, str):
            raise LiveConfigError(f"{where}: key 'profile.{k}': expected a string, got {v!r} ({type(v).__name__})")


def _check_channel(where: str, name: str, known: dict[str, str], section: str = "channels") -> None:
    """A ``[channels.NAME]`` must name a known channel (any spelling, or one side of an unsided one)."""
    key = canonical(name)
    if key in known or split_side(key)[0] in known:
        return
    close = difflib.get_close_matches(key, list(known), n=3, cutoff=0.75)
    hint = (f"; did you mean {' or '.join(known[c] for c in close)}?" if close
            else "; expected an ARKit name (jawOpen, eyeBlinkLeft, ...) or one of the character's shapes")
    raise LiveConfigError(f"{where}: key '{section}.{name}': no channel of that name{hint}")


def _mapping_targets(where: str, key: str, value) -> tuple[MappingTarget, ...]:
    """The targets of one ``[mapping.channels]`` entry: false, a name, a table {to, weight} or an array of them."""
    if value is False:
        return ()
    items = value if isinstance(value, list) else [value]
    out = []
    for item in items:
        if isinstance(item, str) and item.strip():
            out.append(MappingTarget(item.strip()))
            continue
        if not isinstance(item, dict):
            raise LiveConfigError(f"{where}: key '{key}': expected false, a target name, a table "
                                  f"{{ to = NAME, weight = NUMBER }} or an array of them, got {item!r}")
        _table(where, key, item, ("to", "weight"))
        to = item.get("to")
        if not isinstance(to, str) or not to.strip():
            raise LiveConfigError(f"{where}: key '{key}.to': expected the name of an expression or shape, "
                                  f"got {to!r}")
        weight = _number(where, f"{key}.weight", item["weight"]) if "weight" in item else 1.0
        out.append(MappingTarget(to.strip(), weight))
    if not out:
        raise LiveConfigError(f"{where}: key '{key}': an empty array; write false to make the channel drive nothing")
    return tuple(out)


def _mapping(where: str, value, known: dict[str, str]) -> MappingSettings:
    table = _table(where, "mapping", value, ("emotions", "channels"))
    emotions = table.get("emotions", False)
    if not isinstance(emotions, bool):
        raise LiveConfigError(f"{where}: key 'mapping.emotions': expected true or false, got {emotions!r}")
    channels, written = {}, {}
    for name, targets in _table(where, "mapping.channels", table.get("channels", {}), None).items():
        _check_channel(where, name, known, "mapping.channels")
        key = canonical(name)
        channels[key] = _mapping_targets(where, f"mapping.channels.{name}", targets)
        written[key] = name
    return MappingSettings(emotions, channels, written, where)


def parse_live_config(data: dict, where: str = "<config>", known_channels: Iterable[str] | None = None) -> LiveConfig:
    """LiveConfig from an already parsed TOML document; ``where`` names it in errors.

    ``known_channels``: the names a ``[channels.NAME]`` may use besides ARKit's 52 (the character's shapes,
    the elastic muscles); any other name is an error listing the close matches.
    """
    known = {canonical(n): n for n in (*ARKIT_NAMES, *(known_channels or ()))}
    _table(where, "<top>", data, ("filter", "tracking_loss", "calibration", "channels", "default_channel",
                                  "mapping", "face", "neutral", "profile", "mix", "hotkeys"))
    cfg = LiveConfig(path=where)
    filters = dict(DEFAULT_FILTERS)
    for region, values in _table(where, "filter", data.get("filter", {}), REGIONS).items():
        key = f"filter.{region}"
        _table(where, key, values, ("min_cutoff", "beta", "d_cutoff"))
        base = filters[region]
        filters[region] = FilterSettings(
            min_cutoff=_number(where, f"{key}.min_cutoff", values.get("min_cutoff", base.min_cutoff), positive=True),
            beta=_number(where, f"{key}.beta", values.get("beta", base.beta), non_negative=True),
            d_cutoff=_number(where, f"{key}.d_cutoff", values.get("d_cutoff", base.d_cutoff), positive=True),
        )
    loss = _table(where, "tracking_loss", data.get("tracking_loss", {}), LOSS_KEYS)
    calib = _table(where, "calibration", data.get("calibration", {}), ("capture_s",))
    default_channel = cfg.default_channel
    if "default_channel" in data:
        default_channel = _channel(where, "default_channel", data["default_channel"], default_channel)
    channels = {}
    for name, values in _table(where, "channels", data.get("channels", {}), None).items():
        _check_channel(where, name, known)
        channels[canonical(name)] = _channel(where, f"channels.{name}", values, default_channel)
    mapping = _mapping(where, data["mapping"], known) if "mapping" in data else cfg.mapping
    face = _table(where, "face", data.get("face", {}), ("link_blinks", "mirror"))
    if "profile" in data:
        _profile_table(where, data["profile"])  # what a profile was made for: read by runtime.live.profiles
    return replace(
        cfg,
        mapping=mapping,
        link_blinks=_flag(where, "face.link_blinks", face.get("link_blinks", cfg.link_blinks)),
        mirror=_flag(where, "face.mirror", face.get("mirror", cfg.mirror)),
        neutral=_neutral(where, data["neutral"]) if "neutral" in data else None,
        loss=parse_loss(where, loss, LiveConfigError),
        mix=parse_mix(where, data["mix"], LiveConfigError,
                      lambda name: _check_channel(where, name, known, "mix.channels")) if "mix" in data else cfg.mix,
        filters=filters,
        channels=channels,
        default_channel=default_channel,
        timeout_s=_number(where, "tracking_loss.timeout_s", loss.get("timeout_s", cfg.timeout_s), positive=True),
        ease_out_s=_number(where, "tracking_loss.ease_out_s", loss.get("ease_out_s", cfg.ease_out_s), positive=True),
        ease_in_s=_number(where, "tracking_loss.ease_in_s", loss.get("ease_in_s", cfg.ease_in_s), positive=True),
        capture_s=_number(where, "calibration.capture_s", calib.get("capture_s", cfg.capture_s), positive=True),
        hotkeys=parse_hotkeys(where, data["hotkeys"], LiveConfigError) if "hotkeys" in data else (),
    )


MAX_CONFIG_BYTES = 4 << 20  # a config with a large [mapping] is tens of kB


def read_toml(source: bytes | str, where: str) -> dict:
    """The table of TOML ``source``: bytes as read from a file, or text (a recording's config), checked the
    same way wherever it comes from.

    Raises
    ------
    LiveConfigError
        naming ``where``: over MAX_CONFIG_BYTES, not UTF-8, not TOML, or nested deeper than the parser's
        recursion goes (tomllib recurses once per nested array or inline table).
    """
    if len(source) > MAX_CONFIG_BYTES:
        raise LiveConfigError(f"{where}: {len(source)} bytes; a config is at most {MAX_CONFIG_BYTES}")
    try:
        return tomllib.loads(source.decode("utf-8") if isinstance(source, bytes) else source)
    except tomllib.TOMLDecodeError as exc:
        raise LiveConfigError(f"{where}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise LiveConfigError(f"{where}: not UTF-8 text (byte {exc.start}: {exc.reason}); TOML is UTF-8") from None
    except RecursionError:
        raise LiveConfigError(f"{where}: not a config facepuppet can read: arrays or tables nest too deep") from None


def read_toml_file(path: str | os.PathLike, what: str = "TOML config file") -> tuple[Path, dict]:
    """(path, its TOML table): a regular file of at most MAX_CONFIG_BYTES, read by :func:`read_toml`.

    Raises LiveConfigError naming the file (FileNotFoundError when there is none)."""
    path = regular_file(path, what)
    size = path.stat().st_size
    if size > MAX_CONFIG_BYTES:
        raise LiveConfigError(f"{path}: {size} bytes; a config is at most {MAX_CONFIG_BYTES}")
    return path, read_toml(path.read_bytes(), str(path))


def load_live_config(path: str | os.PathLike, known_channels: Iterable[str] | None = None) -> LiveConfig:
    """Read and check a TOML config file (``known_channels`` as :func:`parse_live_config`).

    Raises
    ------
    LiveConfigError
        naming the file and key (bad TOML, wrong type, out of range, unknown key or channel).
    FileNotFoundError
        when the file does not exist.
    """
    path, data = read_toml_file(path)
    return parse_live_config(data, str(path), known_channels)
