"""``facepuppet run``: drive a character live from trackers over UDP.

Parse the options into their groups (:mod:`~facepuppet.runtime.session.options`), open a session on the
live feed (:mod:`~facepuppet.runtime.session.live_feed`: the receivers, the voice, the phone request, the
recording) with :func:`~facepuppet.runtime.session.assemble.open_session`, run its frame loop until
``--duration``, the window closes or Ctrl-C, and report.

Each tick takes the newest frame (older ones are dropped and counted, never queued), runs the stage chain
(filter, calibrate, gain/clamp, tracking-loss easing; the marker solve, kernel PLS, gestures, elastic path
when asked), maps it onto the rig and draws; by default as soon as a new frame arrives (``--draw arrival``;
without new frames it redraws at ``--fps``). Calibration (a neutral captured over 0.5 s) happens at the start
with ``--calibrate``, whenever ``/facepuppet/calibrate`` arrives on the listening port, or with the key C in
a window. It listens on 127.0.0.1 unless ``--listen`` names another address; ``--allow`` keeps only the
listed sender IPs.
"""

from __future__ import annotations

import argparse
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.actuation.saturation import report_line
from facepuppet.runtime.control.options import ControlOptions
from facepuppet.runtime.errors import RecordingFailed, UsageError
from facepuppet.runtime.files.outputs import write_atomic
from facepuppet.runtime.inputs.capture_lag import FLOOR_CAP_S, MAX_LAG_S
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.session.assemble import SessionResult, open_session
from facepuppet.runtime.session.input_options import LiveInputOptions, RecordOptions
from facepuppet.runtime.session.live_feed import LiveFeed
from facepuppet.runtime.session.options import OutputOptions, PacingOptions, PanelOptions, PictureOptions, StageOptions

if TYPE_CHECKING:
    from facepuppet.runtime.live.loop import TickInfo
    from facepuppet.runtime.live.stages import Chain


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "run", help="drive a character live from a tracker over UDP (VMC, Face Cap, FaceOSC, markers, Live Link Face, "
                     "iFacialMocap, VTube Studio, OpenSeeFace)",
        description="Drive a character live from OSC / UDP tracker input on this machine.")
    p.add_argument("-c", "--character", type=Path, required=True, help="character .npz")
    LiveInputOptions.add_arguments(p)
    RecordOptions.add_arguments(p)
    PanelOptions.add_arguments(p)
    PictureOptions.add_arguments(p)
    PacingOptions.add_arguments(
        p, fps=60.0, fps_help="ticks per second (default 60); with --draw arrival, the redraw rate without new frames",
        duration=None, duration_help="stop after this many seconds", draw=True)
    OutputOptions.add_arguments(p, stats_help="print counters and latencies every second and at exit")
    StageOptions.add_arguments(p)
    ControlOptions.add_arguments(p)
    p.set_defaults(func=run_command)


@dataclass(frozen=True)
class RunPlan:
    """The checked options of one live run, every group built once from the command line."""

    character: Path
    inputs: LiveInputOptions
    stages: StageOptions
    pacing: PacingOptions
    picture: PictureOptions
    outputs: OutputOptions
    record: RecordOptions
    panel: PanelOptions
    force: bool = False
    control: ControlOptions = ControlOptions()

    @classmethod
    def from_args(cls, ns: argparse.Namespace) -> RunPlan:
        """Every option that can be checked before anything opens; ValueError naming the option otherwise."""
        inputs = LiveInputOptions.from_args(ns)
        stages = StageOptions.from_args(ns)
        record = RecordOptions.from_args(ns)
        if record.save_profile and stages.profile is None:
            raise UsageError("--save-profile: saves to --profile NAME|PATH; give one")
        if inputs.voice_only and ((stages.gestures is None and stages.voice is None)
                                  or (inputs.audio is None and inputs.audio_file is None)):
            raise UsageError("--input audio: needs --gestures GESTURES.npz or --voice VOICE.npz, and --audio [DEVICE] "
                             "or --audio-file WAV")
        if stages.voice is not None and inputs.audio is None and inputs.audio_file is None:
            raise UsageError(f"--voice {stages.voice}: needs --audio [DEVICE] or --audio-file WAV to listen to")
        picture = PictureOptions.from_args(ns)
        return cls(Path(ns.character), inputs, stages, PacingOptions.from_args(ns), picture,
                   OutputOptions.from_args(ns, picture), record, PanelOptions.from_args(ns),
                   bool(getattr(ns, "force", False)), ControlOptions.from_args(ns))


def plan_from_argv(argv: Sequence[str]) -> RunPlan:
    """The plan of ``facepuppet run ARGV...``, parsed as the command line would be (benchmarks, tests)."""
    parser = argparse.ArgumentParser(prog="facepuppet")
    register(parser.add_subparsers())
    return RunPlan.from_args(parser.parse_args(["run", *argv]))


