"""What a file has that no reader turns into the character's own, kept raw so that an export loses nothing.

The character draws from its look rows; a file says more than they hold: a
material's metal/roughness, normal, occlusion and emissive textures, its
MToon outline, rim, matcap and UV animation (VRM 1.0 ``VRMC_materials_mtoon``;
VRM 0.x keeps them in ``materialProperties``, inside the VRM extension the
character already keeps), VRM 1.0's ``VRMC_springBone`` (a top-level
extension of its own), and the thumbnail. These are kept as the file wrote
them in ``settings.source.kept``: ``materials`` (each file material's JSON),
``spring_bone``, and the textures they name: ``textures`` gives each named
file texture as ``[file texture, "look", stored texture]`` when the look
already holds it (a base colour texture), else ``[file texture, "image",
file image, sampler codes]``; ``images`` holds the bytes of each such file
image as the file had them (PNG or JPEG, base64, never re-encoded), so the
export writes them back unchanged. The kept bytes are bounded by
:data:`MAX_KEPT_IMAGE_BYTES` (they live in the character's JSON manifest);
an image past it is dropped with a warning naming it.
"""

from __future__ import annotations

import base64
from typing import Any

from facepuppet.offline.io.gltf.read_state import ReadState, extensions_of
from facepuppet.offline.io.gltf.structure_limits import check_kept_json
from facepuppet.offline.io.gltf.write_state import WriteState

#: The texture-info fields of a core glTF material besides the base colour texture.
CORE_TEXTURES = ("normalTexture", "occlusionTexture", "emissiveTexture")
#: The texture-info fields of VRMC_materials_mtoon.
MTOON_TEXTURES = ("shadeMultiplyTexture", "shadingShiftTexture", "matcapTexture", "rimMultiplyTexture",
                  "outlineWidthMultiplyTexture", "uvAnimationMaskTexture")
#: The most bytes of images kept raw (base64 in the character's 4 MiB JSON manifest): a thumbnail and a few
#: small textures (Godette's thumbnail and metal/roughness map: 60 kB and 22 kB); 2048² normal maps do not fit.
MAX_KEPT_IMAGE_BYTES = 1_500_000
_SIGNATURES = {b"\x89PNG\r\n\x1a\n": "image/png", b"\xff\xd8\xff": "image/jpeg"}


def keep_parts(state: ReadState, look_textures: dict[int, int]) -> None:
    """``state.kept`` (see the module doc) once the look's textures (``look_textures``: {file texture: stored})
    are read."""
    f = state.f
    kept = state.kept
    mats = f.items("materials")
    named_textures: list[int] = []
    named_images: list[int] = []

    def want(key: Any, into: list[int]) -> None:
        if isinstance(key, int) and not isinstance(key, bool) and key >= 0 and key not in into:
            into.append(key)

    for i, m in enumerate(mats):
        if not isinstance(m, dict):
            continue
        check_kept_json(f, m, f"materials[{i}]")
        pbr = m.get("pbrMetallicRoughness") if isinstance(m.get("pbrMetallicRoughness"), dict) else {}
        infos = [pbr.get("metallicRoughnessTexture")] + [m.get(k) for k in CORE_TEXTURES]
        mt = extensions_of(m).get("VRMC_materials_mtoon")
        if isinstance(mt, dict):
            infos += [mt.get(k) for k in MTOON_TEXTURES]
        for info in infos:
            if isinstance(info, dict):
                want(info.get("index"), named_textures)
    kept["materials"] = [m if isinstance(m, dict) else {} for m in mats]
    if state.vrm0 is not None:
        props = state.vrm0.get("materialProperties")
        for p in props if isinstance(props, list) else []:
            tp = p.get("textureProperties") if isinstance(p, dict) else None
            for t in tp.values() if isinstance(tp, dict) else []:
                want(t, named_textures)
        meta = state.vrm0.get("meta")
        if isinstance(meta, dict):
            want(meta.get("texture"), named_textures)
    if state.vrm1 is not None:
        meta = state.vrm1.get("meta")
        if isinstance(meta, dict):
            want(meta.get("thumbnailImage"), named_images)
    spring = extensions_of(state.doc).get("VRMC_springBone")
    if isinstance(spring, dict):
        check_kept_json(f, spring, "extensions.VRMC_springBone")
        kept["spring_bone"] = spring
    budget = [MAX_KEPT_IMAGE_BYTES]
    images: dict[int, dict] = {}
    textures = []
    tex_list = f.items("textures")
    for t in sorted(named_textures):
        if t in look_textures:
            textures.append([t, "look", int(look_textures[t])])
            continue
        tex = tex_list[t] if t < len(tex_list) and isinstance(tex_list[t], dict) else None
        src = tex.get("source") if tex is not None else None
        if not (isinstance(src, int) and not isinstance(src, bool) and _image(state, src, images, budget)):
            continue
        textures.append([t, "image", src, _sampler(state, tex)])
    for i in named_images:
        _image(state, i, images, budget)
    kept["textures"] = textures
    kept["images"] = [images[i] for i in sorted(images)]


