"""Expression transfer through the parameter space (Shin & Lee 2009, §6.2).

Paper symbols -> code names:

    s(t)        actor actuations of training frame t           s            (n_frames, K)
    x_i(t)      actor marker displacements (head coords)       disp         (n_frames, n_markers, 3)
    v_i         character vertex standing for marker i          marker_vertices (n_markers,)
    B           character blendshape deltas at those vertices   basis        (3 n_markers, n_used)
    w(t)        character weights of frame t                    weights      (n_frames, n_shapes)
    a, b, c     cubic functions s -> w (eq 2 on weights)        pair.cubic   (3, K, n_shapes)

Steps:

1. Marker -> mesh: a similarity of the actor's neutral marker cloud onto the
   character, from corresponding landmarks where the marker names allow it
   (:data:`MARKER_LANDMARKS`, AnimFace names -> 0-based Multi-PIE 68 landmarks,
   given as the character's landmark vertices) -- else ICP-like iterations of
   nearest front-facing skin vertex + Umeyama; then each marker's nearest
   front skin vertex (landmark markers take their landmark's vertex); an
   override file wins over both.
2. Shapes: those the markers cannot observe are left out (weight 0): gaze and
   pupil shapes by name (:data:`UNOBSERVABLE`) and shapes whose moving skin
   region (|delta| >= half its largest) has no marker vertex within
   ``radius`` (a fraction of the character's FAPU). ``include`` brings any back
   (:mod:`shape_choice`).
3. Training pairs where the solve lands: the actuations of frames of the
   training take (the actor's ``s_samples``) and the rest pose s = 0, markers
   by eq 2. The take's frames matter because an actor's actuations can be
   nearly collinear (two jaw actuations at cosine 0.96 on the AnimFace jaw
   take) and then cancel each other near rest; weights are >= 0 and cannot
   cancel, so pairs of each actuation alone teach the additive cubic a large
   face for a near-rest frame (the jaw take's first frame: 2.65 cm of mouth
   opening on ICT where the actor's lips moved 0.68 cm, closing). An actor
   table without samples gets synthetic pairs: s drawn from each actuation's
   quantiles over the capture (``metrics["s_quantiles"]``, negative values
   included) -- each actuation alone across its range, sparse mixes, and
   dense mixes.
4. Each pair's displacements carried to the character's size, rotated into
   its axes: multiplied by the face-size ratio, the median of the ratios of
   the distances between landmark markers on both faces (:mod:`face_scale`;
   one pair of markers, the inner eye corners, set it before, and one marker
   off its landmark scaled the whole face); without three landmark markers
   the FAPU ratio (inner-eye-corner distance on each face: markers
   ``Leye_Inside``/``Reye_Inside``, landmarks 39/42; else the marker cloud's
   RMS radius on both); or the ratio the user gives. Then expressed
   in the character's weights by bounded least squares
   (``scipy.optimize.lsq_linear``, 0 <= w <= 1, small ridge); then cubic
   tables s -> w fitted over that range (eqs 2-4).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
from scipy.optimize import lsq_linear
from scipy.spatial import cKDTree

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.actuation.pair import ActorPair
from facepuppet.runtime.errors import InputFileError, UsageError
from facepuppet.runtime.model.character import Character

from facepuppet.offline.actuation.cubic_fit import fit_polynomial
from facepuppet.offline.actuation.face_scale import face_units, landmark_scale
from facepuppet.offline.actuation.shape_choice import (
    NO_SHAPES,
    REGION_RADIUS,
    UNOBSERVABLE,
    every_shape_left_out,
    front_skin,
    observable_shapes,
)

# AnimFace marker -> 0-based Multi-PIE 68 landmark (L/R = the subject's own side; 36-41 is the right eye).
# Only markers that sit on the landmark: AnimFace's ``*eye_Outside`` markers sit on the temples
# (11.8 cm apart on the actor vs 8.9 cm between ICT's outer eye corners) and are left out.
MARKER_LANDMARKS = {
    "Reye_Inside": 39, "Leye_Inside": 42,           # inner eye corners
    "NoseTop": 27, "NoseHead": 30,                  # top of the nose bridge, nose tip
    "Mouth_Rend": 48, "Mouth_Lend": 54,             # mouth corners
    "Mouth_Up": 51, "Mouth_Down": 57,               # upper / lower lip, middle
    "Chin": 8,                                      # chin
}


def umeyama(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Similarity (scale, rotation, translation) taking ``src`` (n, 3) onto ``dst`` (n, 3); (4, 4) float64."""
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - mu_s, dst - mu_d
    u, sig, vt = np.linalg.svd(b.T @ a / len(src))
    d = np.ones(3)
    d[2] = np.sign(np.linalg.det(u @ vt))
    r = u @ np.diag(d) @ vt
    scale = float(np.sum(sig * d) / max(np.mean(np.sum(a * a, axis=1)), 1e-30))
    m = np.eye(4)
    m[:3, :3] = scale * r
    m[:3, 3] = mu_d - scale * r @ mu_s
    return m


