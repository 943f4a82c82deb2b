"""``facepuppet replay``: play a recording on a character through the live frame loop.

The recording is a session file or a Live Link Face CSV
(:func:`~facepuppet.runtime.recording.replay_source.open_recording`). It plays on recorded
time: headless, as fast as the machine draws (:class:`RecordedClock`); in a
window, paced to real time (:class:`WallClock`). Either way tick ``k`` shows
the recording at ``k / fps`` seconds, so two replays give the same weights and
the same images.

A live recording (``run --record``) with TICK records replays tick for tick
(:mod:`~facepuppet.runtime.recording.ticked_source`): the frames each live tick took, at
its tick times, at the live ``--fps`` (another ``--fps`` resamples instead).
``--pipeline`` (implied by ``--config`` / ``--calibrate``) runs the live
pipeline as ``run`` does, so the same options give the live run's weights.
The parameter-space options (``--actor``/``--pair``, ``--retarget``,
``--elastic``) are ``run``'s (:mod:`~facepuppet.runtime.live.stages`).
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from facepuppet.runtime.character import Character
from facepuppet.runtime.live.loop import FrameLoop, PngSink, RecordedClock, WallClock, WeightLog
from facepuppet.runtime.live.stages import add_stage_arguments
from facepuppet.runtime.recording.replay_source import ReplaySource, open_recording


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
    p.add_argument("--fps", type=float, default=None,
                   help="ticks per second of recorded time (default: the live run's for a live recording, else 60)")
    p.add_argument("--size", default="1280x720", help="image size WIDTHxHEIGHT (default 1280x720)")
    p.add_argument("--path", choices=("auto", "gpu", "cpu"), default="auto", help="deformation path")
    p.add_argument("--duration", type=float, default=None, help="seconds to play (default: the whole recording)")
    p.add_argument("--stats", action="store_true", help="also print the counters and timings as one JSON line")
    p.add_argument("--pipeline", action="store_true",
                   help="run the live pipeline (filters, calibration, tracking loss) as `run` does")
    p.add_argument("--config", type=Path, default=None, help="TOML config of the live pipeline (implies --pipeline)")
    p.add_argument("--calibrate", action="store_true",
                   help="capture the neutral from the first 0.5 s of frames (implies --pipeline)")
    p.add_argument("--dump-weights", type=Path, default=None, metavar="FILE.npy",
                   help="save the weights drawn at every tick, (n_ticks, n_channels) float32")
    add_stage_arguments(p)
    p.set_defaults(func=run_replay)


def run_replay(args, log=print) -> int:
    """Run the ``replay`` command from parsed ``args``; returns the exit code."""
    from facepuppet.runtime.render.gl_context import GLUnavailable, create_context
    from facepuppet.runtime.recording.ticked_source import TickedSource, read_live_recording
    from facepuppet.runtime.live.stages import build_stages, make_input_adapter

    width, height = parse_size(args.size)
    fps = getattr(args, "fps", None)
    if fps is not None and not (fps > 0):
        raise ValueError(f"--fps: expected a positive number, got {fps}")
    character = Character.load(args.character)
    live = read_live_recording(args.session, lambda kind: make_input_adapter(kind, (), log=lambda s: None))
    kind = live.header.get("info", {}).get("input") if live is not None else None
    stages = build_stages(args, character, kind, log=log)
    if live is not None and stages.extra_names:  # decode again, with the muscle names
        live = read_live_recording(args.session, lambda k: make_input_adapter(k, stages.extra_names, log=log))
    pipeline = None
    if getattr(args, "pipeline", False) or getattr(args, "config", None) is not None or getattr(args, "calibrate", False):
        from facepuppet.runtime.live.config import LiveConfig, load_live_config
        from facepuppet.runtime.live.pipeline import LivePipeline

        pipeline = LivePipeline(load_live_config(args.config) if getattr(args, "config", None) else LiveConfig(), log=log)
        if getattr(args, "calibrate", False):
            pipeline.request_calibration()
    ticks = None
    if live is not None and live.ticks:
        live_fps = float(live.header.get("info", {}).get("fps", 60.0))
        if fps is None or fps == live_fps:
            fps = live_fps
            source = TickedSource(live, pipeline.request_calibration if pipeline is not None else None)
            ticks = source.ticks
            pace = (f"drawn on arrival, tick labels at {fps:g} Hz" if live.header.get("info", {}).get("idle_fps")
                    else f"at {fps:g} fps")
            log(f"replay: {args.session} tick for tick ({len(ticks)} live ticks {pace}, "
                f"{len(live.frames)} frames) on {args.character} ({len(stages.names)} channels)")
    if ticks is None:
        fps = 60.0 if fps is None else fps
        source = ReplaySource(live.frames if live is not None else open_recording(args.session))
        log(f"replay: {args.session} ({len(source.frames)} frames, {source.duration:.2f} s) "
            f"on {args.character} ({len(stages.names)} channels)")
    try:
        target = create_context(headless=True if args.headless else None, width=width, height=height,
                                title=f"facepuppet replay {args.session.name}")
    except GLUnavailable as exc:
        print(f"facepuppet replay: error: {exc}", file=sys.stderr)
        return 3
    renderer = None
    weights = WeightLog()
    try:
        screen = None if target.headless else target.ctx.screen
        renderer = stages.renderer(target.ctx, character, width, height, args.path, screen, log)
        sinks = [weights] + ([PngSink(args.out)] if args.out is not None else [])
        clock = RecordedClock() if target.headless else WallClock()
        loop = FrameLoop(SimpleNamespace(shape_names=stages.names), renderer, clock, sinks=sinks, fps=fps, log=log,
                         target=target, retarget=stages.retarget, pipeline=stages.pipeline(pipeline))
        result = loop.run(source, duration=args.duration, ticks=ticks)
    finally:
        if renderer is not None:
            renderer.close()
        target.close()
    c = result.counters
    log(f"replay: {result.n_ticks} ticks at {fps:g} fps, {renderer.path} path; frames received "
        f"{c['frames_received']}, stale dropped {c['stale_dropped']}, non-finite rejected "
        f"{c['nonfinite_rejected']}, ticks without a new frame {c['ticks_without_new_frame']}, "
        f"late ticks {c['late_ticks']}" + (" (window closed)" if result.closed_by_window else ""))
    if getattr(source, "missing", 0):
        log(f"replay: warning: the live ticks drew {source.missing} frames the recording lacks "
            "(packets dropped by the recorder); the weights differ from the live run's from there on")
    log(result.timer.table())
    if args.stats:
        log(json.dumps({"n_ticks": result.n_ticks, "path": renderer.path, "counters": c,
                        "timings_ms": result.timings}, sort_keys=True))
    if getattr(args, "dump_weights", None) is not None:
        np.save(args.dump_weights, weights.array)
        log(f"replay: wrote the weights of {result.n_ticks} ticks to {args.dump_weights}")
    if args.out is not None:
        log(f"replay: wrote {result.n_ticks} PNGs to {args.out}")
    return 0
