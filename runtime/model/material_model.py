"""The material parameters beyond the core look: MToon's outline, rim and UV animation, glTF's
metallic-roughness, and the expressions' material binds.

:class:`~facepuppet.runtime.model.character_parts.Look` holds what every glTF
material has (base colour, emissive, alpha, toon shade). A VRM avatar's MToon
materials also draw an outline (a second pass of the back faces pushed out along
the normals, by a width in metres or as a fraction of the view's half height),
a rim light and a scrolling / turning texture; a plain glTF material is lit by
the metallic-roughness model with its own metallic and roughness (default 1, 1)
and their texture. VRM expressions also change material colours and texture
offsets (VRM 0.x ``materialValues``, 1.0 ``materialColorBinds`` /
``textureTransformBinds``).

Material binds are carried by shapes: each expression with material binds drives
one shape of its own that moves no vertex (named ``material:`` + the expression),
so the expression's weight reaches the renderer through every stage as that
shape's weight, isBinary and overrides applied. A bind sets one property of one
material to ``rest + weight × (target − rest)``, summed over the shapes that
bind it (as three-vrm does).

The textures these parameters use (metallic-roughness, outline width) are data, not colours, and
are held here apart from the look's colour textures (``material_texture_info`` / ``_pixels``, laid
out as the look's), so the look stays what core glTF's base colour needs.

The part (sections ``material_mtoon``, ``material_pbr``, ``material_bind_*``,
``material_texture_*``) is optional; a character without it draws as before (no outline, rim or UV
animation; lit materials by the studio kinds).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from facepuppet.runtime.files.tables import Section, TablesError

#: ``material_mtoon`` columns. Outline mode 0 none, 1 world (width in metres), 2 screen (width as a fraction
#: of the view's half height, three-vrm's ``outlineWidthFactor``); colours linear; texture columns index this
#: part's own textures, or -1; speeds per second (scroll in UV units, rotation in radians).
MTOON_COLUMNS = ("outline_mode", "outline_width", "outline_r", "outline_g", "outline_b", "outline_lighting_mix",
                 "outline_width_texture", "rim_r", "rim_g", "rim_b", "rim_fresnel_power", "rim_lift",
                 "rim_lighting_mix", "uv_scroll_u", "uv_scroll_v", "uv_rotation", "rim_texture", "matcap_r",
                 "matcap_g", "matcap_b", "matcap_texture", "uv_mask_texture")
OUTLINE_MODES = {"none": 0, "worldCoordinates": 1, "screenCoordinates": 2}
#: A material without MToon: no outline, no rim (power 5 as the spec's default, lift 0), no UV animation, no
#: rim, matcap or UV mask texture. The rim multiply and matcap textures are colours (sRGB); the outline
#: width, UV mask and metallic-roughness textures are data (linear).
NO_MTOON = (0, 0, 0, 0, 0, 1, -1, 0, 0, 0, 5, 0, 1, 0, 0, 0, -1, 1, 1, 1, -1, -1)
#: The ``material_mtoon`` columns that name a texture, and whether it holds colours (sRGB)
MTOON_TEXTURES = {6: False, 16: True, 20: True, 21: False}
#: ``material_pbr`` columns: metallic, roughness, metallic-roughness texture (-1 none), model (1: lit by
#: the glTF metallic-roughness model; 0: by the studio lighting of its kind)
PBR_COLUMNS = ("metallic", "roughness", "metallic_roughness_texture", "model")
#: What a material bind changes (``material_bind_target`` column 1); the value is RGBA for the colours and
#: (scale u, scale v, offset u, offset v) for the texture transform.
BIND_KINDS = {"color": 0, "emissionColor": 1, "shadeColor": 2, "rimColor": 3, "outlineColor": 4,
              "matcapColor": 5, "textureTransform": 6}
#: The shape that carries an expression's material binds
BIND_SHAPE_PREFIX = "material:"

SECTIONS = {
    "material_mtoon": Section("float32", ("n_materials", len(MTOON_COLUMNS)), "see MTOON_COLUMNS",
                              optional=True),
    "material_pbr": Section("float32", ("n_materials", len(PBR_COLUMNS)), "see PBR_COLUMNS", optional=True),
    "material_bind_shape": Section("uint32", ("n_material_binds",), "the shape (expression) driving each bind",
                                   optional=True),
    "material_bind_target": Section("int32", ("n_material_binds", 2), "material, BIND_KINDS code",
                                    optional=True),
    "material_bind_value": Section("float32", ("n_material_binds", 4), "target value at weight 1",
                                   optional=True),
    "material_texture_info": Section("int32", ("n_material_textures", 7), "as the look's texture_info",
                                     optional=True),
    "material_texture_pixels": Section("uint8", ("n_material_texels", 4), "RGBA as in the image, rows top first",
                                       optional=True),
}


def _fail(field_name: str, problem: str):
    raise TablesError(None, field_name, problem)


@dataclass(frozen=True, eq=False)
class MaterialModel:
    """MToon and metallic-roughness parameters per material, and the material binds (see the module doc).

    Attributes
    ----------
    mtoon : ndarray (n_materials, 16) float32: :data:`MTOON_COLUMNS`
    pbr : ndarray (n_materials, 4) float32: :data:`PBR_COLUMNS`
    bind_shape : ndarray (n_binds,) uint32
    bind_target : ndarray (n_binds, 2) int32: material, :data:`BIND_KINDS` code
    bind_value : ndarray (n_binds, 4) float32
    texture_info : ndarray (n_textures, 7) int32, as :attr:`Look.texture_info`
    texture_pixels : ndarray (n_texels, 4) uint8
    """

    mtoon: np.ndarray
    pbr: np.ndarray
    bind_shape: np.ndarray
    bind_target: np.ndarray
    bind_value: np.ndarray
    texture_info: np.ndarray
    texture_pixels: np.ndarray

    @property
    def texture_names(self) -> tuple[str, ...]:
        return tuple(f"material_texture{t}" for t in range(len(self.texture_info)))

    def image(self, t: int) -> np.ndarray:
        """Texture ``t`` as ndarray (height, width, 4) uint8, top row first (a view)."""
        first, w, h = (int(x) for x in self.texture_info[t, :3])
        return self.texture_pixels[first:first + w * h].reshape(h, w, 4)

    def check(self, n_materials: int, n_shapes: int) -> None:
        n_textures = len(self.texture_info)
        if self.texture_info.ndim != 2 or self.texture_info.shape[1] != 7:
            _fail("material_texture_info", f"expected shape (n, 7), found {self.texture_info.shape}")
        for t in range(n_textures):
            first, w, h = (int(x) for x in self.texture_info[t, :3])
            if w <= 0 or h <= 0 or first < 0 or first + w * h > len(self.texture_pixels):
                _fail("material_texture_info", f"texture {t}: {w}x{h} at texel {first} does not fit in "
                                               f"{len(self.texture_pixels)} texels")
        if self.mtoon.shape != (n_materials, len(MTOON_COLUMNS)):
            _fail("material_mtoon", f"expected shape {(n_materials, len(MTOON_COLUMNS))}, found {self.mtoon.shape}")
        if self.pbr.shape != (n_materials, len(PBR_COLUMNS)):
            _fail("material_pbr", f"expected shape {(n_materials, len(PBR_COLUMNS))}, found {self.pbr.shape}")
        if not set(np.unique(self.mtoon[:, 0]).tolist()) <= set(OUTLINE_MODES.values()):
            _fail("material_mtoon", "outline mode codes must be 0 (none), 1 (world) or 2 (screen)")
        for name, col in [*(("material_mtoon", self.mtoon[:, c]) for c in MTOON_TEXTURES),
                          ("material_pbr", self.pbr[:, 2])]:
            if len(col) and (col.min() < -1 or col.max() >= n_textures or np.any(col != np.round(col))):
                _fail(name, f"texture index out of range for {n_textures} textures")
        n = len(self.bind_shape)
        if self.bind_target.shape != (n, 2) or self.bind_value.shape != (n, 4):
            _fail("material_bind_target", f"{n} binds need ({n}, 2) targets and ({n}, 4) values")
        if n and (int(self.bind_shape.max()) >= n_shapes or int(self.bind_target[:, 0].min()) < 0
                  or int(self.bind_target[:, 0].max()) >= n_materials
                  or not set(np.unique(self.bind_target[:, 1]).tolist()) <= set(BIND_KINDS.values())):
            _fail("material_bind_target", "a bind's shape, material or kind is out of range")
        for a in self.arrays().values():
            a.setflags(write=False)

    def arrays(self) -> dict[str, np.ndarray]:
        return {"material_mtoon": self.mtoon, "material_pbr": self.pbr, "material_bind_shape": self.bind_shape,
                "material_bind_target": self.bind_target, "material_bind_value": self.bind_value,
                "material_texture_info": self.texture_info, "material_texture_pixels": self.texture_pixels}

    @classmethod
    def from_arrays(cls, a: Mapping[str, np.ndarray]) -> MaterialModel:
        return cls(*(a[k] for k in SECTIONS))


def default_material_model(n_materials: int) -> MaterialModel:
    """No MToon extras, the studio lighting, no binds."""
    pbr = np.tile(np.array([1.0, 1.0, -1.0, 0.0], np.float32), (n_materials, 1))
    return MaterialModel(np.tile(np.array(NO_MTOON, np.float32), (n_materials, 1)), pbr,
                         np.zeros(0, np.uint32), np.zeros((0, 2), np.int32), np.zeros((0, 4), np.float32),
                         np.zeros((0, 7), np.int32), np.zeros((0, 4), np.uint8))


__all__ = ["BIND_KINDS", "BIND_SHAPE_PREFIX", "MTOON_COLUMNS", "MTOON_TEXTURES", "MaterialModel", "NO_MTOON",
           "OUTLINE_MODES", "PBR_COLUMNS", "SECTIONS", "default_material_model"]