def _apply(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ m[:3, :3].T + m[:3, 3]


def read_override(path: str | os.PathLike, marker_names: Sequence[str], n_vertices: int) -> dict[int, int]:
    """``{"marker name": vertex index, ...}`` JSON -> {marker index: vertex index}, checked."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputFileError(f"{path}: not a readable JSON object ({exc})") from None
    if not isinstance(data, dict):
        raise InputFileError(f"{path}: expected a JSON object {{marker name: vertex index}}")
    names = list(marker_names)
    out = {}
    for name, vertex in data.items():
        if name not in names:
            raise InputFileError(f"{path}: field {name!r}: no such actor marker")
        if not isinstance(vertex, int) or not 0 <= vertex < n_vertices:
            raise InputFileError(f"{path}: field {name!r}: expected a vertex index 0..{n_vertices - 1}, got {vertex!r}")
        out[names.index(name)] = vertex
    return out


def read_landmarks(path: str | os.PathLike, n_vertices: int) -> np.ndarray:
    """Landmark vertex indices (68,) int64 from a JSON list or ICT's ``vertex_indices.json``.

    Accepts ``[v0, v1, ...]`` or an object with ``idx_to_landmark_verts`` (0-based Multi-PIE order).
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputFileError(f"{path}: not a readable JSON file ({exc})") from None
    if isinstance(data, dict):
        data = data.get("idx_to_landmark_verts")
    if not (isinstance(data, list) and data and all(isinstance(v, int) and 0 <= v < n_vertices for v in data)):
        raise InputFileError(f"{path}: field idx_to_landmark_verts: expected a list of vertex indices "
                             f"0..{n_vertices - 1}")
    return np.asarray(data, dtype=np.int64)


def character_landmarks(character: Character, path: str | os.PathLike | None = None) -> np.ndarray | None:
    """The character's landmark vertices: from ``path``, else the file named in its import settings, else None."""
    if path is None:
        path = dict(character.metadata.get("settings", {})).get("landmarks")
        if not path or not Path(path).is_file():
            return None
    return read_landmarks(path, character.n_vertices)


class Alignment(NamedTuple):
    """Marker -> mesh mapping: similarity (4, 4) float64, vertices (n_markers,) int64, and its quality.

    rms : RMS distance of the moved markers to their vertices, character units
    landmark_rms : RMS distance of the landmark markers to their landmarks (NaN without landmarks)
    landmarks : {marker index: landmark index} used
    """

    similarity: np.ndarray
    vertices: np.ndarray
    rms: float
    landmark_rms: float
    landmarks: dict


def _icp(src: np.ndarray, verts: np.ndarray, front: np.ndarray, tree, override: dict, iterations: int):
    cloud = verts[front]
    face = cloud[cloud[:, 2] > np.percentile(cloud[:, 2], 40)]
    scale = (np.ptp(face[:, 0]) * 0.75) / max(np.ptp(src[:, 0]), 1e-9)
    m = np.eye(4)
    m[:3, :3] *= scale
    m[:3, 3] = face.mean(axis=0) - scale * src.mean(axis=0)
    m[2, 3] += (face[:, 2].max() - _apply(m, src)[:, 2].max())
    if len(override) >= 3:
        idx = np.array(sorted(override))
        m = umeyama(src[idx], verts[[override[i] for i in idx]])
    for _ in range(iterations):
        _, near = tree.query(_apply(m, src))
        dst = verts[front[near]]
        for i, v in override.items():
            dst[i] = verts[v]
        m_new = umeyama(src, dst)
        if np.allclose(m_new, m, atol=1e-7):
            break
        m = m_new
    return m


def align_markers(actor: Actor, character: Character, override: dict[int, int] | None = None,
                  landmarks: np.ndarray | None = None, iterations: int = 30,
                  snap_landmarks: bool = True) -> Alignment:
    """Similarity alignment of the actor's neutral onto the character; each marker's vertex.

    Parameters
    ----------
    actor, character
    override : {marker index: vertex index}, wins over everything
    landmarks : ndarray of shape (68,), int, the character's Multi-PIE landmark vertices, or None.
        With 3 or more markers named in :data:`MARKER_LANDMARKS` the similarity is the Umeyama fit of
        those markers onto their landmarks; otherwise ICP on the front skin (override vertices held).
    snap_landmarks : landmark markers take their landmark's vertex (else the nearest skin vertex)
    """
    override = override or {}
    verts = character.vertices.astype(np.float64)
    front = front_skin(character)
    tree = cKDTree(verts[front])
    src = actor.neutral.astype(np.float64)
    pairs = {}
    if landmarks is not None:
        pairs = {actor.names.index(name): int(lm) for name, lm in MARKER_LANDMARKS.items()
                 if name in actor.names and lm < len(landmarks)}
    if len(pairs) >= 3:
        idx = np.array(sorted(pairs))
        m = umeyama(src[idx], verts[landmarks[[pairs[i] for i in idx]]])
    else:
        pairs = {}
        m = _icp(src, verts, front, tree, override, iterations)
    moved = _apply(m, src)
    _, near = tree.query(moved)
    vertices = front[near].astype(np.int64)
    if snap_landmarks:
        for i, lm in pairs.items():
            vertices[i] = landmarks[lm]
    for i, v in override.items():
        vertices[i] = v
    rms = float(np.sqrt(np.mean(np.sum((verts[vertices] - moved) ** 2, axis=1))))
    lm_rms = float("nan")
    if pairs:
        idx = np.array(sorted(pairs))
        lm_rms = float(np.sqrt(np.mean(np.sum((verts[landmarks[[pairs[i] for i in idx]]] - moved[idx]) ** 2, 1))))
    return Alignment(m, vertices, rms, lm_rms, pairs)


def s_distribution(actor: Actor) -> tuple[np.ndarray, np.ndarray, str]:
    """Per-actuation quantiles of s over the capture: levels (L,), values (L, K), source.

    From the actor table's ``metrics["s_quantiles"]``; an older table without them gets a uniform
    distribution over its bounds with the training margin taken off (source says which).
    """
    q = dict(actor.metadata.get("metrics", {})).get("s_quantiles")
    k = actor.n_actuations
    if q:
        levels, values = np.asarray(q["levels"], np.float64), np.asarray(q["values"], np.float64)
        if values.shape == (len(levels), k) and levels[0] == 0 and levels[-1] == 1:
            return levels, np.sort(values, axis=0), "capture quantiles"
    lo, hi = actor.s_lower.astype(np.float64), actor.s_upper.astype(np.float64)
    span = (hi - lo) / 1.5                                  # actor_train widens by 0.25 of the span each side
    lo, hi = np.minimum(lo + 0.25 * span, 0.0), np.maximum(hi - 0.25 * span, 0.0)
    return np.array([0.0, 1.0]), np.vstack([lo, hi]), "bounds (table has no s_quantiles)"


def take_pairs(actor: Actor) -> tuple[np.ndarray, np.ndarray] | None:
    """Parameter-shape pairs at the actor's own take: s = 0 and the table's ``s_samples``; None without them.

    Returns s (n, K) float64 and disp (n, n_markers, 3) float64, x(s) - neutral by eq 2.
    """
    if actor.s_samples is None or len(actor.s_samples) == 0:
        return None
    s = np.vstack([np.zeros(actor.n_actuations), actor.s_samples.astype(np.float64)])
    return s, _displacements(actor, s)


def _displacements(actor: Actor, s: np.ndarray) -> np.ndarray:
    k = actor.n_actuations
    coef = actor.cubic.astype(np.float64).reshape(3 * k, -1)
    return (np.concatenate([s ** 3, s ** 2, s], 1) @ coef).reshape(len(s), actor.n_markers, 3)  # eq. 2


def parameter_shape_pairs(actor: Actor, n_sparse: int = 400, n_dense: int = 200, levels: int = 12,
                          seed: int = 0, low: float = 0.01, high: float = 0.99) -> tuple[np.ndarray, np.ndarray]:
    """Synthetic parameter-shape pairs from the actor's own model over the actuations' real range.

    Each actuation alone at ``levels`` values from its ``low`` to its ``high`` quantile (negative
    side included when the capture had one), ``n_sparse`` sparse mixes (each actuation active with
    probability 3/K, drawn from its capture distribution) and ``n_dense`` frames with every
    actuation drawn from its distribution (as in a real frame).

    Returns s (n, K) float64 and disp (n, n_markers, 3) float64, x(s) - neutral by eq 2.
    """
    rng = np.random.default_rng(seed)
    k = actor.n_actuations
    q_levels, q_values, _ = s_distribution(actor)

    def draw(u):                                        # inverse CDF, per actuation
        return np.column_stack([np.interp(u[:, j], q_levels, q_values[:, j]) for j in range(k)])

    ends = draw(np.array([[low] * k, [high] * k]))
    alone = []
    for j in range(k):
        for v in np.linspace(ends[0, j], ends[1, j], levels):
            row = np.zeros(k)
            row[j] = v
            alone.append(row)
    sparse = draw(rng.uniform(size=(n_sparse, k))) * (rng.uniform(size=(n_sparse, k)) < 3.0 / k)
    dense = draw(rng.uniform(size=(n_dense, k)))
    s = np.vstack([np.zeros(k), np.asarray(alone), sparse, dense])
    return s, _displacements(actor, s)


def retarget_actor(actor: Actor, character: Character, s: np.ndarray | None = None, disp: np.ndarray | None = None,
                   override: dict[int, int] | None = None, landmarks: np.ndarray | None = None,
                   exclude: Sequence[str] = UNOBSERVABLE, include: Sequence[str] = (),
                   radius: float = REGION_RADIUS, max_frames: int = 800, ridge: float = 1e-4,
                   snap_landmarks: bool = True, scale: float | None = None) -> ActorPair:
    """Cubic tables s -> character weights from parameter-shape pairs.

    Parameters
    ----------
    actor : Actor
    character : Character
    s : ndarray of shape (n_frames, K), float, training actuations; None: :func:`take_pairs`, else (an actor
        table without ``s_samples``) :func:`parameter_shape_pairs`
    disp : ndarray of shape (n_frames, n_markers, 3), float, actor units, head-coordinate displacements
    override : {marker index: vertex index}
    landmarks : ndarray of shape (68,), int, the character's Multi-PIE landmark vertices, or None
    exclude, include : fnmatch patterns of shape names left out / always kept (:func:`observable_shapes`)
    radius : float, region radius as a fraction of the character's FAPU (:func:`observable_shapes`)
    max_frames : int, training frames used (evenly spaced) for the bounded least squares
    ridge : float, Tikhonov weight on w (relative to the mean squared basis column)
    snap_landmarks : landmark markers take their landmark's vertex
    scale : float, the face-size ratio (character length per actor length) to use; None: measured
        (:func:`landmark_scale`, else the FAPU ratio)

    Left-out shapes keep their name in the pair with all-zero cubic coefficients. The pair's
    s_lower/s_upper are the range of the training s (``ActorPair.weights`` clamps to it).
    """
    if character.n_shapes == 0:
        raise UsageError(f"retarget_actor: {NO_SHAPES.format(name=character.name)}")
    source = "given"
    if s is None or disp is None:
        pairs = take_pairs(actor)
        if pairs is not None:
            (s, disp), source = pairs, "the take's frames"
        else:
            s, disp = parameter_shape_pairs(actor)
            source = s_distribution(actor)[2]
    s, disp = np.asarray(s, np.float64), np.asarray(disp, np.float64)
    align = align_markers(actor, character, override, landmarks, snap_landmarks=snap_landmarks)
    sim, vertices = align.similarity, align.vertices
    rot = sim[:3, :3] / np.cbrt(np.linalg.det(sim[:3, :3]))
    fapu_actor, fapu_char, fapu_kind = face_units(actor, character, vertices, landmarks)
    measured = landmark_scale(actor, character, landmarks, align.landmarks)
    if scale is not None:
        if not (np.isfinite(scale) and scale > 0):
            raise ValueError(f"retarget_actor: scale: expected a positive ratio, got {scale!r}")
        ratio, ratio_source = float(scale), "given"
    elif measured is not None:
        ratio, ratio_source = measured.ratio, f"median of {measured.n} landmark-distance ratios"
    else:
        ratio, ratio_source = fapu_char / fapu_actor, f"FAPU ({fapu_kind})"
    fapu_fapu = fapu_char / fapu_actor
    fapu_actor = fapu_char / ratio          # the actor length that stands for the character's FAPU
    left_out = observable_shapes(character, vertices, radius * fapu_char, exclude, include)
    used = np.array([j for j, n in enumerate(character.shape_names) if n not in left_out], dtype=np.int64)
    if len(used) == 0:
        raise UsageError(every_shape_left_out(character.name, left_out))
    dense = character.dense_deltas().astype(np.float64)           # (S, n_vertices, 3)
    basis = dense[used][:, vertices, :].reshape(len(used), -1).T  # B, (3 n_markers, n_used)
    pick = np.unique(np.linspace(0, len(s) - 1, min(max_frames, len(s))).astype(int))
    target = (disp[pick] / fapu_actor) @ rot.T * fapu_char            # FAPU-normalised, character axes
    col = float(np.mean(np.sum(basis ** 2, axis=0))) or 1.0
    a = np.vstack([basis, np.sqrt(ridge * col) * np.eye(len(used))])
    weights = np.zeros((len(pick), character.n_shapes))
    resid = []
    for row, y in enumerate(target.reshape(len(pick), -1)):
        sol = lsq_linear(a, np.r_[y, np.zeros(len(used))], bounds=(0.0, 1.0), method="bvls")
        weights[row, used] = sol.x
        resid.append(np.sum((basis @ sol.x - y) ** 2))
    cubic = fit_polynomial(s[pick], weights, 3)                       # Shin & Lee eqs 2-4 on weights
    fit = np.clip(np.concatenate([s[pick] ** 3, s[pick] ** 2, s[pick]], 1) @ cubic.reshape(-1, character.n_shapes),
                  0.0, 1.0)
    metrics = {"alignment_rms": align.rms,
               "landmark_rms": None if np.isnan(align.landmark_rms) else align.landmark_rms,
               "landmarks": {actor.names[i]: lm for i, lm in sorted(align.landmarks.items())},
               "scale": float(np.cbrt(np.linalg.det(sim[:3, :3]))),
               "fapu_actor": fapu_actor, "fapu_character": fapu_char, "fapu": fapu_kind,
               "face_scale": {"ratio": ratio, "source": ratio_source, "fapu_ratio": fapu_fapu,
                              "landmarks": None if measured is None else measured.as_dict()},
               "frames": int(len(pick)), "s_source": source,
               "s_range": [s[pick].min(axis=0).round(4).tolist(), s[pick].max(axis=0).round(4).tolist()],
               "marker_fit_rms": float(np.sqrt(np.mean(resid) / len(vertices))),
               "weight_fit_rms": float(np.sqrt(np.mean((fit - weights) ** 2))),
               "overrides": len(override or {}), "shapes_used": int(len(used)), "shapes_left_out": left_out}
    settings = {"max_frames": max_frames, "ridge": ridge, "character": character.name, "exclude": list(exclude),
                "include": list(include), "radius_fapu": radius, "snap_landmarks": snap_landmarks,
                "face_scale": scale}
    return ActorPair(cubic=cubic, shape_names=character.shape_names, marker_names=actor.names,
                     marker_vertices=vertices, similarity=sim, s_lower=np.minimum(s[pick].min(axis=0), 0.0),
                     s_upper=np.maximum(s[pick].max(axis=0), 0.0),
                     metadata={"settings": settings, "metrics": metrics})
