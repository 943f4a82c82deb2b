"""Training pairs for retargeting: matching expressions of two characters, on feature points.

What is retargeted, and why this representation
-----------------------------------------------
A source expression is described by the displacements of the source
character's own feature points (k_A selected vertices, so ``3 k_A`` numbers);
the target expression is the target character's blendshape weights. Each
character keeps its own feature points, and the two counts may differ (the
paper uses 45 and 37).

* The input is linear in the source weights: ``x = F_A w_A`` with
  ``F_A`` of shape (3 k_A, n_shapes_A) (:func:`feature_matrix`), so the
  runtime turns tracker weights into the kernel's input with one small
  product, and a marker tracker could feed feature-point displacements
  directly.
* The output is what the renderer consumes (target weights), so no solve is
  needed per frame.
* The paper's method is meaningful here: the kernel regression learns the
  correspondence between the two characters' expression spaces from examples
  only, not from names or geometry at run time.

Pairs (:func:`expression_pairs`) are: the neutral (0 ↔ 0); every matched shape
alone at weights 0.25, 0.5, 0.75 and 1 (its source weights ↔ its target
weights); and random mixes of 2–``max_mix`` matched pairs with many small
weights and a few large ones, the same mix on both sides, so that the learnt
map sees each channel's whole range and the combinations real takes have, and
is not a lookup of single shapes at full weight.

The correspondence these pairs define is linear (y = M w for x = F_A w), so
with feature points that see every shape (:func:`covering_points`) the
cross-validated kernel of ``fit-retarget`` is the linear one and the retarget
reproduces the by-name mapping; a non-linear kernel pays off only for a
non-linear correspondence (:mod:`facepuppet.offline.kpls.targets`).

Shapes are matched by name through :func:`facepuppet.runtime.mapping.channels.canonical`
(:class:`~facepuppet.runtime.mapping.channels.ChannelMap`: ``eyeBlink_L`` ↔
``eyeBlinkLeft``; a sided shape onto an unsided one at half weight per side),
or by a pairing file of ``source,target`` lines.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.errors import InputFileError, UsageError
from facepuppet.runtime.mapping.channels import ChannelMap, canonical
from facepuppet.runtime.model.character import Character, moving_vertices

if TYPE_CHECKING:
    from numpy.typing import ArrayLike


def moving_region(character: Character, fraction: float = 0.05) -> np.ndarray:
    """The region retargeting works in: :func:`~facepuppet.runtime.model.character.moving_vertices`, (k,) int64.

    Raises ValueError for a character whose shapes move nothing: it has no region to choose feature points in.
    """
    region = moving_vertices(character, fraction)
    if not len(region):
        raise InputFileError(f"character {character.name!r}: its shapes move no vertex; nothing to retarget")
    return region


def farthest_points(points: np.ndarray, k: int, seed: int = 0) -> np.ndarray:
    """Indices (k,) int64 into ``points`` (n, 3) chosen by farthest-point sampling."""
    n = len(points)
    if not 1 <= k <= n:
        raise UsageError(f"farthest_points: k must be in 1..{n} (the candidate count), got {k}")
    chosen = [int(np.random.default_rng(seed).integers(n))]
    dist = np.linalg.norm(points - points[chosen[0]], axis=1)
    for _ in range(k - 1):
        nxt = int(np.argmax(dist))
        chosen.append(nxt)
        dist = np.minimum(dist, np.linalg.norm(points - points[nxt], axis=1))
    return np.asarray(chosen, dtype=np.int64)


def shape_peaks(character: Character) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per shape, the vertices it moves and the length of each move: [(indices (m,) int64, lengths (m,))]."""
    out = []
    for s in range(character.n_shapes):
        sl = character.shape_slice(s)
        out.append((character.delta_indices[sl].astype(np.int64),
                    np.linalg.norm(character.delta_positions[sl].astype(np.float64), axis=1)))
    return out


