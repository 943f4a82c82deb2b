"""A decal eye's looks: only what lies inside it moves (iris, white); the outline, the lashes and the skin stay.

A look is the character's own VRM look expressions' part on that eye where
it has them (:func:`look_expressions`, :func:`look_keys`: Godette's
``look_up`` etc.; these come from her lookAt, not from cloning), otherwise
the inside slides by the source's eye turn on a ball of half the eye's
width, held inside the outline (:func:`decal_look_slide`).
"""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.model.character_parts import Expressions

from facepuppet.offline.perfect_sync.drawn_eyes import eye_inside
from facepuppet.offline.perfect_sync.face import Face
from facepuppet.offline.perfect_sync.pieces import Pieces

#: The VRM 0.x look presets whose shapes give a decal eye's looks where a character has them.
LOOK_PRESETS = ("LookUp", "LookDown", "LookLeft", "LookRight")


def look_expressions(expressions: Expressions | None, delta_offsets: np.ndarray, delta_indices: np.ndarray,
                     delta_positions: np.ndarray, n_vertices: int) -> dict:
    """{preset: dense displacements (n_vertices, 3) float64} of the character's own VRM look expressions
    (``expressions``: its :class:`~facepuppet.runtime.model.character_parts.Expressions`, or None), each its binds'
    weighted sum of the character's sparse shape deltas; an expression that binds no shape is left out."""
    out: dict = {}
    if expressions is None:
        return out
    for e, preset in enumerate(expressions.presets):
        if preset not in LOOK_PRESETS or preset in out:
            continue
        shapes, weights = expressions.binds(e)
        d = np.zeros((n_vertices, 3))
        for s, w in zip(shapes.astype(np.int64), weights):
            sl = slice(int(delta_offsets[s]), int(delta_offsets[s + 1]))
            np.add.at(d, delta_indices[sl].astype(np.int64), float(w) * delta_positions[sl].astype(np.float64))
        if np.abs(d).max(initial=0.0) > 0:
            out[preset] = d
    return out


def look_keys(looks: dict, pieces: Pieces, face: Face, vertices: np.ndarray) -> dict:
    """{(ARKit eye-look key, side): (preset, the ``side`` eye's inside vertices)} for the character's own look
    expressions ``looks`` (:func:`look_expressions`): which ARKit look of which eye each is, told by where it moves
    that eye's iris (the mean motion of :func:`eye_inside` in the face frame), not by its name: a horizontal one
    toward +x (the character's left) is eyeLookOutLeft on the left eye and eyeLookInRight on the right one, an
    upward one eyeLookUp. Of two giving one key, the one moving the iris farther."""
    local = face.to_frame(np.asarray(vertices, np.float64))
    best: dict = {}
    for preset, d in looks.items():
        motion = d @ face.frame.T  # face-frame axes
        for side in pieces.eyes:
            inside = eye_inside(pieces, local, side)
            if not len(inside):
                continue
            mean = motion[inside].mean(0)
            if preset in ("LookUp", "LookDown"):
                amount, key = abs(mean[1]), "eyeLookUp" if mean[1] > 0 else "eyeLookDown"
            else:
                toward_left = mean[0] > 0
                amount = abs(mean[0])
                key = ("eyeLookOut" if toward_left else "eyeLookIn") if side == "L" else (
                    "eyeLookIn" if toward_left else "eyeLookOut")
            if amount <= 1e-9:
                continue
            key += "Left" if side == "L" else "Right"
            if (key, side) not in best or amount > best[(key, side)][0]:
                best[(key, side)] = (amount, preset, inside)
    return {k: (preset, inside) for k, (_, preset, inside) in best.items()}


def decal_look_slide(pieces: Pieces, face: Face, vertices: np.ndarray, side: str, axis: int,
                     slide: float) -> tuple[np.ndarray, np.ndarray]:
    """A drawn eye's look where the character has no look expression: (the ``side`` eye's inside vertices
    (:func:`eye_inside`), their displacement (m, 3) in world axes). They slide together by ``slide`` along the
    face frame's ``axis`` (0 across, + toward the character's left; 1 up), held inside the outline (the eye's other
    pieces): across, the iris stays between the outline's ends; up, its top stays below the outline's top, and
    down it goes no farther than up may (a drawn eye's outline is often its upper lid only). An eye with no outline
    piece slides unheld."""
    local = face.to_frame(np.asarray(vertices, np.float64))
    members, _ = pieces.eyes[side]
    inside = eye_inside(pieces, local, side)
    outline = members[~np.isin(members, inside)]
    if len(outline) and len(inside):
        p, o = local[inside, axis], local[outline, axis]
        if axis == 0:
            room_low, room_high = max(p.min() - o.min(), 0.0), max(o.max() - p.max(), 0.0)
        else:
            room_high = max(o.max() - p.max(), 0.0)
            room_low = room_high
        slide = float(np.clip(slide, -room_low, room_high))
    d = np.zeros((len(inside), 3))
    d[:, axis] = slide
    return inside, d @ face.frame
