"""VRM meta (title, authors, licence, permissions): read with the credits line, written as 0.x or 1.0.

VRM 0.x and 1.0 name the same facts differently (``title`` / ``name``,
``author`` / ``authors``, ``allowedUserName`` / ``avatarPermission``, …). The
character keeps the meta as its file had it (``settings.source.meta``); on
export it is written as it came when the version stays, and converted field
by field when it changes (a 0.x licence name, which 1.0 has no field for,
goes into ``otherLicenseUrl`` or ``copyrightInformation``). A character from
a plain glTF gets its title, author and licence from the asset's.
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


def write_meta0(w: WriteState, raw: dict, vrm: dict[str, Any]) -> None:
    """VRM 0.x ``meta``: kept as read from a VRM 0.x, converted from a VRM 1.0's names, else from the glTF asset's."""
    src = w.c.source
    meta = src.get("meta") if isinstance(src.get("meta"), dict) else {}
    fmt = src.get("format")
    if fmt == "vrm0":
        out = {k: v for k, v in meta.items() if k != "texture"}  # the thumbnail's texture is not kept
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
               == "personalNonProfit" else "Allow",
               "licenseName": "Other", "otherLicenseUrl": meta.get("licenseUrl", "")}
    else:
        out = {"title": meta.get("title", w.c.name), "author": meta.get("author", ""),
               "licenseName": "Other", "otherLicenseUrl": meta.get("license", ""),
               "allowedUserName": "OnlyAuthor", "violentUssageName": "Disallow",
               "sexualUssageName": "Disallow", "commercialUssageName": "Disallow"}
    vrm["meta"] = out


def write_meta1(w: WriteState, raw: dict, vrm: dict[str, Any]) -> None:
    """VRM 1.0 ``meta``: kept as read from a VRM 1.0, converted from a VRM 0.x's names, else from the glTF asset's;
    VRM 1.0 requires an author (written as 'unknown', with a warning, when none is known)."""
    src = w.c.source
    meta = src.get("meta") if isinstance(src.get("meta"), dict) else {}
    fmt = src.get("format")
    if fmt == "vrm1":
        out = {k: v for k, v in meta.items() if k != "thumbnailImage"}  # the thumbnail's image is not kept
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
               "licenseUrl": "https://vrm.dev/licenses/1.0/"}
        licence = " ".join(str(meta.get(k, "")) for k in ("licenseName", "otherLicenseUrl")).strip()
        if licence:
            out["otherLicenseUrl" if meta.get("otherLicenseUrl") else "copyrightInformation"] = \
                meta.get("otherLicenseUrl") or f"licence: {licence}"
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
    vrm["meta"] = out
