"""``facepuppet export-character`` (a character back out as VRM / GLB / glTF) and ``facepuppet check-gltf``."""

from __future__ import annotations

import argparse
from pathlib import Path

from facepuppet.runtime.cli.progress import Progress
from facepuppet.runtime.errors import FacepuppetError
from facepuppet.runtime.model.character import Character

from facepuppet.offline.io.gltf.write import describe, export_character
from facepuppet.offline.io.gltf_check import check_gltf


class GltfProblems(FacepuppetError, ValueError):
    """``check-gltf`` found structural problems (the command exits 2 after listing them)."""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``export-character`` and ``check-gltf`` to the ``facepuppet`` parser."""
    p = subparsers.add_parser(
        "export-character", help="character table -> VRM 0.x/1.0, GLB or glTF (meshes, skin, textures, morphs)",
        description="Write a character table as a VRM (.vrm: the version it came from, or --vrm), a GLB (.glb) or "
                    "a glTF with an embedded buffer (.gltf): meshes, skin, textures, materials, morph targets "
                    "with their names, VRM meta, humanoid and expressions (a custom expression for each shape "
                    "with an ARKit name, for perfect sync), and what the imported file had beyond them: spring "
                    "bones and colliders, look-at, first person, MToon outline and rim, binds on materials, "
                    "thumbnail, metal/roughness and other textures, converted when the VRM version changes. "
                    "Toon materials fall back to KHR_materials_unlit for plain glTF viewers. The file passes "
                    "check-gltf.")
    p.add_argument("character", type=Path, help="character table (.npz)")
    p.add_argument("-o", "--output", type=Path, required=True, help="file to write: .vrm, .glb or .gltf")
    p.add_argument("--vrm", type=int, choices=(0, 1), help="VRM version of a .vrm output (default: as it came; "
                                                           "0 for a character that was not a VRM)")
    p.set_defaults(func=_export)

    c = subparsers.add_parser(
        "check-gltf", help="structural validity check of a glTF/GLB/VRM file (why an application refuses it)",
        description="Check a .gltf/.glb/.vrm against the glTF 2.0 specification's structural rules (GLB chunks "
                    "and alignment, required fields, buffer view and accessor ranges, POSITION min/max, index "
                    "range, morph target counts, skin joints, texture and VRM references). Prints each problem; "
                    "exit 0 when there is none, 2 when there are.")
    c.add_argument("file", type=Path, help="a .gltf, .glb or .vrm file")
    c.set_defaults(func=_check)


def _export(args: argparse.Namespace) -> int:
    character = Character.load(args.character)
    # a progress line for big characters (drawn only on a terminal, as every command's)
    bar = Progress("export-character", unit="primitives", enabled=None if character.n_vertices > 20000 else False)

    with bar:
        summary = export_character(character, args.output, vrm=args.vrm, progress=bar.step)
    print(describe(summary))
    problems = check_gltf(args.output)
    if problems:  # a bug of the exporter, not of the input: say so plainly, keep the file for a report
        raise GltfProblems(f"{args.output}: written, but check-gltf finds {len(problems)} problems (a bug): "
                           + "; ".join(problems[:5]))
    if character.credits:
        print(f"  credits: {character.credits}")
    return 0


def _check(args: argparse.Namespace) -> int:
    problems = check_gltf(args.file)
    for p in problems:
        print(f"{args.file}: {p}")
    if problems:
        raise GltfProblems(f"{args.file}: {len(problems)} structural problem{'s' if len(problems) > 1 else ''} "
                           "(listed above)")
    print(f"{args.file}: no structural problem found")
    return 0
