"""The GL side of a character's materials: uniform blocks, textures and their units, per draw group.

Each material has one std140 ``Material`` block (:func:`~.parts_path.material_block`); its base
colour texture is sRGB (the look's), and the textures of its material model are data (linear:
metallic-roughness, outline width, UV mask) or colours read by MToon's rim (sRGB: rim multiply,
matcap), each on a texture unit of its own above the deformation path's. Expressions' material binds
(:class:`~.material_binds.MaterialBinds`) rewrite the blocks of the materials they change, only when
a bind shape's weight changed.
"""

from __future__ import annotations

import moderngl
import numpy as np

from facepuppet.runtime.model.character import Character
from facepuppet.runtime.model.material_model import MTOON_TEXTURES
from facepuppet.runtime.render.material_binds import MaterialBinds
from facepuppet.runtime.render.parts_path import look_of, make_textures, material_block, material_model_of
from facepuppet.runtime.render.paths.base import PATH_TEXTURE_UNITS

BASE_TEXTURE_UNIT = PATH_TEXTURE_UNITS  # a material's base colour texture, above the path's units
#: A material's textures beyond the base colour: (uniform, unit, material model table, column); the MToon
#: columns' colour space is :data:`~facepuppet.runtime.model.material_model.MTOON_TEXTURES`'s
MATERIAL_TEXTURES = (("u_metal_rough_texture", BASE_TEXTURE_UNIT + 1, "pbr", 2),
                     ("u_outline_texture", BASE_TEXTURE_UNIT + 2, "mtoon", 6),
                     ("u_rim_texture", BASE_TEXTURE_UNIT + 3, "mtoon", 16),
                     ("u_matcap_texture", BASE_TEXTURE_UNIT + 4, "mtoon", 20),
                     ("u_uv_mask_texture", BASE_TEXTURE_UNIT + 5, "mtoon", 21))
#: (uniform, unit) of every sampler ``character.glsl`` may declare
SAMPLER_UNITS = (("u_base_texture", BASE_TEXTURE_UNIT), *((name, unit) for name, unit, _, _ in MATERIAL_TEXTURES))


class MaterialGl:
    """The uniform blocks and textures of a character with parts (see the module doc)."""

    def __init__(self, ctx: moderngl.Context, character: Character) -> None:
        self.character = character
        self.look = look_of(character)
        self.model = material_model_of(character)
        self.textures = make_textures(ctx, self.look)
        has_data = bool(len(self.model.texture_info))
        colour_columns = [c for c, colour in MTOON_TEXTURES.items() if colour]
        self.data_textures = make_textures(ctx, self.model, srgb=False) if has_data else []
        self.colour_data_textures = make_textures(ctx, self.model) \
            if has_data and np.any(self.model.mtoon[:, colour_columns] >= 0) else []
        self.binds = MaterialBinds(character)
        self.blocks = [ctx.buffer(material_block(character, m, self.binds.rows))
                       for m in range(len(character.material_names))]

    def update(self, weights: np.ndarray) -> None:
        """The blocks of the materials the frame's bind shape ``weights`` changed, written again."""
        if self.binds.active:
            for m in self.binds.update(weights):
                self.blocks[m].write(material_block(self.character, int(m), self.binds.rows))

    def use(self, m: int) -> None:
        """Bind material ``m``'s block (binding 0) and its textures to their units."""
        self.blocks[m].bind_to_uniform_block(0)
        t = int(self.look.texture[m])
        if t >= 0:
            self.textures[t].use(BASE_TEXTURE_UNIT)
        for _, unit, table, col in MATERIAL_TEXTURES:
            k = int(getattr(self.model, table)[m, col])
            if k >= 0:
                colour = table == "mtoon" and MTOON_TEXTURES[col]
                (self.colour_data_textures if colour else self.data_textures)[k].use(unit)

    def release(self) -> None:
        for obj in self.textures + self.blocks + self.data_textures + self.colour_data_textures:
            obj.release()


__all__ = ["BASE_TEXTURE_UNIT", "MATERIAL_TEXTURES", "SAMPLER_UNITS", "MaterialGl"]
