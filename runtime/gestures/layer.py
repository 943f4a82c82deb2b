"""Gesture layer: speech-driven stochastic facial gestures (Ju & Lee 2008) over the tracked face, per frame.

:class:`GestureLayer` is the ``gestures`` stage of the live chain, ``(frame, t) -> frame``: it steps a
:class:`~facepuppet.runtime.gestures.synth.GestureSynth` (the two-level MRF of §5.1,
in :mod:`facepuppet.runtime.gestures.synth`) once per animation frame from the voice level and adds
the synthesised motion to the tracked face, fills what tracking lost, or animates
the face from the voice alone (``facepuppet run --input audio``).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.gestures.speaker_normaliser import SILENCE_Z, SpeakerNormaliser
from facepuppet.runtime.gestures.synth import GestureSynth
from facepuppet.runtime.gestures.tables import GESTURE_DB_SCHEMA, GROUPS, HEAD_FEATURES, LEVEL1, load_gesture_db
from facepuppet.runtime.mapping.channels import canonical
from facepuppet.runtime.model.geometry import euler_to_quat, quat_mul

if TYPE_CHECKING:
    import os

logger = logging.getLogger(__name__)

__all__ = ["GESTURE_DB_SCHEMA", "GROUPS", "HEAD_FEATURES", "LEVEL1", "SILENCE_Z", "GestureSynth", "SpeakerNormaliser",
           "load_gesture_db", "GestureLayer", "VoiceOnlySource", "gesture_layer"]


class GestureLayer:
    """Combine synthesised gestures with tracked frames: the ``gestures`` stage, ``(frame, t) -> frame``.

    Modes: ``"add"`` adds the stochastic residuals (brows, eyes, rest) and the
    head motion to the tracked face and fills channels the tracker lost (NaN)
    with the synthesised absolute value; ``"voice"`` animates the face from the
    voice alone (lips from intensity, mood, gestures, head). With no tracked
    frame yet, "add" behaves like "voice".

    Parameters
    ----------
    synth : GestureSynth
    fps : float, animation rate of the database (frames per second)
    mode : "add" or "voice"
    level : callable t -> dBFS or None; default: the frame's ``audio_level``. In the live chain it is the
        tick's level (:class:`~facepuppet.runtime.live.stages.AudioTap`), one value for every animation
        frame stepped that tick, which is the value a recording keeps
    detail : (names, table) or None: §5.2 detail shape weights, table of shape (n_db_frames, len(names)),
        float32, per reference frame of the marker takes (``facepuppet.offline.gestures.detail_transfer.detail_table``);
        the weights of the head group's pick are appended as channels ``names`` (shapes of a character
        made by ``detail_character``)
    """

    name = "gestures"

    def __init__(self, synth: GestureSynth, fps: float, mode: str = "add",
                 level: Callable[[float], float] | None = None,
                 detail: tuple[Sequence[str], np.ndarray] | None = None) -> None:
        if mode not in ("add", "voice"):
            raise ValueError(f"GestureLayer.mode: expected 'add' or 'voice', got {mode!r}")
        if not fps > 0:
            raise ValueError(f"GestureLayer.fps: expected a positive number, got {fps}")
        self.synth, self.fps, self.mode, self.level = synth, float(fps), mode, level
        self._k = 0  # animation frames synthesised
        self._last: Frame | None = None
        self._names = tuple(canonical(n) for n in synth.out_names)
        self._head = [self._names.index(n) if n in self._names else -1 for n in HEAD_FEATURES]
        self._face = np.array([i for i, n in enumerate(self._names) if n not in HEAD_FEATURES], np.int64)
        self._face_names = tuple(self._names[i] for i in self._face)
        stochastic = {synth.names[c] for g in ("brows", "eyes", "rest") if g in synth.groups
                      for c in synth.group_columns(g)}
        self._residual = np.array([canonical(synth.out_names[i]) in {canonical(n) for n in stochastic}
                                   for i in self._face])
        self._maps: dict = {}
        self._detail = None
        if detail is not None:
            names, table = tuple(detail[0]), np.asarray(detail[1], np.float32)
            if "head" not in synth.groups or table.shape != (synth.n_reference_frames, len(names)):
                raise ValueError(f"GestureLayer.detail: expected a head group and a table of shape "
                                 f"({synth.n_reference_frames}, {len(names)}), got {table.shape}")
            self._detail = (names, table)

    def __call__(self, frame: Frame | None, t: float) -> Frame | None:
        if frame is not None:
            self._last = frame
        while self._k <= t * self.fps + 1e-9:  # one synth step per animation frame up to t
            src = self._last
            db = self.level(self._k / self.fps) if self.level is not None else (
                src.audio_level if src is not None else math.nan)
            self.synth.step(db)
            self._k += 1
        return self.compose(self._last if self.mode == "add" else None, t)

    def compose(self, tracked: Frame | None, t: float) -> Frame:
        """The output frame for the current synthesised state over ``tracked`` (None: voice only)."""
        out = self._compose(tracked, t)
        if self._detail is None:
            return out
        names, table = self._detail
        return dataclasses.replace(out, channels=tuple(out.channels) + names,
                                   weights=np.concatenate([out.weights, table[self.synth.pick("head")]]))

    def _compose(self, tracked: Frame | None, t: float) -> Frame:
        add = self.synth.additions
        face = add[self._face]
        rot, trans = self._pose(add)
        if tracked is None or tracked.weights is None:
            return Frame(t, source="gestures", channels=self._face_names, weights=face,
                         head_rotation=rot, head_translation=trans,
                         audio_level=math.nan if tracked is None else tracked.audio_level)
        names, idx_t, idx_s, extra = self._map(tracked.channels)
        residual = face - self.synth.mood_part[self._face]  # the picks' residuals (see GestureSynth.mood_part)
        w = np.array(tracked.weights, np.float32)
        lost = np.isnan(w[idx_t])
        w[idx_t] = np.where(lost, face[idx_s], w[idx_t] + np.where(self._residual[idx_s], residual[idx_s], 0.0))
        weights = np.concatenate([w, face[extra]])
        if tracked.head_rotation is not None and np.isfinite(tracked.head_rotation).all():
            rot = quat_mul(tracked.head_rotation.astype(np.float64), rot)
        if tracked.head_translation is not None and np.isfinite(tracked.head_translation).all():
            trans = tracked.head_translation + trans
        return Frame(t, source=tracked.source, channels=names, weights=weights, head_rotation=rot,
                     head_translation=trans, audio_level=tracked.audio_level, t_sender=tracked.t_sender,
                     number=tracked.number)

    def _pose(self, add: np.ndarray):
        v = [float(add[i]) if i >= 0 else 0.0 for i in self._head]
        return euler_to_quat(v[0], v[1], v[2]), np.array(v[3:], np.float32)

    def _map(self, channels):
        hit = self._maps.get(channels)
        if hit is None:
            keys = [canonical(c) for c in channels]
            idx_t, idx_s = [], []
            for j, n in enumerate(self._face_names):
                if n in keys:
                    idx_t.append(keys.index(n))
                    idx_s.append(j)
            extra = np.array([j for j, n in enumerate(self._face_names) if n not in keys], np.int64)
            names = tuple(channels) + tuple(self._face_names[j] for j in extra)
            hit = self._maps[channels] = (names, np.array(idx_t, np.int64), np.array(idx_s, np.int64), extra)
        return hit


class VoiceOnlySource:
    """A tracker source that never delivers a frame (``--input audio``): the face comes from the voice.

    Has the parts of a live source the run command uses (``start``, ``stop``, ``latest``,
    ``counters``, ``address``, ``duration``).
    """

    address = ("voice", 0)
    frames_taken = 0  # never a frame: a recording's TICK records say so, and replay ticks as the run did
    watched = 0  # no datagrams, so no calibrate messages

    def __init__(self, duration: float | None = None) -> None:
        self.duration = duration
        self.counters: dict = {}

    def start(self) -> None:
        pass

    def stop(self) -> None:
        pass

    def latest(self, t: float) -> tuple[Frame | None, int]:
        return None, 0


def gesture_layer(path: str | os.PathLike, level: Callable[[float], float] | None = None, voice_only: bool = False,
                  seed: int = 0, log: Callable[[str], None] = logger.info, n_neighbours: int = 8,
                  detail: tuple[Sequence[str], np.ndarray] | None = None) -> GestureLayer:
    """A :class:`GestureLayer` from the gesture tables at ``path`` (``--gestures`` of ``run`` and ``replay``).

    n_neighbours : continuity jump candidates per reference frame (fewer: a cheaper step)
    detail : see :class:`GestureLayer`; default: the tables' ``detail_weights`` when they have them
        (written by ``facepuppet transfer-detail --gestures``), named by their ``detail`` channels
    """
    db = load_gesture_db(path)
    synth = GestureSynth(db, seed=seed, n_neighbours=n_neighbours)
    fps = float(db.settings.get("fps", 30.0))
    if detail is None and "detail_weights" in db.arrays:
        detail = (list(db.channels.get("detail", [])), db["detail_weights"])
    log(f"gestures: {path} ({len(db['intensity'])} reference frames at {fps:g} fps, groups "
        f"{', '.join(synth.groups)}), {'voice only' if voice_only else 'added to the tracked face'}"
        + (f", detail shapes {', '.join(detail[0])}" if detail is not None else ""))
    return GestureLayer(synth, fps=fps, mode="voice" if voice_only else "add", level=level, detail=detail)
