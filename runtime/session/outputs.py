"""A session's outputs, built once from :class:`~facepuppet.runtime.session.options.OutputOptions`, the same
for ``run`` and ``replay``.

Every output is a tick observer (:class:`~facepuppet.runtime.protocols.TickObserver`), called by the frame
loop once the GPU is done with a tick, in this order: the weight log, PNG frames, the video, the caller's
observers (the live stats, a benchmark's probe), then what is sent (VMC, Live Link Face, the virtual camera,
the stream: the last two read the pixels back once between them and hand them to their own threads). Tracking
events (``--events-out``, and ``--vmc-out``'s copy) are not per tick: the sender listens on the session's
bus. Each output is registered on the session's ``ExitStack`` when it
opens, so whatever opened is closed however the session ends; a video is completed only when the session
ends normally, and removed (never left half-written) when it fails.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from facepuppet.runtime.live.events_out import TrackingEventSender
from facepuppet.runtime.live.frame_handoff import TickReadback
from facepuppet.runtime.live.llf_out import LlfSender
from facepuppet.runtime.live.sinks import PngSink, WeightLog, png_workers
from facepuppet.runtime.live.stream_out import StreamSink, open_stream
from facepuppet.runtime.live.video_out import VideoSink
from facepuppet.runtime.live.virtual_camera import VirtualCameraSink, open_virtual_camera
from facepuppet.runtime.live.vmc_out import VmcSender, pipeline_status

if TYPE_CHECKING:
    from facepuppet.runtime.cli.progress import Progress
    from facepuppet.runtime.live.bus import SessionBus
    from facepuppet.runtime.live.stages import Chain
    from facepuppet.runtime.protocols import TickObserver
    from facepuppet.runtime.session.options import OutputOptions

logger = logging.getLogger(__name__)


@dataclass
class Outputs:
    """The outputs a session opened.

    Attributes
    ----------
    observers : list of TickObserver, in the order the loop calls them
    counters : dict of counter group name -> counters (``vmc_out``, ``llf_out``, ``events_out``)
    weights : WeightLog or None (``--dump-weights``, or kept for the caller)
    pngs : PngSink or None; video : VideoSink or None
    vmc, llf : the senders or None; events : TrackingEventSender or None
    virtual_camera : VirtualCameraSink or None (not asked for, or the camera could not be opened)
    stream : StreamSink or None
    """

    observers: list = field(default_factory=list)
    counters: dict = field(default_factory=dict)
    weights: WeightLog | None = None
    pngs: PngSink | None = None
    video: VideoSink | None = None
    vmc: VmcSender | None = None
    llf: LlfSender | None = None
    events: TrackingEventSender | None = None
    virtual_camera: VirtualCameraSink | None = None
    stream: StreamSink | None = None


def _complete_or_abort(video: VideoSink) -> Callable:
    """An exit callback for the stack: the video completed when the session ends normally, else removed."""
    def exit_(exc_type, exc, tb) -> bool:
        if exc_type is None:
            video.close()
        else:
            video.abort()
        return False
    return exit_


def open_outputs(options: OutputOptions, stack: contextlib.ExitStack, chain: Chain, bus: SessionBus, fps: float,
                 *, keep_weights: bool = False, progress: Progress | None = None, paced: bool = False,
                 extra: Sequence[TickObserver] = (), log: Callable[[str], None] = logger.info) -> Outputs:
    """Open every output ``options`` asks for; each is closed by ``stack``.

    Parameters
    ----------
    chain : the session's stage chain (the channel names sent, the drive's expressions, the filter's status)
    bus : the session's bus (tracking events)
    fps : float, the tick grid (the video's time base)
    keep_weights : bool, keep every tick's weights even without ``--dump-weights`` (tests, benchmarks)
    progress : Progress or None, told the video's frame count
    paced : bool, the session is paced to real time (said with what is sent)
    extra : observers of the caller's, called after the pictures and before what is sent
    """
    outputs = Outputs()
    if keep_weights or options.dump_weights is not None:
        outputs.weights = WeightLog()
        outputs.observers.append(outputs.weights)
    if options.out is not None:
        outputs.pngs = PngSink(options.out, workers=png_workers())
        stack.callback(outputs.pngs.close)
        outputs.observers.append(outputs.pngs)
    if options.video is not None:
        video = VideoSink(options.video, fps, progress=progress)
        stack.push(_complete_or_abort(video))
        log(options.video.describe(fps))
        outputs.video = video
        outputs.observers.append(video)
    outputs.observers.extend(extra)
    pace = " (paced to real time)" if paced else ""
    if options.vmc_out is not None:
        drive = chain.drive
        own = () if drive is None else tuple(p or n for n, p in zip(drive.expression_names, drive.presets))
        sender = stack.enter_context(contextlib.closing(VmcSender(
            options.vmc_out[0], options.vmc_out[1], chain.names, extra=options.vmc_extra,
            presets=options.vmc_presets, expressions=own, names_mode=options.vmc_names,
            status=pipeline_status(chain.filter) if chain.filter is not None else None)))
        log(sender.describe() + pace)
        outputs.vmc = sender
        outputs.observers.append(sender.on_tick)
        outputs.counters["vmc_out"] = sender.counters
    if options.llf_out is not None:
        llf = stack.enter_context(contextlib.closing(LlfSender(options.llf_out[0], options.llf_out[1], chain.names)))
        log(llf.describe() + pace)
        outputs.llf = llf
        outputs.observers.append(llf.on_tick)
        outputs.counters["llf_out"] = llf.counters
    _open_live_pictures(options, stack, outputs, fps, log)
    if options.vmc_out is not None or options.events_out is not None:
        if chain.filter is None:
            if options.events_out is not None:  # (--vmc-out alone: its tracking flag, nothing to say)
                log("events: no filter stage (--pipeline), so no tracking lost/found events to send")
        else:
            events = stack.enter_context(contextlib.closing(TrackingEventSender(
                [options.events_out] if options.events_out else [], [options.vmc_out] if options.vmc_out else [])))
            log(events.describe())
            bus.on_tracking(events)
            outputs.events = events
            outputs.counters["events_out"] = events.counters
    return outputs


def _open_live_pictures(options: OutputOptions, stack: contextlib.ExitStack, outputs: Outputs, fps: float,
                        log: Callable[[str], None]) -> None:
    """The virtual camera and the stream, at the run's frame rate (``--fps``; else the session's), sharing one
    read-back of each tick's pixels as the framebuffer holds them (the video reads its own, finished)."""
    readback = TickReadback()
    if options.virtual_camera is not None:
        plan = options.virtual_camera
        camera = open_virtual_camera(plan, plan.fps or fps, readback, log)
        if camera is not None:
            stack.callback(camera.close)
            outputs.virtual_camera = camera
            outputs.observers.append(camera)
            outputs.counters["virtual_camera"] = camera.counters
    if options.stream is not None:
        plan = options.stream
        stream = open_stream(plan, plan.fps or fps, readback, log)
        stack.callback(stream.close)
        outputs.stream = stream
        outputs.observers.append(stream)
        outputs.counters["stream"] = stream.counters
