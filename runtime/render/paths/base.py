"""The interface every deformation path gives the renderer.

A path owns its vertex buffer, its textures and one program (with its vertex array) per fragment
variant; the renderer owns everything else a frame needs (camera, framebuffers, the attribute and
index buffers, materials, the draw passes) and calls the path at three points:

* :meth:`DeformationPath.prepare` with the frame's weights and head joints (the CPU side),
* :meth:`DeformationPath.bind` before the draw calls,
* :meth:`DeformationPath.release` when the renderer closes (or drops the slower path).

Texture units below ``PATH_TEXTURE_UNITS`` belong to the path; the renderer binds material
textures above them.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence

import moderngl
import numpy as np

#: Texture units 0 .. PATH_TEXTURE_UNITS - 1 are the path's (deltas, joints; or the elastic basis)
PATH_TEXTURE_UNITS = 3

#: ``build(defines, vbo) -> (programs, vaos)``: the renderer's programs of one path, by fragment variant,
#: each with a vertex array reading [position, normal] from ``vbo`` and the renderer's other attributes
ProgramBuilder = Callable[[dict, moderngl.Buffer], tuple[dict, dict]]


class DeformationPath(ABC):
    """The GL objects of one deformation path and its per-frame work.

    Parameters
    ----------
    programs : dict, fragment variant key -> moderngl.Program (key None for a character without parts)
    vaos : dict, the same keys -> moderngl.VertexArray
    vbo : moderngl.Buffer, interleaved [position, normal] per vertex, 6 float32
    textures : sequence of moderngl.Texture, bound to units 0, 1, ... by :meth:`bind`

    Attributes
    ----------
    name : str, the renderer's ``path`` ("gpu", "cpu" or "elastic")
    """

    name: str = ""

    def __init__(self, programs: dict, vaos: dict, vbo: moderngl.Buffer,
                 textures: Sequence[moderngl.Texture] = ()) -> None:
        self.programs = programs
        self.vaos = vaos
        self.vbo = vbo
        self.textures = list(textures)

    @abstractmethod
    def prepare(self, weights: np.ndarray, joints: np.ndarray | None) -> None:
        """The CPU side of a frame.

        Parameters
        ----------
        weights : ndarray of shape (n_shapes,), float32, checked, in character shape order
        joints : ndarray of shape (n_nodes, 4, 4), float32, the head pose's skinning matrices, or None
            for the rest pose (always None for a character without a skeleton)
        """

    def bind(self) -> None:
        """Bind the path's textures to their units, before the frame's draw calls."""
        for unit, tex in enumerate(self.textures):
            tex.use(unit)

    def release(self) -> None:
        """Release every GL object of the path."""
        for obj in (*self.vaos.values(), *self.programs.values(), self.vbo, *self.textures):
            obj.release()
