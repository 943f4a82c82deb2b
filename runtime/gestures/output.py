"""What the gesture MRF's picks show: per (group, reference frame), the row it adds to the output channels.

The paper composes the output as c(t)·B of the level-1 mood pick (§4.1,
whole-face blend expressions) plus the residuals D_j of the level-2 picks.
:func:`output_table` precomputes that composition per (group, reference frame)
so that a :class:`~facepuppet.runtime.gestures.synth.GestureSynth` step is one
gather of one row per group and their sum.

The eyes are shown whole (``whole``, default ("eyes",)): the eyes group's
channels are its pick's residual plus that *same* frame's mood c·B, i.e.
the reference frame's own value, and the mood group adds nothing to them.
The paper sums c(t)·B of the level-1 pick with D_j of the level-2 pick;
for a lid that turns a blink into the sum of two reference moments (the
residual of a blink plus the windowed lid level of another frame, which
is the local share of closed-eye frames, not an expression), and the
mismatch pushes the lid through 0.5 where neither moment blinks. Measured
on the real database (8 seeds x 10 min): the eyes' own source frames
blink 19.9/min, the summed output 22.8/min (reference 18.4); about 64
crossings per run had no crossing of the source within 3 frames, at a
mood mismatch of +0.13 on the lid. The mood still reaches the eyes through
the β term (the eyes pick is conditioned on the mood track), as in §5.1.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np


@dataclasses.dataclass(frozen=True)
class GestureOutput:
    """The precomputed output rows of the picks.

    names : tuple of str, the output channels
    table : (G n, len(names)) float32, row ``g n + i``: what group g adds when it shows frame i (mood: c·B)
    mood : (k, used, dst) or None, the mood group's index, its basis columns used and their output channels
    whole_k : (W,) int64, indices of the groups shown whole (empty without mood)
    own_table : (W n, len(names)) float32, row ``w n + i``: whole group w's own frame's c·B on its channels
    """

    names: tuple
    table: np.ndarray
    mood: tuple | None
    whole_k: np.ndarray
    own_table: np.ndarray


def output_table(groups: Sequence[str], cols: Sequence[np.ndarray], feature_names: Sequence[str], feats: np.ndarray,
                 basis: np.ndarray, whole: Sequence[str]) -> GestureOutput:
    """Output channels and the per-(group, frame) rows the picks add.

    Parameters
    ----------
    groups : list of str, the synthesised groups (a subset of GROUPS, in order)
    cols : list of (n_g,) int arrays, each group's feature columns
    feature_names : tuple of str, names of the feature columns
    feats : (n, n_features) float32, reference features per frame
    basis : (n_basis, n_features) float32, whole-face blend expressions B (§4.1)
    whole : tuple of str, groups shown whole (own residual + own frame's c·B)
    """
    names: list[str] = []
    out_group, out_cols = [], []
    for k, g in enumerate(groups):
        if g == "mood":
            continue
        names += [feature_names[c] for c in cols[k]]
        out_group += [k] * len(cols[k])
        out_cols += list(cols[k])
    mood = None
    if "mood" in groups:
        used = np.flatnonzero(np.abs(basis).sum(0) > 0)
        for c in used:
            if feature_names[c] not in names:  # a mood-only channel: no residual feature, gather a zero
                names.append(feature_names[c])
                out_group.append(groups.index("mood"))
                out_cols.append(-1)
        dst = np.array([names.index(feature_names[c]) for c in used], np.int64)
        mood = (groups.index("mood"), used, dst)
        basis_out = np.zeros((len(basis), len(names)), np.float32)
        basis_out[:, dst] = basis[:, used]
    # per (group, frame) the group's contribution to the output, the mood rows holding c·B (§4.1), so that
    # the output is one gather of G rows and their sum
    n, G = len(feats), len(groups)
    table = np.zeros((G, n, len(names)), np.float32)
    for j, (k, c) in enumerate(zip(out_group, out_cols)):
        if c >= 0 and groups[k] != "mood":
            table[k, :, j] = feats[:, c]
    whole_groups = [k for k, g in enumerate(groups) if g in whole]
    whole_k = np.array(whole_groups if mood is not None else [], np.int64)
    own_table = np.zeros((len(whole_k) * n, len(names)), np.float32)
    if mood is not None:
        k = mood[0]
        blend = feats[:, cols[k]] @ basis_out  # §4.1: blend expression c·B, per frame
        for w, kw in enumerate(whole_k):  # a whole group: its own frame's c·B on its channels
            own = np.flatnonzero(np.asarray(out_group) == kw)
            table[kw][:, own] += blend[:, own]
            own_table[w * n:(w + 1) * n, own] = blend[:, own]
            blend[:, own] = 0.0
        table[k] = blend
    return GestureOutput(tuple(names), table.reshape(G * n, len(names)), mood, whole_k, own_table)