def covering_points(character: Character, share: float = 0.5) -> np.ndarray:
    """Vertices (c,) int64 such that every shape moves one of them by >= ``share`` of its largest move.

    Greedy over the shapes in order: a shape none of the points chosen so far sees well enough adds
    the vertex it moves most. Farthest-point sampling alone can miss a small region (the ICT head's
    left eyelid: 0.025 cm of eyeBlink_L's 1.78 cm seen by 45 farthest points), and a shape the
    feature points do not see cannot be retargeted by any method.
    """
    pos = character.vertices.astype(np.float64)
    eps = 1e-6 * float(np.linalg.norm(pos.max(0) - pos.min(0)))
    chosen: list[int] = []
    for idx, length in shape_peaks(character):
        if not len(length) or length.max() <= 0:
            continue
        seen = length[np.isin(idx, chosen)]
        if len(seen) and seen.max() >= share * length.max():
            continue
        # the most-moved vertex not lying on a chosen one: a seam's duplicate vertex (same place, another
        # index) as a second feature point would make every RBF over the points singular
        for j in np.argsort(-length, kind="stable"):
            if length[j] < share * length.max():
                break
            v = int(idx[j])
            if not chosen or np.linalg.norm(pos[chosen] - pos[v], axis=1).min() > eps:
                chosen.append(v)
                break
    return np.asarray(chosen, dtype=np.int64)


def feature_points(character: Character, k: int = 45, given: ArrayLike | None = None, seed: int = 0,
                   cover: bool = True) -> np.ndarray:
    """Feature-point vertex indices (>= k,) int64: ``given`` as is, else points over the moving region.

    With ``cover``, the :func:`covering_points` (one per shape not yet seen) come first and
    farthest-point sampling over the moving region fills up to ``k``; when the shapes need more
    than ``k`` points to be seen, all of them are kept (the runtime cost does not depend on the
    count: the stage folds the feature matrix into its training inputs).
    """
    if given is not None:
        idx = np.asarray(given, dtype=np.int64).ravel()
        if idx.size == 0 or idx.min() < 0 or idx.max() >= character.n_vertices:
            raise ValueError(f"feature_points: given indices must lie in 0..{character.n_vertices - 1}")
        return idx
    region = moving_region(character)
    pts = character.vertices[region].astype(np.float64)
    if not cover:
        return region[farthest_points(pts, min(k, len(region)), seed)]
    chosen = list(covering_points(character))
    if not chosen:
        chosen = [int(region[np.random.default_rng(seed).integers(len(region))])]
    dist = np.linalg.norm(pts[:, None, :] - character.vertices[chosen].astype(np.float64)[None], axis=2).min(1)
    while len(chosen) < min(k, len(region)):
        nxt = int(np.argmax(dist))
        chosen.append(int(region[nxt]))
        dist = np.minimum(dist, np.linalg.norm(pts - pts[nxt], axis=1))
    return np.asarray(list(dict.fromkeys(chosen)), dtype=np.int64)


def feature_matrix(character: Character, points: np.ndarray) -> np.ndarray:
    """F of shape (3 k, n_shapes), float64, units: feature displacements = F @ weights.

    Row ``3 i + j`` is axis j of feature point i.
    """
    where = {int(v): i for i, v in enumerate(points)}
    F = np.zeros((len(points), 3, character.n_shapes))
    for s in range(character.n_shapes):
        sl = character.shape_slice(s)
        for v, d in zip(character.delta_indices[sl], character.delta_positions[sl]):
            i = where.get(int(v))
            if i is not None:
                F[i, :, s] = d
    return F.reshape(3 * len(points), character.n_shapes)


