"""A character without parts as ``face.glsl`` draws it: per-vertex materials and the triangle order.

The OBJ rig's materials are per triangle (a kind, a specular strength, a shininess); ``face.glsl``
reads them per vertex. Triangles are drawn in two runs: the one-sided surfaces (back faces may be
culled) in compact patches, then the thin see-through layers (:mod:`~facepuppet.runtime.render.layers`),
blended in their fixed order. Hidden triangles are not drawn.
"""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.model.character import MATERIAL_KINDS, Character
from facepuppet.runtime.render.layers import LAYER_KINDS
from facepuppet.runtime.render.triangle_order import cache_order

_HIDDEN = MATERIAL_KINDS["hidden"]
# Thin layers drawn two-sided and blended after the surfaces, in this order (each over the ones before).
_TWO_SIDED = LAYER_KINDS


def vertex_materials(character: Character) -> np.ndarray:
    """Per-vertex (kind, specular, shininess) from the first triangle using each vertex.

    Returns
    -------
    ndarray of shape (n_vertices, 3), float32; vertices in no triangle get skin.
    """
    params = character.material_params
    per_tri = np.stack(
        [params[:, 2], params[:, 0], params[:, 1]], axis=1
    )[character.triangle_material]
    out = np.tile(np.array([MATERIAL_KINDS["skin"], 0.1, 16.0], np.float32), (character.n_vertices, 1))
    tris = character.triangles.astype(np.int64)
    # Reverse order so the first triangle that names a vertex is the last write.
    out[tris[::-1].reshape(-1)] = np.repeat(per_tri[::-1], 3, axis=0)
    return out.astype(np.float32)


def visible_triangles(character: Character) -> tuple[np.ndarray, int]:
    """Triangles not of kind ``hidden``, one-sided kinds first (by material, each in compact patches:
    :mod:`~facepuppet.runtime.render.triangle_order`), then the thin layers in ``_TWO_SIDED`` order.

    Returns
    -------
    triangles : ndarray of shape (m, 3), uint32
    n_one_sided : int, the first ``n_one_sided`` rows may be back-face culled;
        the rest (thin cards such as lashes) are seen from both sides.
    """
    kinds = character.material_params[:, 2].round().astype(int)[character.triangle_material]
    keep = (kinds != _HIDDEN) & ~np.isin(kinds, _TWO_SIDED)
    # material by material in file order (the face before what it hides), each in compact patches
    one_sided = np.vstack([np.zeros((0, 3), np.uint32)] + [
        cache_order(character.triangles[keep & (character.triangle_material == m)], character.vertices)
        for m in range(len(character.material_names))])
    two_sided = [character.triangles[kinds == k] for k in _TWO_SIDED]
    tris = np.ascontiguousarray(np.vstack([one_sided, *two_sided]), dtype=np.uint32)
    return tris, len(one_sided)
