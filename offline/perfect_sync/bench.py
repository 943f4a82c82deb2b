"""``facepuppet bench perfect-sync --json OUT.json``: cloned ARKit shapes measured on characters with truth.

* ICT variants whose true expressions are known (the same rig deformed, its
  shapes carried along): the ICT head itself, its proportions changed (a
  linear map: wider, shorter, deeper; truth A d) and the cartoon warp of
  ``bench kpls`` (:func:`facepuppet.offline.kpls.targets.stylise`: big eyes,
  long jaw; truth f(v + d) − f(v)). Each is given to ``perfect-sync`` with its
  shapes renamed out of ARKit's names, so all are cloned; per shape and over
  all, the relative error (:func:`.evaluate.truth_errors`; goal median < 15 %,
  no shape over 40 %), with and without the eye looks (the eyeballs do not
  turn: the elastic skin model has no handle on them).
* Heads of real other proportions (:mod:`.real_variants`): ICT warped by a
  thin-plate spline towards the MediaPipe canonical face's landmarks (the
  whole face, half and 1.5 times the way, only the eyes and brows, the lips,
  the nose and jaw, the eyes and lips 1.5 times), truth W(v + d) − W(v). The
  cloning was designed on "mediapipe" (``DESIGN_VARIANT``); the figures of
  the set (``held_out``) are over the others. Besides the errors, the blinks'
  lid closure: the mid-lid gap at rest, true and cloned (within ±25 % of the
  rest gap: neither left open nor driven through the lower lid), how much of the eye shows through the
  closed lid seen from the front, true and cloned (:mod:`.lid_cover`; ``lids_cover``: at most
  :data:`~.lid_cover.ALLOWED` of the opening, also on the ICT variants), how far each proposed control point
  lies from the true one (the variant's own landmarks), and the errors of the clone given the true points
  (``true_points``): the error a set has beyond those is the proposal's; and the doubt report's recall
  (``doubt_recall``, :func:`.doubt_measure.named_far`): of the proposed points out of place, how many it
  names, with its false alarms on the true points.
* Godette (the data kit's VRM): cosine and magnitude ratio of each cloned
  shape against the artist's shape meaning the same (goal cosine >= 0.7 on
  the blinks and the open mouth), and the doubts of the proposal. Her decal
  eyes' looks are her own look expressions (:func:`.transfer.decal_eye_looks`):
  those pairs are reported "from the character's lookAt", not as cloned.
* With ``--pictures DIR``: contact sheets of the cloned shapes and
  ``godette_llf_side_by_side.png``, a Live Link Face take of the kit replayed
  at 8 moments on Godette through her VRM presets (top) and on her clone
  through the ARKit shapes (bottom), the picture a user would compare.
* The doubt report's figures (:mod:`.doubt_measure`): false alarms on the ICT
  head's true points, the points moved out of place that it names, and the
  MediaPipe face's proposed points far from their known meaning that it names;
  Godette's channels taken from her own expressions and the shapes defective
  without one (:mod:`.own_expressions`).
* Time of the whole command's work per character (goals: Godette < 30 s, a
  30k-vertex face < 2 min; the ICT head has 26.7k vertices).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from facepuppet.runtime.cli.progress import Progress
from facepuppet.runtime.elastic.model import ElasticModel
from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.model.character import Character

from facepuppet.offline.bench_data import add_data_argument, data_dir
from facepuppet.offline.elastic.commands import main_front
from facepuppet.offline.elastic.control_points import ControlPoints, ict_control_points, write_control_points
from facepuppet.offline.io.capture import read_trc
from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.io.obj import read_vertices_only
from facepuppet.offline.io.rig_import import import_rig, read_ict_landmarks
from facepuppet.offline.kpls.targets import stylise
from facepuppet.offline.perfect_sync.commands import load_source, perfect_sync
from facepuppet.offline.perfect_sync.doubt_measure import doubt_figures, named_far
from facepuppet.offline.perfect_sync.evaluate import LOOKAT, OWN, godette_pairs, lid_closure, truth_errors
from facepuppet.offline.perfect_sync.face import Face, find_face
from facepuppet.offline.perfect_sync.lid_cover import ALLOWED, cover_against_truth
from facepuppet.offline.perfect_sync.pictures import shape_sheet, take_side_by_side
from facepuppet.offline.perfect_sync.proposal import doubts
from facepuppet.offline.perfect_sync.real_variants import (
    MARKER_VARIANTS,
    MULTIPIE_TO_MARKERS,
    VARIANTS,
    marker_variants,
    real_variants,
)
from facepuppet.offline.perfect_sync.source import fit_kit_source

GOAL_MEDIAN, GOAL_WORST, GOAL_COSINE = 0.15, 0.40, 0.7
GOAL_GODETTE_S, GOAL_30K_S = 30.0, 120.0
GOAL_LID = 0.25  # a cloned blink closes the lid: the mid-lid gap within ± this fraction of the rest gap
DESIGN_VARIANT = "mediapipe"  # the real-proportions variant the cloning was designed on; the others are held out
MARKER_TAKE = "animface_jaw.trc"  # the actor whose neutral face makes the second face's variants
TAKE = "livelinkface_myslate_3.csv"  # the kit's Live Link Face take the side-by-side picture replays


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    add_data_argument(parser)
    parser.add_argument("--source", type=Path, help="source elastic table (default: fit-elastic of the kit's ICT)")
    parser.add_argument("--pictures", type=Path, help="folder for contact sheets of the cloned shapes (GL)")
    parser.add_argument("--variants", nargs="*", choices=[v[0] for v in VARIANTS + MARKER_VARIANTS],
                        default=None,
                        help="real-proportion variants to measure (default: all; none with an empty list)")


def _renamed(character):
    return character.with_parts(shape_names=tuple(f"truth{i}" for i in range(character.n_shapes)), expressions=None)


def proportions(character: Character, scale: tuple[float, float, float] = (1.15, 0.9, 1.05)) -> Character:
    """The character under the linear map diag(scale) about its pivot; the shapes carried (A d)."""
    a = np.asarray(scale, np.float32)
    p = character.pivot
    return character.with_parts(name=f"{character.name} (proportions)", vertices=((character.vertices - p) * a + p),
                                delta_positions=character.delta_positions * a, normals=None)


def _summary(errs: dict) -> dict:
    skin = {k: v for k, v in errs.items() if not k.startswith("eyeLook")}
    worst = max(errs, key=errs.get)
    return {"per_shape": errs, "median": float(np.median(list(errs.values()))),
            "median_without_eye_looks": float(np.median(list(skin.values()))),
            "worst": [worst, errs[worst]], "n_over_40": int(sum(v > GOAL_WORST for v in errs.values())),
            "meets_goal": bool(np.median(list(errs.values())) < GOAL_MEDIAN and errs[worst] < GOAL_WORST)}


def _covers(cover: dict) -> bool:
    """Each cloned blink's closed lid covers the eye: at most :data:`~.lid_cover.ALLOWED` of its opening shows."""
    return bool(cover) and all(v["cloned"] <= ALLOWED for v in cover.values())


