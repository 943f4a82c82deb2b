"""The materials of a glTF file: their names and kinds, the core look of each, the textures they use.

A material is stored with [specular, shininess, kind, 0]: skin (the OBJ
import's skin shine), unless ``extras.facepuppet`` (written by
``export-character``) names another kind. Its look row holds what core glTF
2.0 says: ``baseColorFactor``, ``emissiveFactor``, ``alphaMode`` /
``alphaCutoff``, ``doubleSided`` and the base colour texture (TEXCOORD_0
only). The extensions that change a row (unlit, emissive strength, texture
transform, MToon) are read after this, each by its own reader. Textures are
decoded with Pillow (PNG or JPEG) into RGBA as in the image (sRGB-encoded),
with their samplers' codes. A file can declare a texture far larger than its
bytes (a blank 8000×8000 PNG is 100 KB), so all used images' sizes are read
from their headers and held to :data:`MAX_TEXTURE_SIDE` and
:data:`MAX_TEXTURE_TEXELS` before any is decoded.
"""

from __future__ import annotations

import io
import warnings as _warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import BinaryIO

import numpy as np
from PIL import Image, UnidentifiedImageError

from facepuppet.runtime.model.character import MATERIAL_KINDS
from facepuppet.runtime.model.character_parts import ALPHA_MODES, IDENTITY_UV_TRANSFORM

from facepuppet.offline.io.gltf.kept_parts import keep_parts
from facepuppet.offline.io.gltf.names import UniqueNames
from facepuppet.offline.io.gltf.read_state import LookRows, ReadState
from facepuppet.offline.io.gltf_files import Opened

_SKIN_SHINE = (0.05, 18.0)  # rig_import.KIND_SHINE["skin"]
_MAG = frozenset({9728, 9729})
_MIN = frozenset({9728, 9729, 9984, 9985, 9986, 9987})
_WRAP = frozenset({33071, 33648, 10497})
#: The widest and tallest texture decoded: avatars ship 1024-4096 texel textures; one 8192x8192 is 256 MiB of RGBA.
MAX_TEXTURE_SIDE = 8192
#: The most texels of all used textures together, checked from the images' headers before any is decoded: 128 Mi
#: texels (512 MiB of RGBA) hold 32 textures of 2048x2048, 8 of 4096x4096 or 2 of 8192x8192 (the data kit's
#: largest avatar uses 2.5 Mi), and stay half of the character table's 1 GiB cap on its one texel section.
MAX_TEXTURE_TEXELS = 128 << 20


def read_materials(state: ReadState) -> None:
    """Fill the stored materials, their core look rows and the decoded textures (see the module doc)."""
    default_material = _materials(state)
    textures = _look_rows(state, default_material)
    _textures(state, textures)
    keep_parts(state, textures)


def _materials(state: ReadState) -> int | None:
    """Names (unique) and [specular, shininess, kind, 0] of the stored materials: the file's, then the spec's
    default material when a primitive has none (or when the file has no material at all)."""
    f = state.f
    used = state.geo["material_used"]
    mats = f.items("materials")
    names, params = [], []
    unique = UniqueNames()
    for i, m in enumerate(mats):
        f.obj("materials", i, f"materials[{i}]")
        names.append(unique.take(m.get("name") if isinstance(m.get("name"), str) and m["name"] else f"material{i}"))
        params.append(_material_kind(state, m, i))
    default_material = None
    if -1 in used:  # primitives without a material: the spec's default material, appended
        default_material = len(names)
        n = "default"
        while n in unique.used:
            n += "_"
        names.append(n)
        params.append([_SKIN_SHINE[0], _SKIN_SHINE[1], MATERIAL_KINDS["skin"], 0.0])
    if not names:
        names, params = ["default"], [[_SKIN_SHINE[0], _SKIN_SHINE[1], MATERIAL_KINDS["skin"], 0.0]]
    state.material_names = tuple(names)
    state.material_params = np.asarray(params, dtype=np.float32)
    return default_material


def _material_kind(state: ReadState, m: dict, i: int) -> list[float]:
    """[specular, shininess, kind, 0] of material ``i``: skin, unless ``extras.facepuppet`` (written by
    ``export-character``) names another kind; a malformed entry is warned about and ignored."""
    skin = [_SKIN_SHINE[0], _SKIN_SHINE[1], float(MATERIAL_KINDS["skin"]), 0.0]
    extras = m.get("extras")
    ours = extras.get("facepuppet") if isinstance(extras, dict) else None
    if ours is None:
        return skin
    kind, spec, shine = (ours.get(k) if isinstance(ours, dict) else None for k in ("kind", "specular", "shininess"))
    numbers = all(isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x) and x >= 0
                  for x in (spec, shine))
    if kind not in MATERIAL_KINDS or not numbers:
        state.warn(f"materials[{i}].extras.facepuppet: expected a kind of {sorted(MATERIAL_KINDS)} and "
                   f"finite specular/shininess >= 0, got {ours!r}; read as skin")
        return skin
    return [float(spec), float(shine), float(MATERIAL_KINDS[kind]), 0.0]