def run_live(args: argparse.Namespace | RunPlan, stop_event: threading.Event | None = None,
             on_ready: Callable[[tuple[str, int]], None] | None = None,
             hooks: Sequence[Callable[[TickInfo], None]] = (), keep_weights: bool = False,
             on_chain: Callable[[Chain], None] | None = None,
             on_panel: Callable[[object], None] | None = None) -> SessionResult:
    """Run a live session and return what it did.

    ``stop_event`` set from another thread ends the run at the next tick; ``on_ready(address)`` is called
    once the sockets are bound, before the first tick; ``hooks`` are extra tick observers (benchmarks,
    tests). Each tick's weights are kept (``result.weights``) only with ``--dump-weights`` or
    ``keep_weights``: a show runs for hours. ``on_chain(chain)`` is called once the stage chain is built,
    ``on_panel(panel)`` with the run's DeskPanel once made. With ``--save-profile`` the config in force is
    saved to the profile at the end.
    """
    plan = args if isinstance(args, RunPlan) else RunPlan.from_args(args)
    character = Character.load(plan.character)
    feed = LiveFeed(plan.inputs, plan.stages, plan.pacing, plan.record, plan.picture, plan.panel, plan.character,
                    force=plan.force, stop_event=stop_event, control=plan.control.web is not None)
    with open_session(character, feed, stages=plan.stages, outputs=plan.outputs, picture=plan.picture,
                      panel=plan.panel, observers=hooks, keep_weights=keep_weights,
                      stats_interval_s=1.0 if plan.outputs.stats else None, on_chain=on_chain, on_panel=on_panel,
                      on_ready=on_ready, control=plan.control) as session:
        result = session.run()
        if plan.record.save_profile and session.chain.profile is not None and session.chain.filter is not None:
            session.chain.profile.save(session.chain.filter.current_config())
    return result


def run_command(args: argparse.Namespace) -> int:
    """The ``run`` command: returns the exit code (errors are mapped to exit codes in ``cli.main``; a recording
    that could not be written to its end stopped the run and raises RecordingFailed, exit 1)."""
    plan = RunPlan.from_args(args)
    result = run_live(plan)
    loop, c = result.loop, result.loop.counters
    fps = plan.pacing.fps
    pace = (f"at {fps:g} fps" if plan.pacing.draw == "tick" or plan.inputs.voice_only
            else f"on arrival (idle redraw {fps:g} fps)")
    print(f"run: {loop.n_ticks} ticks {pace}, {result.path} path; frames received "
          f"{c['frames_received']}, stale dropped {c['stale_dropped']}, non-finite rejected "
          f"{c['nonfinite_rejected']}, late ticks "
          f"{c['late_ticks']} (skipped {c['skipped_ticks']})" + (" (window closed)" if loop.closed_by_window else ""))
    line = report_line(result.saturation, plan.outputs.stats)
    if line is not None:
        print(f"run: {line}")
    mic = result.counters.get("microphone")
    if mic is not None:
        print(f"run: microphone: {mic['read']} of {mic['blocks']} blocks read, {mic['stale_dropped']} dropped as stale "
              f"(the stalest {mic['max_stale_lag_ms']} ms behind the capture clock); the most a block read lagged "
              f"{mic['max_read_lag_ms']} ms (bound: {MAX_LAG_S * 1000:g} ms past the standing latency, at most "
              f"{(MAX_LAG_S + FLOOR_CAP_S) * 1000:g} ms; at the end {mic['bound_ms']} ms); "
              f"{mic['status_errors']} flagged by PortAudio")
    if plan.outputs.stats:
        print("\n".join(result.stats.final()))
    report_outputs("run", plan.outputs, result)
    failure = result.recorder.failure if result.recorder is not None else None
    if failure is not None:  # the run stopped there; nothing may read as recorded
        raise RecordingFailed(failure)
    if plan.record.record is not None:
        print(f"run: recorded to {plan.record.record}")
    return 0


def report_outputs(command: str, outputs: OutputOptions, result: SessionResult) -> None:
    """The lines saying what a session wrote and sent (``run`` and ``replay``); writes ``--dump-weights``."""
    n = result.loop.n_ticks
    if outputs.dump_weights is not None:
        write_atomic(outputs.dump_weights, lambda temp: np.save(temp, result.weights.array))
        print(f"{command}: wrote the weights of {n} ticks to {outputs.dump_weights}")
    if outputs.out is not None:
        pngs = result.outputs.pngs
        print(f"{command}: wrote {pngs.written if pngs is not None else n} PNGs to {outputs.out}"
              + (f" (frame_00000.png to {pngs.last_path.name}; their ticks and times in {pngs.INDEX})"
                 if pngs is not None and pngs.last_path is not None else ""))
    if outputs.video is not None:
        print(f"{command}: wrote {n} video frames to {outputs.video.path}")
    if outputs.llf_out is not None:
        print(f"{command}: sent {n} Live Link Face packets to {outputs.llf_out[0]}:{outputs.llf_out[1]}")
    if outputs.vmc_out is not None:
        print(f"{command}: sent {n} ticks as VMC to {outputs.vmc_out[0]}:{outputs.vmc_out[1]}")
    report_live_pictures(command, outputs, result)


def report_live_pictures(command: str, outputs: OutputOptions, result: SessionResult) -> None:
    """The lines of the virtual camera and the stream: pictures sent and dropped (the loop never waits)."""
    camera, stream = result.outputs.virtual_camera, result.outputs.stream
    if outputs.virtual_camera is not None:
        if camera is None:
            print(f"{command}: no virtual camera (not available; said at the start)")
        else:
            c = camera.counters
            print(f"{command}: sent {c['sent']} frames to the virtual camera {camera.device}, "
                  f"dropped {c['dropped']}" + (f" (stopped: {camera.handoff.failure})" if c["failed"] else ""))
    if stream is not None:
        c = stream.counters
        print(f"{command}: streamed {c['sent']} frames to {stream.plan.given}, dropped {c['dropped']}"
              + (f" (stopped: {stream.handoff.failure})" if c["failed"] else ""))
