"""VRM meta (title, authors, licence, permissions): read with the credits line, written as 0.x or 1.0.

VRM 0.x and 1.0 name the same facts differently (``title`` / ``name``,
``author`` / ``authors``, ``allowedUserName`` / ``avatarPermission``, …). The
character keeps the meta as its file had it (``settings.source.meta``); on
export it is written as it came when the version stays, and converted field
by field when it changes, as the VRM migration does: a 0.x licence name
sets 1.0's redistribution, modification, credit and commercial fields one by
one (:data:`LICENCES`; the CC deed goes in ``otherLicenseUrl``), and a 1.0
meta whose fields are those of a CC licence (or whose ``otherLicenseUrl`` is
its deed) goes back as that name, one that forbids redistribution as
``Redistribution_Prohibited``, any other as ``Other`` with its URL. The
thumbnail (0.x a texture, 1.0 an image) goes back onto the written texture or
image when the reader kept its bytes. A character from a plain glTF gets its
title, author and licence from the asset's.
"""

from __future__ import annotations

from typing import Any

from facepuppet.offline.io.gltf.credits import credit_line, text
from facepuppet.offline.io.gltf.read_state import ReadState
from facepuppet.offline.io.gltf.write_state import WriteState


def read_meta(state: ReadState) -> None:
    """``state.meta`` and ``state.credits`` of a VRM: its ``meta`` object as it is, and the line of attribution
    from its title, author(s), reference and licence (nothing for a plain glTF: the core reader took the
    asset's)."""
    if state.vrm1 is not None:
        meta = state.vrm1.get("meta", {})
    elif state.vrm0 is not None:
        meta = state.vrm0.get("meta", {})
    else:
        return
    meta = meta if isinstance(meta, dict) else {}
    state.meta = meta
    if state.vrm1 is not None:
        authors = meta.get("authors")
        author = ", ".join(a for a in authors if isinstance(a, str)) if isinstance(authors, list) else ""
        state.credits = credit_line(text(meta, "name"), author, text(meta, "licenseUrl"),
                                    text(meta, "copyrightInformation"))
    else:
        licence = text(meta, "licenseName").replace("_", " ")  # CC_BY -> "CC BY" (VRM 0.x names carry no version)
        if licence in ("Other", "Redistribution Prohibited") and text(meta, "otherLicenseUrl"):
            licence = f"{licence} ({text(meta, 'otherLicenseUrl')})"
        state.credits = credit_line(text(meta, "title"), text(meta, "author"), licence, text(meta, "reference"))


#: VRM 0.x licence name -> VRM 1.0 (allowRedistribution, modification, creditNotation, non-commercial only,
#: the licence's deed)
LICENCES: dict[str, tuple[bool, str, str, bool, str]] = {
    "CC0": (True, "allowModificationRedistribution", "unnecessary", False,
            "https://creativecommons.org/publicdomain/zero/1.0/"),
    "CC_BY": (True, "allowModificationRedistribution", "required", False,
              "https://creativecommons.org/licenses/by/4.0/"),
    "CC_BY_NC": (True, "allowModificationRedistribution", "required", True,
                 "https://creativecommons.org/licenses/by-nc/4.0/"),
    "CC_BY_SA": (True, "allowModificationRedistribution", "required", False,
                 "https://creativecommons.org/licenses/by-sa/4.0/"),
    "CC_BY_NC_SA": (True, "allowModificationRedistribution", "required", True,
                    "https://creativecommons.org/licenses/by-nc-sa/4.0/"),
    "CC_BY_ND": (True, "prohibited", "required", False, "https://creativecommons.org/licenses/by-nd/4.0/"),
    "CC_BY_NC_ND": (True, "prohibited", "required", True, "https://creativecommons.org/licenses/by-nc-nd/4.0/"),
    "Redistribution_Prohibited": (False, "prohibited", "required", False, ""),
    "Other": (False, "prohibited", "required", False, ""),
}
_SHARE_ALIKE = ("CC_BY_SA", "CC_BY_NC_SA")


