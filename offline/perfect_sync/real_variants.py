"""Heads of ICT's topology with a real face's proportions, whose true expression shapes are known.

Scaling parts of the ICT head changes every distance of a region alike; a
real identity moves the eye sockets, the lid openings, the lip line, the
nose and the jaw each its own way. Here the ICT neutral is warped by a
smooth spatial field W fitted to landmark correspondences between ICT and
another real face (the data kit's MediaPipe canonical face: an average
human face of other proportions), and every expression target is carried by
the same warp: the true shape of the variant is W(v + d) − W(v). W is
continuous, so where ICT's lids meet in eyeBlink, the warped lids meet too.

W is a 3-D thin-plate (biharmonic, φ(r) = r) spline with an affine part,
fitted to the 68 Multi-PIE landmarks of ICT against the same landmarks on
the other face after a similarity alignment (so W changes proportions, not
size or pose). The face contour's outer points (0–3, 13–16: on a 3-D face
they are a silhouette, not a fixed place) are left out; the inner lips take
the mean of their upper and lower partners' motion (a face with its lips
apart would tear ICT's closed lip line open). A region variant moves only
some landmark groups (the others are held where they are), and a blend
moves a fraction of the way.

Every MediaPipe variant leans on one face. A second, independent face is a real actor's: the neutral first
frame of the data kit's AnimFace marker take (:func:`marker_variants`). Its 41 markers are not anatomical
landmarks: 23 of them sit near one (:data:`MULTIPIE_TO_MARKERS`), after a similarity alignment within
0.3–1.7 cm of ICT's, and all on the skin's surface, in front of recessed places such as the eye corners
(1.4 cm in front of ICT's). So only their front-view places (across and up, in ICT's frame after the
alignment) move the landmarks; the depth stays ICT's, and the landmarks without a marker are carried by
the spline. Markers that sit around a feature, outside its ends (the eyes' corners, the nose wings:
:data:`MARKER_PAIRS`), say where the feature is, not how wide: taken as its ends they made eyes 5 cm wide
with their inner corners on a crumpled nose bridge, a head no face has. Each such pair moves its feature's
landmarks (an eye's six) by the motion of the pair's centre.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from facepuppet.runtime.model.character import Character

from facepuppet.offline.elastic.thin_plate import thin_plate
from facepuppet.offline.kpls.targets import warped_rig

#: Multi-PIE landmark i → the MediaPipe face-mesh vertex at the same place (checked on the data kit: after a
#: similarity alignment every inner landmark lies within 0.93 cm of ICT's, the contour within 1.7)
MULTIPIE_TO_MEDIAPIPE = (
    162, 234, 93, 58, 172, 136, 149, 148, 152, 377, 378, 365, 397, 288, 323, 454, 389,  # contour 0-16
    71, 63, 105, 66, 107, 336, 296, 334, 293, 301,  # brows 17-26
    168, 197, 5, 4, 75, 97, 2, 326, 305,  # nose 27-35
    33, 160, 158, 133, 153, 144, 362, 385, 387, 263, 373, 380,  # eyes 36-47
    61, 39, 37, 0, 267, 269, 291, 405, 314, 17, 84, 181,  # outer lips 48-59
    78, 82, 13, 312, 308, 317, 14, 87,  # inner lips 60-67
)
#: landmark groups a region variant moves (Multi-PIE numbering)
REGIONS = {
    "jaw": tuple(range(4, 13)),
    "brows": tuple(range(17, 27)),
    "nose": tuple(range(27, 36)),
    "eyes": tuple(range(36, 48)),
    "lips": tuple(range(48, 68)),
}
USED = tuple(range(4, 68))  # the contour's outer points (0-3, 13-16) are a silhouette on a 3-D face
# inner lips: upper ↔ lower partners (61↔67, 62↔66, 63↔65); the corners 60, 64 are their own
INNER_LIP_PAIRS = ((61, 67), (62, 66), (63, 65))
SMOOTHING = 0.05  # the spline's regularisation (units): it need not pass exactly through every landmark


def similarity(moving: np.ndarray, fixed: np.ndarray) -> np.ndarray:
    """``moving`` (n, 3) after the rotation, uniform scale and translation that best fits it onto ``fixed``."""
    a, b = np.asarray(moving, np.float64), np.asarray(fixed, np.float64)
    ma, mb = a.mean(0), b.mean(0)
    u, s, vt = np.linalg.svd((a - ma).T @ (b - mb))
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    r = u @ d @ vt
    scale = float((s * np.diag(d)).sum() / ((a - ma) ** 2).sum())
    return (a - ma) @ r * scale + mb


def landmark_motion(ict_marks: np.ndarray, other_marks: np.ndarray) -> np.ndarray:
    """(68, 3): how far each ICT landmark moves to sit where the other face (similarity-aligned) has it; the
    inner lips move as the mean of each upper/lower pair."""
    a = np.asarray(ict_marks, np.float64)
    motion = similarity(other_marks, a) - a
    for up, low in INNER_LIP_PAIRS:
        motion[[up, low]] = motion[[up, low]].mean(0)
    return motion


def proportion_warp(ict_marks: np.ndarray, motion: np.ndarray, regions: Sequence[str] | None = None,
                    amount: float = 1.0) -> Callable[[np.ndarray], np.ndarray]:
    """W moving the landmarks of ``regions`` (names of :data:`REGIONS`; None: all) by ``amount`` of ``motion``
    and holding the other used landmarks."""
    moved = set(USED) if regions is None else {i for r in regions for i in REGIONS[r]}
    used = np.asarray(USED)
    step = np.where(np.isin(used, sorted(moved))[:, None], amount * motion[used], 0.0)
    src = np.asarray(ict_marks, np.float64)[used]
    return thin_plate(src, src + step, SMOOTHING)


def fold_fraction(character: Character, warp: Callable[[np.ndarray], np.ndarray], step: float = 0.05) -> float:
    """Fraction of ``character``'s vertices where ``warp``'s Jacobian (central differences) is not positive: a
    warp that turns space inside out somewhere would make a head no face has."""
    v = character.vertices.astype(np.float64)
    cols = [(warp(v + step * e) - warp(v - step * e)) / (2 * step) for e in np.eye(3)]
    det = np.linalg.det(np.stack(cols, axis=2))
    return float((det <= 0).mean())


#: the variants of :func:`real_variants`: (label, regions (None: all), amount)
VARIANTS = (
    ("mediapipe", None, 1.0),
    ("mediapipe_half", None, 0.5),
    ("mediapipe_strong", None, 1.5),
    ("mediapipe_eyes_brows", ("eyes", "brows"), 1.0),
    ("mediapipe_lips", ("lips",), 1.0),
    ("mediapipe_nose_jaw", ("nose", "jaw"), 1.0),
    ("mediapipe_eyes_lips_strong", ("eyes", "lips"), 1.5),
)


#: Multi-PIE landmark → the AnimFace marker near it (the character's right is −x: 36-41, 17-21 and 48 are its right)
MULTIPIE_TO_MARKERS = (
    (36, "Reye_Outside"), (39, "Reye_Inside"), (42, "Leye_Inside"), (45, "Leye_Outside"),
    (17, "Reyebrow_Outside"), (19, "Reyebrow_M"), (21, "Reyebrow_Inside"),
    (22, "Leyebrow_Inside"), (24, "Leyebrow_M"), (26, "Leyebrow_Outside"),
    (27, "NoseTop"), (30, "NoseHead"), (31, "NoseHead_R"), (35, "NoseHead_L"),
    (48, "Mouth_Rend"), (50, "Mouth_UpR1"), (51, "Mouth_Up"), (52, "Mouth_UpL1"), (54, "Mouth_Lend"),
    (56, "Mouth_DownL"), (57, "Mouth_Down"), (58, "Mouth_DownR"), (8, "Chin"),
)
#: landmarks whose markers sit on the skin around a feature, outside its ends (the eye's corners: its markers are
#: 4.5-5.0 cm apart after the alignment, where an eye opening is about 3; the nose wings' on the alae, above and
#: beside the nostrils' bases): each pair moves by the motion of its centre, with the feature's other landmarks
#: (an eye's lids), so the feature moves, not resized or bent: (the pair, the feature's landmarks)
MARKER_PAIRS = (((36, 39), tuple(range(36, 42))), ((42, 45), tuple(range(42, 48))), ((31, 35), (31, 35)))
#: the variants of :func:`marker_variants`: (label, amount)
MARKER_VARIANTS = (("animface", 1.0), ("animface_half", 0.5))


def marker_variants(ict: Character, ict_marks: np.ndarray, markers: dict,
                    labels: Sequence[str] | None = None) -> list[tuple[str, Character, float]]:
    """[(label, variant, fraction of vertices the warp folds)] of :data:`MARKER_VARIANTS` (those in ``labels``;
    None: all): ``ict`` warped towards the face whose marker places (name → (3,), a neutral frame) ``markers``
    gives, by the front-view places of :data:`MULTIPIE_TO_MARKERS` (see the module doc)."""
    a = ict.vertices.astype(np.float64)[np.asarray(ict_marks, np.int64)]
    idx = [i for i, _ in MULTIPIE_TO_MARKERS]
    src = a[idx]
    centred, moving = src.copy(), np.asarray([markers[n] for _, n in MULTIPIE_TO_MARKERS], np.float64)
    for pair, _ in MARKER_PAIRS:  # markers around a feature tell where it is, not how wide: each pair by its centre
        k = [idx.index(i) for i in pair]
        centred[k], moving[k] = centred[k].mean(0), moving[k].mean(0)
    motion = similarity(moving, centred) - centred
    motion[:, 2] = 0.0  # markers sit on the skin in front of recessed landmarks: their depth says nothing
    for pair, whole in MARKER_PAIRS:  # the feature's other landmarks move with it (an eye's lids with its corners)
        extra = [i for i in whole if i not in idx]
        idx += extra
        src = np.vstack([src, a[extra]])
        motion = np.vstack([motion, np.repeat(motion[[idx.index(pair[0])]], len(extra), axis=0)])
    out = []
    for label, amount in MARKER_VARIANTS:
        if labels is not None and label not in labels:
            continue
        w = thin_plate(src, src + amount * motion, SMOOTHING)
        out.append((label, warped_rig(ict, w, f"{ict.name} ({label})"), fold_fraction(ict, w)))
    return out


def real_variants(ict: Character, ict_marks: np.ndarray, other_vertices: np.ndarray,
                  labels: Sequence[str] | None = None) -> list[tuple[str, Character, float]]:
    """[(label, variant, fraction of vertices the warp folds)] of :data:`VARIANTS` (those in ``labels``; None:
    all): ``ict`` (its 68 Multi-PIE landmark vertices ``ict_marks``) warped towards the face whose vertices
    ``other_vertices`` are numbered as MediaPipe's face mesh."""
    a = ict.vertices.astype(np.float64)[np.asarray(ict_marks, np.int64)]
    motion = landmark_motion(a, np.asarray(other_vertices, np.float64)[list(MULTIPIE_TO_MEDIAPIPE)])
    out = []
    for label, regions, amount in VARIANTS:
        if labels is not None and label not in labels:
            continue
        w = proportion_warp(a, motion, regions, amount)
        out.append((label, warped_rig(ict, w, f"{ict.name} ({label})"), fold_fraction(ict, w)))
    return out
