"""``facepuppet train-actor`` and ``facepuppet retarget-actor`` (Shin & Lee 2009)."""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.cli.progress import Progress
from facepuppet.runtime.errors import InputFileError, UsageError
from facepuppet.runtime.model.character import Character

from facepuppet.offline.actuation import transfer
from facepuppet.offline.actuation.face_scale import FaceScale
from facepuppet.offline.actuation.pictures import actuation_sheet, face_actuation_sheet, signal_plot
from facepuppet.offline.actuation.shape_choice import NO_SHAPES
from facepuppet.offline.actuation.transfer_eval import transfer_error
from facepuppet.offline.io.capture import read_capture


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``train-actor`` and ``retarget-actor`` to the ``facepuppet`` parser."""
    p = subparsers.add_parser(
        "train-actor", help="marker capture (TRC/C3D/CSV) -> actor table (actuations + cubic functions)",
        description="Remove head motion, find actuation parameters (mean-shift classes, FastICA) and fit "
                    "cubic deformation functions (Shin & Lee 2009); write an actor table.")
    p.add_argument("capture", type=Path, help="marker capture: .trc, .c3d or .csv")
    p.add_argument("-o", "--output", type=Path, required=True, help="actor table to write (.npz)")
    p.add_argument("--k", type=int, default=13, help="number of actuations K (default 13)")
    p.add_argument("--head-markers", nargs="+", metavar="NAME",
                   help="rigid markers on the skull, e.g. forehead and nose bridge (default: found by name and "
                        "motion; when the take cannot tell, train-actor stops and names the rival sets)")
    p.add_argument("--neutral-frame", type=int, help="neutral frame, 0-based (default: closest to the median)")
    p.add_argument("--max-gap", type=int, default=10, help="fill occlusion gaps up to this many frames")
    p.add_argument("--pictures", type=Path, metavar="DIR",
                   help="write actuations.png (K actuations at s=1) and signals.png (s over the take) here")
    p.set_defaults(func=_train_actor)

    r = subparsers.add_parser(
        "retarget-actor", help="actor table + character table -> actor-pair table (s -> character weights)",
        description="Map the actor's markers onto the character (similarity alignment, nearest skin vertices, "
                    "override file), express parameter-shape pairs in the character's weights (bounded least "
                    "squares) and fit cubic tables s -> weights (Shin & Lee 2009, 6.2).")
    r.add_argument("actor", type=Path, help="actor table (.npz) from train-actor")
    r.add_argument("character", type=Path, help="character table (.npz) from import-rig")
    r.add_argument("-o", "--output", type=Path, required=True, help="actor-pair table to write (.npz)")
    r.add_argument("--markers-to-mesh", type=Path, metavar="OVERRIDE.json",
                   help='JSON {"marker name": vertex index} overriding the nearest-vertex choice')
    r.add_argument("--landmarks", type=Path, metavar="JSON",
                   help="the character's 68 Multi-PIE landmark vertices (a JSON list or ICT's vertex_indices.json); "
                        "default: the file named in the character's import settings")
    r.add_argument("--include-shapes", nargs="+", default=[], metavar="PATTERN",
                   help="shape names (fnmatch patterns) kept even if the markers cannot observe them, "
                        "e.g. 'eyeLook*' or '*' for all")
    r.add_argument("--exclude-shapes", nargs="+", metavar="PATTERN",
                   help="shape names left out by name (default: eyeLook* PupilDilate*)")
    r.add_argument("--region-radius", type=float, default=None, metavar="FAPU",
                   help="a shape needs a marker within this many FAPU of its moving region (default 0.3)")
    r.add_argument("--face-scale", type=float, metavar="RATIO",
                   help="character length per actor length, by which the actor's motion is scaled (default: the "
                        "median of the ratios of the distances between landmark markers on both faces, else the "
                        "inner-eye-corner distances' ratio)")
    r.add_argument("--evaluate", type=Path, metavar="CAPTURE",
                   help="report the marker-space transfer error on this take's frames "
                        "(TRC/C3D/CSV, the actor's markers)")
    r.add_argument("--pictures", type=Path, metavar="DIR",
                   help="write face_actuations.png (the K actuations at s=1 on the character's face) here")
    r.set_defaults(func=_retarget_actor)


TRAIN_STAGES = ("stabilise", "actuation", "cubic")


def _progress(bar):
    """The trainer's ``progress(stage, fraction, message)`` on a :class:`Progress` over its stages: a stage
    starting (fraction 0) is the line's note; what a stage reports (fraction > 0) is a line of its own."""
    def show(stage: str, fraction: float, message: str) -> None:
        done = TRAIN_STAGES.index(stage) if stage in TRAIN_STAGES else bar.done
        if fraction <= 0:
            bar.update(done, note=f"{stage}: {message}")
            return
        bar.write(f"  {stage}: {message}")
        bar.update(done + min(fraction, 1.0), note=stage)
    return show


