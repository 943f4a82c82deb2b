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
The stage chain is ``run``'s, built by the same function
(:func:`~facepuppet.runtime.live.stages.build_chain`) from the same options
(``--actor``/``--pair``, ``--retarget``, ``--elastic``, ``--gestures``,
``--gesture-seed``); ``--pipeline`` (implied by ``--config`` / ``--calibrate``)
adds the filter stage as ``run`` has it. The audio levels a live recording kept
(one per tick) feed the ``audio`` stage, so the same options give the live run's
weights, gestures included.

``--video FILE`` encodes the drawn ticks (:mod:`~facepuppet.runtime.live.video_out`; the
same recording gives the same frames), with ``--audio-file WAV`` as the sound
(a recording keeps audio levels, not samples). ``--llf-out HOST:PORT`` sends each
tick as a Live Link Face packet (:mod:`~facepuppet.runtime.live.llf_out`); the
replay is then paced to real time even headless, as a receiver expects.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from facepuppet.runtime.character import Character
from facepuppet.runtime.commands.options import parse_host_port, parse_size
from facepuppet.runtime.live.llf_out import LlfSender
from facepuppet.runtime.live.loop import FrameLoop, RecordedClock, WallClock
from facepuppet.runtime.live.sinks import PngSink, WeightLog
from facepuppet.runtime.live.stages import (
    RecordedLevels,
    add_stage_arguments,
    build_chain,
    follow_mapping,
    make_input_adapter,
)
from facepuppet.runtime.live.video_out import VideoSink, add_video_arguments, plan_video_from_args
from facepuppet.runtime.progress import Progress
from facepuppet.runtime.recording.replay_source import DEFAULT_MAX_GAP_S, ReplaySource, open_recording
from facepuppet.runtime.render.options import add_render_arguments, render_options


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "replay",
        help="play a recorded session or Live Link Face CSV on a character",
        description="Play a recording (session file or Live Link Face CSV) on a character through "
                    "the frame loop, on recorded time.",
    )
    p.add_argument("session", type=Path,
                   help="session file (.fps), Live Link Face CSV, or a marker take (.trc/.c3d/.csv, with "
                        "--actor/--pair)")
    p.add_argument("-c", "--character", type=Path, required=True, help="character .npz")
    p.add_argument("--headless", action="store_true", help="render offscreen through EGL, as fast as possible")
    p.add_argument("--out", type=Path, default=None, help="write each tick as DIR/frame_00000.png")
    p.add_argument("--fps", type=float, default=None,
                   help="ticks per second of recorded time (default: the live run's for a live recording, else 60)")
    p.add_argument("--size", default="1280x720", help="image size WIDTHxHEIGHT (default 1280x720)")
    p.add_argument("--path", choices=("auto", "gpu", "cpu"), default="auto", help="deformation path")
    add_render_arguments(p)
    p.add_argument("--duration", type=float, default=None, help="seconds to play (default: the whole recording)")
    p.add_argument("--max-gap", type=_gap_seconds, default=DEFAULT_MAX_GAP_S, metavar="SECONDS",
                   help=f"cut a pause between recorded frames longer than this to this length, and say so "
                        f"(default {DEFAULT_MAX_GAP_S:g}; 'inf' keeps every pause)")
    p.add_argument("--stats", action="store_true", help="also print the counters and timings as one JSON line")
    p.add_argument("--pipeline", action=argparse.BooleanOptionalAction, default=None,
                   help="run the filter stage (filters, calibration, tracking loss) as `run` does; default: on for "
                        "a live recording (run --record) and a marker take, so the replay draws what the live run "
                        "drew, off for other recordings; implied by --config and --calibrate; --no-pipeline plays "
                        "the raw frames")
    p.add_argument("--dump-weights", type=Path, default=None, metavar="FILE.npy",
                   help="save the weights drawn at every tick, (n_ticks, n_channels) float32")
    p.add_argument("--llf-out", default=None, metavar="HOST:PORT",
                   help="send each tick as a Live Link Face packet (the phone's UDP format) there, paced to real "
                        "time")
    add_video_arguments(p, audio_help="with --video, the sound track (a recording keeps audio levels, not samples)")
    add_stage_arguments(p)
    p.set_defaults(func=run_replay)


