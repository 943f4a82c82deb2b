"""Expression transfer through the parameter space (Shin & Lee 2009, §6.2).

Paper symbols -> code names:

    s(t)        actor actuations of training frame t           s            (n_frames, K)
    x_i(t)      actor marker displacements (head coords)       disp         (n_frames, n_markers, 3)
    v_i         character vertex standing for marker i          marker_vertices (n_markers,)
    B           character blendshape deltas at those vertices   basis        (3 n_markers, n_shapes)
    w(t)        character weights of frame t                    weights      (n_frames, n_shapes)
    a, b, c     cubic functions s -> w (eq 2 on weights)        pair.cubic   (3, K, n_shapes)

Steps: a similarity transform of the actor's neutral marker cloud onto the
character's skin (given landmarks / override vertices first, then ICP-like
iterations of nearest front-facing skin vertex + Umeyama); each marker's
nearest vertex (or the override); every training frame's displacements,
FAPU-normalised (divided by the RMS radius of the marker cloud on each face),
expressed in the character's weights by bounded least squares
(``scipy.optimize.lsq_linear``, 0 <= w <= 1, small ridge); then cubic tables
s -> w fitted like the markers (eqs 2-4).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
from scipy.optimize import lsq_linear
from scipy.spatial import cKDTree

from facepuppet.runtime.actor import Actor, ActorPair
from facepuppet.runtime.character import MATERIAL_KINDS, Character
from facepuppet.runtime.geometry import vertex_normals

from .cubic_fit import fit_polynomial


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


def read_override(path: str | os.PathLike, marker_names, n_vertices: int) -> dict[int, int]:
    """``{"marker name": vertex index, ...}`` JSON -> {marker index: vertex index}, checked."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: not a readable JSON object ({exc})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a JSON object {{marker name: vertex index}}")
    names = list(marker_names)
    out = {}
    for name, vertex in data.items():
        if name not in names:
            raise ValueError(f"{path}: field {name!r}: no such actor marker")
        if not isinstance(vertex, int) or not 0 <= vertex < n_vertices:
            raise ValueError(f"{path}: field {name!r}: expected a vertex index 0..{n_vertices - 1}, got {vertex!r}")
        out[names.index(name)] = vertex
    return out


def align_markers(actor: Actor, character: Character, override: dict[int, int] | None = None,
                  iterations: int = 30) -> tuple[np.ndarray, np.ndarray, float]:
    """Similarity alignment of the actor's neutral onto the character's front skin; nearest vertices.

    Returns similarity (4, 4) float64, marker_vertices (n_markers,) int64, RMS distance (character units).
    """
    override = override or {}
    verts = character.vertices.astype(np.float64)
    kinds = character.material_params[:, 2].astype(int)
    skin_tri = kinds[character.triangle_material] == MATERIAL_KINDS["skin"]
    skin = np.unique(character.triangles[skin_tri])
    normals = vertex_normals(character.vertices, character.triangles)
    front = skin[normals[skin, 2] > 0.3] if len(skin) else np.arange(len(verts))
    if len(front) < 3:
        front = np.arange(len(verts))
    tree = cKDTree(verts[front])
    src = actor.neutral.astype(np.float64)
    # start: same axes convention; centre on the front skin, scale by the marker cloud's width
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
        moved = _apply(m, src)
        _, near = tree.query(moved)
        dst = verts[front[near]]
        for i, v in override.items():
            dst[i] = verts[v]
        m_new = umeyama(src, dst)
        if np.allclose(m_new, m, atol=1e-7):
            break
        m = m_new
    moved = _apply(m, src)
    dist, near = tree.query(moved)
    vertices = front[near].astype(np.int64)
    for i, v in override.items():
        vertices[i] = v
    rms = float(np.sqrt(np.mean(np.sum((verts[vertices] - moved) ** 2, axis=1))))
    return m, vertices, rms


