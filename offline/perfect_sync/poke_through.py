"""The skin showing through a drawn piece between its corners: a notch that reads as a hook or a break.

A decal face's pieces (brows, lash lines, lip strips) lie a little in front of a still skin, and the clone
keeps each moved vertex in front of it (:mod:`.skin_clearance`). A triangle of a piece is flat, though, and
the skin under it is not: where a piece slides over a convex crease of the skin (Godette's brows, raised over
the corner of her box head), the crease comes through the middle of a triangle whose three corners are all
in front of it. The viewer sees a notch of skin cut across the brow, its outer end standing apart like a hook,
and a check of the corners alone (or of four points a triangle) says the brow is fine.

This is what no drawn feature does: an artist hides a piece by moving it behind the skin (her own blinks and
her "ee" push whole triangles back, their corners too), never by letting the skin cut through a piece that
stays in front. So the measure counts, per drawn piece, what goes behind the skin or another mesh in its
triangles whose corners all stay in front (:func:`poke_through`), sampled finely over each triangle (a grid
about ``SPACING`` inner-eye distances apart), and reports the worst **cross band** of the piece: the piece is
cut into ``BANDS`` bands along its longest front-view axis at rest, and a band's share is what of the band
(shown at rest) the skin shows through. Measured on Godette's own expressions (her blinks, vowels, looks,
angled brows, Joy/Angry/Sorrow/Fun): 0 on every piece; ICT's true shapes on the pieces lying on its skin
(lashes, films): at most 0.023; her clone with the clearance kept at the triangles' corners only: browOuterUp
0.81 of one band of each brow, nothing else over 0.03.
"""

from __future__ import annotations

import numpy as np

from facepuppet.offline.perfect_sync.face import Face
from facepuppet.offline.perfect_sync.triangles import skin_front_depth

SPACING = 0.1  # inner-eye distances between the samples of a triangle (at most MAX_STEPS a side)
MAX_STEPS = 12
BANDS = 12  # cross bands a piece is cut into along its length for the share
CHUNK = 4096  # samples at a time against the occluders


def grid(steps: int) -> np.ndarray:
    """Barycentric coordinates (k, 3) of a regular grid of ``steps`` steps a side over a triangle, corners and
    edges included."""
    ij = [(i, j) for i in range(steps + 1) for j in range(steps + 1 - i)]
    return np.array([(i / steps, j / steps, 1.0 - (i + j) / steps) for i, j in ij])


class PokeThrough:
    """The measure of the module doc over the drawn ``triangles`` (q, 3) of pieces ``piece`` (q,) labels.

    ``occluders`` (o, 3) are the triangles that can hide them (the skin, the hair), ``hidden`` the depth (in
    face-frame units) by which a point must lie behind the frontmost of them to count as hidden."""

    def __init__(self, face: Face, vertices: np.ndarray, triangles: np.ndarray, piece: np.ndarray,
                 occluders: np.ndarray, es: float, hidden: float) -> None:
        self.face, self.occluders, self.hidden = face, np.asarray(occluders, np.int64), float(hidden)
        self.v = np.asarray(vertices, np.float64)
        self.triangles = np.asarray(triangles, np.int64)
        self.piece = np.asarray(piece)
        rest = face.to_frame(self.v)
        self.parts: dict[int, tuple] = {}  # label -> (its triangles, barycentrics, band of each sample, weights)
        for p in np.unique(self.piece):
            mine = np.flatnonzero(self.piece == p)
            t = self.triangles[mine]
            edge = float(np.linalg.norm(self.v[t] - self.v[np.roll(t, 1, axis=1)], axis=2).max(initial=0.0))
            bary = grid(int(min(MAX_STEPS, max(2, np.ceil(edge / max(SPACING * es, 1e-12))))))
            at = np.einsum("sk,tkc->tsc", bary, rest[t])[:, :, :2].reshape(-1, 2)
            q = at - at.mean(0)
            axis = np.linalg.eigh(q.T @ q)[1][:, -1]  # its longest front-view direction
            u = q @ axis
            band = np.minimum(((u - u.min()) / max(float(np.ptp(u)), 1e-12) * BANDS).astype(np.int64), BANDS - 1)
            e1, e2 = rest[t[:, 1], :2] - rest[t[:, 0], :2], rest[t[:, 2], :2] - rest[t[:, 0], :2]
            area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
            weight = np.repeat(area / len(bary), len(bary))
            self.parts[int(p)] = (t, bary, band, weight)
        self.at_rest = {p: self._shown(np.zeros_like(self.v), p) for p in self.parts}

    def _shown(self, d: np.ndarray, p: int) -> tuple[np.ndarray, np.ndarray]:
        """(each sample in front of every occluder, each sample's triangle has all its corners in front)."""
        t, bary, _, _ = self.parts[p]
        local = self.face.to_frame(self.v + d)
        corners = local[t].reshape(-1, 3)
        points = np.concatenate([corners, np.einsum("sk,tkc->tsc", bary, local[t]).reshape(-1, 3)])
        front = np.concatenate([skin_front_depth(points[i:i + CHUNK, :2], local, self.occluders)
                                for i in range(0, len(points), CHUNK)])
        shown = ~(front > points[:, 2] + self.hidden)
        corner_ok = np.repeat(shown[:len(corners)].reshape(len(t), 3).all(axis=1), len(bary))
        return shown[len(corners):], corner_ok

    def __call__(self, d: np.ndarray) -> dict[int, float]:
        """{piece label: the largest share of one of its cross bands, shown at rest, that the skin shows through
        between corners in front of it under displacements ``d`` (n_vertices, 3)} (pieces with any)."""
        out = {}
        for p, (t, _, band, weight) in self.parts.items():
            if not np.abs(d[np.unique(t)]).max(initial=0.0) > 0:
                continue
            rest, _ = self.at_rest[p]
            shown, corner_ok = self._shown(d, p)
            lost = rest & ~shown & corner_ok
            if not lost.any():
                continue
            total = np.bincount(band, weights=weight * rest, minlength=BANDS)
            share = np.bincount(band, weights=weight * lost, minlength=BANDS) / np.maximum(total, 1e-300)
            out[p] = float(share[total > 0].max())
        return out
