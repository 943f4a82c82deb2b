"""``bench perfect-sync``'s figures for the doubt report: does it name the points that are wrong, and only them?

On heads whose right landmark places are known:

* the ICT head with its kit landmarks (the source's own layout): how many
  points are doubted (a false alarm each);
* the same with one point moved out of place (:data:`DISPLACED`: a lid onto
  the brow, a mouth corner a third of the mouth inwards, an eye corner down,
  the nose root up, the lower lip up to the nose, the upper lip up off its outline): whether the moved point is
  named, and how many are;
* the MediaPipe canonical face (its landmark indices have a known meaning,
  :data:`MEDIAPIPE`): the proposal's points further than 0.3 inner-eye
  distances from the vertex of their meaning, and whether each is doubted;
  the local fit of those known places (its largest residual; under
  :data:`~.local_fit.POOR` when the measure raises no false alarm there);
* on any head whose true points are known (``bench perfect-sync``'s real-proportion sets), the proposal's
  points further than :data:`WITHIN` inner-eye distances from the true ones and how many of them the doubt
  report names (its recall), with the true points' own doubts (false alarms) beside it (:func:`named_far`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from facepuppet.offline.elastic.commands import main_front
from facepuppet.offline.elastic.control_points import ControlPoints, ict_control_points
from facepuppet.offline.io.rig_import import import_rig, read_ict_landmarks
from facepuppet.offline.perfect_sync.face import find_face
from facepuppet.offline.perfect_sync.local_fit import residuals
from facepuppet.offline.perfect_sync.pieces import find_pieces
from facepuppet.offline.perfect_sync.proposal import doubts, propose, skin_triangles

#: case -> (point moved, where to as a function of the true places by name and the inner-eye distance)
DISPLACED: dict[str, tuple[str, Callable[[dict, float], np.ndarray]]] = {
    "lid on the brow": ("lid_upper_inner_L", lambda p, es: 0.2 * p["lid_upper_inner_L"] + 0.8 * p["brow_inner_L"]),
    "mouth corner a third inwards": ("mouth_corner_R", lambda p, es: p["mouth_corner_R"]
                                     + (p["mouth_corner_L"] - p["mouth_corner_R"]) / 3),
    "eye corner down": ("eye_outer_R", lambda p, es: p["eye_outer_R"] - np.array([0, 0.4 * es, 0])),
    "nose root up": ("nose_root", lambda p, es: p["nose_root"] + np.array([0, 0.6 * es, 0])),
    "lower lip up to the nose": ("lip_lower", lambda p, es: 0.5 * (p["lip_lower"] + p["nose_base"])),
    "upper lip a third of the eyes' distance up": ("lip_upper", lambda p, es: p["lip_upper"]
                                                    + np.array([0, es / 3, 0])),  # 1.1 cm on ICT: off its outline
}
#: MediaPipe canonical face: vertex indices of documented meaning (the subject's right is R)
MEDIAPIPE = {"eye_outer_R": 33, "eye_inner_R": 133, "eye_inner_L": 362, "eye_outer_L": 263, "mouth_corner_R": 61,
             "mouth_corner_L": 291, "lip_upper_inner": 13, "lip_lower_inner": 14, "lip_upper": 0, "lip_lower": 17,
             "chin": 152, "nose_tip": 1}
FAR = 0.3  # a proposed point this many inner-eye distances from the vertex of its meaning is wrong
WITHIN = 0.15  # a proposed point further than this many inner-eye distances from the true one is out of place
#: (0.15 ES is 0.49 cm on the ICT head)


def moved(points: ControlPoints, vertices: np.ndarray, free: np.ndarray, name: str, to: np.ndarray) -> ControlPoints:
    """``points`` with ``name`` on the vertex of ``free`` (not already a point) nearest ``to``."""
    v = np.asarray(vertices, np.float64)
    free = np.setdiff1d(free, points.vertices)
    out = points.vertices.copy()
    out[points.index(name)] = free[np.argmin(np.linalg.norm(v[free] - to, axis=1))]
    return ControlPoints(points.names, out)


def _named(found: list[dict]) -> set:
    return {n for d in found for n in d["points"]}


def named_far(proposed: ControlPoints, true: ControlPoints, vertices: np.ndarray, found: list[dict],
              false_alarms: list[dict], within: float = WITHIN) -> dict:
    """The doubt report's recall on a head with known points: the ``proposed`` points further than ``within``
    inner-eye distances (of the ``true`` points) from the true ones, those of them the doubts ``found`` name and
    those they miss, the in-place points they name, and the points the true points' own doubts
    (``false_alarms``) name."""
    v = np.asarray(vertices, np.float64)
    es = float(np.linalg.norm(v[true.vertex("eye_inner_L")] - v[true.vertex("eye_inner_R")]))
    far = {n for n in proposed.names if n in true.names
           and np.linalg.norm(v[proposed.vertex(n)] - v[true.vertex(n)]) > within * es}
    named = _named(found)
    return {"within_es": within, "within_units": round(within * es, 3), "n_far": len(far),
            "far_named": sorted(far & named), "far_missed": sorted(far - named),
            "recall": round(len(far & named) / len(far), 3) if far else None,
            "named_in_place": sorted(named - far), "true_points_doubted": sorted(_named(false_alarms))}


def doubt_figures(kit: Path) -> dict:
    """The module doc's figures, from the data kit folder ``kit`` (holding ict-facekit/ and mediapipe/)."""
    folder = kit / "ict-facekit"
    ict = import_rig(folder / "generic_neutral_mesh.obj", folder)
    marks = read_ict_landmarks(folder / "vertex_indices.json", ict.n_vertices)
    truth = ict_control_points(marks, ict.vertices, ict.triangles, main_front(ict))
    face = find_face(ict)
    v = ict.vertices.astype(np.float64)
    layout = v[truth.vertices]
    out: dict = {"ict_true": {"n_doubted": len(_named(doubts(truth, v, face, source_positions=layout)))}}
    places = dict(zip(truth.names, layout))
    es = float(np.linalg.norm(places["eye_inner_L"] - places["eye_inner_R"]))
    cases = {}
    for case, (name, where) in DISPLACED.items():
        wrong = moved(truth, v, face.skin, name, where(places, es))
        named = _named(doubts(wrong, v, face, source_positions=layout))
        cases[case] = {"moved": name, "named": name in named, "n_doubted": len(named)}
    out["ict_displaced"] = cases
    out["ict_displaced_recall"] = float(np.mean([c["named"] for c in cases.values()]))
    mp_path = kit / "mediapipe" / "canonical_face_model.obj"
    if mp_path.exists():
        mp = import_rig(mp_path, None)
        mface = find_face(mp)
        names = truth.names
        points, fitted = propose(layout, names, mp.vertices, mface,
                                 find_pieces(mp.vertices, mface, skin_triangles(mface)))
        mv = mp.vertices.astype(np.float64)
        mes = float(np.linalg.norm(mv[MEDIAPIPE["eye_inner_L"]] - mv[MEDIAPIPE["eye_inner_R"]]))
        named = _named(doubts(points, mv, mface, fitted, source_positions=layout))
        far = {n: round(float(np.linalg.norm(mv[points.vertex(n)] - mv[i])) / mes, 3) for n, i in MEDIAPIPE.items()}
        far = {n: d for n, d in far.items() if d > FAR}
        known = mface.to_frame(mv[points.vertices])
        for n, i in MEDIAPIPE.items():
            known[names.index(n)] = mface.to_frame(mv[i])
        r, _ = residuals(layout[:, :2], known[:, :2])
        out["mediapipe"] = {"far_from_meaning": far, "far_doubted": sorted(n for n in far if n in named),
                            "n_doubted": len(named), "doubted": sorted(named),
                            "largest_residual_of_known_places": round(float(r.max()), 3)}
    return out
