"""``facepuppet replay``: play a recording on a character through the live frame loop.

The recording is a session file or a Live Link Face CSV
(:func:`~facepuppet.runtime.sources.open_recording`). It plays on recorded
time: headless, as fast as the machine draws (:class:`RecordedClock`); in a
window, paced to real time (:class:`WallClock`). Either way tick ``k`` shows
the recording at ``k / fps`` seconds, so two replays give the same weights and
the same images.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

from .character import Character
from .loop import FrameLoop, PngSink, RecordedClock, WallClock
from .sources import ReplaySource, open_recording


def parse_size(text: str) -> tuple[int, int]:
    """(width, height) of ``"1280x720"``; ValueError otherwise."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if m is None or int(m.group(1)) <= 0 or int(m.group(2)) <= 0:
        raise ValueError(f"--size: expected WIDTHxHEIGHT in pixels such as 1280x720, got {text!r}")
    return int(m.group(1)), int(m.group(2))


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "replay",
        help="play a recorded session or Live Link Face CSV on a character",
        description="Play a recording (session file or Live Link Face CSV) on a character through "
                    "the frame loop, on recorded time.",
    )
    p.add_argument("session", type=Path, help="session file (.fps) or Live Link Face CSV")
    p.add_argument("-c", "--character", type=Path, required=True, help="character .npz")
    p.add_argument("--headless", action="store_true", help="render offscreen through EGL, as fast as possible")
    p.add_argument("--out", type=Path, default=None, help="write each tick as DIR/frame_00000.png")
    p.add_argument("--fps", type=float, default=60.0, help="ticks per second of recorded time (default 60)")
    p.add_argument("--size", default="1280x720", help="image size WIDTHxHEIGHT (default 1280x720)")
    p.add_argument("--path", choices=("auto", "gpu", "cpu"), default="auto", help="deformation path")
    p.add_argument("--duration", type=float, default=None, help="seconds to play (default: the whole recording)")
    p.add_argument("--stats", action="store_true", help="also print the counters and timings as one JSON line")
    p.add_argument("--retarget", type=Path, default=None,
                   help="retarget tables (.npz, e.g. from fit-retarget) mapping the source channels to the "
                        "character's shapes, instead of matching channel names")
    p.set_defaults(func=run_replay)


def run_replay(args, log=print) -> int:
    """Run the ``replay`` command from parsed ``args``; returns the exit code."""
    from .gl_context import GLUnavailable, create_context
    from .renderer import FaceRenderer

    width, height = parse_size(args.size)
    if not (args.fps > 0):
        raise ValueError(f"--fps: expected a positive number, got {args.fps}")
    character = Character.load(args.character)
    retarget = None
    if getattr(args, "retarget", None) is not None:
        from .kpls_retarget import KplsRetarget

        retarget = KplsRetarget.load(args.retarget)
        if retarget.target_names != tuple(character.shape_names):
            raise ValueError(f"--retarget {args.retarget}: its target shapes ({len(retarget.target_names)}) "
                             f"are not the shapes of {args.character} ({len(character.shape_names)}) in order")
        log(f"replay: retarget {args.retarget} ({retarget.kernel} kernel, {len(retarget.source_names)} source "
            f"shapes -> {len(retarget.target_names)} character shapes)")
    source = ReplaySource(open_recording(args.session))
    log(f"replay: {args.session} ({len(source.frames)} frames, {source.duration:.2f} s) "
        f"on {args.character} ({len(character.shape_names)} shapes)")
    try:
        target = create_context(headless=True if args.headless else None, width=width, height=height,
                                title=f"facepuppet replay {args.session.name}")
    except GLUnavailable as exc:
        print(f"facepuppet replay: error: {exc}", file=sys.stderr)
        return 3
    renderer = None
    try:
        screen = None if target.headless else target.ctx.screen
        renderer = FaceRenderer(target.ctx, character, width, height, path=args.path, target_fbo=screen, log=log)
        sinks = [PngSink(args.out)] if args.out is not None else []
        clock = RecordedClock() if target.headless else WallClock()
        loop = FrameLoop(character, renderer, clock, sinks=sinks, fps=args.fps, log=log, target=target,
                         retarget=retarget)
        result = loop.run(source, duration=args.duration)
    finally:
        if renderer is not None:
            renderer.close()
        target.close()
    c = result.counters
    log(f"replay: {result.n_ticks} ticks at {args.fps:g} fps, {renderer.path} path; frames received "
        f"{c['frames_received']}, stale dropped {c['stale_dropped']}, non-finite rejected "
        f"{c['nonfinite_rejected']}, ticks without a new frame {c['ticks_without_new_frame']}, "
        f"late ticks {c['late_ticks']}" + (" (window closed)" if result.closed_by_window else ""))
    log(result.timer.table())
    if args.stats:
        log(json.dumps({"n_ticks": result.n_ticks, "path": renderer.path, "counters": c,
                        "timings_ms": result.timings}, sort_keys=True))
    if args.out is not None:
        log(f"replay: wrote {result.n_ticks} PNGs to {args.out}")
    return 0
