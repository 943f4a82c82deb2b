"""Boosted regression trees of a voice table, evaluated per hop without allocating, or over many rows at once.

Every tree is *complete*: ``depth`` levels of internal nodes in heap order (node ``i`` has children
``2i + 1`` and ``2i + 2``), ``2 ** depth - 1`` of them, then ``2 ** depth`` leaves. A sample goes right
at a node when its feature is greater than the node's threshold; a node that never splits has the
threshold :data:`NEVER` (every finite value goes left) and equal leaves below it. So one evaluation
is ``depth`` gathers over all trees at once, never a walk in Python per node.

Trees are stored output by output: the table's ``n_trees`` trees are ``n_outputs`` runs of
``n_trees / n_outputs``; an output is the sum of its run's leaf values.

Arrays (the voice table's sections, see :mod:`facepuppet.runtime.voice.table`):

feature : ndarray (n_trees, n_internal), int32, in [0, n_features)
threshold : ndarray (n_trees, n_internal), float64, compared with the standardised feature
value : ndarray (n_trees, n_leaves), float32
"""

from __future__ import annotations

import numpy as np

#: The threshold of a node that does not split: no finite feature value is greater.
NEVER = float(np.finfo(np.float64).max)
MAX_DEPTH = 6
MAX_TREES = 8192  # bounds a hostile table's cost per hop


def depth_of(n_internal: int, n_leaves: int) -> int | None:
    """The depth of complete trees with these node counts, or None when they are not such trees."""
    for d in range(1, MAX_DEPTH + 1):
        if n_internal == 2 ** d - 1 and n_leaves == 2 ** d:
            return d
    return None


def predict_rows(Z: np.ndarray, feature: np.ndarray, threshold: np.ndarray, value: np.ndarray,
                 n_outputs: int) -> np.ndarray:
    """Sum of the trees per output for rows Z (k, n_features): shape (k, n_outputs), float64.

    The same comparisons as :class:`TreeEvaluator` (Z is compared as float32 values, as the run-time
    evaluator holds it), so offline and run-time predictions agree exactly.
    """
    Z = np.asarray(Z, np.float32).astype(np.float64)
    n_trees, n_internal = feature.shape
    depth = depth_of(n_internal, value.shape[1])
    rows = np.arange(len(Z))[:, None]
    trees = np.arange(n_trees)[None, :]
    node = np.zeros((len(Z), n_trees), np.intp)
    for _ in range(depth):
        f = feature[trees, node]
        right = Z[rows, f] > threshold[trees, node]
        node = 2 * node + 1 + right
    leaf = value[trees, node - n_internal].astype(np.float64)
    return leaf.reshape(len(Z), n_outputs, n_trees // n_outputs).sum(axis=2)


class TreeEvaluator:
    """``ev(z, out)`` adds each output's tree sum to ``out`` (float32, n_outputs) for z (n_features,); buffers
    made once."""

    def __init__(self, feature: np.ndarray, threshold: np.ndarray, value: np.ndarray, n_outputs: int,
                 n_features: int) -> None:
        n_trees, n_internal = feature.shape
        self.depth = depth_of(n_internal, value.shape[1])
        self._feature = np.ascontiguousarray(feature, np.intp).ravel()
        self._threshold = np.ascontiguousarray(threshold, np.float64).ravel()
        self._value = np.ascontiguousarray(value, np.float32).ravel()
        self._base = np.arange(n_trees, dtype=np.intp) * n_internal  # flat index of each tree's root
        self._leaf_base = np.arange(n_trees, dtype=np.intp) * value.shape[1] - n_internal
        self._node = np.zeros(n_trees, np.intp)
        self._flat = np.zeros(n_trees, np.intp)
        self._f = np.zeros(n_trees, np.intp)
        self._zf = np.zeros(n_trees, np.float64)
        self._t = np.zeros(n_trees, np.float64)
        self._right = np.zeros(n_trees, bool)
        self._step = np.zeros(n_trees, np.intp)  # 1 + right, as an index step (no scalar or cast in the ufuncs)
        self._ones = np.ones(n_trees, np.intp)
        self._leaf = np.zeros(n_trees, np.float32)
        # each output's trees summed as one product (a reduction along an axis would buffer)
        self._owner = np.kron(np.eye(n_outputs, dtype=np.float32), np.ones(n_trees // n_outputs, np.float32))
        self._per_output = np.zeros(n_outputs, np.float32)
        self._z64 = np.zeros(n_features, np.float64)

    def __call__(self, z: np.ndarray, out: np.ndarray) -> None:
        np.copyto(self._z64, z)
        node, flat = self._node, self._flat
        node.fill(0)
        # mode="clip": a gather into ``out`` with bounds checks ("raise") buffers a copy; the indices are in range
        # (the table checks its feature indices, the heap arithmetic stays inside each tree)
        for _ in range(self.depth):
            np.add(self._base, node, out=flat)
            self._feature.take(flat, out=self._f, mode="clip")
            self._z64.take(self._f, out=self._zf, mode="clip")
            self._threshold.take(flat, out=self._t, mode="clip")
            np.greater(self._zf, self._t, out=self._right)
            np.copyto(self._step, self._right)
            np.add(self._step, self._ones, out=self._step)
            np.add(node, node, out=node)
            np.add(node, self._step, out=node)
        np.add(self._leaf_base, node, out=flat)
        self._value.take(flat, out=self._leaf, mode="clip")
        np.dot(self._owner, self._leaf, out=self._per_output)
        np.add(out, self._per_output, out=out)
