"""Channel names across conventions, and the map from a source's channels to a rig's.

Conventions met in the wild, all for the same ARKit expression:

==================  ==================  ============================
convention          example             where
==================  ==================  ============================
ARKit camelCase     ``eyeBlinkLeft``    ARKit, MediaPipe, this project
PascalCase          ``EyeBlinkLeft``    Live Link Face, VMC perfect sync
``_L``/``_R``       ``eyeBlink_L``      ICT-FaceKit, Face Cap's head
split unsided       ``browInnerUp_L``   rigs that split ARKit's unsided
                                        shapes (browInnerUp, cheekPuff)
==================  ==================  ============================

Every name is brought to one canonical key (ARKit camelCase, sides spelled
``Left``/``Right``); :class:`ChannelMap` then matches keys, splitting an
unsided source onto both sides of a rig that splits it, and averaging two
sided sources onto a rig that has one unsided shape. Names that do not match
are reported once (:attr:`ChannelMap.unmatched_source`,
:attr:`ChannelMap.undriven_target`), never silently dropped.

Left and right are the subject's own, in every convention.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

# Apple's order (PROTOCOLS.md §2); the same as Unreal EARFaceBlendShape 0-51.
ARKIT_NAMES: tuple[str, ...] = (
    "eyeBlinkLeft", "eyeLookDownLeft", "eyeLookInLeft", "eyeLookOutLeft", "eyeLookUpLeft",
    "eyeSquintLeft", "eyeWideLeft", "eyeBlinkRight", "eyeLookDownRight", "eyeLookInRight",
    "eyeLookOutRight", "eyeLookUpRight", "eyeSquintRight", "eyeWideRight", "jawForward",
    "jawLeft", "jawRight", "jawOpen", "mouthClose", "mouthFunnel",
    "mouthPucker", "mouthLeft", "mouthRight", "mouthSmileLeft", "mouthSmileRight",
    "mouthFrownLeft", "mouthFrownRight", "mouthDimpleLeft", "mouthDimpleRight", "mouthStretchLeft",
    "mouthStretchRight", "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper",
    "mouthPressLeft", "mouthPressRight", "mouthLowerDownLeft", "mouthLowerDownRight", "mouthUpperUpLeft",
    "mouthUpperUpRight", "browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft",
    "browOuterUpRight", "cheekPuff", "cheekSquintLeft", "cheekSquintRight", "noseSneerLeft",
    "noseSneerRight", "tongueOut",
)

# Names whose trailing Left/Right is a direction of motion, not a side of the face.
_DIRECTIONAL = frozenset({"jawLeft", "jawRight", "mouthLeft", "mouthRight"})

_SUFFIX = re.compile(r"^(?P<base>.+?)[_.\-]?(?P<side>L|R|l|r|Left|Right|left|right)$")


def canonical(name: str) -> str:
    """Canonical key of a channel name.

    ``EyeBlinkLeft``, ``eyeBlink_L``, ``eyeBlinkLeft`` and ``eyeBlink_l`` all
    give ``eyeBlinkLeft``; ``JawOpen`` gives ``jawOpen``; ``browInnerUp_L``
    gives ``browInnerUpLeft`` (a side of the unsided ``browInnerUp``).
    """
    name = name.strip()
    if not name:
        return name
    camel = name[0].lower() + name[1:]
    if camel in _DIRECTIONAL:
        return camel
    match = _SUFFIX.match(camel)
    if match is None:
        return camel
    base, side = match.group("base"), match.group("side")
    # A bare trailing lowercase l/r without separator is part of a word
    # ("mouthPucker" ends in r): only accept single letters after a separator.
    sep = camel[len(base):len(camel) - len(side)]
    if len(side) == 1 and not sep:
        return camel
    side = "Left" if side[0] in "Ll" else "Right"
    return base + side


_ARKIT_INDEX = {name: i for i, name in enumerate(ARKIT_NAMES)}
_WIRE_NAMES: dict[str, int | None] = {}
MAX_CACHED_NAMES = 512  # names seen on the wire (stray keys too), so the cache is bounded


def arkit_index(name: str) -> int | None:
    """Index in :data:`ARKIT_NAMES` of a name in any convention (:func:`canonical`), None for others.

    For decoders that meet the same few names in every datagram: cached, the cache bounded (cleared
    when full).
    """
    try:
        return _WIRE_NAMES[name]
    except KeyError:
        pass
    index = _ARKIT_INDEX.get(canonical(name))
    if len(_WIRE_NAMES) >= MAX_CACHED_NAMES:
        _WIRE_NAMES.clear()
    _WIRE_NAMES[name] = index
    return index


def pascal(name: str) -> str:
    """PascalCase spelling of the canonical key (VMC perfect sync, Live Link Face)."""
    key = canonical(name)
    return key[:1].upper() + key[1:]


def split_side(key: str) -> tuple[str, str | None]:
    """(base, side) of a canonical key; side is "Left", "Right" or None."""
    if key in _DIRECTIONAL:
        return key, None
    for side in ("Left", "Right"):
        if key.endswith(side) and len(key) > len(side):
            return key[: -len(side)], side
    return key, None


# The part of the face a channel moves, by the prefix of its canonical key, in the two groupings the
# project uses. They differ on purpose, on cheeks, lips and tongue:
# - filter region (the live One-Euro filters, runtime.live.config): the mouth is everything that moves as fast
#   as speech, so cheeks, lips and tongue filter with it; anything else is "other".
# - gesture group (Ju & Lee 2008 §4.2, runtime.gestures.tables GROUPS): "lips" are only the mouth and jaw
#   channels, the P(t) that speech drives; cheeks, lips and tongue are stochastic, with everything else "rest".
#   prefix     filter region  gesture group
CHANNEL_REGIONS: tuple[tuple[str, str, str], ...] = (
    ("eye", "eyes", "eyes"),
    ("brow", "brows", "brows"),
    ("mouth", "mouth", "lips"),
    ("jaw", "mouth", "lips"),
    ("lip", "mouth", "rest"),
    ("tongue", "mouth", "rest"),
    ("cheek", "mouth", "rest"),
)
_NO_REGION = ("", "other", "rest")  # a channel no prefix matches (noseSneer, a rig's own shapes)


def _region_row(name: str) -> tuple[str, str, str]:
    key = canonical(name)
    return next((row for row in CHANNEL_REGIONS if key.startswith(row[0])), _NO_REGION)


def filter_region(name: str) -> str:
    """Live filter region of a weight channel (any spelling): ``eyes``, ``brows``, ``mouth`` or ``other``."""
    return _region_row(name)[1]


def gesture_group(name: str) -> str:
    """Gesture feature group of a channel (any spelling, Ju & Lee §4.2): ``brows``, ``eyes``, ``lips`` or ``rest``."""
    return _region_row(name)[2]


@dataclass(frozen=True)
class ChannelMap:
    """Linear map from source channel values to target (rig) channel values.

    ``target = matrix @ source``; unmatched target channels stay 0.

    Attributes
    ----------
    source_names : tuple of n_source str
    target_names : tuple of n_target str
    matrix : ndarray of shape (n_target, n_source), float32
    unmatched_source : tuple of str, source channels the rig has no shape for
    undriven_target : tuple of str, rig shapes no source channel drives
    identity : bool, the matrix is the identity (the source's channels are the rig's, in order: a
        solve or kernel-PLS stage writes them so); :meth:`apply` then copies instead of multiplying
    """

    source_names: tuple[str, ...]
    target_names: tuple[str, ...]
    matrix: np.ndarray
    unmatched_source: tuple[str, ...]
    undriven_target: tuple[str, ...]
    identity: bool = False

    @classmethod
    def build(cls, source_names: Iterable[str], target_names: Iterable[str]) -> ChannelMap:
        source_names = tuple(source_names)
        target_names = tuple(target_names)
        src_index: dict[str, int] = {}
        for i, n in enumerate(source_names):
            src_index.setdefault(canonical(n), i)
        tgt_keys = [canonical(n) for n in target_names]
        tgt_set = set(tgt_keys)
        m = np.zeros((len(target_names), len(source_names)), dtype=np.float32)
        used = set()
        for t, key in enumerate(tgt_keys):
            if key in src_index:  # same channel, any spelling
                m[t, src_index[key]] = 1.0
                used.add(src_index[key])
                continue
            base, side = split_side(key)
            if side is not None and base in src_index and key not in src_index:
                # the rig splits an unsided source shape: drive both sides with it
                m[t, src_index[base]] = 1.0
                used.add(src_index[base])
                continue
            sides = [src_index.get(key + s) for s in ("Left", "Right")]
            if side is None and all(i is not None for i in sides) and not (
                {key + "Left", key + "Right"} & tgt_set
            ):
                # sided source onto an unsided rig shape: the mean of both sides
                for i in sides:
                    m[t, i] = 0.5
                    used.add(i)
        unmatched = tuple(n for i, n in enumerate(source_names) if i not in used)
        undriven = tuple(n for t, n in enumerate(target_names) if not m[t].any())
        m.setflags(write=False)
        identity = m.shape[0] == m.shape[1] and bool(np.array_equal(m, np.eye(len(m), dtype=np.float32)))
        return cls(source_names, target_names, m, unmatched, undriven, identity)

    def apply(self, source_values: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Target values (n_target,) float32 from source values (n_source,).

        NaN in a source channel (missing data) counts as 0 for the target.
        """
        values = np.nan_to_num(np.asarray(source_values, dtype=np.float32), nan=0.0)
        if self.identity:
            if out is None:
                return values
            np.copyto(out, values)
            return out
        return np.matmul(self.matrix, values, out=out)

    def first_targets(self) -> np.ndarray:
        """Per source channel the first rig shape it drives, (n_source,) int64, -1 for none: the shape of the
        same name where there is one (an unsided browInnerUp that also drives browInnerUp_L/R meters as
        browInnerUp), else the first the matrix sends it to. What an operator's meter reads."""
        where = {canonical(n): i for i, n in enumerate(self.target_names)}
        first = np.array([where.get(canonical(c), -1) for c in self.source_names], dtype=np.int64)
        for i in np.flatnonzero(first < 0):
            targets = np.flatnonzero(self.matrix[:, i])
            first[i] = targets[0] if targets.size else -1
        return first

    def report(self) -> str:
        """One human-readable paragraph on what does not match (empty when all do)."""
        lines = []
        if self.unmatched_source:
            lines.append(
                f"{len(self.unmatched_source)} source channel(s) have no shape on this rig and are ignored: "
                + ", ".join(self.unmatched_source)
            )
        if self.undriven_target:
            lines.append(
                f"{len(self.undriven_target)} rig shape(s) are driven by no source channel: "
                + ", ".join(self.undriven_target)
            )
        return "\n".join(lines)
