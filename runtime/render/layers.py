"""The thin see-through layers of an OBJ rig (eye occlusion, lacrimal and eye-blend films, lashes) and
their fade: what the renderer draws blended and the glTF exporter writes as COLOR_0 alpha.

No GL here: :func:`vertex_opacity` is geometry (distances to the skin and the eyes), shared by the
OBJ path and the parts path of :mod:`~facepuppet.runtime.render.renderer` and by ``export-character``.
"""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.model.character import MATERIAL_KINDS, Character

#: The layer kinds, in drawing order (each blended over the ones before)
LAYER_KINDS = (MATERIAL_KINDS["occlusion"], MATERIAL_KINDS["film"], MATERIAL_KINDS["lashes"])
#: The layers a frame budget may leave out (the lid shadow and wet films: a few pixels of shading in the eyes);
#: first in LAYER_KINDS, so the rest are one run after them. The lashes draw the eye line and always stay.
SUBTLE_LAYER_KINDS = LAYER_KINDS[:2]
#: Opacity of the thin layers: lashes at the root, the eye occlusion at the lids, films
LASH_ROOT_OPACITY, OCCLUSION_OPACITY, FILM_OPACITY = 0.9, 0.6, 0.22


def has_layers(character: Character) -> bool:
    """True when some material of ``character`` is a thin layer."""
    return bool(np.isin(character.material_params[:, 2].round().astype(int), LAYER_KINDS).any())


def vertex_opacity(character: Character) -> np.ndarray:
    """Per-vertex opacity (n_vertices,) float32: 1 on surfaces; on the thin layers a fade with a distance
    ``d``, ``s = (d - d_min) / (d_90 - d_min)`` clipped to [0, 1] (units cancel):

    * lashes: ``LASH_ROOT_OPACITY (1 - s)^3``, ``d`` to the nearest eye vertex: dense at the lid margin,
      fading to the tips (the cards carry no strand texture here; drawn at one opacity, the lower lash
      card lying on the cheek read as a grey band under every ICT eye);
    * occlusion: ``OCCLUSION_OPACITY (1 - s)^2``, ``d`` to the nearest skin vertex: the soft shadow the
      lids cast on the eye, clear over the iris;
    * film (lacrimal fluid, eye blend): ``FILM_OPACITY``, a faint wet layer with a highlight.
    """
    from scipy.spatial import cKDTree

    c = character
    kinds = c.material_params[:, 2].round().astype(int)
    out = np.ones(c.n_vertices, np.float32)
    tri_kind = kinds[c.triangle_material]
    trees = {}
    for name, near in (("skin", ("skin", "lips")), ("eye", ("eye",))):
        verts = np.unique(c.triangles[np.isin(tri_kind, [MATERIAL_KINDS[k] for k in near])])
        trees[name] = cKDTree(c.vertices[verts]) if len(verts) else None
    for kind, opacity, power, near in ((MATERIAL_KINDS["lashes"], LASH_ROOT_OPACITY, 3.0, "eye"),
                                       (MATERIAL_KINDS["occlusion"], OCCLUSION_OPACITY, 2.0, "skin"),
                                       (MATERIAL_KINDS["film"], FILM_OPACITY, 0.0, "skin")):
        v = np.unique(c.triangles[tri_kind == kind])
        tree = trees[near]
        if not len(v):
            continue
        if tree is None or power == 0.0:  # no eye to measure from (a lash card alone): one opacity
            out[v] = opacity
            continue
        d, _ = tree.query(c.vertices[v])
        lo, hi = float(d.min()), float(np.percentile(d, 90))
        s = np.clip((d - lo) / max(hi - lo, 1e-9), 0.0, 1.0)
        out[v] = opacity * (1.0 - s) ** power
    return out
