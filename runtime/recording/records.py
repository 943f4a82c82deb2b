"""Session record kinds and the byte layout of each kind's payload (encode and decode).

The file framing around these payloads (magic, length, CRC, kind code) and the
writer and reader live in :mod:`facepuppet.runtime.recording.session`. Payloads, all
integers and floats little-endian:

========  ====  ==============================================================
kind      code  payload
========  ====  ==============================================================
HEADER    0     UTF-8 JSON object
LAYOUT    1     UTF-8 JSON ``{"id", "source", "channels", "marker_names",
                "n_markers"}``: what the following frames with this layout id
                carry. Written automatically the first time a frame with a new
                (source, channels, markers) combination is written.
FRAME     2     ``t f64, t_sender f64, number i64, layout id u32, flags u8``,
                then, each present only when its flag bit is set, in this
                order: weights f32[n_channels], head rotation f32[4] (x, y, z,
                w), head translation f32[3], audio level f32 (dBFS), markers
                f32[n_markers * 3]
PACKET    3     live recording: ``b"P1"``, receive time f64 (monotonic s),
                input kind length u16, input kind UTF-8, then the datagram's
                raw bytes
AUDIO     4     live recording: ``b"A1"``, tick time f64 (s), level f32 (dBFS)
TICK      5     live recording: ``b"K1"``, tick index i64, tick time f64 (s
                since the loop started), frames i64 (frames the source had
                completed when the tick took its snapshot), snapshot time f64
                (monotonic s, the packets' clock); lets a replay tick as the
                live run did (same frames at the same tick times)
CONFIG    6     live recording: ``b"C1"``, tick time f64 (s), then the live
                config that took effect at that tick, as UTF-8 TOML (the
                schema of ``--config``, neutral included); the header's
                ``info.config`` is the config the run started with
EVENT     7     live recording: ``b"E1"``, tick time f64 (s), found u8 (1
                tracking found, 0 lost): the filter stage's tracking events
SOURCES   8     live recording with several inputs: ``b"S1"``, tick index
                i64, count u16, then count x i64: frames each mix source
                (the header's ``info.mix_sources``, in order) had completed
                at that tick; one after each TICK record
STATE     9     live recording started mid-run: ``b"T1"``, tick time f64,
                the filter stage's state (UTF-8 JSON)
VOICE     10    live recording with ``--voice``: ``b"V1"``, tick time f64
                (s), count u16, then count x f32: the voice's mouth
                channels that tick (the header's ``info.voice_channels``)
CONTROL   11    live recording: ``b"X1"``, tick time f64 (s), then the
                control command applied at that tick as a UTF-8 JSON object
                (:mod:`facepuppet.runtime.control.commands`)
========  ====  ==============================================================

The PACKET/AUDIO/TICK/CONFIG/EVENT/SOURCES/CONTROL decoders return None for a payload they cannot decode
(the reader counts those as skipped); the FRAME and LAYOUT decoders raise
ValueError (the reader treats that as corruption).
"""

from __future__ import annotations

import enum
import json
import math
import struct
from dataclasses import dataclass

import numpy as np

from facepuppet.runtime.files.json_limits import JsonLimitError, JsonTextError, loads_limited
from facepuppet.runtime.frames import Frame

_FRAME_HEAD = struct.Struct("<ddqIB")  # t, t_sender, number, layout id, flags
_PACKET_HEAD = struct.Struct("<2sdH")  # b"P1", receive time, input kind length
_AUDIO = struct.Struct("<2sdf")  # b"A1", time, level dBFS
_TICK = struct.Struct("<2sqdqd")  # b"K1", tick index, tick time, frames completed, snapshot time
_CONFIG_HEAD = struct.Struct("<2sd")  # b"C1" (CONFIG) or b"T1" (STATE), tick time; then the text
_EVENT = struct.Struct("<2sdB")  # b"E1", tick time, found
_SOURCES_HEAD = struct.Struct("<2sqH")  # b"S1", tick index, count (then count x i64)
_VOICE_HEAD = struct.Struct("<2sdH")  # b"V1", tick time, count (then count x f32)