def _look_rows(state: ReadState, default_material: int | None) -> dict[int, int]:
    """The core glTF look of each material (base colour, emissive, alpha mode, double-sided, base colour
    texture) into ``state.look``; returns {glTF texture index: stored texture index} of the textures used."""
    f, geo = state.f, state.geo
    if default_material is not None:
        geo["triangle_material"][geo["triangle_material"] == -1] = default_material
        p = geo["primitives"]
        p[p[:, 5] == -1, 5] = default_material
    mats = f.items("materials")
    n_m = len(state.material_names)
    rows = LookRows(base=np.ones((n_m, 4)), emissive=np.zeros((n_m, 3)),
                    alpha=np.tile([ALPHA_MODES["OPAQUE"], 0.5], (n_m, 1)), shading=np.zeros((n_m, 8)),
                    texture=np.full(n_m, -1, dtype=np.int64), uv_transform=np.tile(IDENTITY_UV_TRANSFORM, (n_m, 1)))
    textures: dict[int, int] = {}  # glTF texture index -> stored texture index
    for i, m in enumerate(mats):
        w = f"materials[{i}]"
        pbr = f.get(m, "pbrMetallicRoughness", dict, w, {})
        rows.base[i] = f.numbers(pbr, "baseColorFactor", 4, f"{w}.pbrMetallicRoughness", [1, 1, 1, 1])
        rows.emissive[i] = f.numbers(m, "emissiveFactor", 3, w, [0, 0, 0])
        mode = f.get(m, "alphaMode", str, w, "OPAQUE")
        if mode not in ALPHA_MODES:
            f.fail(f"{w}.alphaMode", f"{mode!r} is not OPAQUE, MASK or BLEND")
        cutoff = f.get(m, "alphaCutoff", float, w, 0.5)
        rows.alpha[i] = (ALPHA_MODES[mode], cutoff)
        rows.shading[i, 1] = 1.0 if f.get(m, "doubleSided", bool, w, False) else 0.0
        if "baseColorTexture" in pbr:
            info = f.get(pbr, "baseColorTexture", dict, f"{w}.pbrMetallicRoughness")
            tw = f"{w}.pbrMetallicRoughness.baseColorTexture"
            t = f.get(info, "index", int, tw)
            f.obj("textures", t, f"{tw}.index")
            if f.get(info, "texCoord", int, tw, 0) != 0:
                state.warn(f"{tw}.texCoord: TEXCOORD_{info['texCoord']} asked for; only TEXCOORD_0 is read")
            if t not in textures:
                textures[t] = len(textures)
            rows.texture[i] = textures[t]
    state.look = rows
    return textures


def _textures(state: ReadState, textures: dict[int, int]) -> None:
    """Decode the used textures' images (PNG or JPEG, Pillow) and samplers into ``state.texture_*``.

    Every used image's size is read from its header first, and the sizes checked against
    :data:`MAX_TEXTURE_SIDE` and :data:`MAX_TEXTURE_TEXELS`, before any image is decoded; then each is
    decoded straight into its rows of the one texel array."""
    f = state.f
    used = [_texture(state, t) for t, _stored in sorted(textures.items(), key=lambda kv: kv[1])]
    total = 0
    for u in used:
        if u.width > MAX_TEXTURE_SIDE or u.height > MAX_TEXTURE_SIDE:
            f.fail(u.where, f"{u.width}x{u.height} texels: larger than {MAX_TEXTURE_SIDE}x{MAX_TEXTURE_SIDE}")
        total += u.width * u.height
        if total > MAX_TEXTURE_TEXELS:
            f.fail(u.where, f"{u.width}x{u.height} texels bring the used textures to {total} texels, more than "
                            f"the {MAX_TEXTURE_TEXELS} read ({MAX_TEXTURE_TEXELS * 4 >> 20} MiB of RGBA)")
    pixels = np.empty((total, 4), np.uint8)
    names, info = [], []
    first = 0
    unique = UniqueNames()
    for u in used:
        n = u.width * u.height
        _decode_into(state, u, pixels[first:first + n])
        names.append(unique.take(u.image.get("name") if isinstance(u.image.get("name"), str) and u.image["name"]
                                 else f"image{u.source}"))
        info.append([first, u.width, u.height, *u.sampler])
        first += n
    state.texture_names = tuple(names)
    state.texture_info = np.asarray(info, dtype=np.int32).reshape(-1, 7)
    state.texture_pixels = pixels


@dataclass(frozen=True)
class _UsedTexture:
    """A used texture: its image (index, JSON, path) with the size its header gives, and its sampler codes."""

    source: int
    image: dict
    where: str
    width: int
    height: int
    sampler: tuple[int, int, int, int]


