"""How well a transferred expression matches the actor, measured in marker space (Shin & Lee §6.2).

For each frame of a take: bring the markers into the actor's head coordinates
(Kabsch on the actor's head markers), solve the actuations s (eq 5, the
runtime :class:`~facepuppet.runtime.actuation.solver.MarkerSolver`), drive the character
through the pair (w = pair.weights(s)) and compare, at each marker's vertex,
the character's displacement B w with the actor's observed displacement
carried into character units and axes (divided by the actor's FAPU, rotated by
the pair's similarity, multiplied by the character's FAPU).

Numbers (character units, RMS of the 3-D distance over markers and frames):

    transfer_rms   the pair's weights                  (what the character shows)
    zero_rms       w = 0, the neutral face             (scale of the motion itself)
    oracle_rms     per-frame bounded least squares     (best these shapes and vertices can do)
    solve_rms      the actor's own model x(s) vs the observed markers, actor units
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import lsq_linear

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.actuation.pair import ActorPair
from facepuppet.runtime.actuation.solver import MarkerSolver
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.model.rigid import kabsch


def head_coordinates(actor: Actor, markers: np.ndarray) -> np.ndarray:
    """Frames of a take in the actor's head coordinates (Kabsch of the head markers onto the neutral's).

    markers : ndarray of shape (n_frames, n_markers, 3), float, actor units, the actor's marker order
    Returns ndarray of shape (n_frames, n_markers, 3), float64.
    """
    m = np.asarray(markers, dtype=np.float64)
    if m.ndim != 3 or m.shape[1:] != (actor.n_markers, 3):
        raise ValueError(f"markers: expected shape (n_frames, {actor.n_markers}, 3), got {m.shape}")
    head = actor.head_markers
    ref = np.broadcast_to(actor.neutral.astype(np.float64)[head], (len(m), len(head), 3))
    r, t = kabsch(ref, m[:, head])
    return m @ np.swapaxes(r, 1, 2) + t[:, None, :]


def transfer_error(actor: Actor, pair: ActorPair, character: Character, markers: np.ndarray,
                   fapu_actor: float, fapu_character: float, iterations: int = 20,
                   oracle_frames: int = 200) -> dict:
    """Marker-space error of the transfer on the frames of a take.

    Parameters
    ----------
    actor, pair, character : the actor, its pair for ``character``
    markers : ndarray of shape (n_frames, n_markers, 3), float, actor units, capture frame, actor's order
    fapu_actor, fapu_character : float, the face units used to carry displacements across (actor units,
        character units); pass the same yardstick when comparing pairs
    iterations : LM budget per frame of the solve (warm-started through the take, as at runtime)
    oracle_frames : frames (evenly spaced) for the per-frame bounded least squares

    Returns {"frames", "transfer_rms", "zero_rms", "oracle_rms", "solve_rms", "relative"} where
    relative = transfer_rms / zero_rms.
    """
    if not (fapu_actor > 0 and fapu_character > 0):
        raise ValueError(f"fapu: expected two positive lengths, got {fapu_actor!r}, {fapu_character!r}")
    head = head_coordinates(actor, markers)
    solver = MarkerSolver(actor)
    s = np.array([solver.solve(frame, iterations=iterations) for frame in head])
    model = np.array([actor.evaluate(x) for x in s])
    disp = head - actor.neutral.astype(np.float64)
    sim = pair.similarity.astype(np.float64)
    rot = sim[:3, :3] / np.cbrt(np.linalg.det(sim[:3, :3]))
    target = (disp / fapu_actor) @ rot.T * fapu_character               # character units and axes
    dense = character.dense_deltas().astype(np.float64)[:, pair.marker_vertices, :]   # (S, n_markers, 3)
    w = np.array([pair.weights(x) for x in s], dtype=np.float64)
    shown = np.einsum("fs,smc->fmc", w, dense)

    def rms(a):
        return float(np.sqrt(np.mean(np.sum(a ** 2, axis=-1))))

    basis = dense.reshape(len(dense), -1).T
    used = np.flatnonzero(np.abs(pair.cubic).reshape(-1, pair.cubic.shape[2]).max(axis=0) > 0)
    pick = np.unique(np.linspace(0, len(s) - 1, min(oracle_frames, len(s))).astype(int))
    oracle = []
    for f in pick:
        sol = lsq_linear(basis[:, used], target[f].ravel(), bounds=(0.0, 1.0), method="bvls")
        oracle.append(basis[:, used] @ sol.x - target[f].ravel())
    out = {"frames": int(len(s)), "transfer_rms": rms(shown - target), "zero_rms": rms(target),
           "oracle_rms": rms(np.array(oracle).reshape(-1, 3)), "solve_rms": rms(model - head),
           "shapes_driven": int(len(used))}
    out["relative"] = out["transfer_rms"] / max(out["zero_rms"], 1e-30)
    return out