class RecordKind(enum.IntEnum):
    """Record kind codes; new kinds get new codes, codes are never reused."""

    HEADER = 0
    LAYOUT = 1
    FRAME = 2
    PACKET = 3  # live recording: raw bytes + receive time + input kind
    AUDIO = 4  # live recording: audio levels
    TICK = 5  # live recording: which frame each tick took, and when
    CONFIG = 6  # live recording: a config change and the tick it took effect at
    EVENT = 7  # live recording: tracking lost / found
    SOURCES = 8  # live recording, several inputs: frames each mix source had per tick
    STATE = 9  # live recording started mid-run: the filter stage's state at its start (JSON)
    VOICE = 10  # live recording with --voice: the voice's mouth channels per tick
    CONTROL = 11  # live recording: a control command and the tick it was applied at (JSON)


RESERVED_KINDS = frozenset({RecordKind.PACKET, RecordKind.AUDIO, RecordKind.TICK, RecordKind.CONFIG,
                            RecordKind.EVENT, RecordKind.SOURCES, RecordKind.STATE, RecordKind.VOICE,
                            RecordKind.CONTROL})


class FrameFlags(enum.IntFlag):
    """Which optional parts a FRAME record carries."""

    WEIGHTS = 1
    HEAD_ROTATION = 2
    HEAD_TRANSLATION = 4
    AUDIO_LEVEL = 8
    MARKERS = 16


@dataclass(frozen=True)
class Layout:
    """What the FRAME records under one layout id carry (a LAYOUT record's content)."""

    source: str
    channels: tuple[str, ...] | None
    marker_names: tuple[str, ...] | None
    n_markers: int

    def to_json(self, layout_id: int) -> dict:
        return {
            "id": layout_id,
            "source": self.source,
            "channels": None if self.channels is None else list(self.channels),
            "marker_names": None if self.marker_names is None else list(self.marker_names),
            "n_markers": self.n_markers,
        }


def layout_of(frame: Frame) -> Layout:
    """The layout ``frame`` is written under."""
    n_markers = 0 if frame.markers is None else int(frame.markers.shape[0])
    return Layout(frame.source, frame.channels, frame.marker_names, n_markers)


def encode_frame(frame: Frame, layout_id: int) -> bytes:
    """FRAME payload of ``frame`` under ``layout_id`` (see the module docstring)."""
    flags = 0
    parts = []
    if frame.weights is not None:
        flags |= FrameFlags.WEIGHTS
        parts.append(frame.weights.astype("<f4", copy=False).tobytes())
    if frame.head_rotation is not None:
        flags |= FrameFlags.HEAD_ROTATION
        parts.append(frame.head_rotation.astype("<f4", copy=False).tobytes())
    if frame.head_translation is not None:
        flags |= FrameFlags.HEAD_TRANSLATION
        parts.append(frame.head_translation.astype("<f4", copy=False).tobytes())
    if not math.isnan(frame.audio_level):
        flags |= FrameFlags.AUDIO_LEVEL
        parts.append(struct.pack("<f", frame.audio_level))
    if frame.markers is not None:
        flags |= FrameFlags.MARKERS
        parts.append(frame.markers.astype("<f4", copy=False).tobytes())
    head = _FRAME_HEAD.pack(frame.t, frame.t_sender, frame.number, layout_id, flags)
    return head + b"".join(parts)


@dataclass(frozen=True)
class Packet:
    """One received datagram of a live recording.

    Attributes
    ----------
    t : float, receive time, seconds on the monotonic clock
    kind : str, the input kind that decoded it ("vmc", "livelinkface", ...)
    data : bytes, the datagram as received
    """

    t: float
    kind: str
    data: bytes


def encode_packet_record(t: float, kind: str, data: bytes) -> bytes:
    """PACKET record payload: one received datagram as recorded (see the module docstring)."""
    name = kind.encode("utf-8")
    return _PACKET_HEAD.pack(b"P1", t, len(name)) + name + bytes(data)


def encode_audio(t: float, level_db: float) -> bytes:
    """AUDIO payload (see the module docstring)."""
    return _AUDIO.pack(b"A1", t, level_db)


@dataclass(frozen=True)
class Tick:
    """One drawn tick of a live recording.

    Attributes
    ----------
    k : int, tick index (t = k / fps)
    t : float, tick time, seconds since the frame loop started
    frames : int, frames the live source had completed when this tick took its snapshot
    t_clock : float, the snapshot's time on the monotonic clock (the packets' receive clock)
    """

    k: int
    t: float
    frames: int
    t_clock: float


def encode_tick(k: int, t: float, frames: int, t_clock: float) -> bytes:
    """TICK payload (see the module docstring)."""
    return _TICK.pack(b"K1", int(k), float(t), int(frames), float(t_clock))