def _closes(lids: dict) -> bool:
    """Each cloned blink brings the lids together: neither left open nor driven through the lower lid."""
    return all(abs(v["cloned"]) <= GOAL_LID * v["rest"] for v in lids.values()) and bool(lids)


def point_error(proposed: ControlPoints, true: ControlPoints, vertices: np.ndarray) -> dict:
    """How far each proposed control point lies from the true one (the head's units): {"per_point", "median",
    "worst": [name, distance]}; where the cloning's error comes from, point by point."""
    v = np.asarray(vertices, np.float64)
    d = {n: round(float(np.linalg.norm(v[proposed.vertex(n)] - v[true.vertex(n)])), 3) for n in proposed.names
         if n in true.names}
    worst = max(d, key=d.get)
    return {"per_point": d, "median": float(np.median(list(d.values()))), "worst": [worst, d[worst]]}


def _real_set(args: argparse.Namespace, kit: Path, ict: Character, source) -> dict:
    """The ICT head warped to the MediaPipe face's proportions (:mod:`.real_variants`), each cloned and measured
    against its true shapes, with the blink's lid closure; the set's figures over the held-out variants."""
    face_obj = kit / "mediapipe" / "canonical_face_model.obj"
    labels = args.variants if getattr(args, "variants", None) is not None else [v[0] for v in VARIANTS +
                                                                                  MARKER_VARIANTS]
    if not labels:
        return {"note": "no variants asked for"}
    marks = read_ict_landmarks(kit / "ict-facekit" / "vertex_indices.json", ict.n_vertices)
    out: dict = {"design": DESIGN_VARIANT, "goal_lid_gap": GOAL_LID, "variants": {}}
    heads = []
    if face_obj.exists():
        heads += real_variants(ict, marks, read_vertices_only(face_obj, 468), labels)
    else:
        out["note"] = f"{face_obj} not in the data kit: its variants not measured"
    heads += _marker_heads(kit / "markers" / MARKER_TAKE, ict, marks, labels, out)
    layout = np.asarray(source.arrays["control_positions"], np.float64)
    for label, variant, folded in heads:
        with Progress(f"perfect-sync {label}", total=None, unit="shapes") as bar:
            t = time.perf_counter()
            synced, report, used = perfect_sync(_renamed(variant), source, progress=bar)
            seconds = time.perf_counter() - t
        face = find_face(variant)
        errs = truth_errors(variant, synced, face)
        points = ict_control_points(marks, variant.vertices, variant.triangles, main_front(variant))
        lids = lid_closure(variant, synced, face, points)
        cover = cover_against_truth(variant, synced, face, points)
        _sheet(args, synced, report, f"real_{label}")
        s = out["variants"][label] = {"seconds": seconds, "folded_fraction": folded, "n_doubts": len(report["doubts"]),
                                      **_summary(errs), "lids": lids, "lids_close": _closes(lids),
                                      "lid_cover": cover, "lids_cover": _covers(cover),
                                      "point_error": point_error(used, points, variant.vertices),
                                      "true_points": _with_true_points(variant, source, points, face),
                                      "doubt_recall": named_far(used, points, variant.vertices, report["doubts"],
                                                                doubts(points.reorder(used.names), variant.vertices,
                                                                       face, source_positions=layout))}
        r = s["doubt_recall"]
        print(f"bench perfect-sync: {label}: doubts name {len(r['far_named'])} of {r['n_far']} proposed points "
              f"further than {r['within_units']:.2f} cm from the true ones (missed: {', '.join(r['far_missed'])}), "
              f"{len(r['named_in_place'])} in place; the true points: {len(r['true_points_doubted'])} doubted")
        print(f"bench perfect-sync: {label}: median {100 * s['median']:.1f}%, worst {s['worst'][0]} "
              f"{100 * s['worst'][1]:.1f}%, {s['n_over_40']} over 40%; blink mid-lid gap " + ", ".join(
                  f"{v['cloned']:.2f} (true {v['true']:.2f}, rest {v['rest']:.2f})" for v in lids.values())
              + f"; proposed points from the true ones: median {s['point_error']['median']:.2f} cm, worst "
                f"{s['point_error']['worst'][0]} {s['point_error']['worst'][1]:.2f} cm; {seconds:.1f} s; "
                + "eye showing through the closed lid " + ", ".join(
                    f"{100 * v['cloned']:.1f}% (true {100 * v['true']:.1f}%)" for v in cover.values()) + "; "
                + (f"with the true points: median {100 * s['true_points']['median']:.1f}%, worst "
                   f"{s['true_points']['worst'][0]} {100 * s['true_points']['worst'][1]:.1f}%"
                   if "median" in s["true_points"] else f"with the true points: {s['true_points']['note']}"))
    held = {k: v for k, v in out["variants"].items() if k != DESIGN_VARIANT}
    if held:
        worst = max(held, key=lambda k: held[k]["worst"][1])
        out["held_out"] = {"variants": sorted(held), "median_of_medians": float(np.median([v["median"] for v in
                                                                                           held.values()])),
                           "worst_median": max(v["median"] for v in held.values()),
                           "worst": [worst, *held[worst]["worst"]],
                           "n_over_40": sum(v["n_over_40"] for v in held.values()),
                           "lids_close": all(v["lids_close"] for v in held.values()),
                           "lids_cover": all(v["lids_cover"] for v in held.values()),
                           "meets_goal": all(v["meets_goal"] and v["lids_close"] for v in held.values())}
    other = {k: v for k, v in held.items() if k in dict(MARKER_VARIANTS)}
    if other:  # the one set built from another face than the design variant's: its figures on their own
        out["other_face"] = {"take": MARKER_TAKE, "variants": sorted(other),
                             "worst_median": max(v["median"] for v in other.values()),
                             "worst": max(([k, *v["worst"]] for k, v in other.items()), key=lambda w: w[2]),
                             "lids_close": all(v["lids_close"] for v in other.values()),
                             "meets_goal": all(v["meets_goal"] and v["lids_close"] for v in other.values())}
    return out


