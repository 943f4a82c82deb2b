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
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from facepuppet.runtime.cli.progress import Progress
from facepuppet.runtime.model.character import Character

from facepuppet.offline.bench_data import add_data_argument, data_dir
from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.io.rig_import import import_rig
from facepuppet.offline.kpls.targets import stylise
from facepuppet.offline.perfect_sync.commands import load_source, perfect_sync
from facepuppet.offline.perfect_sync.doubt_measure import doubt_figures
from facepuppet.offline.perfect_sync.evaluate import LOOKAT, OWN, godette_pairs, truth_errors
from facepuppet.offline.perfect_sync.face import find_face
from facepuppet.offline.perfect_sync.pictures import shape_sheet, take_side_by_side
from facepuppet.offline.perfect_sync.source import fit_kit_source

GOAL_MEDIAN, GOAL_WORST, GOAL_COSINE = 0.15, 0.40, 0.7
GOAL_GODETTE_S, GOAL_30K_S = 30.0, 120.0
TAKE = "livelinkface_myslate_3.csv"  # the kit's Live Link Face take the side-by-side picture replays


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    add_data_argument(parser)
    parser.add_argument("--source", type=Path, help="source elastic table (default: fit-elastic of the kit's ICT)")
    parser.add_argument("--pictures", type=Path, help="folder for contact sheets of the cloned shapes (GL)")


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
        _sheet(args, out, report, f"ict_{label}")
        result["ict_variants"][label] = {"n_vertices": variant.n_vertices, "seconds": seconds,
                                         "n_added": len(report["added"]), "n_doubts": len(report["doubts"]),
                                         **_summary(errs)}
        s = result["ict_variants"][label]
        print(f"bench perfect-sync: {label}: median {100 * s['median']:.1f}% "
              f"({100 * s['median_without_eye_looks']:.1f}% without eye looks), "
              f"worst {s['worst'][0]} {100 * s['worst'][1]:.1f}%, {seconds:.1f} s")
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