def _licence1(meta: dict) -> dict[str, Any]:
    """VRM 1.0's licence fields from a VRM 0.x meta's ``licenseName`` (and its URLs)."""
    name = meta.get("licenseName") if meta.get("licenseName") in LICENCES else "Other"
    redistribution, modification, credit, non_commercial, deed = LICENCES[name]
    out: dict[str, Any] = {"allowRedistribution": redistribution, "modification": modification,
                           "creditNotation": credit, "allowPoliticalOrReligiousUsage": False,
                           "allowAntisocialOrHateUsage": False}
    if non_commercial:
        out["commercialUsage"] = "personalNonProfit"
    url = deed or (meta.get("otherLicenseUrl") if isinstance(meta.get("otherLicenseUrl"), str) else "")
    if url:
        out["otherLicenseUrl"] = url
    if isinstance(meta.get("otherPermissionUrl"), str) and meta["otherPermissionUrl"]:
        out["copyrightInformation"] = f"other permissions: {meta['otherPermissionUrl']}"
    return out


def _licence0(meta: dict) -> dict[str, Any]:
    """VRM 0.x's ``licenseName`` (and ``otherLicenseUrl``) from a VRM 1.0 meta's licence fields."""
    other = meta.get("otherLicenseUrl") if isinstance(meta.get("otherLicenseUrl"), str) else ""
    for name, (_, _, _, _, deed) in LICENCES.items():
        if deed and other.rstrip("/") == deed.rstrip("/"):
            return {"licenseName": name, "otherLicenseUrl": ""}
    fields = (meta.get("allowRedistribution", False), meta.get("modification", "prohibited"),
              meta.get("creditNotation", "required"), meta.get("commercialUsage") == "personalNonProfit")
    for name in ("CC0", "CC_BY", "CC_BY_NC", "CC_BY_ND", "CC_BY_NC_ND"):  # share-alike is told by its deed only
        if LICENCES[name][:4] == fields:
            return {"licenseName": name, "otherLicenseUrl": ""}
    if not fields[0]:
        return {"licenseName": "Redistribution_Prohibited", "otherLicenseUrl": other}
    return {"licenseName": "Other", "otherLicenseUrl": other or str(meta.get("licenseUrl", ""))}


def _thumbnail_texture(w: WriteState, meta: dict, fmt: str) -> int | None:
    """The written texture of the kept thumbnail (adding a texture for a VRM 1.0's image), or None."""
    if fmt == "vrm0":
        t = meta.get("texture")
        return w.file_texture.get(t) if isinstance(t, int) else None
    image = meta.get("thumbnailImage")
    if not isinstance(image, int) or image not in w.file_image:
        return None
    for k, tex in enumerate(w.textures):
        if tex.get("source") == w.file_image[image]:
            return k
    w.textures.append({"source": w.file_image[image]})
    return len(w.textures) - 1


def _thumbnail_image(w: WriteState, meta: dict, fmt: str) -> int | None:
    """The written image of the kept thumbnail, or None."""
    if fmt == "vrm1":
        image = meta.get("thumbnailImage")
        return w.file_image.get(image) if isinstance(image, int) else None
    t = _thumbnail_texture(w, meta, fmt)
    return w.textures[t].get("source") if t is not None else None