def _with_true_points(variant: Character, source: ElasticModel, points: ControlPoints, face: Face) -> dict:
    """The clone's figures when given the variant's true control points (``--landmarks``): what the cloning
    reaches with a perfect proposal, so a set's error splits into the proposal's part and the cloning's."""
    with tempfile.TemporaryDirectory() as folder:
        path = write_control_points(Path(folder) / "landmarks.json", points.reorder(tuple(source.control_names)))
        try:
            synced, _, _ = perfect_sync(_renamed(variant), source, landmarks=path)
        except InputFileError as exc:  # a true point the cloning cannot take (in its fixed region): said
            return {"note": f"not cloned: {exc}"}
    return _summary(truth_errors(variant, synced, face))


def _marker_heads(take: Path, ict: Character, marks: np.ndarray, labels: list, out: dict) -> list:
    """The variants towards the actor of the marker ``take`` (its first frame with every needed marker: the
    take's neutral start), or none, said in ``out["note_markers"]``, without the take."""
    wanted = [v[0] for v in MARKER_VARIANTS if v[0] in labels]
    if not wanted:
        return []
    if not take.exists():
        out["note_markers"] = f"{take} not in the data kit: its variants not measured"
        return []
    capture = read_trc(take)
    need = [capture.names.index(n) for _, n in MULTIPIE_TO_MARKERS]
    whole = np.flatnonzero(np.isfinite(capture.markers[:, need]).all(axis=(1, 2)))
    if not len(whole):
        out["note_markers"] = f"{take}: no frame has every needed marker: its variants not measured"
        return []
    frame = capture.markers[whole[0]]
    return marker_variants(ict, marks, {n: frame[capture.names.index(n)] for _, n in MULTIPIE_TO_MARKERS}, wanted)


