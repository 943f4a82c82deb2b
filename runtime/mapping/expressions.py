"""What drives a character with VRM expressions: a frame's channels onto its shapes, directly and through expressions.

A character's drivable channels are its shapes (morph targets) and, when it
came from a VRM avatar, its expressions
(:class:`~facepuppet.runtime.model.character_parts.Expressions`: each binds several
shapes at bind weights 0..1). A character without expressions, and without a
``[mapping]`` in ``--config``, is driven as before by a plain
:class:`~facepuppet.runtime.mapping.channels.ChannelMap`. Otherwise
:class:`ExpressionDrive` builds, once per channel layout, an
:class:`ExpressionMap` that routes each input channel by the first rule that
applies:

1. **config**: a channel named in ``[mapping.channels]`` of ``--config``
   drives exactly the targets listed there (expressions or shapes, each at its
   weight) and nothing else; ``false`` makes it drive nothing. A target name is
   looked up among the expressions first (any VRM spelling), then the shapes
   (Godette has a morph ``oh`` and a preset ``O``: ``oh`` is the preset).
2. **expression**: a channel naming one of the avatar's expressions drives
   that expression. A preset is named in any VRM spelling, any case: VRM 0.x
   (``A``, ``a``, ``Blink_L``, ``blink_l``, ``Joy``) or VRM 1.0 (``aa``,
   ``blinkLeft``, ``happy``; :data:`~facepuppet.runtime.mapping.vrm_names.VRM1_FROM_VRM0`);
   a custom expression by its own name, any case. This comes before the
   morphs on purpose: a VRM preset name means the expression (VSeeFace applies
   the clip), and :func:`~facepuppet.runtime.mapping.channels.canonical` would
   otherwise fold ``Blink_L`` and ``blinkLeft`` onto a morph named
   ``blink_left``, skipping the expression's other binds. Several channels
   naming one expression (``Joy`` and ``happy`` from a VRM 1.0 sender) combine
   by their maximum.
3. **morph**: a channel matched onto shapes by the existing explicit mapping
   (:class:`~facepuppet.runtime.mapping.channels.ChannelMap`: ARKit names straight onto
   ARKit-named morphs in any case and ``Left``/``_L`` style — perfect sync —
   splitting and averaging sides as there).
4. **default preset mapping**: an ARKit channel left over (the avatar has no
   ARKit-named morph for it) feeds the VRM 0.x presets the avatar has by the
   documented default of :mod:`facepuppet.runtime.mapping.vrm_names`
   (:data:`~facepuppet.runtime.mapping.vrm_names.VRM0_FROM_ARKIT`: blinks from
   eyeBlink*, A/I/U/E/O from the jaw and mouth shapes, Look* from eyeLook*),
   each preset's sum clipped to [0, 1]. The emotion presets (Joy, Angry,
   Sorrow, Fun) are left out unless ``[mapping] emotions = true``. The blinks:
   an avatar with ``Blink`` and ``Blink_L``/``Blink_R`` gets the split of
   :func:`~facepuppet.runtime.mapping.vrm_names.vrm0_from_arkit` (``Blink = min(L, R)``,
   ``Blink_L = L - Blink``, ``Blink_R = R - Blink``, so each eye closes as
   much as ARKit says); one with only ``Blink`` gets the mean of both eyes; one
   with only the sides gets each eye on its side. When an expression is both
   named by the input and fed by the default mapping (the VMC input carries
   both ``Blink`` and ``EyeBlinkLeft``), the named value wins in every frame
   that sends it; a frame that leaves it out (NaN: not sent) uses the default.

What is left over is unmatched and reported. A layout that *is* the
character's shapes in order (what a kernel-PLS retarget or a marker solve's
pair table writes) is taken as shape weights: every channel onto its shape.

**Expressions onto shapes** (VRM 1.0 ``expressions.md``, "Expression update
algorithm"; VRM 0.x adds the binds of its blend shape groups the same way),
each frame, in this order:

* expression values are clamped to [0, 1];
* ``isBinary``: a value greater than 0.5 is 1.0, otherwise 0.0 (the
  expression table of the spec; its override note says "greater than or equals
  0.5", the table is the normative line and is what is done here);
* overrides (VRM 1.0 only: VRM 0.x has none, its flags are all "none"): for
  each group — blink (Blink, Blink_L, Blink_R), lookAt (LookUp, LookDown,
  LookLeft, LookRight), mouth (A, I, U, E, O) — an expression that is not in
  the group and has ``override<Group>`` ``block`` sets every preset of the
  group to 0 when its value is > 0; otherwise the ``blend`` ones scale the
  group by ``1 - min(1, sum of their values)``. An overriding ``isBinary``
  expression acts with its binary value; an ``isBinary`` expression of the
  group that is overridden at all (factor < 1) is set to 0. Every factor is
  computed from the values before any override, so the order of groups does
  not matter. Custom expressions are never overridden (the spec leaves it
  open);
* each shape gets the sum over expressions of value × bind weight, clipped to
  [0, 1].

**A shape driven both directly and through an expression**: the direct route
wins. A shape that a channel drives directly (rule 3, or a config target that
is a shape) takes that channel's value and expressions do not add to it; the
expression's other binds still apply. So a perfect-sync avatar whose ``Blink``
expression binds the same morphs as ``eyeBlinkLeft`` never closes an eye twice.
This holds in each frame that sends the direct channel: a frame that leaves it
out (NaN, e.g. a VMC sender of VRM presets only, whose frames carry the 52
ARKit channels unsent) lets the expressions drive the shape.

**Cost.** Everything by name is resolved when a layout is first seen (one
:class:`ExpressionMap` per distinct channel tuple, cached by the frame loop);
a frame is a few small matrix products and index gathers over preallocated
buffers, no dictionaries.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.errors import FacepuppetError
from facepuppet.runtime.mapping.channels import ARKIT_NAMES, ChannelMap, canonical
from facepuppet.runtime.mapping.vrm_names import PRESET_MATRIX, VRM0_PRESETS, VRM1_FROM_VRM0
from facepuppet.runtime.model.character_parts import OVERRIDES, Expressions
from facepuppet.runtime.model.look_at import LOOK_EXPRESSIONS, Gaze, LookAt

if TYPE_CHECKING:
    from facepuppet.runtime.model.character import Character

#: The emotion presets the default mapping leaves out unless ``[mapping] emotions = true``.
EMOTIONS: tuple[str, ...] = ("Joy", "Angry", "Sorrow", "Fun")
#: The preset groups the VRM 1.0 overrides act on: (flag column of ``Expressions.flags``, presets).
OVERRIDE_GROUPS: tuple[tuple[str, int, tuple[str, ...]], ...] = (
    ("blink", 1, ("Blink", "Blink_L", "Blink_R")),
    ("lookAt", 2, ("LookUp", "LookDown", "LookLeft", "LookRight")),
    ("mouth", 3, ("A", "I", "U", "E", "O")),
)
_BLINKS = ("Blink", "Blink_L", "Blink_R")
_PRESET_ROW = {p: i for i, p in enumerate(VRM0_PRESETS)}
#: Every spelling of a preset, lower case -> its VRM 0.x spelling (``blink_l``, ``blinkleft`` -> ``Blink_L``).
PRESET_SPELLINGS: dict[str, str] = {
    **{p.lower(): p for p in VRM0_PRESETS}, **{v.lower(): p for p, v in VRM1_FROM_VRM0.items()}}

ROUTES = ("config", "expression", "morph", "default preset mapping")


class MappingError(FacepuppetError, ValueError):
    """A ``[mapping]`` of ``--config`` that does not fit the character: names the file, the key and the target."""


def preset_of(name: str) -> str | None:
    """The VRM 0.x spelling of a preset named in any VRM spelling and case (``aa`` -> ``A``), else None."""
    return PRESET_SPELLINGS.get(name.strip().lower())


@dataclass(frozen=True)
class MappingTarget:
    """One target of a ``[mapping.channels]`` entry: an expression or shape name, and the weight."""

    to: str
    weight: float = 1.0


@dataclass(frozen=True)
class MappingSettings:
    """The ``[mapping]`` of ``--config`` (see :mod:`facepuppet.runtime.live.config`).

    Attributes
    ----------
    emotions : bool, the default mapping also drives Joy, Angry, Sorrow and Fun
    channels : dict of canonical channel key -> tuple of MappingTarget (empty: the channel drives nothing)
    written : dict of canonical channel key -> the channel name as written in the file (for messages)
    path : str, the file (for messages)
    """

    emotions: bool = False
    channels: dict = field(default_factory=dict)
    written: dict = field(default_factory=dict)
    path: str = ""

    @property
    def empty(self) -> bool:
        return not self.emotions and not self.channels


class ExpressionDrive:
    """The character's channels (shapes and expressions) and the maps onto them, one per channel layout.

    Parameters
    ----------
    shape_names : sequence of n_shapes str, the character's shapes, in the renderer's order
    expressions : Expressions or None
    mapping : MappingSettings (``--config``'s ``[mapping]``; default: none)
    look_at : LookAt or None, the avatar's look-at; an expression-type one sets LookLeft/Right/Up/Down from
        the eye-look channels through its range maps (instead of the default preset mapping's sums)

    Raises
    ------
    MappingError
        when a config target names neither an expression nor a shape of the character.
    """

    def __init__(self, shape_names: Sequence[str], expressions: Expressions | None,
                 mapping: MappingSettings | None = None, look_at: LookAt | None = None) -> None:
        self.shape_names = tuple(shape_names)
        self.look_at = look_at if look_at is not None and look_at.kind == "expression" else None
        self.expressions = expressions
        self.mapping = mapping or MappingSettings()
        n_s = len(self.shape_names)
        if expressions is None:
            self.expression_names: tuple[str, ...] = ()
            self.presets: tuple[str, ...] = ()
            self.binds = np.zeros((0, n_s), np.float32)
            flags = np.zeros((0, 4), np.int32)
        else:
            self.expression_names = tuple(expressions.names)
            self.presets = tuple(expressions.presets)
            self.binds = expressions.dense(n_s)
            flags = np.asarray(expressions.flags)
        self.binds_t = np.ascontiguousarray(self.binds.T)  # (n_shapes, n_expressions)
        n_e = len(self.expression_names)
        # name -> expression, every spelling (preset: its VRM 0.x and 1.0 spellings; custom: its own), lower case
        self._by_name: dict[str, int] = {}
        for e, (name, preset) in enumerate(zip(self.expression_names, self.presets)):
            spellings = [name]
            if preset:
                spellings += [preset, VRM1_FROM_VRM0.get(preset, preset)]
            for s in spellings:
                self._by_name.setdefault(s.strip().lower(), e)
        self.preset_index = {p: e for e, p in enumerate(self.presets) if p}
        self.look_index = tuple(self.preset_index.get(p) for p in LOOK_EXPRESSIONS)
        self.is_binary = flags[:, 0].astype(bool) if n_e else np.zeros(0, bool)
        self.overrides = self._overrides(flags)
        self._targets = self._resolve_mapping()

    # -- what the character offers -------------------------------------------------
    def expression_of(self, name: str) -> int | None:
        """Index of the expression an input channel name names (any VRM spelling / case), else None."""
        return self._by_name.get(name.strip().lower())

    def receive_names(self) -> tuple[str, ...]:
        """The extra channel names an input that names its channels itself (VMC) should carry: the expressions,
        except those named like an ARKit shape (a perfect-sync avatar's ``EyeBlinkLeft`` clip): those arrive in
        the ARKit channel of that name, which reaches the expression by its name (rule 2)."""
        arkit = {n.lower() for n in ARKIT_NAMES}
        return tuple(n for n in self.expression_names if n.strip().lower() not in arkit)

    def _overrides(self, flags: np.ndarray) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], ...]:
        """Per group with any overrider: (target expressions, binary targets mask, blockers, blenders)."""
        out = []
        for _, column, members in OVERRIDE_GROUPS:
            targets = np.array([self.preset_index[p] for p in members if p in self.preset_index], np.intp)
            if not len(targets) or not len(flags):
                continue
            in_group = np.isin(np.arange(len(flags)), targets)  # "settings for the same kind are invalid"
            blockers = np.flatnonzero((flags[:, column] == OVERRIDES["block"]) & ~in_group)
            blenders = np.flatnonzero((flags[:, column] == OVERRIDES["blend"]) & ~in_group)
            if len(blockers) or len(blenders):
                out.append((targets, self.is_binary[targets], blockers, blenders))
        return tuple(out)

    def _resolve_mapping(self) -> dict[str, tuple[tuple[str, int, float], ...]]:
        """Config targets resolved onto the character: key -> (("expression"|"shape", index, weight), ...)."""
        shapes = {}
        for s, name in enumerate(self.shape_names):
            shapes.setdefault(name, s)
            shapes.setdefault(name.lower(), s)
        out = {}
        for key, targets in self.mapping.channels.items():
            resolved = []
            for t in targets:
                e = self.expression_of(t.to)
                s = shapes.get(t.to, shapes.get(t.to.lower()))
                if e is not None:
                    resolved.append(("expression", e, t.weight))
                elif s is not None:
                    resolved.append(("shape", s, t.weight))
                else:
                    where = self.mapping.path or "<config>"
                    ex = ", ".join(self.expression_names) or "none"
                    raise MappingError(
                        f"{where}: key 'mapping.channels.{self.mapping.written.get(key, key)}': target {t.to!r} is "
                        f"neither an expression nor a shape of the character (expressions: {ex}; "
                        f"{len(self.shape_names)} shapes: {', '.join(self.shape_names[:12])}"
                        + (" …" if len(self.shape_names) > 12 else "") + ")")
            out[key] = tuple(resolved)
        return out

    def build(self, channels: Sequence[str]) -> ExpressionMap:
        """The map of one channel layout (see the module doc for the routes)."""
        return ExpressionMap(self, tuple(channels))


class ExpressionMap:
    """Source channel values -> the character's shape weights, through expressions (one channel layout).

    Same use as :class:`~facepuppet.runtime.mapping.channels.ChannelMap`: :meth:`apply`, :meth:`report`,
    ``source_names``, ``target_names``, ``undriven_target``, ``unmatched_source``.

    Attributes
    ----------
    routes : tuple of n_source str, the route each channel took (:data:`ROUTES`, or "" for unmatched)
    expression_values : ndarray of shape (n_expressions,), float32, the expressions' values of the
        last :meth:`apply` (after isBinary and overrides; the map's buffer: copy to keep)
    drives_expressions : bool, some channel of this layout reaches an expression
    """

    def __init__(self, drive: ExpressionDrive, channels: tuple[str, ...]) -> None:
        self.drive = drive
        self.source_names = channels
        self.target_names = drive.shape_names
        n, n_s, n_e = len(channels), len(drive.shape_names), len(drive.expression_names)
        routes = [""] * n
        detail: list[str] = [""] * n
        direct = np.zeros((n_s, n), np.float32)  # shapes driven directly
        linear = np.zeros((n_e, n), np.float32)  # expressions, linear part (config and default mapping)
        named: dict[int, list[int]] = {}  # expression -> the channels naming it
        mapping = drive._targets
        rest = []
        # a stage that writes the character's own shapes, in order (kernel-PLS retarget, the pair table of a
        # marker solve): its values are shape weights, never expressions or ARKit channels
        own_shapes = channels == drive.shape_names
        for i, name in enumerate(channels):
            if own_shapes:
                rest.append(i)
                continue
            key = canonical(name)
            if key in mapping:
                routes[i] = "config"
                parts = []
                for kind, index, weight in mapping[key]:
                    (linear if kind == "expression" else direct)[index, i] += weight
                    label = drive.expression_names[index] if kind == "expression" else drive.shape_names[index]
                    parts.append(f"{label}×{weight:g}")
                detail[i] = "+".join(parts) or "nothing (off)"
                continue
            e = drive.expression_of(name)
            if e is not None:
                routes[i], detail[i] = "expression", drive.expression_names[e]
                named.setdefault(e, []).append(i)
                continue
            rest.append(i)
        # 3. morphs, by the explicit mapping
        morph = ChannelMap.build([channels[i] for i in rest], drive.shape_names)
        used_by_morph = set()
        for j, i in enumerate(rest):
            col = morph.matrix[:, j]
            if col.any():
                direct[:, i] += col
                used_by_morph.add(i)
                routes[i] = "morph"
                detail[i] = "+".join(drive.shape_names[s] for s in np.flatnonzero(col))
        # 4. the default ARKit -> VRM preset mapping, on the ARKit channels left over
        left = [i for i in rest if i not in used_by_morph and not own_shapes]
        arkit = ChannelMap.build([channels[i] for i in left], ARKIT_NAMES).matrix  # (52, n_left)
        a = np.zeros((len(ARKIT_NAMES), n), np.float32)
        a[:, left] = arkit
        rows = self._default_rows(drive)  # (n_e, 52) float32
        linear += rows @ a
        self._blink_split = None
        blink_l, blink_r = (a[ARKIT_NAMES.index(k)] for k in ("eyeBlinkLeft", "eyeBlinkRight"))
        present = [drive.preset_index.get(p) for p in _BLINKS]
        if not (blink_l.any() or blink_r.any()):
            pass  # no eyeBlink channel reaches the default mapping
        elif present[0] is not None and (present[1] is not None or present[2] is not None):
            self._blink_split = (np.stack([blink_l, blink_r]), np.array(present[0], np.intp),
                                 tuple(-1 if p is None else p for p in present[1:]))
        elif present[0] is not None:
            linear[present[0]] += 0.5 * (blink_l + blink_r)
        else:
            for side, p in zip((blink_l, blink_r), present[1:]):
                if p is not None:
                    linear[p] += side
        feeds = (rows != 0).any(axis=0)  # ARKit channels that feed some preset
        if self._blink_split is not None or any(p is not None for p in present):
            feeds[[ARKIT_NAMES.index("eyeBlinkLeft"), ARKIT_NAMES.index("eyeBlinkRight")]] = True
        for i in left:
            k = np.flatnonzero(a[:, i])
            if len(k) and feeds[k].any():
                routes[i] = "default preset mapping"
                targets = sorted({drive.expression_names[e] for e in np.flatnonzero(
                    (rows[:, k] != 0).any(axis=1))} | self._blink_targets(drive, k))
                detail[i] = "+".join(targets)
        self.routes = tuple(routes)
        self._detail = tuple(detail)
        self.unmatched_source = tuple(channels[i] for i in range(n) if not routes[i])

        # the per-frame arrays
        self._direct = direct
        self._direct_mask = direct.any(axis=1)
        self._direct_from = (direct != 0).astype(np.float32)  # (n_shapes, n): which channels drive a shape directly
        self._reached = np.zeros(n_s, bool)  # per frame: a shape whose direct channel was sent
        self._sent = np.zeros(n, np.float32)
        self._nan = np.zeros(n, bool)
        self._linear = linear
        self._named_e = np.array(sorted(named), np.intp)
        width = max((len(v) for v in named.values()), default=0)
        self._named_src = np.full((len(named), width), n, np.intp)  # padded with the NaN slot at index n
        for r, e in enumerate(sorted(named)):
            self._named_src[r, :len(named[e])] = named[e]
        driven_e = linear.any(axis=1)
        driven_e[self._named_e] = True
        if self._blink_split is not None:
            driven_e[self._blink_split[1]] = True
            driven_e[[p for p in self._blink_split[2] if p >= 0]] = True
        # an expression-type look-at: Look* from the eye angles through the avatar's range maps
        self._gaze = None
        if drive.look_at is not None:
            gaze = Gaze(channels)
            pairs = [(k, e) for k, e in enumerate(drive.look_index) if e is not None]
            if gaze.available and pairs:
                self._gaze = (gaze, np.array([k for k, _ in pairs], np.intp),
                              np.array([e for _, e in pairs], np.intp), np.zeros(4))
                driven_e[self._gaze[2]] = True
        self.drives_expressions = bool(driven_e.any())
        self._first_targets = self._first_of(n, n_s)
        reach = (drive.binds[driven_e] != 0).any(axis=0) if n_e else np.zeros(n_s, bool)
        self.undriven_target = tuple(s for k, s in enumerate(drive.shape_names)
                                     if not self._direct_mask[k] and not reach[k])
        self._identity = (not self.drives_expressions and n == n_s
                          and bool(np.array_equal(direct, np.eye(n, dtype=np.float32))))
        self._x = np.zeros(n + 1, np.float32)  # the frame's values, then the NaN slot
        self._x[n] = np.nan
        self._clean = np.zeros(n, np.float32)
        self._unit = np.zeros(n, np.float32)
        self.expression_values = np.zeros(n_e, np.float32)
        self._shapes = np.zeros(n_s, np.float32)

    def _first_of(self, n: int, n_s: int) -> np.ndarray:
        first = np.full(n, -1, np.int64)
        for i in range(n):
            shapes = np.flatnonzero(self._direct[:, i])
            exprs = np.flatnonzero(self._linear[:, i])
            if shapes.size:
                first[i] = shapes[0]
            elif exprs.size:
                first[i] = n_s + exprs[0]
        for r, e in enumerate(self._named_e):
            for i in self._named_src[r]:
                if i < n and first[i] < 0:
                    first[i] = n_s + e
        if self._blink_split is not None:  # an eye's closing is the both-eyes Blink plus its own
            for k, side in enumerate(self._blink_split[0]):
                first[(side != 0) & (first < 0)] = n_s + len(self._linear) + k
        return first

    def first_targets(self) -> np.ndarray:
        """Per source channel the first thing it drives, (n_source,) int64: a shape s, ``n_shapes + e`` for an
        expression e, ``n_shapes + n_expressions + k`` for eye k's blink when the blinks are split into Blink and
        Blink_L/R (:meth:`eye_blinks`), or -1 for nothing: what an operator's meter of "what the character gets"
        reads from the shapes' weights, the expressions' values and the eyes' blinks, in that order."""
        return self._first_targets

    def eye_blinks(self, expression_values: np.ndarray) -> tuple[float, float]:
        """(left, right) closing of the eyes in ``expression_values`` when the blinks are split: Blink plus the
        eye's own Blink_L/R, at most 1 (both 0.0 without a split)."""
        if self._blink_split is None:
            return 0.0, 0.0
        both, own = float(expression_values[self._blink_split[1]]), self._blink_split[2]
        return tuple(min(1.0, both + (float(expression_values[o]) if o >= 0 else 0.0)) for o in own)

    @staticmethod
    def _default_rows(drive: ExpressionDrive) -> np.ndarray:
        """(n_expressions, 52): the linear default presets the avatar has (emotions only when switched on)."""
        rows = np.zeros((len(drive.expression_names), len(ARKIT_NAMES)), np.float32)
        for preset, e in drive.preset_index.items():
            if preset in EMOTIONS and not drive.mapping.emotions:
                continue
            if preset in _PRESET_ROW:
                rows[e] = PRESET_MATRIX[_PRESET_ROW[preset]]
        return rows

    def _blink_targets(self, drive: ExpressionDrive, k: np.ndarray) -> set[str]:
        blinks = {ARKIT_NAMES.index("eyeBlinkLeft"): ("Blink", "Blink_L"),
                  ARKIT_NAMES.index("eyeBlinkRight"): ("Blink", "Blink_R")}
        return {drive.expression_names[drive.preset_index[p]] for j in k for p in blinks.get(int(j), ())
                if p in drive.preset_index}

    def apply(self, source_values: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Shape weights (n_shapes,) float32 from source values (n_source,); NaN is "not sent" (0 for morphs)."""
        n = len(self.source_names)
        x = self._x
        x[:n] = source_values
        clean = self._clean
        np.copyto(clean, x[:n])
        np.nan_to_num(clean, copy=False, nan=0.0)
        if out is None:
            out = np.empty(len(self.target_names), np.float32)
        if self._identity:
            np.copyto(out, clean)
            return out
        np.matmul(self._direct, clean, out=out)
        if not self.drives_expressions:
            return out
        e = self.expression_values
        unit = self._unit
        np.clip(clean, 0.0, 1.0, out=unit)  # the default mapping reads ARKit values in [0, 1] (vrm0_from_arkit)
        np.matmul(self._linear, unit, out=e)
        if self._blink_split is not None:
            rows, both_e, sides = self._blink_split
            lr = np.clip(rows @ unit, 0.0, 1.0)
            both = min(lr[0], lr[1])
            e[both_e] += both
            for side, value in zip(sides, lr):
                if side >= 0:
                    e[side] += value - both
        np.clip(e, 0.0, 1.0, out=e)
        if self._gaze is not None:
            gaze, which, targets, angles = self._gaze
            looks = self.drive.look_at.expression_weights(gaze.angles(x[:n], out=angles))
            e[targets] = np.asarray(looks, np.float32)[which]
        if len(self._named_e):
            sent = np.fmax.reduce(x[self._named_src], axis=1)  # NaN only when no channel sent it
            e[self._named_e] = np.where(np.isnan(sent), e[self._named_e], np.clip(sent, 0.0, 1.0))
        d = self.drive
        if d.is_binary.any():
            e[d.is_binary] = (e[d.is_binary] > 0.5).astype(np.float32)
        if d.overrides:
            factors = []
            for _, _, blockers, blenders in d.overrides:  # every factor from the values before
                if len(blockers) and bool((e[blockers] > 0).any()):
                    factors.append(0.0)
                else:
                    factors.append(1.0 - min(1.0, float(e[blenders].sum())) if len(blenders) else 1.0)
            for (targets, binary, _, _), f in zip(d.overrides, factors):
                if f < 1.0:
                    e[targets] = np.where(binary, 0.0, e[targets] * f)
        shapes = self._shapes
        np.matmul(d.binds_t, e, out=shapes)
        np.clip(shapes, 0.0, 1.0, out=shapes)
        # the direct route wins where its channel was sent this frame; elsewhere the expressions drive the shape
        np.isnan(x[:n], out=self._nan)
        np.subtract(1.0, self._nan, out=self._sent)
        np.greater(self._direct_from @ self._sent, 0.0, out=self._reached)
        np.copyto(out, shapes, where=~self._reached)
        return out

    def report(self) -> str:
        """Which route each channel took (morph / expression / default preset mapping / config), what is left."""
        lines = []
        for route in ROUTES:
            items = [f"{self.source_names[i]}→{self._detail[i]}" for i in range(len(self.source_names))
                     if self.routes[i] == route]
            if items:
                lines.append(f"  {route} ({len(items)}): " + ", ".join(items))
        if self.unmatched_source:
            lines.append(f"{len(self.unmatched_source)} source channel(s) have no shape or expression on this "
                         f"character and are ignored: " + ", ".join(self.unmatched_source))
            off = [p for p in EMOTIONS if p in self.drive.preset_index]
            if off and not self.drive.mapping.emotions:
                lines.append(f"the default preset mapping leaves the emotions off ({', '.join(off)}); "
                             "[mapping] emotions = true in --config switches them on")
        if self.undriven_target:
            lines.append(f"{len(self.undriven_target)} rig shape(s) are driven by no source channel: "
                         + ", ".join(self.undriven_target))
        return "\n".join(lines)


def make_drive(shape_names: Sequence[str], expressions: Expressions | None,
               mapping: MappingSettings | None = None, look_at: LookAt | None = None) -> ExpressionDrive | None:
    """An :class:`ExpressionDrive` when the character has expressions or the config has a ``[mapping]``; else None
    (the frame loop then maps with a plain ChannelMap, as for every OBJ rig)."""
    if (expressions is None or expressions.n_expressions == 0) and (mapping is None or mapping.empty):
        return None
    return ExpressionDrive(shape_names, expressions, mapping, look_at)


def expression_spellings(character: Character) -> tuple[str, ...]:
    """Every name an input channel may use for the character's expressions (``--config`` checks its keys
    against them): each expression's name and, for a preset, its VRM 0.x and 1.0 spellings."""
    e = character.expressions
    if e is None:
        return ()
    out = list(e.names)
    for preset in e.presets:
        if preset:
            out += [preset, VRM1_FROM_VRM0.get(preset, preset)]
    return tuple(dict.fromkeys(out))
