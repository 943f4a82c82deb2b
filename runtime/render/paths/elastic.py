"""The ``elastic`` deformation path: control points spread by the compact basis on the GPU.

The compact basis (k control indices, weights and normal gradients per
vertex) lives in two float textures made once; per frame only the control
displacements, n_controls × 3 floats, are uploaded as a uniform array (and,
for rigid parts such as the lower teeth, one 3 × 4 transform per part) and
``shaders/elastic.glsl`` does the rest (Yano & Harada eq. 5).

:class:`ElasticDraw` is what the frame loop draws with on this path: it takes the elastic
table's channel values (shapes, then muscles) instead of the character's weights.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import moderngl
import numpy as np

from facepuppet.runtime.elastic.model import ElasticModel
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.render.paths.base import DeformationPath, ProgramBuilder

if TYPE_CHECKING:  # for the annotation only: renderer.py imports this module
    from facepuppet.runtime.render.renderer import FaceRenderer

ELASTIC_TEXTURE_WIDTH = 4096
BASIS_UNIT, INDEX_UNIT, RIGID_LABEL_UNIT = 0, 1, 2


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


class ElasticPath(DeformationPath):
    """The rest mesh in a vertex buffer, the basis in textures, the control displacements in uniforms.

    Parameters
    ----------
    ctx : moderngl.Context
    character : Character, without parts (one ``face.glsl`` program)
    model : ElasticModel, made for ``character`` (checked)
    build : ProgramBuilder, the renderer's programs and vertex arrays

    Attributes
    ----------
    model : ElasticModel
    """

    name = "elastic"

    def __init__(self, ctx: moderngl.Context, character: Character, model: ElasticModel,
                 build: ProgramBuilder) -> None:
        self.model = check_model(character, model)
        rest = np.hstack([character.vertices, character.rest_normals()]).astype(np.float32)
        vbo = ctx.buffer(rest.tobytes())
        programs, vaos = build(elastic_defines(model), vbo)
        self._prog = programs[None]
        self._prog["u_basis"].value = BASIS_UNIT
        self._prog["u_basis_index"].value = INDEX_UNIT
        if model.n_rigid:
            self._prog["u_rigid_label"].value = RIGID_LABEL_UNIT
        super().__init__(programs, vaos, vbo, basis_textures(ctx, model))

    def prepare(self, weights: np.ndarray, joints: np.ndarray | None) -> None:
        """Controls from the weights: U = Σ w P (Yano & Harada eq. 7)."""
        self.prepare_controls(self.model.blend(weights))

    def prepare_controls(self, controls: np.ndarray) -> None:
        """Write the frame's control displacements, (n_controls, 3) float32, into the uniform array."""
        model = self.model
        u = np.ascontiguousarray(controls, dtype=np.float32)
        if u.shape != (model.n_controls, 3):
            raise ValueError(f"controls: expected shape ({model.n_controls}, 3), got {u.shape}")
        if model.n_controls:
            self._prog["u_controls"].write(u.tobytes())
        if model.n_rigid:  # rows of [R | t] per rigid part, fitted to the anchors on the CPU
            self._prog["u_rigid"].write(np.ascontiguousarray(model.rigid_transforms(u)).tobytes())


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

    def read_rgba(self) -> np.ndarray:
        return self.renderer.read_rgba()

    @property
    def transparent(self) -> bool:
        return self.renderer.transparent

    def close(self) -> None:
        self.renderer.close()
