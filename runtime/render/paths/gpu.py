"""The ``gpu`` deformation path: the vertex shader sums the active shapes' deltas.

Every shape's position and normal deltas sit in one texture (16-bit fixed point,
:func:`~facepuppet.runtime.render.paths.deltas.delta_texture`); per frame only the active
(shape, weight) pairs are uploaded as uniforms (a few hundred bytes) and ``shaders/blendshapes.glsl``
sums them. A character with a skeleton is skinned in the same vertex shader, from a joint texture
rewritten each frame with the head pose.

On a real GPU this path wins by far; on Mesa's software rasteriser the vertex shader is emulated
and the cpu path can be faster (the renderer's ``path="auto"`` times both).
"""

from __future__ import annotations

import moderngl
import numpy as np

from facepuppet.runtime.model.character import Character
from facepuppet.runtime.render.parts_path import joint_texels
from facepuppet.runtime.render.paths.base import DeformationPath, ProgramBuilder
from facepuppet.runtime.render.paths.deltas import DELTA_TEXTURE_WIDTH, active_uniforms, delta_texture

MAX_ACTIVE_LIMIT = 256  # uniform array length cap; more active shapes keep the largest weights
DELTA_UNIT, JOINT_UNIT = 0, 2


def gpu_defines(character: Character) -> dict:
    """The #defines of face.glsl's GPU deformation variant for ``character``."""
    return {
        "GPU_DEFORM": 1,
        "MAX_ACTIVE": max(1, min(character.n_shapes, MAX_ACTIVE_LIMIT)),
        "N_VERTICES": character.n_vertices,
        "DELTA_TEXTURE_WIDTH": DELTA_TEXTURE_WIDTH,
    }


class GpuPath(DeformationPath):
    """Deltas in a texture, the active list in uniforms, the sum (and skinning) in the vertex shader.

    Parameters
    ----------
    ctx : moderngl.Context
    character : Character
    build : ProgramBuilder, the renderer's programs and vertex arrays by fragment variant
    skin : bool, skin through the character's skeleton (a joint texture, ``SKIN`` defined)

    Attributes
    ----------
    steps : ndarray of shape (n_shapes, 2), float32, a weight's (position, normal) scale
    max_active : int, length of the active list
    joints : moderngl.Texture or None, the skinning matrices (RGBA32F, 4 texels per node)
    """

    name = "gpu"

    def __init__(self, ctx: moderngl.Context, character: Character, build: ProgramBuilder, skin: bool) -> None:
        defines = gpu_defines(character)
        self.max_active = defines["MAX_ACTIVE"]
        if skin:
            defines["SKIN"] = 1
        deltas, self.steps = delta_texture(ctx, character)
        rest = np.hstack([character.vertices, character.rest_normals()]).astype(np.float32)
        vbo = ctx.buffer(rest.tobytes())
        programs, vaos = build(defines, vbo)
        self.joints = None
        if skin:
            n_nodes = character.skeleton.n_nodes
            self._rest_joints = np.tile(np.eye(4, dtype=np.float32), (n_nodes, 1, 1))
            self.joints = ctx.texture((4 * n_nodes, 1), 4, joint_texels(self._rest_joints), dtype="f4")
            self.joints.filter = (moderngl.NEAREST, moderngl.NEAREST)
        for prog in programs.values():  # an unlit variant does not read the normals
            for name, unit in (("u_deltas", DELTA_UNIT), ("u_joints", JOINT_UNIT)):
                if name in prog:
                    prog[name].value = unit
        super().__init__(programs, vaos, vbo, [deltas])

    def prepare(self, weights: np.ndarray, joints: np.ndarray | None) -> None:
        """Upload the active list to every program and the head pose to the joint texture."""
        count, shapes, scaled = active_uniforms(weights, self.steps, self.max_active)
        shapes, scaled = shapes.tobytes(), scaled.tobytes()
        for prog in self.programs.values():
            prog["u_active_count"].value = count
            if count:
                prog["u_active_shape"].write(shapes)
                prog["u_active_weight"].write(scaled)
        if self.joints is not None:
            self.joints.write(joint_texels(joints if joints is not None else self._rest_joints))

    def bind(self) -> None:
        super().bind()
        if self.joints is not None:
            self.joints.use(JOINT_UNIT)

    def release(self) -> None:
        super().release()
        if self.joints is not None:
            self.joints.release()
