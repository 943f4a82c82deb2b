"""The pieces lying on the skin (lashes, tear films, blush decals): carried by the skin under them.

Every vertex of such a piece (each within ``ON_SKIN`` face widths of the
skin, :mod:`.pieces`) takes the barycentric mix of its nearest skin
triangle's cloned displacements, so it stays where it was on the skin.
"""

from __future__ import annotations

import numpy as np

from facepuppet.offline.perfect_sync.triangles import nearest_triangles


def embed(vertices: np.ndarray, pieces: np.ndarray, skin_triangles: np.ndarray,
          dense: np.ndarray) -> np.ndarray:
    """Displacements (n_shapes, p, 3) of the ``pieces`` vertices carried by their nearest skin triangles'
    (barycentric mix of ``dense`` (n_shapes, n_vertices, 3))."""
    v = np.asarray(vertices, np.float64)
    tri, bary, _ = nearest_triangles(v[pieces], v, skin_triangles)
    corners = skin_triangles[tri]  # (p, 3)
    return np.einsum("pk,spkc->spc", bary, dense[:, corners])
