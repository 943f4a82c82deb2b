"""Offline subcommands of ``facepuppet``, registered through an entry point."""

from __future__ import annotations

import argparse
import importlib
import time
from collections.abc import Callable
from pathlib import Path

from facepuppet.runtime.cli.progress import Progress
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.model.character import MATERIAL_KINDS, Character
from facepuppet.runtime.model.springs import springs_of

from facepuppet.offline.io import capture_replay
from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.io.gltf_container import is_gltf_file
from facepuppet.offline.io.rig_import import import_rig

# Offline modules with their own ``register(subparsers)``; each must exist and import
# (a missing one is an error, never a silently dropped command).
_COMMAND_MODULES = ("facepuppet.offline.actuation.commands", "facepuppet.offline.elastic.commands",
                    "facepuppet.offline.gestures.commands", "facepuppet.offline.kpls.commands",
                    "facepuppet.offline.io.gltf_commands", "facepuppet.offline.perfect_sync.commands",
                    "facepuppet.offline.batch.commands", "facepuppet.offline.batch.golden_report")
# Offline modules with ``register_benches(register_bench)``, same rule.
_BENCH_MODULES = ("facepuppet.offline.actuation.bench", "facepuppet.offline.elastic.bench",
                  "facepuppet.offline.gestures.bench", "facepuppet.offline.kpls.bench",
                  "facepuppet.offline.io.gltf_bench", "facepuppet.offline.io.gltf_bombs_bench",
                  "facepuppet.offline.perfect_sync.bench", "facepuppet.offline.gpu_bench",
                  "facepuppet.offline.replay_bench", "facepuppet.offline.batch.bench")


def _modules(names):
    for name in names:
        yield importlib.import_module(name)


