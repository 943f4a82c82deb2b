"""``fit-elastic`` and ``clone-elastic``: the Yano & Harada (2009) elastic model from the command line."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from facepuppet.runtime.demo.head import build_demo_character
from facepuppet.runtime.demo.head_parts import EYE_XY, MOUTH_HALF_WIDTH, MOUTH_Y
from facepuppet.runtime.elastic.model import ElasticModel
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.files.outputs import OutputSet
from facepuppet.runtime.model.character import Character

from facepuppet.offline.elastic.basis import DEFAULT_FIXED_RATIO, DEFAULT_K
from facepuppet.offline.elastic.clone import character_with_shapes, clone_model, mesh_character
from facepuppet.offline.elastic.control_points import (
    ANCHOR_NAMES,
    MEDIAPIPE_ANCHORS,
    ControlPoints,
    anchor_positions,
    front_vertices,
    ict_control_points,
    propose_control_points,
    read_control_points,
    write_control_points,
)
from facepuppet.offline.elastic.laplacian import components
from facepuppet.offline.elastic.lip_line import MEDIAPIPE_INNER_LIPS, cut_lip_line, fix_inner_lips
from facepuppet.offline.elastic.params import build_model, fit_character
from facepuppet.offline.io.obj import read_obj
from facepuppet.offline.io.rig_import import read_ict_landmarks

# Anchor groups (control_points.ANCHOR_NAMES) by control-point name.
POINT_ANCHORS = {
    "eye_R": ("eye_outer_R", "eye_inner_R"), "eye_L": ("eye_inner_L", "eye_outer_L"), "nose_tip": ("nose_tip",),
    "mouth_corner_R": ("mouth_corner_R",), "mouth_corner_L": ("mouth_corner_L",),
}


def demo_anchors(character: Character) -> dict:
    """Anchor groups on the procedural demo head, from its construction constants."""
    v = character.vertices.astype(np.float64)
    front = main_front(character)

    def at(x, y):
        return (int(front[np.argmin(np.hypot(v[front, 0] - x, v[front, 1] - y))]),)

    nose = front[np.abs(v[front, 0]) < 0.3]
    return {
        "eye_R": at(-EYE_XY[0] - 1.0, EYE_XY[1]) + at(-EYE_XY[0] + 1.0, EYE_XY[1]),
        "eye_L": at(EYE_XY[0] - 1.0, EYE_XY[1]) + at(EYE_XY[0] + 1.0, EYE_XY[1]),
        "nose_tip": (int(nose[np.argmax(v[nose, 2])]),),
        "mouth_corner_R": at(-MOUTH_HALF_WIDTH, MOUTH_Y),
        "mouth_corner_L": at(MOUTH_HALF_WIDTH, MOUTH_Y),
    }


def main_front(character: Character) -> np.ndarray:
    """Front-facing vertices of the largest connected component (the skin)."""
    _, labels = components(character.n_vertices, character.triangles)
    main = np.flatnonzero(labels == np.bincount(labels).argmax())
    return np.intersect1d(front_vertices(character.vertices, character.triangles), main)


def load_target(spec: str) -> Character:
    """A target character: ``demo``, a character table (.npz) or a bare OBJ mesh."""
    if spec == "demo":
        return build_demo_character()
    path = Path(spec)
    if path.suffix.lower() == ".obj":
        mesh = read_obj(path)
        return mesh_character(mesh.vertices, mesh.triangles, path.stem)
    return Character.load(path)


def _fit(args: argparse.Namespace) -> int:
    character = load_target(str(args.character))
    if args.controls:
        points = read_control_points(args.controls, character.n_vertices)
    else:
        landmarks = args.landmarks or character.metadata.get("settings", {}).get("landmarks")
        if not landmarks:
            raise UsageError(f"fit-elastic: {args.character} has no landmarks: give --controls FILE or "
                             "--landmarks vertex_indices.json (the 68 landmarks of ICT-FaceKit)")
        marks = read_ict_landmarks(landmarks, character.n_vertices)
        points = ict_control_points(marks, character.vertices, character.triangles, main_front(character))
    model, basis, report = fit_character(character, points, k=args.k, fixed_ratio=args.fixed_ratio)
    with OutputSet() as outputs:        # both files, or neither
        model.save(outputs.path(args.output))
        if args.save_controls:
            write_control_points(outputs.path(args.save_controls), points)
    out = Path(args.output)
    print(f"{out}: {len(points.names)} control points, k={args.k}, basis {report['basis_seconds']:.2f} s; "
          f"relative error median {100 * report['median_relative']:.1f}% worst {100 * report['worst_relative']:.1f}% "
          f"(truncation adds {100 * report['truncation_added_median']:.2f}% median); "
          f"tables {report['ratio']:.1f}x smaller than dense deltas")
    if args.pictures:
        from facepuppet.runtime.render.gl_context import create_context  # GL: these import moderngl

        from facepuppet.offline.elastic.pictures import overlay, reconstruction_sheets

        args.pictures.mkdir(parents=True, exist_ok=True)
        ctx = create_context(headless=True).ctx
        for path in reconstruction_sheets(ctx, character, model, args.pictures):
            print(path)
        print(overlay(ctx, character, model, args.pictures / "controls_and_muscles.png"))
    return 0


def _clone_character_path(args: argparse.Namespace) -> Path:
    """clone-elastic's second output: the target character, beside -o as STEM_character.npz."""
    return Path(args.output).with_name(Path(args.output).stem + "_character.npz")


