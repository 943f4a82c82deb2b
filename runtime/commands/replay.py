"""``facepuppet replay``: play a recording on a character through the live frame loop.

Parse the options into their groups (:mod:`~facepuppet.runtime.session.options`), open a session on the
recording feed (:mod:`~facepuppet.runtime.session.recording_feed`: a session file, a Live Link Face CSV or a
marker take, on recorded time) with :func:`~facepuppet.runtime.session.assemble.open_session`, run it and
report. The stage chain is ``run``'s, built by the same function from the same options, and every output of
``run`` (``--vmc-out``, ``--llf-out``, ``--events-out``, ``--video``, ``--out``, ``--dump-weights``) works
here too; a replay that sends anything is paced to real time, as a receiver expects.

Ctrl-C or SIGTERM stops a replay at its next tick: the outputs are completed (a video with its end, every PNG
whole), the summary is printed as at the end of the take, with the signal that stopped it, and the exit code
is the shell's ``128 + signal`` (130, 143), so a script does not take a cut replay for a whole one.
"""

from __future__ import annotations

import argparse
import signal
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from facepuppet.runtime.actuation.saturation import report_line
from facepuppet.runtime.commands.run import report_outputs
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.files.json_limits import dumps_strict
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.session.assemble import SessionResult, open_session
from facepuppet.runtime.session.input_options import ReplayInputOptions
from facepuppet.runtime.session.options import OutputOptions, PacingOptions, PictureOptions, StageOptions
from facepuppet.runtime.session.recording_feed import RecordingFeed

if TYPE_CHECKING:
    from facepuppet.runtime.protocols import TickObserver
    from facepuppet.runtime.render.gl_context import GLTarget


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "replay",
        help="play a recorded session or Live Link Face CSV on a character",
        description="Play a recording (session file or Live Link Face CSV) on a character through "
                    "the frame loop, on recorded time.",
    )
    ReplayInputOptions.add_arguments(p)
    p.add_argument("-c", "--character", type=Path, required=True, help="character .npz")
    PictureOptions.add_arguments(p, headless_help="render offscreen through EGL, as fast as possible")
    PacingOptions.add_arguments(
        p, fps=None, fps_help="ticks per second of recorded time (default: the live run's for a live recording, "
                              "else the take's own frame rate, read from its times, so each frame is drawn once; "
                              "60 when its times have no steady rate)",
        duration=None, duration_help="seconds to play (default: the whole recording)")
    OutputOptions.add_arguments(p, stats_help="also print the counters and timings as one JSON line",
                                sound_help="with --video, the sound track (a recording keeps audio levels, not "
                                           "samples)")
    StageOptions.add_arguments(p)
    p.set_defaults(func=run_replay)


@dataclass(frozen=True)
class ReplayPlan:
    """The checked options of one replay, every group built once from the command line."""

    character: Path
    replay: ReplayInputOptions
    stages: StageOptions
    pacing: PacingOptions
    picture: PictureOptions
    outputs: OutputOptions

    @classmethod
    def from_args(cls, ns: argparse.Namespace) -> ReplayPlan:
        """Every option that can be checked before anything opens; ValueError naming the option otherwise."""
        stages = StageOptions.from_args(ns)
        if getattr(ns, "audio_file", None) is not None and getattr(ns, "video", None) is None:
            raise UsageError("--audio-file: in a replay it is the sound track of --video FILE; give --video too")
        picture = PictureOptions.from_args(ns)
        return cls(Path(ns.character), ReplayInputOptions.from_args(ns, stages), stages,
                   PacingOptions.from_args(ns, fps=None), picture, OutputOptions.from_args(ns, picture))


def replay(plan: ReplayPlan, keep_weights: bool = False, *, context: GLTarget | None = None,
           observers: Sequence[TickObserver] = (), keeps_pictures: bool = False
           ) -> tuple[SessionResult, RecordingFeed]:
    """Play the plan's recording; the result and the feed (its report).

    ``context``, ``observers`` and ``keeps_pictures`` are :func:`open_session`'s: ``facepuppet batch`` plays
    each job through this function in its worker's one headless context, its frames at chosen times kept by an
    observer of its own.
    """
    character = Character.load(plan.character)
    video = plan.outputs.video
    feed = RecordingFeed(plan.replay, plan.stages, plan.pacing, plan.character,
                         progress_label="replay" if video is None else f"replay --video {video.path.name}")
    with open_session(character, feed, stages=plan.stages, outputs=plan.outputs, picture=plan.picture,
                      keep_weights=keep_weights, context=context, observers=observers,
                      keeps_pictures=keeps_pictures) as session:
        result = session.run()
    return result, feed


def run_replay(args: argparse.Namespace) -> int:
    """Run the ``replay`` command from parsed ``args``; returns the exit code."""
    plan = ReplayPlan.from_args(args)
    result, feed = replay(plan)
    loop, c = result.loop, result.loop.counters
    print(f"replay: {loop.n_ticks} ticks at {result.fps:g} fps, {result.path} path; frames received "
          f"{c['frames_received']}, stale dropped {c['stale_dropped']}, non-finite rejected "
          f"{c['nonfinite_rejected']}, ticks without a new frame {c['ticks_without_new_frame']}, "
          f"late ticks {c['late_ticks']}" + (" (window closed)" if loop.closed_by_window else ""))
    if feed.missing_line():
        print(feed.missing_line())
    print(loop.timer.table())
    saturation = result.saturation
    line = report_line(saturation, plan.outputs.stats)
    if line is not None:
        print(f"replay: {line}")
    if plan.outputs.stats:
        summary = {"n_ticks": loop.n_ticks, "path": result.path, "counters": c, "timings_ms": loop.timings}
        if saturation is not None:
            summary["saturation"] = saturation.fractions()
        for sink in (result.outputs.virtual_camera, result.outputs.stream):
            if sink is not None:  # pictures sent and dropped, the loop's and the sender's ms
                summary[sink.name] = sink.costs()
        print(dumps_strict(summary, sort_keys=True))
    report_outputs("replay", plan.outputs, result)
    if feed.events_line():
        print(feed.events_line())
    stopped = feed.stopped_by
    if stopped is None:
        return 0
    total = feed.progress.total if feed.progress is not None else None
    print(f"replay: stopped by {stopped} after {loop.n_ticks}" + (f" of {total:g}" if total else "")
          + " ticks; what was written above is complete")
    return 128 + int(getattr(signal, stopped))
