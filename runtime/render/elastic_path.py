"""The renderer's ``elastic`` deformation path: control points spread by the compact basis on the GPU.

The compact basis (k control indices, weights and normal gradients per
vertex) lives in two float textures made once; per frame only the control
displacements, n_controls × 3 floats, are uploaded as a uniform array (and,
for rigid parts such as the lower teeth, one 3 × 4 transform per part) and
``shaders/elastic.glsl`` does the rest (Yano & Harada eq. 5).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import moderngl
import numpy as np

from facepuppet.runtime.character import Character
from facepuppet.runtime.elastic.model import ElasticModel
from facepuppet.runtime.render.shader_loader import load_program

if TYPE_CHECKING:
    from facepuppet.runtime.render.renderer import FaceRenderer

ELASTIC_TEXTURE_WIDTH = 4096


def elastic_defines(model: ElasticModel) -> dict:
    """The #defines of face.glsl's elastic variant."""
    return {
        "ELASTIC_DEFORM": 1,
        "K": model.k,
        "N_CONTROLS": max(1, model.n_controls),
        "ELASTIC_TEXTURE_WIDTH": ELASTIC_TEXTURE_WIDTH,
        "N_RIGID": model.n_rigid,
    }


def basis_textures(ctx: moderngl.Context, model: ElasticModel) -> list:
    """[basis (RGBA32F: gradient xyz, weight), index (R32F)], texel vertex * k + j;
    then, with rigid parts, [part + 1 (R32F, 0 for none)], texel vertex."""
    a = model.arrays
    count = model.n_vertices * model.k
    rows = max(1, -(-count // ELASTIC_TEXTURE_WIDTH))
    basis = np.zeros((rows * ELASTIC_TEXTURE_WIDTH, 4), np.float32)
    basis[:count, :3] = a["basis_gradients"].reshape(-1, 3)
    basis[:count, 3] = a["basis_weights"].reshape(-1)
    index = np.zeros(rows * ELASTIC_TEXTURE_WIDTH, np.float32)
    index[:count] = a["basis_indices"].reshape(-1)
    textures = [
        ctx.texture((ELASTIC_TEXTURE_WIDTH, rows), 4, basis.tobytes(), dtype="f4"),
        ctx.texture((ELASTIC_TEXTURE_WIDTH, rows), 1, index.tobytes(), dtype="f4"),
    ]
    if model.n_rigid:
        label_rows = max(1, -(-model.n_vertices // ELASTIC_TEXTURE_WIDTH))
        labels = np.zeros(label_rows * ELASTIC_TEXTURE_WIDTH, np.float32)
        labels[: model.n_vertices] = a["rigid_labels"].astype(np.float32) + 1.0
        textures.append(ctx.texture((ELASTIC_TEXTURE_WIDTH, label_rows), 1, labels.tobytes(), dtype="f4"))
    for tex in textures:
        tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    return textures


def check_model(character: Character, model: ElasticModel) -> ElasticModel:
    """ValueError unless ``model`` was made for ``character``'s mesh."""
    if not isinstance(model, ElasticModel):
        raise ValueError(f"elastic: expected an ElasticModel for path 'elastic', got {type(model).__name__}")
    if model.n_vertices != character.n_vertices:
        raise ValueError(
            f"elastic: table has {model.n_vertices} vertices, character {character.name!r} has {character.n_vertices}"
        )
    if tuple(model.shape_names) != tuple(character.shape_names):
        raise ValueError("elastic: the table's shapes must be the character's, in its order (weights are shared)")
    return model


def setup_elastic(ctx: moderngl.Context, character: Character, model: ElasticModel,
                  make_vao: Callable[[moderngl.Program, moderngl.Buffer], moderngl.VertexArray]) -> dict:
    """GL objects of the elastic path: program, rest vertex buffer, VAO, basis textures.

    ``make_vao(prog, vbo)`` is the renderer's VAO builder (same attribute layout as its other paths).
    """
    prog = load_program(ctx, "face.glsl", elastic_defines(model))
    rest = np.hstack([character.vertices, character.rest_normals()]).astype(np.float32)
    vbo = ctx.buffer(rest.tobytes())
    prog["u_basis"].value = 0
    prog["u_basis_index"].value = 1
    if model.n_rigid:
        prog["u_rigid_label"].value = 2
    vao = make_vao(prog, vbo)
    # "programs" / "vaos" keyed as the renderer's other paths (one program here)
    return {"prog": prog, "programs": {None: prog}, "vaos": {None: vao}, "vbo": vbo,
            "textures": basis_textures(ctx, model), "model": model}


def upload_controls(state: dict, controls: np.ndarray) -> None:
    """Write the frame's control displacements, (n_controls, 3) float32, into the uniform array."""
    model = state["model"]
    u = np.ascontiguousarray(controls, dtype=np.float32)
    if u.shape != (model.n_controls, 3):
        raise ValueError(f"controls: expected shape ({model.n_controls}, 3), got {u.shape}")
    if model.n_controls:
        state["prog"]["u_controls"].write(u.tobytes())
    if model.n_rigid:  # rows of [R | t] per rigid part, fitted to the anchors on the CPU
        state["prog"]["u_rigid"].write(np.ascontiguousarray(model.rigid_transforms(u)).tobytes())


class ElasticDraw:
    """Renderer adapter of the elastic path: ``draw(values)`` with values of the table's channels.

    Parameters
    ----------
    renderer : FaceRenderer made with ``path="elastic"``
    model : ElasticModel

    Attributes
    ----------
    shape_names : tuple of str, ``model.channel_names`` (shapes then muscles): the
        frame loop's targets (the loop reads nothing else of its ``character``)
    path : str, "elastic"
    """

    def __init__(self, renderer: FaceRenderer, model: ElasticModel) -> None:
        if renderer.path != "elastic":
            raise ValueError(f"ElasticDraw: the renderer must use the 'elastic' path, not {renderer.path!r}")
        self.renderer = renderer
        self.model = model
        self.shape_names = tuple(model.channel_names)
        self.path = "elastic"

    def draw(self, values: np.ndarray, head_rotation: np.ndarray | None = None,
             head_translation: np.ndarray | None = None) -> None:
        """Draw channel values, ndarray (n_shapes + n_muscles,) float32: U = Σ w P + Σ c Q, then the basis."""
        self.renderer.prepare_controls(self.model.controls(values), head_rotation, head_translation)
        self.renderer.submit()

    def finish(self) -> None:
        self.renderer.finish()

    def read_pixels(self) -> np.ndarray:
        return self.renderer.read_pixels()

    def close(self) -> None:
        self.renderer.close()