def read_pairing(path: str | os.PathLike) -> list[tuple[str, str]]:
    """``source,target`` name pairs from a text file (``#`` comments and blank lines skipped)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise InputFileError(f"{path}: not a UTF-8 text file ({exc})") from None
    pairs = []
    for number, line in enumerate(text.splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        parts = [p.strip() for p in line.split(",")]
        if len(parts) != 2 or not all(parts):
            raise InputFileError(f"{path}:{number}: expected 'source_name,target_name', found {line!r}")
        pairs.append((parts[0], parts[1]))
    if not pairs:
        raise InputFileError(f"{path}: no pairs in the pairing file")
    return pairs


def match_matrix(source_names: Sequence[str], target_names: Sequence[str],
                 pairing: Sequence[tuple[str, str]] | None = None) -> np.ndarray:
    """M of shape (n_target, n_source), float64: target weights of each source shape at weight 1.

    By canonical names (:class:`ChannelMap`) or by ``pairing`` (list of
    (source, target) names, matched through :func:`canonical`).
    """
    source_names, target_names = list(source_names), list(target_names)
    if pairing is None:
        return ChannelMap.build(source_names, target_names).matrix.astype(np.float64)
    s_index = {canonical(n): i for i, n in enumerate(source_names)}
    t_index = {canonical(n): i for i, n in enumerate(target_names)}
    M = np.zeros((len(target_names), len(source_names)))
    for s, t in pairing:
        if canonical(s) not in s_index:
            raise InputFileError(f"pairing: source shape {s!r} is not among the source's {len(source_names)} shapes")
        if canonical(t) not in t_index:
            raise InputFileError(f"pairing: target shape {t!r} is not among the target's {len(target_names)} shapes")
        M[t_index[canonical(t)], s_index[canonical(s)]] = 1.0
    return M


@dataclass(frozen=True)
class TrainingPairs:
    """Paired expressions of a source and a target character.

    Attributes
    ----------
    X : ndarray of shape (n_pairs, 3 k_source), float64, source feature displacements, source units
    Y : ndarray of shape (n_pairs, n_target_shapes), float64, target weights
    source_weights : ndarray of shape (n_pairs, n_source_shapes), float64
    source_features : ndarray of shape (3 k_source, n_source_shapes), float64, X = W_A F_Aᵀ
    source_points, target_points : ndarray of int64, feature-point vertex indices
    matched : ndarray of int64, source shapes that have a partner
    """

    X: np.ndarray
    Y: np.ndarray
    source_weights: np.ndarray
    source_features: np.ndarray
    source_points: np.ndarray
    target_points: np.ndarray
    matched: np.ndarray


AMPLITUDES = (0.25, 0.5, 0.75, 1.0)


def pair_weights(n_shapes: int, matched: ArrayLike, n_mixes: int = 300, max_mix: int = 24, seed: int = 0,
                 amplitudes: Sequence[float] = AMPLITUDES) -> np.ndarray:
    """Source weights of the training expressions, (1 + len(amplitudes) len(matched) + n_mixes, n_shapes).

    The neutral; each matched shape alone at every weight of ``amplitudes`` (so each channel's whole
    range [0, 1] is in the pairs, not only its end); and ``n_mixes`` random mixes of
    2..``max_mix`` matched shapes with weights u², u uniform in [0, 1): many small weights and a few
    large ones at once, as in a real take (a Live Link Face frame of speech has 15–30 channels
    above 0.01, most of them small).
    """
    matched = np.asarray(matched, dtype=np.int64)
    if len(matched) < 2:
        raise ValueError(f"pair_weights: needs at least 2 matched shapes, got {len(matched)}")
    rng = np.random.default_rng(seed)
    rows = [np.zeros(n_shapes)]
    for a in amplitudes:
        for s in matched:
            w = np.zeros(n_shapes)
            w[s] = a
            rows.append(w)
    for _ in range(n_mixes):
        w = np.zeros(n_shapes)
        pick = rng.choice(matched, size=int(rng.integers(2, max(2, min(max_mix, len(matched))) + 1)),
                          replace=False)
        w[pick] = rng.uniform(0.0, 1.0, size=len(pick)) ** 2
        rows.append(w)
    return np.stack(rows)


def expression_pairs(source: Character, target: Character, source_points: ArrayLike | None = None,
                     target_points: ArrayLike | None = None, pairing: Sequence[tuple[str, str]] | None = None,
                     n_mixes: int = 300, max_mix: int = 24, seed: int = 0, k_source: int = 45,
                     k_target: int = 37) -> TrainingPairs:
    """Neutral, each matched shape over its range, and random mixes, on each side's own feature points."""
    sp = feature_points(source, k_source, source_points, seed)
    tp = feature_points(target, k_target, target_points, seed)
    M = match_matrix(source.shape_names, target.shape_names, pairing)
    matched = np.flatnonzero(M.any(axis=0))
    if len(matched) < 2:
        raise UsageError(f"expression_pairs: only {len(matched)} shapes of {source.name!r} match a shape of "
                         f"{target.name!r}; give a pairing file")
    W = pair_weights(source.n_shapes, matched, n_mixes, max_mix, seed)
    F = feature_matrix(source, sp)
    return TrainingPairs(X=W @ F.T, Y=W @ M.T, source_weights=W, source_features=F,
                         source_points=sp, target_points=tp, matched=matched)