def _encode_text(tag: bytes, t: float, text: str) -> bytes:
    return _CONFIG_HEAD.pack(tag, float(t)) + text.encode("utf-8")


def _decode_text(tag: bytes, payload: bytes) -> tuple[float, str] | None:
    """(t, text) of a payload of ``tag``, tick time and UTF-8 text (CONFIG, STATE); None when not one."""
    if len(payload) < _CONFIG_HEAD.size or payload[:2] != tag:
        return None
    _, t = _CONFIG_HEAD.unpack_from(payload)
    try:
        return t, payload[_CONFIG_HEAD.size:].decode("utf-8")
    except UnicodeDecodeError:
        return None


def encode_config(t: float, text: str) -> bytes:
    """CONFIG payload: the config (TOML text) that took effect at tick time ``t``."""
    return _encode_text(b"C1", t, text)


def decode_config(payload: bytes) -> tuple[float, str] | None:
    """(t, TOML text) from a CONFIG payload; None when it is not one this reader knows."""
    return _decode_text(b"C1", payload)


def encode_state(t: float, text: str) -> bytes:
    """STATE payload: the filter stage's state (JSON text, LivePipeline.state_snapshot) at tick time ``t``."""
    return _encode_text(b"T1", t, text)


def decode_state(payload: bytes) -> tuple[float, str] | None:
    """(t, JSON text) from a STATE payload; None when it is not one this reader knows."""
    return _decode_text(b"T1", payload)


MAX_CONTROL_JSON = 64 << 10  # a command is a few hundred bytes; the WebSocket's own limit is this


def encode_control(t: float, command: dict) -> bytes:
    """CONTROL payload: the command (a JSON object) applied at tick time ``t``."""
    return _encode_text(b"X1", t, json.dumps(command, separators=(",", ":"), allow_nan=False))


def decode_control(payload: bytes) -> tuple[float, dict] | None:
    """(t, command object) from a CONTROL payload; None when it is not one this reader knows (or not an object
    within the JSON limits)."""
    if len(payload) > MAX_CONTROL_JSON + _CONFIG_HEAD.size:
        return None
    decoded = _decode_text(b"X1", payload)
    if decoded is None:
        return None
    try:
        doc = loads_limited(decoded[1], "CONTROL record")
    except JsonTextError:
        return None
    return (decoded[0], doc) if isinstance(doc, dict) and math.isfinite(decoded[0]) else None


def decode_packet_record(payload: bytes) -> Packet | None:
    """Packet from a PACKET payload; None when it is not one this reader knows."""
    if len(payload) < _PACKET_HEAD.size or payload[:2] != b"P1":
        return None
    _, t, n = _PACKET_HEAD.unpack_from(payload)
    end = _PACKET_HEAD.size + n
    if end > len(payload):
        return None
    try:
        kind = payload[_PACKET_HEAD.size:end].decode("utf-8")
    except UnicodeDecodeError:
        return None
    return Packet(t, kind, bytes(payload[end:]))


def encode_voice(t: float, values: np.ndarray) -> bytes:
    """VOICE payload (see the module docstring)."""
    v = np.asarray(values, "<f4")
    return _VOICE_HEAD.pack(b"V1", t, len(v)) + v.tobytes()


def decode_voice(payload: bytes) -> tuple[float, np.ndarray] | None:
    """(t, channels float32) from a VOICE payload; None when it is not one this reader knows."""
    if len(payload) < _VOICE_HEAD.size or payload[:2] != b"V1":
        return None
    _, t, n = _VOICE_HEAD.unpack_from(payload)
    if len(payload) != _VOICE_HEAD.size + 4 * n:
        return None
    return t, np.frombuffer(payload, "<f4", n, _VOICE_HEAD.size).astype(np.float32)


def decode_audio(payload: bytes) -> tuple[float, float] | None:
    """(t, level_db) from an AUDIO payload; None when it is not one this reader knows."""
    if len(payload) != _AUDIO.size or payload[:2] != b"A1":
        return None
    _, t, level = _AUDIO.unpack(payload)
    return t, level


def decode_tick(payload: bytes) -> Tick | None:
    """Tick from a TICK payload; None when it is not one this reader knows."""
    if len(payload) != _TICK.size or payload[:2] != b"K1":
        return None
    _, k, t, frames, t_clock = _TICK.unpack(payload)
    return Tick(k, t, frames, t_clock)


