"""The camera of a picture: which vertices of a character the framing fits (body, head or face).

The choice (``--framing``) is parsed in :mod:`~facepuppet.runtime.render.options`; here it becomes a
box and the box a camera (:func:`~facepuppet.runtime.render.camera.frame_bounds`).
"""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.model.character import MATERIAL_KINDS, Character, moving_vertices
from facepuppet.runtime.model.geometry import bounds
from facepuppet.runtime.render.camera import Camera, frame_bounds
from facepuppet.runtime.render.parts_path import head_vertices


def frame_character(character: Character, framing: str, aspect: float) -> Camera:
    """Camera fitting the drawn (not hidden) vertices of ``character`` that ``framing`` names.

    Parameters
    ----------
    character : Character
    framing : str, "body" (every drawn vertex), "head" (the vertices following the humanoid head bone;
        every drawn vertex for a character without a skeleton) or "face" (the vertices the shapes move)
    aspect : float, width / height of the target
    """
    c = character
    kinds = c.material_params[:, 2].round().astype(int)
    tris = c.triangles[kinds[c.triangle_material] != MATERIAL_KINDS["hidden"]]
    used = np.unique(tris) if len(tris) else np.arange(c.n_vertices)
    if framing == "head":  # the head bone and below; a character without a skeleton is a head
        head = np.intersect1d(used, head_vertices(c))
        used = head if len(head) else used
    elif framing == "face":  # the part the shapes move; a character nothing moves is framed whole
        moving = moving_vertices(c)
        used = np.intersect1d(used, moving) if len(moving) else used
    lo, hi = bounds(c.vertices[used])
    whole_lo, whole_hi = bounds(c.vertices[np.unique(tris)] if len(tris) else c.vertices)
    if float(np.max(hi - lo)) <= 0.05 * float(np.max(whole_hi - whole_lo)):
        # a head or face part too small to frame (one moving vertex, a degenerate head box): frame it all
        lo, hi = whole_lo, whole_hi
    return frame_bounds(lo, hi, aspect)
