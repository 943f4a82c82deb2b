"""The ``cpu`` deformation path: NumPy sums the deltas and the result is written into the vertex buffer.

The deltas are the gpu path's 16-bit ones (:func:`~facepuppet.runtime.render.paths.deltas.on_delta_grid`),
so both paths draw the same surface; a character whose skeleton turns the head is skinned on the CPU too
(:class:`~facepuppet.runtime.render.parts_path.CpuSkinner`). The programs are the plain variants: the
vertex shader only transforms.
"""

from __future__ import annotations

import moderngl
import numpy as np

from facepuppet.runtime.model.character import Character
from facepuppet.runtime.render.cpu_deform import CpuDeformer
from facepuppet.runtime.render.parts_path import CpuSkinner, HeadPose
from facepuppet.runtime.render.paths.base import DeformationPath, ProgramBuilder
from facepuppet.runtime.render.paths.deltas import on_delta_grid


class CpuPath(DeformationPath):
    """Deformation (and head skinning) with NumPy, one vertex buffer upload per frame.

    Parameters
    ----------
    ctx : moderngl.Context
    character : Character
    build : ProgramBuilder, the renderer's programs and vertex arrays by fragment variant
    head_pose : HeadPose or None; with an available head bone the moving part is skinned per frame

    Attributes
    ----------
    deformer : CpuDeformer, over the deltas on the gpu path's 16-bit grid
    skinner : CpuSkinner or None
    """

    name = "cpu"

    def __init__(self, ctx: moderngl.Context, character: Character, build: ProgramBuilder,
                 head_pose: HeadPose | None) -> None:
        self.deformer = CpuDeformer(on_delta_grid(character))  # the deltas the gpu path draws
        vbo = ctx.buffer(self.deformer.rest.tobytes(), dynamic=True)
        programs, vaos = build({}, vbo)
        self.skinner = None
        if head_pose is not None and head_pose.available:
            self.skinner = CpuSkinner(character, head_pose.moved_nodes)
        super().__init__(programs, vaos, vbo)

    def prepare(self, weights: np.ndarray, joints: np.ndarray | None) -> None:
        """Deform, skin, and replace the vertex buffer's contents."""
        out = self.deformer.deform_into(weights)
        if self.skinner is not None:
            out = self.skinner.skin(out, joints)
        self.vbo.orphan()
        self.vbo.write(out)