def _clone(args: argparse.Namespace) -> int:
    source = ElasticModel.load(args.elastic)
    target = load_target(str(args.target))
    slit = None
    if target.n_vertices == 468 and args.target.suffix.lower() == ".obj":  # the MediaPipe face: open its lip line
        slit = MEDIAPIPE_INNER_LIPS
        target = mesh_character(target.vertices, cut_lip_line(target.triangles, *slit), target.name, target.units)
    names = tuple(source.control_names)
    src_points = ControlPoints(names, source.arrays["control_vertices"])
    if args.correspondences and args.correspondences.exists():
        points = read_control_points(args.correspondences, target.n_vertices)
    elif target.n_vertices == source.n_vertices and args.target.suffix.lower() != ".obj":
        # the source's topology (a variant of the same rig: import-rig keeps the vertex order), so each
        # control point stays on its vertex
        points = src_points
        print(f"clone-elastic: {args.target} has the source's {target.n_vertices} vertices: taken as the same "
              "topology, each control point on the same vertex (give --correspondences FILE otherwise)")
        if args.correspondences:
            write_control_points(args.correspondences, points)
            print(f"{args.correspondences}: the correspondences used written")
    else:
        if args.target.suffix.lower() == ".obj":
            anchors = MEDIAPIPE_ANCHORS
        elif str(args.target) == "demo":
            anchors = demo_anchors(target)
        else:
            raise UsageError(f"clone-elastic: {args.target} has {target.n_vertices} vertices, not the source's "
                             f"{source.n_vertices}, and no proposal of correspondences for it is built in (the "
                             "MediaPipe face OBJ and 'demo' have one): give --correspondences FILE")
        src_pos = source.arrays["control_positions"].astype(np.float64)
        src_anchor = np.stack([src_pos[[src_points.index(n) for n in POINT_ANCHORS[a]]].mean(0) for a in ANCHOR_NAMES])
        points = propose_control_points(src_pos, src_anchor, target.vertices,
                                        anchor_positions(target.vertices, anchors), main_front(target), names)
        points = fix_inner_lips(points, target.vertices, target.triangles, main_front(target), slit)
        if args.correspondences:
            write_control_points(args.correspondences, points)
            print(f"{args.correspondences}: proposed correspondences written (check them)")

    def build(tgt_points, params, shape_names):
        return build_model(target.vertices, target.triangles, tgt_points, params, shape_names, k=args.k,
                           fixed_ratio=args.fixed_ratio, units=target.units)[0]

    model = clone_model(source, points, target.vertices, build)
    # The target character carries the cloned shapes as dense deltas too (so both paths draw it).
    basis_shapes = {}
    for s, name in enumerate(model.shape_names):
        w = np.zeros(len(model.shape_names), np.float32)
        w[s] = 1
        pos, _ = model.deform(model.blend(w), target.vertices, np.tile([0, 0, 1.0], (target.n_vertices, 1)))
        basis_shapes[name] = pos - target.vertices
    character = character_with_shapes(target, basis_shapes)
    out, char_out = Path(args.output), _clone_character_path(args)
    with OutputSet() as outputs:        # the elastic table and its character, or neither
        model.save(outputs.path(out))
        character.save(outputs.path(char_out))
    print(f"{out}: cloned {len(model.shape_names)} expressions onto {target.n_vertices} vertices; character {char_out}")
    if args.pictures:
        from facepuppet.runtime.render.gl_context import create_context  # GL: these import moderngl

        from facepuppet.offline.elastic.pictures import expression_sheet, overlay

        args.pictures.mkdir(parents=True, exist_ok=True)
        ctx = create_context(headless=True).ctx
        print(expression_sheet(ctx, character, model, model.channel_names, args.pictures / f"clone_{target.name}.png"))
        print(overlay(ctx, character, model, args.pictures / f"clone_{target.name}_controls.png"))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("fit-elastic", help="elastic control-point model (Yano & Harada 2009) of a character")
    p.add_argument("character", type=Path, help="character table (.npz) or 'demo'")
    p.add_argument("-o", "--output", type=Path, required=True, help="elastic tables to write (.npz)")
    p.add_argument("--controls", type=Path, help="control-point file (JSON); default: 47 points from --landmarks")
    p.add_argument("--landmarks", type=Path, help="ICT vertex_indices.json (default: the one the character names)")
    p.add_argument("--save-controls", type=Path, help="write the control points used (JSON)")
    p.add_argument("--k", type=int, default=DEFAULT_K, help=f"basis weights kept per vertex (default {DEFAULT_K})")
    p.add_argument("--fixed-ratio", type=float, default=DEFAULT_FIXED_RATIO,
                   help=f"fixed region beyond this many nose–forehead distances (default {DEFAULT_FIXED_RATIO})")
    p.add_argument("--pictures", type=Path, help="folder for original-vs-reconstruction sheets and the overlay")
    p.set_defaults(func=_fit)

    c = subparsers.add_parser("clone-elastic", help="clone elastic expression parameters to another mesh (§5)")
    c.add_argument("elastic", type=Path, help="source elastic tables (.npz)")
    c.add_argument("target", type=Path, help="target OBJ, character table (.npz) or 'demo'")
    c.add_argument("-o", "--output", type=Path, required=True, help="target elastic tables to write (.npz)")
    c.add_argument("--correspondences", type=Path,
                   help="target control-point file with the source's names; proposed and written when missing")
    c.add_argument("--k", type=int, default=DEFAULT_K)
    c.add_argument("--fixed-ratio", type=float, default=DEFAULT_FIXED_RATIO)
    c.add_argument("--pictures", type=Path, help="folder for the cloned-expression sheet and overlay")
    c.set_defaults(func=_clone, derived_outputs=lambda args: [_clone_character_path(args)])
