"""``facepuppet perfect-sync``: ARKit-named shapes cloned onto any character's face (issue 14).

Where the character has its own VRM expression for a channel (a blink, a vowel), the clone is used only where
it is no worse than that expression (:mod:`.own_expressions`); the report says per channel which was used."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

from facepuppet.runtime.cli.progress import Progress
from facepuppet.runtime.elastic.model import ElasticModel
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.files.outputs import OutputSet
from facepuppet.runtime.files.tables import TablesError
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.recording.replay_source import open_recording

from facepuppet.offline.elastic.control_points import ControlPoints, write_control_points
from facepuppet.offline.perfect_sync.face import FaceError, find_face
from facepuppet.offline.perfect_sync.lid_cover import EyeCover, blink_cover, open_blinks
from facepuppet.offline.perfect_sync.own_expressions import prefer_own as prefer_own_expressions
from facepuppet.offline.perfect_sync.pictures import shape_sheet, take_side_by_side
from facepuppet.offline.perfect_sync.pieces import find_pieces
from facepuppet.offline.perfect_sync.proposal import doubts, fapu_of, picture, propose, read_landmarks, skin_triangles
from facepuppet.offline.perfect_sync.source import default_source
from facepuppet.offline.perfect_sync.transfer import add_shapes, clone_face

#: a cloned shape moving a vertex this many inner-eye distances (ES, the FAPU of the cloning) is reported; the
#: ICT head's own largest, jawOpen, moves 1.14 ES (in face widths the check depended on how much head a mesh has:
#: a face mask's width is about its features', a whole head's includes the ears)
IMPLAUSIBLE = 2.5


def load_source(path: str | os.PathLike) -> ElasticModel:
    """The source elastic table (``fit-elastic`` of a head with ARKit shapes); TablesError for another kind."""
    source = ElasticModel.load(path)
    for role in ("nose_tip", "forehead", "eye_inner_L", "eye_inner_R"):
        if role not in source.control_names:
            raise TablesError(path, "control_names", f"the source has no {role!r} point (the cloning's face frame "
                                                     "needs it)")
    return source


def perfect_sync(character: Character, source: ElasticModel, landmarks: Path | None = None,
                 replace: bool = False, progress: Progress | None = None,
                 prefer_own: bool = False) -> tuple[Character, dict, ControlPoints]:
    """(character with the ARKit shapes, report, control points used); see the module doc.

    ``prefer_own`` (the command's way): a channel the character has its own expression for takes that
    expression where the clone is worse (:mod:`.own_expressions`); without it every shape is the clone (what the
    cloning's own measures and tests look at), and report["own_expressions"] says what would have been used."""
    face = find_face(character)
    names = tuple(source.control_names)
    pieces = find_pieces(character.vertices, face, skin_triangles(face))  # decal features place the points
    if landmarks is not None:
        points, fitted = read_landmarks(landmarks, names, character.n_vertices), None
    else:
        points, fitted = propose(source.arrays["control_positions"], names, character.vertices, face, pieces)
    doubtful = doubts(points, character.vertices, face, fitted, pieces,
                      source_positions=source.arrays["control_positions"])
    def step(i: int, n: int, name: str) -> None:
        progress.total = n
        progress.update(i, name)

    info: dict = {}
    keys, dense = clone_face(source, character, face, points, progress=None if progress is None else step, info=info)
    es = max(fapu_of(points, character.vertices), 1e-12)
    own, defective = prefer_own_expressions(character, face, pieces, keys, dense, es, points, apply=prefer_own)
    # does each blink's closed lid cover the eye over its whole length? (the lid points meeting do not say)
    lid_cover = blink_cover(EyeCover(character.vertices, face, points), keys, dense)
    out, added = add_shapes(character, keys, dense, replace)
    largest = np.linalg.norm(dense, axis=2).max(axis=1) / es
    implausible = [{"shape": k, "why": f"moves a vertex {r:.2f} inner-eye distances (> {IMPLAUSIBLE}): check the "
                                       "points"} for k, r in zip(keys, largest) if r > IMPLAUSIBLE]
    report = {"face": {"evidence": face.evidence, "mesh_vertices": int(len(face.mesh)), "skin_vertices":
                       int(len(face.skin)), "symmetry_error": face.symmetry_error, "nose_tip": face.nose_tip},
              "pieces": info["pieces"], "doubts": doubtful, "own_expressions": own,
              "defective_shapes": [{"shape": k, "why": "; ".join(w)} for k, w in defective.items()],
              "implausible_shapes": implausible, "lid_cover": lid_cover, "open_blinks": open_blinks(lid_cover),
              **added}
    return out, report, points


def _run(args: argparse.Namespace) -> int:
    if args.sheet and not args.pictures:
        raise UsageError("--sheet: needs --pictures DIR (the folder the contact sheet goes to)")
    if args.take is not None and not args.sheet:
        raise UsageError("--take: needs --pictures DIR --sheet (the side-by-side picture is one of the sheets)")
    if args.take is not None:
        open_recording(args.take)  # a take that cannot be read is refused before the work, nothing written
    character = Character.load(args.character)
    if args.source is not None:
        source = load_source(args.source)
    else:
        source = default_source(args.data)
    with Progress("perfect-sync", total=None, unit="shapes") as bar:
        try:
            out, report, points = perfect_sync(character, source, args.landmarks, args.replace, bar, prefer_own=True)
        except FaceError as exc:  # the message names the character by its name; say which file too
            text, own = str(exc), f"{character.name}: "
            raise FaceError(f"{args.character} ({character.name!r}): {text.removeprefix(own)}"
                            if text.startswith(own) else f"{args.character}: {text}") from None
    with OutputSet() as outputs:
        out.save(outputs.path(args.output))
    if args.pictures:
        args.pictures.mkdir(parents=True, exist_ok=True)
        write_control_points(args.pictures / "landmarks.json", points)
        face = find_face(character)
        bad = [n for d in report["doubts"] for n in d["points"]]
        print(picture(args.pictures / "landmarks.png", character.vertices, face, points, bad, report["doubts"]))
        (args.pictures / "report.json").write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
        from facepuppet.runtime.render.gl_context import GLUnavailable  # GL: importing it loads moderngl

        if args.sheet:
            try:
                print(shape_sheet(out, report["added"] + report["replaced"], args.pictures / "shapes.png"))
                if args.take is not None:
                    side = take_side_by_side(character, out, args.take, args.pictures / "side_by_side.png")
                    print(f"{side} (top: {args.take.name} on the character as it was, bottom: perfect sync)")
            except GLUnavailable as exc:
                print(f"perfect-sync: no contact sheet of the shapes (no OpenGL: {exc})")
    for d in report["doubts"]:
        print(f"doubtful: {', '.join(d['points'])}: {d['why']}")
    for d in report["implausible_shapes"]:
        print(f"implausible: {d['shape']}: {d['why']}")
    for d in report["defective_shapes"]:
        print(f"defective: {d['shape']}: {d['why']} (no expression of the character's to fall back on; see it "
              "with --pictures DIR --sheet)")
    for d in report["open_blinks"]:
        print(f"defective: {d['shape']}: {d['why']} (see it with --pictures DIR --sheet)")
    for key, d in report["own_expressions"].items():
        print(f"{key}: {d['used']}: {d['why']} (cosine {d['cosine']:.2f}, x{d['magnitude_ratio']:.2f})")
    if report["doubts"] and not args.pictures:
        print("perfect-sync: the doubtful points are drawn and numbered by --pictures DIR (DIR/landmarks.png); correct "
              "them in DIR/landmarks.json and rerun with --landmarks DIR/landmarks.json")
    if not report["doubts"]:
        where = args.pictures / "landmarks.png" if args.pictures else "--pictures DIR (DIR/landmarks.png)"
        print("perfect-sync: no point was found doubtful, which is not a proof: the checks find a point out of step "
              "with its neighbours, the face's layout or the lips' outline, not a region placed off as a whole "
              f"(bench perfect-sync measures how many they miss); look at the points in {where}")
    print(f"{args.output}: {len(report['added'])} ARKit shapes added, {len(report['kept'])} kept, "
          f"{len(report['replaced'])} replaced; {len(report['doubts'])} doubtful proposal(s)"
          + (f" (correct them in {args.pictures / 'landmarks.json'} and rerun with --landmarks)"
             if report["doubts"] and args.pictures else ""))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("perfect-sync", help="add the 52 ARKit shapes to a character by elastic cloning")
    p.add_argument("character", type=Path, help="character table (.npz, from import-rig of OBJ/GLB/VRM)")
    p.add_argument("-o", "--output", type=Path, required=True, help="character table to write (.npz)")
    p.add_argument("--source", type=Path,
                   help="source elastic table (fit-elastic of a head with ARKit shapes; default: the ICT head "
                        "of the data kit, fitted once and cached under ~/.cache/facepuppet)")
    p.add_argument("--data", type=Path, default=None,
                   help="the data kit folder holding ict-facekit/, for the default source (default: "
                        "$FACEPUPPET_DATA)")
    p.add_argument("--landmarks", type=Path, help="control points to use (the JSON --pictures writes, edited)")
    p.add_argument("--pictures", type=Path, help="folder for the proposed points (PNG, JSON) and the report")
    p.add_argument("--sheet", action="store_true",
                   help="with --pictures: also render a contact sheet of the cloned shapes there (OpenGL)")
    p.add_argument("--take", type=Path, metavar="TAKE.csv",
                   help="with --pictures --sheet: also side_by_side.png, this Live Link Face take (or session) "
                        "replayed at 8 moments on the character as it was (top) and with the cloned shapes "
                        "(bottom)")
    p.add_argument("--replace", action="store_true", help="replace shapes it already has under an ARKit name")
    p.set_defaults(func=_run)