def register_benches(register_bench: Callable[..., None]) -> None:
    """Entry point of the ``facepuppet.benches`` group: add the offline benchmarks."""
    for module in _modules(_BENCH_MODULES):
        module.register_benches(register_bench)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the offline commands to the ``facepuppet`` parser (and let ``replay`` read marker captures)."""
    capture_replay.register()
    _register_import_rig(subparsers)
    for module in _modules(_COMMAND_MODULES):
        module.register(subparsers)


def _register_import_rig(subparsers) -> None:
    p = subparsers.add_parser(
        "import-rig",
        help="blendshape rig (neutral OBJ + folder of shape OBJs, or a glTF/GLB/VRM avatar) -> character table",
        description="Import a neutral OBJ and a folder of OBJ shapes with the same vertex order "
        "as a character table (.npz): triangulated mesh, materials, sparse float32 deltas. "
        "Or import a glTF 2.0 / GLB / VRM 0.x / VRM 1.0 avatar (the format is found from the file: GLB magic, "
        "else JSON): meshes, skin, morph targets, materials and textures, VRM expressions, humanoid and meta.",
    )
    p.add_argument("neutral", type=Path, help="neutral mesh OBJ, or a .gltf/.glb/.vrm file")
    p.add_argument("shapes_dir", type=Path, nargs="?",
                   help="folder of shape OBJs (the neutral is skipped if inside); none: a character without "
                        "shapes. Not given for glTF/VRM")
    p.add_argument("-o", "--output", type=Path, required=True, help="character table to write (.npz)")
    p.add_argument("--units", choices=("cm", "mm", "m"), default="cm", help="units of the OBJ files (default cm)")
    p.add_argument("--name", help="character name (default: the neutral's folder name)")
    p.add_argument(
        "--tolerance", type=float, default=1e-5, help="smallest stored vertex displacement, in units (default 1e-5)"
    )
    p.add_argument("--landmarks", type=Path, help="ICT vertex_indices.json (default: the one beside the neutral)")
    p.add_argument("--forward", choices=("+z", "-z", "+x", "-x"), default="+z",
                   help="the axis the OBJ's face looks along, Y up (default +z; write --forward=-z); it is "
                        "turned to face +Z, its shapes with it")
    p.set_defaults(func=_import_rig)


def _import_rig(args: argparse.Namespace) -> int:
    if is_gltf_file(args.neutral):   # by its name, or the bytes of a regular file
        return _import_gltf(args)
    start = time.perf_counter()
    bar = Progress("import-rig", unit="shapes")

    with bar:
        character = import_rig(
            args.neutral,
            args.shapes_dir,
            tolerance=args.tolerance,
            name=args.name,
            units=args.units,
            landmarks=args.landmarks,
            forward=args.forward,
            progress=bar.step,
        )
    out = character.save(args.output)
    seconds = time.perf_counter() - start
    metrics = character.metadata["metrics"]
    kind_names = {code: kind for kind, code in MATERIAL_KINDS.items()}
    kinds = ", ".join(
        f"{m} ({kind_names[int(p[2])]})" for m, p in zip(character.material_names, character.material_params)
    )
    stored, dense = metrics["stored_deltas"], metrics["dense_deltas"]
    print(
        f"{out}: character '{character.name}', {character.n_vertices} vertices, "
        f"{len(character.triangles)} triangles, {character.units}\n"
        f"  materials ({len(character.material_names)}): {kinds}\n"
        f"  shapes: {character.n_shapes}; stored deltas {stored} of {dense} dense "
        f"({100.0 * stored / max(dense, 1):.1f}%)\n"
        f"  file {out.stat().st_size / 1e6:.2f} MB, {seconds:.2f} s"
    )
    if character.n_shapes == 0:
        print("  note: no expression shapes (no shapes folder given): this character can be drawn but not driven "
              "by weights or an actor; give its folder of shape OBJs to drive it")
    return 0


def _import_gltf(args: argparse.Namespace) -> int:
    if args.shapes_dir is not None:
        raise UsageError(f"{args.shapes_dir}: a glTF/VRM file carries its own morph targets; give no shapes folder")
    for flag, value, default in (("--units", args.units, "cm"), ("--landmarks", args.landmarks, None),
                                 ("--forward", args.forward, "+z")):
        if value != default:
            raise UsageError(f"{flag}: not used for glTF/VRM (glTF is in metres and faces +Z, VRM 0.x is turned "
                             "on import; landmarks are ICT's)")
    start = time.perf_counter()
    bar = Progress("import-rig", unit="meshes")

    with bar:
        character = read_gltf(args.neutral, name=args.name, progress=bar.step)
    out = character.save(args.output)
    _print_gltf_summary(character, time.perf_counter() - start, out)
    return 0


def _print_gltf_summary(character: Character, seconds: float, out: Path) -> None:
    """The import summary of a glTF/VRM character: sizes, humanoid head and neck, VRM meta, credits, the reader's
    warnings."""
    src = character.source
    m = character.metadata.get("metrics", {})
    bones = character.skeleton.bones if character.skeleton is not None else {}
    head = "head" + ("" if "head" in bones else " (not found)")
    neck = "neck" + ("" if "neck" in bones else " (not found)")
    print(f"{out}: character '{character.name}' from {src.get('format')} {src.get('file')}: "
          f"{character.n_vertices} vertices, {len(character.triangles)} triangles, "
          f"{m.get('n_meshes')} meshes / {m.get('n_primitives')} primitives, metres"
          f"{', turned 180° about +Y (VRM 0.x faces -Z)' if src.get('turned_y180') else ''}\n"
          f"  shapes: {character.n_shapes}; expressions: {character.n_expressions}; "
          f"nodes: {m.get('n_nodes')} ({m.get('n_joints')} joints used); textures: {m.get('n_textures')}; "
          f"humanoid {head}, {neck}")
    meta = src.get("meta") or {}
    if src.get("format") in ("vrm0", "vrm1"):
        keys = (("title", "version", "author", "licenseName", "allowedUserName", "commercialUssageName",
                 "violentUssageName", "sexualUssageName") if src.get("format") == "vrm0" else
                ("name", "version", "authors", "licenseUrl", "avatarPermission", "commercialUsage",
                 "allowExcessivelyViolentUsage", "allowExcessivelySexualUsage", "allowRedistribution"))
        shown = ", ".join(f"{k}={meta[k]}" for k in keys if k in meta)
        print(f"  VRM meta: {shown}")
    if character.credits:
        print(f"  credits: {character.credits}")
    rig = springs_of(character)
    if rig is not None:
        print(f"  spring bones: {len(rig.chain_names)} chains, {rig.n_joints} joints, {rig.n_colliders} colliders")
        for line in rig.describe(character.skeleton.names):
            print(f"    {line}")
    look = character.metadata.get("settings", {}).get("look_at")
    if look:
        eyes = [k for k in ("left_eye", "right_eye") if look.get(k, -1) >= 0]
        print(f"  look-at: {look['type']}" + (f" (eye bones: {', '.join(eyes)})" if look["type"] == "bone" else ""))
    for line in src.get("warnings", []):
        print(f"  warning: {line}")
    print(f"  file {out.stat().st_size / 1e6:.2f} MB, {seconds:.2f} s")
