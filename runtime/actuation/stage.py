"""Frame-loop Retarget stage: marker frames -> actuations s -> character weights.

Each accepted frame's markers (capture coordinates, NaN = occluded) are
matched to the actor's markers by name, brought into head coordinates by a
Kabsch fit of the visible head markers to the actor's neutral, solved for s
(:class:`~facepuppet.runtime.actuation.solver.MarkerSolver`, eq 5, warm-started) and
mapped to the character's weights through the pair table (§6.2).
"""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.actuation.pair import ActorPair
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.actuation.solver import MarkerSolver
from facepuppet.runtime.rigid import kabsch


class ActorRetarget:
    """Implements the ``Retarget`` protocol of :mod:`facepuppet.runtime.live.loop`.

    Parameters
    ----------
    actor : Actor
    pair : ActorPair, made for this actor (same markers and K)
    solver : MarkerSolver or None (default settings)

    Attributes
    ----------
    target_names : tuple of n_shapes str
    s : ndarray of shape (K,), float64, the last solved actuations
    counters : dict, ``frames``, ``no_markers``, ``no_head_pose``
    """

    def __init__(self, actor: Actor, pair: ActorPair, solver: MarkerSolver | None = None):
        if tuple(pair.marker_names) != tuple(actor.names) or pair.cubic.shape[1] != actor.n_actuations:
            raise ValueError("ActorRetarget: the pair table was not made for this actor "
                             f"({len(pair.marker_names)} markers / K={pair.cubic.shape[1]} vs "
                             f"{actor.n_markers} / K={actor.n_actuations})")
        self.actor = actor
        self.pair = pair
        self.solver = solver or MarkerSolver(actor)
        self.target_names = tuple(pair.shape_names)
        self.s = np.zeros(actor.n_actuations)
        self.counters = {"frames": 0, "no_markers": 0, "no_head_pose": 0}
        self._names: tuple[str, ...] | None = None
        self._index: np.ndarray | None = None
        self._head = np.asarray(actor.head_markers, dtype=np.int64)
        self._neutral = actor.neutral.astype(np.float64)

    def _order(self, names) -> np.ndarray:
        """Frame marker index of each actor marker (-1 when the frame lacks it), cached per name tuple."""
        if names != self._names:
            lookup = {n: i for i, n in enumerate(names)}
            self._index = np.array([lookup.get(n, -1) for n in self.actor.names])
            self._names = names
        return self._index

    def observed(self, frame: Frame) -> np.ndarray | None:
        """The frame's markers in the actor's order and head coordinates, (n_markers, 3) float64; None if unusable."""
        if frame.markers is None:
            return None
        names = frame.marker_names or tuple(self.actor.names[:len(frame.markers)])
        index = self._order(tuple(names))
        obs = np.full((self.actor.n_markers, 3), np.nan)
        ok = index >= 0
        obs[ok] = frame.markers[index[ok]]
        head_visible = ~np.isnan(obs[self._head]).any(axis=1)
        if head_visible.sum() < 3:
            self.counters["no_head_pose"] += 1
            return None
        h = self._head[head_visible]
        r, t = kabsch(self._neutral[h], obs[h])
        return obs @ r.T + t

    def apply(self, frame: Frame) -> np.ndarray | None:
        """Character weights (n_shapes,) float32 for a marker frame, or None to keep the previous ones."""
        self.counters["frames"] += 1
        obs = self.observed(frame)
        if obs is None or np.isnan(obs).all():
            self.counters["no_markers"] += obs is not None
            return None
        self.s = self.solver.solve(obs)
        return self.pair.weights(self.s)