def _image(state: ReadState, i: int, images: dict[int, dict], budget: list[int]) -> bool:
    """Keep file image ``i``'s bytes in ``images`` (once); False when it cannot be kept (warned)."""
    if i in images:
        return True
    f = state.f
    img_list = f.items("images")
    img = img_list[i] if 0 <= i < len(img_list) and isinstance(img_list[i], dict) else None
    where = f"images[{i}]"
    if img is None:
        return False
    data = b""
    if isinstance(img.get("bufferView"), int):
        buf, start, length, _ = f.view_bytes(img["bufferView"], f"{where}.bufferView")
        if length <= budget[0]:
            data = bytes(buf[start:start + length])
    elif isinstance(img.get("uri"), str):
        with f.open_image(img["uri"], f"{where}.uri") as opened:
            if opened.size <= budget[0]:
                data = opened.handle.read(opened.size + 1)
    if not data or len(data) > budget[0]:
        state.warn(f"{where}: not kept for export (its bytes would pass the {MAX_KEPT_IMAGE_BYTES} kept; only "
                   "the look's base colour textures are kept whole)")
        return False
    mime = next((m for sig, m in _SIGNATURES.items() if data.startswith(sig)), None)
    if mime is None:
        state.warn(f"{where}: not a PNG or JPEG image; not kept for export")
        return False
    budget[0] -= len(data)
    name = img.get("name") if isinstance(img.get("name"), str) else ""
    images[i] = {"image": i, "name": name, "mimeType": mime, "data": base64.b64encode(data).decode("ascii")}
    return True


def _sampler(state: ReadState, tex: dict) -> list[int]:
    """The texture's sampler as [magFilter, minFilter, wrapS, wrapT] codes (0: unset), as the file has them."""
    samplers = state.f.items("samplers")
    s = tex.get("sampler")
    smp = samplers[s] if isinstance(s, int) and not isinstance(s, bool) and 0 <= s < len(samplers) else None
    if not isinstance(smp, dict):
        return [0, 0, 0, 0]
    return [v if isinstance(v, int) and not isinstance(v, bool) else 0
            for v in (smp.get(k) for k in ("magFilter", "minFilter", "wrapS", "wrapT"))]


def kept(source: dict, key: str, default: Any) -> Any:
    """``source.kept[key]`` when the character kept it with the expected type, else ``default``."""
    k = source.get("kept")
    v = k.get(key) if isinstance(k, dict) else None
    return v if isinstance(v, type(default)) else default


def write_kept_textures(w: WriteState, images: list[dict], textures: list[dict], samplers: list[dict],
                        sampler_of: dict[tuple, int]) -> None:
    """Append the images and textures kept raw (after the look's, texture i = image i there), and record where
    each file texture and image went (``w.file_texture``, ``w.file_image``): a file texture the look holds is
    the written texture of its stored one."""
    n_look = len(textures)
    entries = [e for e in kept(w.c.source, "textures", []) if isinstance(e, list) and len(e) >= 3
               and isinstance(e[0], int) and isinstance(e[2], int)]
    for t, kind, ref, *_ in entries:
        if kind == "look" and 0 <= ref < n_look:
            w.file_texture[int(t)] = ref
    for entry in kept(w.c.source, "images", []):
        try:
            data = base64.b64decode(entry["data"], validate=True)
        except (KeyError, TypeError, ValueError):
            w.warn(f"settings.source.kept.images: {str(entry)[:60]!r} is not an image entry; skipped")
            continue
        w.file_image[int(entry.get("image", -1))] = len(images)
        image = {"mimeType": entry.get("mimeType", "image/png"), "bufferView": w.buf.view(data)}
        if entry.get("name"):
            image["name"] = entry["name"]
        images.append(image)
    for t, kind, ref, *rest in entries:
        if kind != "image" or ref not in w.file_image:
            continue
        codes = tuple(int(x) for x in (rest[0] if rest and isinstance(rest[0], list) else [0, 0, 0, 0]))
        if codes not in sampler_of:
            sampler_of[codes] = len(samplers)
            samplers.append({k: v for k, v in zip(("magFilter", "minFilter", "wrapS", "wrapT"), codes) if v})
        w.file_texture[int(t)] = len(textures)
        textures.append({"source": w.file_image[ref], "sampler": sampler_of[codes]})


def kept_texture_info(w: WriteState, info: Any) -> dict | None:
    """A file's texture info (``{"index": file texture, ...}``) onto the written textures; None when it names
    no texture that was written."""
    if not isinstance(info, dict) or not isinstance(info.get("index"), int) or info["index"] not in w.file_texture:
        return None
    out = {k: v for k, v in info.items() if k in ("texCoord", "scale", "strength", "extensions")}
    out["index"] = w.file_texture[info["index"]]
    return out


def kept_material(w: WriteState, i: int) -> dict:
    """The file's JSON of stored material ``i`` when the character still has that material (same index and
    name: a character changed after import keeps only what still matches), else {}."""
    mats = kept(w.c.source, "materials", [])
    raw = mats[i] if i < len(mats) and isinstance(mats[i], dict) else {}
    name = raw.get("name") if isinstance(raw.get("name"), str) and raw.get("name") else f"material{i}"
    return raw if i < len(w.c.material_names) and w.c.material_names[i] == name else {}