def _texture(state: ReadState, t: int) -> _UsedTexture:
    """Texture ``t``: its image's size from the image's header (nothing decoded) and its sampler."""
    f = state.f
    tex = f.obj("textures", t, f"textures[{t}]")
    w = f"textures[{t}]"
    src = f.get(tex, "source", int, w, None)
    if src is None:
        f.fail(f"{w}.source", "missing: the texture has no PNG/JPEG image (KHR_texture_basisu and other "
                              "image extensions are not read)")
    img = f.obj("images", src, f"{w}.source")
    iw = f"images[{src}]"
    sampler = (0, 0, 0, 0)
    if "sampler" in tex:
        s_i = f.get(tex, "sampler", int, w)
        s = f.obj("samplers", s_i, f"{w}.sampler")
        codes = []
        for k, allowed in (("magFilter", _MAG), ("minFilter", _MIN), ("wrapS", _WRAP), ("wrapT", _WRAP)):
            v = f.get(s, k, int, f"samplers[{s_i}]", 0)
            if v and v not in allowed:
                f.fail(f"samplers[{s_i}].{k}", f"{v} is not one of {sorted(allowed)}")
            codes.append(v)
        sampler = tuple(codes)
    with _open_image(state, img, iw) as opened, _image(state, opened, img, iw) as im:
        width, height = im.size
    return _UsedTexture(src, img, iw, width, height, sampler)


def _decode_into(state: ReadState, u: _UsedTexture, out: np.ndarray) -> None:
    """Decode ``u``'s image as RGBA into ``out`` : ndarray (width * height, 4) uint8."""
    with _open_image(state, u.image, u.where) as opened, _image(state, opened, u.image, u.where) as im:
        if im.size != (u.width, u.height):  # the file changed between the two reads
            state.f.fail(u.where, f"{im.size[0]}x{im.size[1]} now, {u.width}x{u.height} when first read")
        try:
            with _warnings.catch_warnings():
                _warnings.simplefilter("error", Image.DecompressionBombWarning)
                rgba = im.convert("RGBA")
        except _DECODE_ERRORS as exc:
            state.f.fail(u.where, f"the image cannot be decoded ({str(exc)[:120]})")
        out[:] = np.asarray(rgba, dtype=np.uint8).reshape(-1, 4)
        rgba.close()


def _open_image(state: ReadState, img: dict, iw: str) -> Opened:
    """The bytes of image ``iw``: its buffer view, or its URI through :mod:`..gltf_files`."""
    f = state.f
    if "bufferView" in img:
        data, start, length, _ = f.view_bytes(f.get(img, "bufferView", int, iw), f"{iw}.bufferView")
        return Opened(io.BytesIO(data[start:start + length]), length, None, f"{iw}.bufferView")
    if "uri" in img:
        return f.open_image(f.get(img, "uri", str, iw), f"{iw}.uri")
    f.fail(iw, "missing: an image needs a uri or a bufferView")


@contextmanager
def _image(state: ReadState, opened: Opened, img: dict, iw: str) -> Iterator[Image.Image]:
    """The PNG or JPEG image of ``opened``, opened lazily by Pillow: only its header is read."""
    f = state.f
    if not _png_or_jpeg(opened.handle):
        f.fail(iw, f"not a PNG or JPEG image (mimeType {img.get('mimeType')!r}); only those are decoded")
    try:
        with _warnings.catch_warnings():
            _warnings.simplefilter("error", Image.DecompressionBombWarning)
            im = Image.open(opened.handle, formats=("PNG", "JPEG"))
    except _DECODE_ERRORS as exc:
        f.fail(iw, f"the image cannot be decoded ({str(exc)[:120]})")
    with im:
        yield im


_DECODE_ERRORS = (UnidentifiedImageError, OSError, ValueError, SyntaxError, EOFError, Image.DecompressionBombWarning,
                  Image.DecompressionBombError)


def image_size(handle: BinaryIO) -> tuple[int, int] | None:
    """(width, height) of a PNG or JPEG from its header (Pillow opens lazily: nothing is decoded); None when it
    is neither or its header is broken."""
    if not _png_or_jpeg(handle):
        return None
    try:
        with _warnings.catch_warnings():
            _warnings.simplefilter("ignore")  # a decompression-bomb warning: the size is what is checked here
            with Image.open(handle, formats=("PNG", "JPEG")) as im:
                return im.size
    except _DECODE_ERRORS:
        return None


def _png_or_jpeg(handle: BinaryIO) -> bool:
    """Whether ``handle`` starts with the PNG or JPEG signature (read, then rewound)."""
    head = handle.read(8)
    handle.seek(0)
    return head == b"\x89PNG\r\n\x1a\n" or head[:3] == b"\xff\xd8\xff"
