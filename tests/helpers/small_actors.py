"""A tiny synthetic actor (eq 2 tables) shared by the Actor, MarkerSolver and ActorRetarget tests."""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.actuation.actor import Actor

N, K = 12, 4


def make_actor(seed: int = 0) -> Actor:
    """A smooth face-like actor: each actuation moves a neighbourhood of markers, nonlinearly."""
    rng = np.random.default_rng(seed)
    neutral = np.c_[rng.uniform(-5, 5, N), rng.uniform(-7, 7, N), rng.uniform(0, 3, N)]
    cubic = np.zeros((3, K, N, 3))
    for k in range(K):
        fall = np.exp(-np.sum((neutral - neutral[rng.integers(3, N)]) ** 2, axis=1) / 18.0)
        fall[:3] = 0.0                                   # head markers
        direction = rng.normal(size=3)
        field = fall[:, None] * direction / np.linalg.norm(direction)
        cubic[:, k] = np.array([-0.2, 0.4, 1.0])[:, None, None] * field
    return Actor(names=tuple(f"m{i}" for i in range(N)), units="cm", neutral=neutral, cubic=cubic,
                 unmixing=np.eye(K, 2 * K), class_axes=np.tile([0.0, 1.0, 0.0], (2 * K, 1)),
                 class_marker=np.arange(2 * K) % N, head_markers=np.arange(3),
                 s_lower=np.full(K, -0.5), s_upper=np.full(K, 1.5))