def encode_event(t: float, found: bool) -> bytes:
    """EVENT payload (see the module docstring)."""
    return _EVENT.pack(b"E1", float(t), 1 if found else 0)


def decode_event(payload: bytes) -> tuple[float, bool] | None:
    """(tick time, found) from an EVENT payload; None when it is not one this reader knows."""
    if len(payload) != _EVENT.size or payload[:2] != b"E1":
        return None
    _, t, found = _EVENT.unpack(payload)
    if found not in (0, 1):
        return None
    return t, bool(found)


def encode_sources(k: int, frames: tuple[int, ...] | list[int]) -> bytes:
    """SOURCES payload (see the module docstring)."""
    return _SOURCES_HEAD.pack(b"S1", int(k), len(frames)) + struct.pack(f"<{len(frames)}q", *map(int, frames))


def decode_sources(payload: bytes) -> tuple[int, tuple[int, ...]] | None:
    """(tick index, frames per mix source) from a SOURCES payload; None when it is not one this reader knows."""
    if len(payload) < _SOURCES_HEAD.size or payload[:2] != b"S1":
        return None
    _, k, n = _SOURCES_HEAD.unpack_from(payload)
    if len(payload) != _SOURCES_HEAD.size + 8 * n:
        return None
    return k, struct.unpack_from(f"<{n}q", payload, _SOURCES_HEAD.size)


def decode_frame(payload: bytes, layouts: dict[int, Layout]) -> Frame:
    """Frame from a FRAME payload; ValueError when it does not fit its layout."""
    if len(payload) < _FRAME_HEAD.size:
        raise ValueError(f"frame record of {len(payload)} bytes, shorter than its {_FRAME_HEAD.size}-byte head")
    t, t_sender, number, layout_id, flags = _FRAME_HEAD.unpack_from(payload)
    layout = layouts.get(layout_id)
    if layout is None:
        raise ValueError(f"frame refers to layout id {layout_id}, which no earlier LAYOUT record defined")
    if flags & ~0x1F:
        raise ValueError(f"frame flags 0x{flags:02x} have unknown bits")
    n_ch = 0 if layout.channels is None else len(layout.channels)
    sizes = (
        (FrameFlags.WEIGHTS, "weights", n_ch),
        (FrameFlags.HEAD_ROTATION, "head_rotation", 4),
        (FrameFlags.HEAD_TRANSLATION, "head_translation", 3),
        (FrameFlags.AUDIO_LEVEL, "audio_level", 1),
        (FrameFlags.MARKERS, "markers", layout.n_markers * 3),
    )
    expected = _FRAME_HEAD.size + 4 * sum(n for flag, _, n in sizes if flags & flag)
    if len(payload) != expected:
        raise ValueError(f"frame record of {len(payload)} bytes, its flags and layout need {expected}")
    values = np.frombuffer(payload, dtype="<f4", offset=_FRAME_HEAD.size)
    parts: dict = {}
    at = 0
    for flag, name, n in sizes:
        if flags & flag:
            parts[name] = values[at:at + n]
            at += n
    markers = parts.get("markers")
    return Frame(
        t=t,
        source=layout.source,
        channels=layout.channels,
        weights=parts.get("weights"),
        head_rotation=parts.get("head_rotation"),
        head_translation=parts.get("head_translation"),
        audio_level=float(parts["audio_level"][0]) if "audio_level" in parts else math.nan,
        markers=None if markers is None else markers.reshape(-1, 3),
        marker_names=layout.marker_names if markers is not None else None,
        t_sender=t_sender,
        number=number,
    )


def decode_layout(payload: bytes) -> tuple[int, Layout]:
    """(layout id, Layout) from a LAYOUT payload; ValueError when it is not the expected JSON, JsonLimitError
    (a ValueError too) when it is over the JSON limits."""
    try:
        obj = loads_limited(payload, "LAYOUT record")
        channels = obj["channels"]
        marker_names = obj["marker_names"]
        layout = Layout(
            str(obj["source"]),
            None if channels is None else tuple(str(c) for c in channels),
            None if marker_names is None else tuple(str(m) for m in marker_names),
            int(obj["n_markers"]),
        )
        return int(obj["id"]), layout
    except JsonLimitError:
        raise
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"layout record is not the expected JSON object: {exc}") from None