def _sheet(args: argparse.Namespace, character: Character, report: dict, label: str) -> None:
    if not getattr(args, "pictures", None):
        return
    args.pictures.mkdir(parents=True, exist_ok=True)
    print(f"bench perfect-sync: {shape_sheet(character, report['added'], args.pictures / f'{label}_shapes.png')}")


def _side_by_side(args: argparse.Namespace, original: Character, synced: Character, take: Path) -> str | None:
    """With ``--pictures``: the Live Link Face take replayed on the original (VRM presets) over the clone."""
    if not getattr(args, "pictures", None):
        return None
    if not take.exists():
        print(f"bench perfect-sync: no side-by-side picture: {take} not in the data kit")
        return None
    args.pictures.mkdir(parents=True, exist_ok=True)
    path = take_side_by_side(original, synced, take, args.pictures / "godette_llf_side_by_side.png")
    print(f"bench perfect-sync: {path} (top: {take.name} through the VRM presets, bottom: perfect sync)")
    return str(path)


def run_bench(args: argparse.Namespace) -> dict:
    kit = data_dir(args.data)
    ict = import_rig(kit / "ict-facekit" / "generic_neutral_mesh.obj", kit / "ict-facekit")
    if args.source:
        source = load_source(args.source)
    else:
        source = fit_kit_source(kit / "ict-facekit")
    result: dict = {"goals": {"median": GOAL_MEDIAN, "worst": GOAL_WORST, "cosine": GOAL_COSINE,
                              "godette_s": GOAL_GODETTE_S, "face_30k_s": GOAL_30K_S}, "ict_variants": {}}
    for label, variant in (("identical", ict), ("proportions", proportions(ict)), ("stylised", stylise(ict))):
        with Progress(f"perfect-sync {label}", total=None, unit="shapes") as bar:
            t = time.perf_counter()
            out, report, _ = perfect_sync(_renamed(variant), source, progress=bar)
            seconds = time.perf_counter() - t
        errs = truth_errors(variant, out, find_face(variant))
        cover = cover_against_truth(variant, out, find_face(variant), ict_control_points(
            read_ict_landmarks(kit / "ict-facekit" / "vertex_indices.json", ict.n_vertices), variant.vertices,
            variant.triangles, main_front(variant)))
        _sheet(args, out, report, f"ict_{label}")
        result["ict_variants"][label] = {"n_vertices": variant.n_vertices, "seconds": seconds,
                                         "n_added": len(report["added"]), "n_doubts": len(report["doubts"]),
                                         **_summary(errs), "lid_cover": cover, "lids_cover": _covers(cover)}
        s = result["ict_variants"][label]
        print(f"bench perfect-sync: {label}: median {100 * s['median']:.1f}% "
              f"({100 * s['median_without_eye_looks']:.1f}% without eye looks), "
              f"worst {s['worst'][0]} {100 * s['worst'][1]:.1f}%, {seconds:.1f} s; eye showing through the closed "
              "lid " + ", ".join(f"{100 * v['cloned']:.1f}% (true {100 * v['true']:.1f}%)" for v in cover.values()))
    result["real_proportions"] = _real_set(args, kit, ict, source)
    godette_path = kit / "gltf" / "Godette_vrm_v4.vrm"
    if godette_path.exists():
        godette = read_gltf(godette_path)
        with Progress("perfect-sync Godette", total=None, unit="shapes") as bar:
            t = time.perf_counter()
            out, report, _ = perfect_sync(godette, source, progress=bar, prefer_own=True)  # as the command does
            seconds = time.perf_counter() - t
        _sheet(args, out, report, "godette")
        side = _side_by_side(args, godette, out, kit / "tracker" / TAKE)
        face = find_face(godette)
        pairs = godette_pairs(out, report["pieces"].get("eye_looks", {}), face.mesh, report["own_expressions"])
        result["godette"] = {"n_vertices": godette.n_vertices, "face_vertices": int(len(face.mesh)),
                             "skin_vertices": int(len(face.skin)), "seconds": seconds, "pairs": pairs,
                             "pieces": report["pieces"], "meets_cosine_goal": {
                                 k: v.get("clone_cosine", v["cosine"]) is not None  # the cloning's, used or not
                                 and v.get("clone_cosine", v["cosine"]) >= GOAL_COSINE for k, v in pairs.items()
                                 if k.split("~")[0] in ("eyeBlinkLeft", "eyeBlinkRight", "jawOpen")},
                             "n_doubts": len(report["doubts"]), "doubts": report["doubts"],
                             "own_expressions": report["own_expressions"],
                             "defective_shapes": report["defective_shapes"],
                             "meets_time_goal": seconds < GOAL_GODETTE_S,
                             **({"side_by_side": side} if side else {})}
        print(f"bench perfect-sync: Godette {seconds:.1f} s; cloned: " + ", ".join(
            f"{k} cos {v['cosine']:.2f} x{v['magnitude_ratio']:.2f}" for k, v in pairs.items()
            if v["cosine"] is not None and v["from"] == "cloned"))
        print("bench perfect-sync: Godette, from the character's lookAt (not cloned): " + ", ".join(
            k for k, v in pairs.items() if v["from"] == LOOKAT))
        print("bench perfect-sync: Godette, her own expression where the clone was worse: " + ", ".join(
            f"{k} (clone cos {v['clone_cosine']:.2f})" if "clone_cosine" in v else k
            for k, v in pairs.items() if v["from"] == OWN))
    else:
        result["godette"] = {"note": f"{godette_path} not in the data kit: not measured"}
    result["doubts"] = doubt_figures(kit)  # does the doubt report name the wrong points, and only them?
    d = result["doubts"]
    print(f"bench perfect-sync: doubts: ICT true points {d['ict_true']['n_doubted']} doubted, moved points named "
          f"{100 * d['ict_displaced_recall']:.0f} %" + (f"; MediaPipe: {len(d['mediapipe']['far_doubted'])} of "
          f"{len(d['mediapipe']['far_from_meaning'])} far points doubted" if "mediapipe" in d else ""))
    result["face_30k"] = {"n_vertices": ict.n_vertices, "seconds": result["ict_variants"]["identical"]["seconds"],
                          "meets_goal": result["ict_variants"]["identical"]["seconds"] < GOAL_30K_S}
    return result


def register_benches(register_bench: Callable[..., None]) -> None:
    """Entry of ``offline/commands.py``: add ``bench perfect-sync``."""
    register_bench("perfect-sync", run_bench, "cloned ARKit shapes against true ones (ICT variants), against "
                   "Godette's artist shapes, and their time", _add_arguments)
