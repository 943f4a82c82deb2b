"""What kind of mesh file a path holds, from its first bytes: so a refusal can name the format found.

``import-rig`` reads Wavefront OBJ only. A glTF, FBX, PLY, STL, Collada or
USD file handed to it would otherwise fail deep in the OBJ reader ("no
vertices"); :func:`refuse_non_obj` says what the file is instead, and what is
accepted.
"""

from __future__ import annotations

import os
from pathlib import Path

from facepuppet.runtime.errors import InputFileError

ACCEPTED = "Wavefront OBJ (text 'v'/'f' lines; a neutral .obj and a folder of shape .obj files, same vertex order)"


def sniff_mesh_format(path: str | os.PathLike) -> str | None:
    """A name for the format of ``path`` when its first bytes show one that is not OBJ, else None."""
    with open(path, "rb") as f:
        head = f.read(4096)
    if head.startswith(b"glTF"):
        return "glTF binary (.glb/.vrm)"
    if head.startswith(b"Kaydara FBX Binary"):
        return "FBX (binary)"
    if head.startswith(b"PXR-USDC"):
        return "USD (binary crate)"
    if head.startswith(b"PK\x03\x04"):
        return "a ZIP archive (e.g. USDZ or a zipped export)"
    text = head.lstrip(b"\xef\xbb\xbf \t\r\n")
    if text.startswith(b"{") and (b'"asset"' in head or b'"meshes"' in head or b'"accessors"' in head):
        return "glTF JSON (.gltf)"
    if text.startswith(b"; FBX"):
        return "FBX (ASCII)"
    if text.startswith(b"ply\n") or text.startswith(b"ply\r\n"):
        return "PLY"
    if text.startswith(b"#usda"):
        return "USD (ASCII)"
    if text.startswith(b"<?xml") and b"COLLADA" in head:
        return "Collada (.dae)"
    if text.startswith(b"solid ") and b"facet" in head:
        return "STL (ASCII)"
    return None


def refuse_non_obj(path: str | os.PathLike, role: str = "mesh") -> None:
    """Raise ValueError naming the format found when ``path`` is a known non-OBJ mesh format."""
    found = sniff_mesh_format(path)
    if found is not None:
        raise InputFileError(f"{Path(path)}: {role} is a {found} file, not an OBJ; import-rig reads {ACCEPTED}. "
                             "Export the rig as OBJ (one file per shape)")