def training_pairs(actor: Actor, n_random: int = 400, levels: int = 8, seed: int = 0):
    """Parameter-shape pairs from the actor's own model: each actuation alone, then sparse mixes.

    Returns s (n, K) float64 within the actor's bounds (non-negative part) and
    disp (n, n_markers, 3) float64, x(s) - neutral by eq 2.
    """
    rng = np.random.default_rng(seed)
    k = actor.n_actuations
    hi = np.clip(actor.s_upper.astype(np.float64), 0.0, 1.0)      # s = 1: a strong actuation
    alone = [np.eye(k)[j] * hi[j] * t for j in range(k) for t in np.linspace(0, 1, levels + 1)[1:]]
    mixes = rng.uniform(0, 1, (n_random, k)) * (rng.uniform(size=(n_random, k)) < 3.0 / k) * hi
    s = np.vstack([np.zeros(k), np.asarray(alone), mixes])
    coef = actor.cubic.astype(np.float64).reshape(3 * k, -1)
    disp = (np.concatenate([s ** 3, s ** 2, s], 1) @ coef).reshape(len(s), actor.n_markers, 3)  # eq. 2
    return s, disp


def retarget_actor(actor: Actor, character: Character, s: np.ndarray | None = None, disp: np.ndarray | None = None,
                   override: dict[int, int] | None = None, max_frames: int = 600, ridge: float = 1e-4) -> ActorPair:
    """Cubic tables s -> character weights from the actor's training frames.

    Parameters
    ----------
    actor : Actor
    character : Character
    s : ndarray of shape (n_frames, K), float, training actuations; None: :func:`training_pairs`
    disp : ndarray of shape (n_frames, n_markers, 3), float, actor units, head-coordinate displacements
    override : {marker index: vertex index}
    max_frames : int, training frames used (evenly spaced) for the bounded least squares
    ridge : float, Tikhonov weight on w (relative to the mean squared basis column)
    """
    if s is None or disp is None:
        s, disp = training_pairs(actor)
    sim, vertices, rms = align_markers(actor, character, override)
    rot = sim[:3, :3] / np.cbrt(np.linalg.det(sim[:3, :3]))
    dense = character.dense_deltas().astype(np.float64)           # (S, n_vertices, 3)
    basis = dense[:, vertices, :].reshape(character.n_shapes, -1).T    # B, (3 n_markers, S)
    # FAPU: RMS radius of the marker cloud on each face (actor units / character units)
    src = actor.neutral.astype(np.float64)
    fapu_actor = np.sqrt(np.mean(np.sum((src - src.mean(axis=0)) ** 2, axis=1)))
    mapped = character.vertices[vertices].astype(np.float64)
    fapu_char = np.sqrt(np.mean(np.sum((mapped - mapped.mean(axis=0)) ** 2, axis=1)))
    pick = np.unique(np.linspace(0, len(s) - 1, min(max_frames, len(s))).astype(int))
    target = (disp[pick] / fapu_actor) @ rot.T * fapu_char            # FAPU-normalised, character axes
    col = float(np.mean(np.sum(basis ** 2, axis=0))) or 1.0
    a = np.vstack([basis, np.sqrt(ridge * col) * np.eye(character.n_shapes)])
    weights = np.zeros((len(pick), character.n_shapes))
    resid = []
    for row, y in enumerate(target.reshape(len(pick), -1)):
        sol = lsq_linear(a, np.r_[y, np.zeros(character.n_shapes)], bounds=(0.0, 1.0), method="bvls")
        weights[row] = sol.x
        resid.append(np.sum((basis @ sol.x - y) ** 2))
    cubic = fit_polynomial(s[pick], weights, 3)                       # Shin & Lee eqs 2-4 on weights
    fit = np.concatenate([s[pick] ** 3, s[pick] ** 2, s[pick]], 1) @ cubic.reshape(-1, character.n_shapes)
    metrics = {"alignment_rms": rms, "scale": float(np.cbrt(np.linalg.det(sim[:3, :3]))),
               "fapu_actor": float(fapu_actor), "fapu_character": float(fapu_char),
               "frames": int(len(pick)), "marker_fit_rms": float(np.sqrt(np.mean(resid) / len(vertices))),
               "weight_fit_rms": float(np.sqrt(np.mean((fit - weights) ** 2))),
               "overrides": len(override or {})}
    return ActorPair(cubic=cubic, shape_names=character.shape_names, marker_names=actor.names,
                     marker_vertices=vertices, similarity=sim, s_lower=actor.s_lower, s_upper=actor.s_upper,
                     metadata={"settings": {"max_frames": max_frames, "ridge": ridge, "character": character.name},
                               "metrics": metrics})
