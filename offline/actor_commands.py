"""``facepuppet train-actor`` and ``facepuppet retarget-actor`` (Shin & Lee 2009)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


def register(subparsers) -> None:
    """Add ``train-actor`` and ``retarget-actor`` to the ``facepuppet`` parser."""
    p = subparsers.add_parser(
        "train-actor", help="marker capture (TRC/C3D/CSV) -> actor table (actuations + cubic functions)",
        description="Remove head motion, find actuation parameters (mean-shift classes, FastICA) and fit "
                    "cubic deformation functions (Shin & Lee 2009); write an actor table.")
    p.add_argument("capture", type=Path, help="marker capture: .trc, .c3d or .csv")
    p.add_argument("-o", "--output", type=Path, required=True, help="actor table to write (.npz)")
    p.add_argument("--k", type=int, default=13, help="number of actuations K (default 13)")
    p.add_argument("--head-markers", nargs="+", metavar="NAME", help="rigid head markers (default: found)")
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
    r.add_argument("--pictures", type=Path, metavar="DIR",
                   help="write face_actuations.png (the K actuations at s=1 on the character's face) here")
    r.set_defaults(func=_retarget_actor)


def _progress():
    tty = sys.stderr.isatty()

    def show(stage: str, fraction: float, message: str) -> None:
        line = f"[{stage:<9} {int(100 * fraction):>3d}%] {message}"
        print(f"\r{line:<100}" if tty and fraction < 1 else line, end="" if tty and fraction < 1 else "\n",
              file=sys.stderr, flush=True)
    return show


def _train_actor(args: argparse.Namespace) -> int:
    from .actor_train import train_actor
    from .capture_io import read_capture

    start = time.perf_counter()
    capture = read_capture(args.capture, max_gap=args.max_gap)
    print(f"{args.capture}: {capture.n_frames} frames x {capture.n_markers} markers, {capture.rate:g} Hz, "
          f"{capture.units}; {capture.filled} samples filled, {len(capture.gaps)} long gaps"
          + "".join(f"\n  long gap: {g.marker} frames {g.start}..{g.start + g.length - 1}" for g in capture.gaps[:10]),
          file=sys.stderr)
    model = train_actor(capture, k=args.k, progress=_progress(), head_markers=args.head_markers,
                        neutral_frame=args.neutral_frame)
    out = model.actor_.save(args.output)
    print(f"{out}: written, {time.perf_counter() - start:.2f} s\n{model.summary()}")
    if args.pictures:
        from .actor_pictures import actuation_sheet, signal_plot

        args.pictures.mkdir(parents=True, exist_ok=True)
        sheet = actuation_sheet(model.actor_, args.pictures / "actuations.png")
        plot = signal_plot(model.s_, capture.rate, args.pictures / "signals.png")
        print(f"pictures: {sheet}, {plot}")
    return 0


def _retarget_actor(args: argparse.Namespace) -> int:
    from facepuppet.runtime.actor import Actor
    from facepuppet.runtime.character import Character

    from .actor_transfer import read_override, retarget_actor

    start = time.perf_counter()
    actor = Actor.load(args.actor)
    character = Character.load(args.character)
    override = read_override(args.markers_to_mesh, actor.names, character.n_vertices) if args.markers_to_mesh else None
    pair = retarget_actor(actor, character, override=override)
    out = pair.save(args.output)
    m = pair.metadata["metrics"]
    print(f"{out}: {actor.n_markers} markers, K = {actor.n_actuations} -> {character.n_shapes} shapes of "
          f"'{character.name}', {time.perf_counter() - start:.2f} s\n"
          f"  alignment: scale {m['scale']:.3f}, RMS marker-to-skin {m['alignment_rms']:.3f} {character.units}, "
          f"{m['overrides']} overrides\n"
          f"  weights fit: {m['frames']} parameter-shape pairs, marker RMS {m['marker_fit_rms']:.3f} "
          f"{character.units}, cubic weight RMS {m['weight_fit_rms']:.3f}")
    if args.pictures:
        from .actor_pictures import face_actuation_sheet

        args.pictures.mkdir(parents=True, exist_ok=True)
        print(f"pictures: {face_actuation_sheet(pair, character, args.pictures / 'face_actuations.png')}")
    return 0