def _gap_seconds(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds (or inf), got {text!r}")
    return value


def _recorded_face_id(header: dict) -> int | None:
    """The ``--face-id`` a live recording was made with (openseeface); None when it has none."""
    options = header.get("info", {}).get("options") if isinstance(header.get("info"), dict) else None
    value = options.get("face_id") if isinstance(options, dict) else None
    try:
        return None if value is None else int(value)
    except (TypeError, ValueError):
        return None


def run_replay(args: argparse.Namespace, log: Callable[[str], None] = print) -> int:
    """Run the ``replay`` command from parsed ``args``; returns the exit code."""
    from facepuppet.runtime.recording.ticked_source import TickedSource, read_live_recording
    from facepuppet.runtime.render.gl_context import create_context

    width, height = parse_size(args.size)
    fps = getattr(args, "fps", None)
    if fps is not None and not (fps > 0):
        raise ValueError(f"--fps: expected a positive number, got {fps}")
    llf_out = parse_host_port(args.llf_out, "--llf-out") if getattr(args, "llf_out", None) else None
    if getattr(args, "audio_file", None) is not None and getattr(args, "video", None) is None:
        raise ValueError("--audio-file: in a replay it is the sound track of --video FILE; give --video too")
    video_plan = plan_video_from_args(args, width, height, alpha=render_options(args).transparent)
    character = Character.load(args.character)
    picture = render_options(args)
    if character.credits:
        log(f"credits: {character.credits}")
    live = read_live_recording(args.session, lambda kind: make_input_adapter(kind, (), log=lambda s: None))
    face_id = _recorded_face_id(live.header) if live is not None else None
    if face_id is not None:  # decode again following the face the run followed
        live = read_live_recording(args.session, lambda kind: make_input_adapter(kind, (), log=lambda s: None,
                                                                                 face_id=face_id))
    kind = live.header.get("info", {}).get("input") if live is not None else None
    take = _marker_take(args.session) if live is None else None
    if take is not None:
        kind = take.kind
    filtered = _filtered(args, live, take, log)
    levels = RecordedLevels(live.audio_levels) if live is not None and live.audio_levels else None
    if take is None:
        source, ticks, fps = _source(args, live, fps, log)
    config_text, schedule = _recorded_config(args, live, filtered, log)
    chain = build_chain(args, character, kind, filtered=filtered, audio_level=levels,
                        config_text=config_text, schedule=schedule,
                        calibrate_requests=(lambda: source.watched) if take is None and isinstance(source, TickedSource)
                        else None,
                        voice_only=kind == "audio", label=f"replay({kind or 'frames'})", log=log)
    if take is not None:
        _check_take_layouts(args.session, take, chain)
        source, ticks, fps = _take_source(args, take, chain.marker_units, fps, log)
    units = getattr(args, "marker_units", None)
    if live is not None and (chain.extra_names or (kind == "markers" and (units or chain.marker_units))):
        # decode again, with the muscle names / converting marker frames to the actor's units
        live = read_live_recording(args.session, lambda k: make_input_adapter(
            k, chain.extra_names, log=log, marker_units=units, to_units=chain.marker_units, face_id=face_id))
        source, ticks, fps = _source(args, live, getattr(args, "fps", None), lambda s: None)
    if live is not None and live.header.get("info", {}).get("mix_sources") is not None:
        _replay_mix(live, chain, ticks, log)
    if live is not None and live.states and chain.filter is not None and filtered:
        _restore_state(chain.filter, live.states[0], args.session, log)
    log(chain.describe())
    target = create_context(headless=True if args.headless else None, width=width, height=height,
                            title=f"facepuppet replay {args.session.name}", log=log, samples=picture.msaa,
                            transparent=picture.transparent)
    renderer = video = llf = None
    weights = WeightLog()
    try:
        screen = None if target.headless else target.ctx.screen
        renderer = chain.renderer(target.ctx, character, width, height, args.path, screen, log,
                                  **picture.renderer_kwargs(),
                                  credits=character.credits if picture.credits else None)
        sinks = [weights] + ([PngSink(args.out)] if args.out is not None else [])
        if video_plan is not None:
            video = VideoSink(video_plan, fps)
            log(video_plan.describe(fps))
            sinks.append(video)
        total = _expected_ticks(args, source, ticks, fps)
        progress = Progress("replay" if video is None else f"replay --video {video_plan.path.name}", total=total,
                            unit="ticks")
        hooks = [lambda info: progress.update(info.k + 1 if ticks is None else progress.done + 1)]
        if llf_out is not None:
            llf = LlfSender(llf_out[0], llf_out[1], chain.names)
            log(llf.describe() + " (paced to real time)")
            hooks.append(llf.on_tick)
        events: list = []  # the replay's tracking events, compared with the recording's at the end
        if chain.filter is not None:
            chain.filter.listeners.append(lambda t, found: events.append((t, found)))
        clock = RecordedClock() if target.headless and llf is None else replay_wall_clock(ticks, fps)
        loop = FrameLoop(chain.names, renderer, clock, sinks=sinks, fps=fps, log=log, target=target,
                         stages=chain.stages, on_tick=hooks, drive=chain.drive)
        if chain.filter is not None:  # a [mapping] applied live (the panel, a recorded change) maps from then on
            chain.filter.on_config.append(follow_mapping(chain, loop, character.expressions, log))
        with progress:           # on a terminal: ticks done, rate, time left (quiet when piped)
            result = loop.run(source, duration=args.duration, ticks=ticks)
        if video is not None:
            video.close()
    except BaseException:
        if video is not None:
            video.abort()
        raise
    finally:
        if llf is not None:
            llf.close()
        if renderer is not None:
            renderer.close()
        target.close()
    _report(args, result, renderer.path, fps, source, weights, log)
    if chain.filter is not None and live is not None:
        log(_compare_events(live.events, events))
    return 0


class WallClockFrom(WallClock):
    """Real time that starts at ``t0`` seconds instead of 0 (:meth:`start` puts the origin ``t0`` back)."""

    def __init__(self, t0: float) -> None:
        super().__init__()
        self.t0 = float(t0)

    def start(self) -> None:
        super().start()
        self._origin -= self.t0


def replay_wall_clock(ticks: list[int] | None, fps: float) -> WallClock:
    """Real time for a replay; a recording whose first tick is late (one the panel started during a run) plays
    its first tick at once, not after that tick's time."""
    first = ticks[0] / fps if ticks else 0.0
    return WallClockFrom(first) if first > 0 else WallClock()


def _replay_mix(live, chain, ticks, log) -> None:
    """The ``mix`` stage of a recording of a run with several inputs: each mix source's frames at the ticks
    the live run took them (its SOURCES records), the voice from the recorded levels, the order of the config."""
    from dataclasses import replace

    from facepuppet.runtime.live.mix import MixStage, VoiceMixSource, check_mix_sources, follow_config
    from facepuppet.runtime.recording.ticked_source import TickedSource

    info = live.header["info"]
    names = tuple(info.get("inputs") or ())
    if ticks is None or not names:
        raise ValueError("replay: a recording of several inputs replays tick for tick only; this one has no TICK "
                         "records or no list of its inputs")
    sources = {}
    for name in names[1:]:
        if name == "audio":
            if chain.audio is None:
                raise ValueError("replay: the recording mixed the voice but kept no audio levels")
            sources[name] = VoiceMixSource(chain.audio.level, chain.config.loss)
        else:
            sources[name] = TickedSource(live.mix[name])
    settings = chain.config.mix
    if settings.order is None:
        settings = replace(settings, order=names)
    check_mix_sources(settings, names, chain.config.path or "(defaults)")
    # as the live run ordered them: its own input, the other trackers in the order given, the voice last
    loop_first = (info["input"], *(n for n in names if n not in (info["input"], "audio")),
                  *(("audio",) if "audio" in names else ()))
    stage = MixStage(loop_first, {n: sources[n] for n in loop_first[1:]}, settings, chain.config.timeout_s)
    chain.add_mix(stage, label=f"replay({'+'.join(names)})")
    if chain.filter is not None:  # the live run's config changes (its CONFIG records) reach the mix as they did
        chain.filter.on_config.append(follow_config(stage, names, log))


def _restore_state(pipeline, state: tuple[float, str], path, log: Callable[[str], None]) -> None:
    """A recording started mid-run: the filter stage goes on from the state it had then (its STATE record).
    One that cannot be used is said and left: the replay then starts the stage afresh, as before STATE."""
    import json

    t, text = state
    try:
        pipeline.restore_state(json.loads(text))
    except (ValueError, json.JSONDecodeError) as exc:
        log(f"replay: warning: {path}: the filter stage's state at the recording's start (t = {t:.3f} s) is not "
            f"usable ({exc}); its first ticks may differ from the run")
        return
    log(f"replay: the filter stage goes on from its state at the recording's start (t = {t:.3f} s)")


def _compare_events(recorded: list, replayed: list) -> str:
    """The report line on the tracking events: as recorded, or where the replay's first differ."""
    def text(events):
        return ", ".join(f"{'found' if f else 'lost'} at {t:.3f} s" for t, f in events[:6]) + (
            ", ..." if len(events) > 6 else "")

    if [(round(t, 9), f) for t, f in recorded] == [(round(t, 9), f) for t, f in replayed]:
        return f"replay: tracking events as recorded ({len(replayed)}" + (f": {text(replayed)})" if replayed else ")")
    return (f"replay: warning: tracking events differ from the recording's: recorded {len(recorded)} "
            f"({text(recorded) or 'none'}), replayed {len(replayed)} ({text(replayed) or 'none'})")


def _source(args, live, fps, log):
    """(frame source, the live tick schedule or None, ticks per second) for the recording."""
    from facepuppet.runtime.recording.ticked_source import TickedSource

    if live is not None and live.ticks:
        live_fps = float(live.header.get("info", {}).get("fps", 60.0))
        if fps is None or fps == live_fps:
            source = TickedSource(live)
            pace = (f"drawn on arrival, tick labels at {live_fps:g} Hz" if live.header.get("info", {}).get("idle_fps")
                    else f"at {live_fps:g} fps")
            log(f"replay: {args.session} tick for tick ({len(source.ticks)} live ticks {pace}, "
                f"{len(live.frames)} frames) on {args.character}")
            return source, source.ticks, live_fps
    fps = 60.0 if fps is None else fps
    source_limit = getattr(args, "max_gap", DEFAULT_MAX_GAP_S)
    source = ReplaySource(live.frames if live is not None else open_recording(args.session), max_gap=source_limit)
    log(f"replay: {args.session} ({len(source.frames)} frames, {source.duration:.2f} s) on {args.character}")
    if source.gaps:
        log(f"replay: {source.describe_gaps()}; --max-gap SECONDS changes the limit ({source_limit:g} s), "
            f"--max-gap inf keeps them")
    return source, None, fps


def _expected_ticks(args, source, ticks, fps: float) -> int | None:
    """How many ticks the replay will draw, for the progress line (None when unknown)."""
    if ticks is not None:
        return len(ticks)
    seconds = getattr(source, "duration", None)
    if args.duration is not None:
        seconds = args.duration if seconds is None else min(seconds, args.duration)
    return None if seconds is None else int(seconds * fps) + 1


def _filtered(args, live, take, log) -> bool:
    """Whether the replay runs the filter stage: asked for, implied, or (by default) a live run's or a take's."""
    asked = getattr(args, "pipeline", None)
    implied = getattr(args, "config", None) is not None or bool(getattr(args, "calibrate", False))
    if asked is False:
        if implied:
            raise ValueError("--no-pipeline: --config and --calibrate configure the filter stage; drop them or it")
        return False
    if asked or implied:
        return True
    reproducing = (live is not None and bool(live.ticks)) or take is not None
    if live is not None and live.ticks:
        recorded = dict(live.header.get("info", {}).get("options", {}) or {})
        if isinstance(live.header.get("info", {}).get("config"), str):  # the config itself is in the recording
            recorded.pop("config", None)
            recorded.pop("profile", None)
        lacking = [f"--{name.replace('_', '-')} {value}" if value not in ("True", "False") else f"--{name}"
                   for name, value in recorded.items()
                   if value not in (None, "False", "0") and getattr(args, name, None) in (None, False, 0)]
        log("replay: a live recording: the filter stage runs as in the live run (--no-pipeline: the raw frames)"
            + (f"; the live run also had {' '.join(lacking)}: give the same to reproduce it" if lacking else ""))
    return reproducing


def _recorded_config(args, live, filtered: bool, log) -> tuple[tuple[str, str] | None, list]:
    """(where, TOML) of the config a live run started with, and its changes, for a replay without --config or
    --profile (they win, and the live run's changes are not applied over them)."""
    text = live.header.get("info", {}).get("config") if live is not None else None
    if not filtered or not isinstance(text, str):
        return None, []
    if getattr(args, "config", None) is not None or getattr(args, "profile", None) is not None:
        log("replay: the live run's recorded config (and its changes) is not used: --config/--profile given")
        return None, []
    changes = list(live.configs)
    log("replay: the live run's config in force (recorded)"
        + (f" and its {len(changes)} change{'s' if len(changes) != 1 else ''} during the run" if changes else ""))
    return (f"{args.session} (its recorded config)", text), changes


def _marker_take(path: Path):
    """The recording a registered reader (a marker capture: TRC, C3D, CSV) makes of ``path``, or None."""
    from facepuppet.runtime.recording.readers import find_reader

    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except IsADirectoryError:
        return None
    reader = find_reader(path, head)
    return reader.read(path) if reader is not None else None


def _check_take_layouts(path: Path, take, chain) -> None:
    """Refuse a marker take none of whose layouts the solve can use, before drawing a neutral face to its end."""
    solve = next((stage for stage in chain.stages if getattr(stage, "name", None) == "solve"), None)
    if solve is None:
        return
    layouts = {tuple(f.marker_names) for f in take.frames if f.marker_names is not None}
    if layouts and not any(solve.accepts_layout(names) for names in layouts):
        raise ValueError(f"{path}: the actor's markers are not in this take (its marker layout is refused, "
                         "see above): train the actor on a take with these marker names, or rename them")


def _take_source(args, take, to_units, fps, log):
    """(frame source, None, ticks per second) of a marker take, its positions in the actor's units."""
    from facepuppet.runtime.frames import Frame
    from facepuppet.runtime.inputs.markers import UNIT_METRES

    units = getattr(args, "marker_units", None) or take.units
    frames = take.frames
    note = ""
    if units in UNIT_METRES and to_units in UNIT_METRES and units != to_units:
        factor = np.float32(UNIT_METRES[units] / UNIT_METRES[to_units])
        frames = [Frame(t=f.t, source=f.source, markers=f.markers * factor, marker_names=f.marker_names,
                        t_sender=f.t_sender, number=f.number) for f in frames]
        note = f", converted {units} -> {to_units}"
    source = ReplaySource(frames)
    fps = 60.0 if fps is None else fps
    log(f"replay: {args.session} ({take.description}{note}; {source.duration:.2f} s) on {args.character}, "
        "through the solve as --input markers")
    return source, None, fps


def _report(args, result, path: str, fps: float, source, weights, log) -> None:
    c = result.counters
    log(f"replay: {result.n_ticks} ticks at {fps:g} fps, {path} path; frames received "
        f"{c['frames_received']}, stale dropped {c['stale_dropped']}, non-finite rejected "
        f"{c['nonfinite_rejected']}, ticks without a new frame {c['ticks_without_new_frame']}, "
        f"late ticks {c['late_ticks']}" + (" (window closed)" if result.closed_by_window else ""))
    if getattr(source, "missing", 0):
        log(f"replay: warning: the live ticks drew {source.missing} frames the recording lacks "
            "(packets dropped by the recorder); the weights differ from the live run's from there on")
    log(result.timer.table())
    if args.stats:
        log(json.dumps({"n_ticks": result.n_ticks, "path": path, "counters": c,
                        "timings_ms": result.timings}, sort_keys=True))
    if getattr(args, "dump_weights", None) is not None:
        from facepuppet.runtime.outputs import write_atomic

        write_atomic(args.dump_weights, lambda temp: np.save(temp, weights.array))
        log(f"replay: wrote the weights of {result.n_ticks} ticks to {args.dump_weights}")
    if args.out is not None:
        log(f"replay: wrote {result.n_ticks} PNGs to {args.out}")
    if getattr(args, "video", None) is not None:
        log(f"replay: wrote {result.n_ticks} video frames to {args.video}")
    if getattr(args, "llf_out", None):
        log(f"replay: sent {result.n_ticks} Live Link Face packets to {args.llf_out}")