def write_meta0(w: WriteState, raw: dict, vrm: dict[str, Any]) -> None:
    """VRM 0.x ``meta``: kept as read from a VRM 0.x, converted from a VRM 1.0's names, else from the glTF asset's."""
    src = w.c.source
    meta = src.get("meta") if isinstance(src.get("meta"), dict) else {}
    fmt = src.get("format")
    if fmt == "vrm0":
        out = {k: v for k, v in meta.items() if k != "texture"}
    elif fmt == "vrm1":
        authors = meta.get("authors") if isinstance(meta.get("authors"), list) else []
        refs = meta.get("references") if isinstance(meta.get("references"), list) else []
        perm = {"onlyAuthor": "OnlyAuthor", "onlySeparatelyLicensedPerson": "ExplicitlyLicensedPerson",
                "everyone": "Everyone"}
        out = {"title": meta.get("name", w.c.name), "version": meta.get("version", ""),
               "author": ", ".join(str(a) for a in authors),
               "contactInformation": meta.get("contactInformation", ""),
               "reference": ", ".join(str(r) for r in refs),
               "allowedUserName": perm.get(meta.get("avatarPermission"), "OnlyAuthor"),
               "violentUssageName": "Allow" if meta.get("allowExcessivelyViolentUsage") else "Disallow",
               "sexualUssageName": "Allow" if meta.get("allowExcessivelySexualUsage") else "Disallow",
               "commercialUssageName": "Disallow" if meta.get("commercialUsage", "personalNonProfit")
               == "personalNonProfit" else "Allow", **_licence0(meta)}
    else:
        out = {"title": meta.get("title", w.c.name), "author": meta.get("author", ""),
               "licenseName": "Other", "otherLicenseUrl": meta.get("license", ""),
               "allowedUserName": "OnlyAuthor", "violentUssageName": "Disallow",
               "sexualUssageName": "Disallow", "commercialUssageName": "Disallow"}
    thumb = _thumbnail_texture(w, meta, fmt) if fmt in ("vrm0", "vrm1") else None
    if thumb is not None:
        out["texture"] = thumb
    vrm["meta"] = out


def write_meta1(w: WriteState, raw: dict, vrm: dict[str, Any]) -> None:
    """VRM 1.0 ``meta``: kept as read from a VRM 1.0, converted from a VRM 0.x's names, else from the glTF asset's;
    VRM 1.0 requires an author (written as 'unknown', with a warning, when none is known)."""
    src = w.c.source
    meta = src.get("meta") if isinstance(src.get("meta"), dict) else {}
    fmt = src.get("format")
    if fmt == "vrm1":
        out = {k: v for k, v in meta.items() if k != "thumbnailImage"}
    elif fmt == "vrm0":
        perm = {"OnlyAuthor": "onlyAuthor", "ExplicitlyLicensedPerson": "onlySeparatelyLicensedPerson",
                "Everyone": "everyone"}
        out = {"name": meta.get("title") or w.c.name, "version": meta.get("version", ""),
               "authors": [meta["author"]] if meta.get("author") else [],
               "contactInformation": meta.get("contactInformation", ""),
               "references": [meta["reference"]] if meta.get("reference") else [],
               "avatarPermission": perm.get(meta.get("allowedUserName"), "onlyAuthor"),
               "allowExcessivelyViolentUsage": meta.get("violentUssageName") == "Allow",
               "allowExcessivelySexualUsage": meta.get("sexualUssageName") == "Allow",
               "commercialUsage": "corporation" if meta.get("commercialUssageName") == "Allow"
               else "personalNonProfit",
               "licenseUrl": "https://vrm.dev/licenses/1.0/", **_licence1(meta)}
    else:
        out = {"name": meta.get("title") or w.c.name,
               "authors": [meta["author"]] if meta.get("author") else [],
               "licenseUrl": "https://vrm.dev/licenses/1.0/"}
        if meta.get("license"):
            out["otherLicenseUrl"] = meta["license"]
    out.setdefault("name", w.c.name)
    if not out.get("authors"):
        out["authors"] = ["unknown"]  # required, one at least
        w.warn("meta: no author known; VRM 1.0 requires one, written as 'unknown'")
    out.setdefault("licenseUrl", "https://vrm.dev/licenses/1.0/")
    thumb = _thumbnail_image(w, meta, fmt) if fmt in ("vrm0", "vrm1") else None
    if thumb is not None:
        out["thumbnailImage"] = thumb
    vrm["meta"] = out