def _train_actor(args: argparse.Namespace) -> int:
    # imported here, not at the top: it loads scipy.signal, which every `facepuppet` start would pay
    from facepuppet.offline.actuation.train import train_actor

    start = time.perf_counter()
    capture = read_capture(args.capture, max_gap=args.max_gap)
    print(f"{args.capture}: {capture.n_frames} frames x {capture.n_markers} markers, {capture.rate:g} Hz, "
          f"{capture.units}; {capture.filled} samples filled, {len(capture.gaps)} long gaps"
          + "".join(f"\n  long gap: {g.marker} frames {g.start}..{g.start + g.length - 1}" for g in capture.gaps[:10]),
          file=sys.stderr)
    with Progress("train-actor", total=len(TRAIN_STAGES), unit="stages") as bar:
        model = train_actor(capture, k=args.k, progress=_progress(bar), head_markers=args.head_markers,
                            neutral_frame=args.neutral_frame)
    out = model.actor_.save(args.output)
    print(f"{out}: written, {time.perf_counter() - start:.2f} s\n{model.summary()}")
    if args.pictures:
        args.pictures.mkdir(parents=True, exist_ok=True)
        sheet = actuation_sheet(model.actor_, args.pictures / "actuations.png")
        plot = signal_plot(model.s_, capture.rate, args.pictures / "signals.png")
        print(f"pictures: {sheet}, {plot}")
    return 0


def _scale_lines(m: dict, actor_units: str, units: str) -> str:
    """What the actor's motion is multiplied by, from what, and whether the landmarks agree on it."""
    scale = m["face_scale"]
    measured = FaceScale.from_dict(scale["landmarks"]) if scale["landmarks"] else None
    if scale["source"] == "given":
        line = f"face-size ratio {scale['ratio']:.3f} (given)" + (
            f"; the landmarks say {measured.ratio:.3f} (middle half {measured.low:.2f}-{measured.high:.2f})"
            if measured else "")
    elif measured is not None:
        line = measured.summary()
    else:
        line = f"face-size ratio {scale['ratio']:.3f} (from the {scale['source']}; fewer than 3 landmark markers)"
    return (f"{line}\n  FAPU ({m['fapu']}) {m['fapu_character']:.3f} {units} on the character, "
            f"{m['fapu_actor']:.3f} {actor_units} on the actor at that ratio (the FAPU ratio is "
            f"{scale['fapu_ratio']:.3f})")


def _retarget_actor(args: argparse.Namespace) -> int:
    start = time.perf_counter()
    actor = Actor.load(args.actor)
    character = Character.load(args.character)
    if character.n_shapes == 0:
        raise InputFileError(f"{args.character}: {NO_SHAPES.format(name=character.name)}")
    override = (transfer.read_override(args.markers_to_mesh, actor.names, character.n_vertices)
                if args.markers_to_mesh else None)
    landmarks = transfer.character_landmarks(character, args.landmarks)
    options = {"include": args.include_shapes}
    if args.exclude_shapes is not None:
        options["exclude"] = args.exclude_shapes
    if args.region_radius is not None:
        options["radius"] = args.region_radius
    if args.face_scale is not None:
        if not (math.isfinite(args.face_scale) and args.face_scale > 0):
            raise UsageError(f"--face-scale: expected a positive ratio, got {args.face_scale!r}")
        options["scale"] = args.face_scale
    pair = transfer.retarget_actor(actor, character, override=override, landmarks=landmarks, **options)
    out = pair.save(args.output)
    m = pair.metadata["metrics"]
    u = character.units
    lm = (f"{len(m['landmarks'])} landmark markers (RMS {m['landmark_rms']:.3f} {u})" if m["landmarks"]
          else "no landmarks: ICP on the skin")
    print(f"{out}: {actor.n_markers} markers, K = {actor.n_actuations} -> {m['shapes_used']} of {character.n_shapes} "
          f"shapes of '{character.name}', {time.perf_counter() - start:.2f} s\n"
          f"  alignment: {lm}, scale {m['scale']:.3f}, RMS marker-to-skin {m['alignment_rms']:.3f} {u}, "
          f"{m['overrides']} overrides\n"
          f"  {_scale_lines(m, actor.units, u)}\n"
          f"  left out: " + (", ".join(f"{n} ({why})" for n, why in m["shapes_left_out"].items()) or "none") + "\n"
          f"  weights fit: {m['frames']} parameter-shape pairs, s from {m['s_source']}, marker RMS "
          f"{m['marker_fit_rms']:.3f} {u}, cubic weight RMS {m['weight_fit_rms']:.3f}")
    if args.evaluate:
        capture = read_capture(args.evaluate)
        missing = [n for n in actor.names if n not in capture.names]
        if missing:
            raise InputFileError(f"{args.evaluate}: markers {missing[:5]} of the actor are not in this take")
        frames = capture.markers[:, [capture.names.index(n) for n in actor.names]]
        e = transfer_error(actor, pair, character, frames, m["fapu_actor"], m["fapu_character"])
        print(f"  {args.evaluate}: {e['frames']} frames, marker-space RMS transfer {e['transfer_rms']:.3f} {u} "
              f"(neutral {e['zero_rms']:.3f}, per-frame best {e['oracle_rms']:.3f}; relative "
              f"{e['relative']:.3f}); actor solve RMS {e['solve_rms']:.3f} {actor.units}")
    if args.pictures:
        args.pictures.mkdir(parents=True, exist_ok=True)
        print(f"pictures: {face_actuation_sheet(pair, character, args.pictures / 'face_actuations.png')}")
    return 0
