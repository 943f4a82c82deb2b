"""The coarse fit's points between the eyes and the mouth moved as the found features moved.

The coarse fit (:func:`~.proposal.fit_points`) places every point by one scale per axis and a smooth bend;
the eyes' openings and the mouth's slit then put the features' own points where the skin shows them
(:mod:`.eye_openings`, :mod:`.mouth_slit`). On a head whose eye-to-mouth height differs from the source's
(the fit lands the eyes 1 cm high and leaves the mouth where it is), the points between them (cheekbones,
cheeks, nostrils) stay where the fit put them, as far off as the eyes were. Here each such point keeps its
place between the two found features as the source has it: at the fraction ``t`` of the way from the mouth's
line (through its corners) up to the eyes' line (through the corners of the eye on its side; both eyes for a
point on the middle), it moves by ``t`` of the eye corners' move and ``1 - t`` of the mouth corners'.

Points above the eyes or below the mouth (brows, forehead, chin, jaw) keep the fit's place: nothing found
bounds them on the far side, and the brow-to-eye height is its own proportion, not the eye-to-mouth one.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from facepuppet.offline.perfect_sync.face import Face

EYE_CORNERS = ("eye_inner", "eye_outer")
MOUTH_CORNERS = ("mouth_corner_L", "mouth_corner_R")


def between_features(source_positions: np.ndarray, names: Sequence[str], fitted: np.ndarray, found: dict,
                     face: Face, skip: set) -> dict:
    """{name: moved place (3,) world} for the points between the eyes' and the mouth's lines (see the module
    doc); ``fitted`` (n_c, 3) the coarse fit (world), ``found`` {name: place (3,) world} the features' points
    where their openings put them, ``skip`` the names placed otherwise. Empty unless both eyes' corners and both
    mouth corners were found."""
    names = tuple(names)
    idx = {n: i for i, n in enumerate(names)}
    corners = {side: [f"{c}_{side}" for c in EYE_CORNERS] for side in ("L", "R")}
    need = [n for side in corners.values() for n in side] + list(MOUTH_CORNERS)
    if not all(n in found and n in idx for n in need):
        return {}
    src = np.asarray(source_positions, np.float64)
    fit = face.to_frame(np.asarray(fitted, np.float64))
    move = {n: face.to_frame(np.asarray(found[n], np.float64)) - fit[idx[n]] for n in need}
    mouth_y = src[[idx[n] for n in MOUTH_CORNERS], 1].mean()
    mouth_move = np.mean([move[n] for n in MOUTH_CORNERS], axis=0)
    out = {}
    for name in names:
        if name in skip or name in found:
            continue
        sides = [name[-1]] if name.endswith(("_L", "_R")) else ["L", "R"]
        eye = [n for s in sides for n in corners[s]]
        eye_y = src[[idx[n] for n in eye], 1].mean()
        t = (src[idx[name], 1] - mouth_y) / (eye_y - mouth_y) if eye_y != mouth_y else -1.0
        if not 0.0 < t < 1.0:
            continue
        shift = t * np.mean([move[n] for n in eye], axis=0) + (1.0 - t) * mouth_move
        out[name] = (fit[idx[name]] + shift + face.origin) @ face.frame
    return out
