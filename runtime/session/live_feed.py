"""The live feed of ``run``: UDP receivers for the trackers, the voice, the phone request, the recording.

One UDP socket per tracker input, read by a child process
(:class:`~facepuppet.runtime.inputs.udp_process.UdpProcessSource`; ``--receiver thread``: a thread of this
process, :class:`~facepuppet.runtime.inputs.udp.UdpSource`) that decodes the input kind's datagrams into
frames. The first tracker is the frame loop's own source; the others, and the voice, are the ``mix``
stage's sources (:mod:`~facepuppet.runtime.live.mix`). The loop draws as soon as a frame of any input
arrives (``--draw arrival``, :class:`~facepuppet.runtime.inputs.arrival.ArrivalWaiter`) or on a fixed grid.

The parts are opened in an order in which none needs one not made yet: the receivers hand every accepted
datagram to the session's bus (the recorder listens there) and count calibrate messages for the bus (the
filter stage reads the count there), so the source is made before the recorder, which is made from the
source (its frame counts) and hears the chain's config through the bus.
"""

from __future__ import annotations

import contextlib
import sys
import threading
from collections.abc import Callable
from dataclasses import replace
from importlib.util import find_spec
from pathlib import Path
from typing import TYPE_CHECKING, Any

from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.gestures.layer import VoiceOnlySource
from facepuppet.runtime.inputs.arrival import ArrivalWaiter
from facepuppet.runtime.inputs.audio import MicLevel, open_audio
from facepuppet.runtime.inputs.osc import CALIBRATE_ADDRESS
from facepuppet.runtime.inputs.phone import PhoneRequester
from facepuppet.runtime.inputs.udp import UdpSource
from facepuppet.runtime.inputs.udp_process import UdpProcessSource
from facepuppet.runtime.live.loop import ARRIVAL_GRID_HZ, WallClock
from facepuppet.runtime.live.mix import MixStage, VoiceMixSource, check_mix_sources, follow_config
from facepuppet.runtime.live.profiles import config_to_toml
from facepuppet.runtime.live.sinks import RecordingHook
from facepuppet.runtime.live.stages import make_input_adapter
from facepuppet.runtime.recording.recorder import PacketRecorder
from facepuppet.runtime.recording.switch import SwitchableRecorder
from facepuppet.runtime.session.feeds import ChainInputs, FeedParts
from facepuppet.runtime.session.stop_signals import StopOnSignals
from facepuppet.runtime.voice.source import MicVoice, WavVoice, load_voice

if TYPE_CHECKING:
    from facepuppet.runtime.live.bus import SessionBus
    from facepuppet.runtime.live.loop import FrameLoop, LoopResult
    from facepuppet.runtime.live.stages import Chain
    from facepuppet.runtime.model.character import Character
    from facepuppet.runtime.render.gl_context import GLTarget
    from facepuppet.runtime.session.input_options import LiveInputOptions, RecordOptions
    from facepuppet.runtime.session.options import PacingOptions, PanelOptions, PictureOptions, StageOptions

THREAD_SWITCH_INTERVAL_S = 0.0005  # GIL switch interval while a receive *thread* shares the loop's process


def wants_panel(picture: PictureOptions, panel: PanelOptions) -> bool:
    """Whether a run may show the panel (a window, or ``--headless --panel``) and imgui-bundle is there."""
    if picture.headless and not panel.panel:
        return False
    return find_spec("imgui_bundle") is not None


def voice_line(audio: Any) -> str:
    """What a run with the voice as its only input plays: a WAV file (read on the run's clock, to its end) or
    a microphone (listened to); it has no network address to name."""
    path = getattr(audio, "path", None)
    if path is not None:
        return (f"run: playing the voice from {path} ({audio.duration:.2f} s, {audio.sample_rate:g} Hz) on the "
                "run's clock")
    return f"run: listening to the voice on {getattr(audio, 'device_name', 'the default input device')}"


class LiveFeed:
    """The trackers and the voice of ``run`` (see the module docstring).

    Parameters
    ----------
    inputs, stages, pacing, record, picture, panel : the run's option groups
    character_path : Path, the character's file (a recording's header names it)
    force : bool, ``--force`` (the ``--record`` file may be overwritten)
    stop_event : threading.Event, set (Ctrl-C, SIGTERM, a caller) to end the run at its next tick
    """

    def __init__(self, inputs: LiveInputOptions, stages: StageOptions, pacing: PacingOptions,
                 record: RecordOptions, picture: PictureOptions, panel: PanelOptions, character_path: Path,
                 force: bool = False, stop_event: threading.Event | None = None, control: bool = False) -> None:
        self.inputs, self.stages, self.pacing, self.record = inputs, stages, pacing, record
        self.character_path = Path(character_path)
        self.force = force
        self.stop_event = stop_event or threading.Event()
        # only the panel and the control API (``--web``) start a recording once the run ticks
        self.recordable = record.record is not None or wants_panel(picture, panel) or control
        self.midrun = wants_panel(picture, panel) or control
        self.control = control
        self.title = f"facepuppet run ({inputs.input})"
        self.audio = None
        self.voice_outputs: tuple[str, ...] = ()  # the VOICE records' channels (--voice)
        self.adapter = None  # the loop's input adapter, once open (None for the voice alone)
        self.fps = float(pacing.fps)
        # draw on arrival: tick labels on a 1 kHz grid (so a replay can follow them), redraws at --fps when idle
        self.arrival = pacing.draw == "arrival" and not inputs.voice_only
        self.loop_fps, self.idle_fps = (ARRIVAL_GRID_HZ, self.fps) if self.arrival else (self.fps, None)

    # -- before the chain --------------------------------------------------------------------------

    def prepare(self, character: Character, stack: contextlib.ExitStack,
                log: Callable[[str], None]) -> ChainInputs:
        # from here on a SIGTERM or Ctrl-C ends the run cleanly (the loop stops at its next tick)
        stack.enter_context(StopOnSignals(self.stop_event))
        inputs = self.inputs
        table = load_voice(self.stages.voice) if self.stages.voice is not None else None
        if table is not None and inputs.audio is None and inputs.audio_file is None:
            raise UsageError(f"--voice {self.stages.voice}: needs --audio [DEVICE] or --audio-file WAV to listen to")
        if inputs.audio is not None or inputs.audio_file is not None:
            # a microphone is started by run(), when the loop is about to tick: samples captured during the
            # chain's and the window's set-up would only be queued, stale, ahead of the first tick's
            self.audio = open_audio(device=inputs.audio, wav=inputs.audio_file, log=log, start=False)
            if self.audio is not None:
                stack.callback(self.audio.close)
        voice = None
        if table is not None:
            voice = self._open_voice(table, log)
            if voice is not None:
                stack.callback(voice.close)
                self.voice_outputs = voice.outputs
        return ChainInputs(kind=inputs.kind, label=inputs.label, filtered=True, voice_only=inputs.voice_only,
                           audio_level=self.audio.level if self.audio is not None else None,
                           keep_snapshots=self.midrun, packets=self.recordable, voice=voice)

    def _open_voice(self, table, log: Callable[[str], None]):
        """The voice's channel source of ``--voice``: the WAV on the run's clock, or the microphone's blocks (None,
        said, when there is no microphone: the run goes on without the voice)."""
        delay_s = self.stages.voice_delay / 1000.0
        if not 0.0 <= delay_s <= 1.0:
            raise UsageError(f"--voice-delay: expected 0..1000 ms, got {self.stages.voice_delay:g}")
        if self.inputs.audio_file is not None:
            return WavVoice(self.inputs.audio_file, table, delay_s)
        if self.audio is None or not hasattr(self.audio, "meter"):
            log(f"--voice {self.stages.voice}: no audio input, so no voice; the run goes on without it")
            return None
        return MicVoice(self.audio, table, delay_s)

    # -- once the chain exists ---------------------------------------------------------------------

    def open(self, stack: contextlib.ExitStack, chain: Chain, bus: SessionBus,
             log: Callable[[str], None]) -> FeedParts:
        inputs = self.inputs
        source = self._open_source(chain, bus, log)
        bus.count_requests(lambda: source.watched)
        counters: dict = {"udp": source.counters}
        recorder = self._open_recorder(chain, bus, source, log) if self.recordable else None
        if recorder is not None:
            stack.callback(recorder.close)  # close() waits for every recording's file
            if self.record.record is not None:
                recorder.start(self.record.record)
        if inputs.voice_only:
            source.duration = getattr(self.audio, "duration", None)
        source.start()
        stack.callback(source.stop)
        if inputs.voice_only:
            log(voice_line(self.audio))
        else:
            log(f"run: listening for {inputs.input} on {source.address[0]}:{source.address[1]}"
                + (f" (only from {', '.join(sorted(inputs.allow))})" if inputs.allow else ""))
        if inputs.mix:
            self._open_mix(stack, chain, bus, log)
        requester = self._start_phone(source, log)
        if requester is not None:
            stack.callback(requester.stop)
            counters["phone"] = requester.counters
        if isinstance(self.audio, MicLevel):
            counters["microphone"] = self.audio.counters
        if chain.filter is not None:
            counters["pipeline"] = chain.filter.counters
        if chain.mix is not None:
            counters["mix"] = chain.mix.counters
        observers = []
        if recorder is not None:
            counters["record"] = recorder.counters
            observers.append(RecordingHook(recorder, source, chain.audio, voice=chain.voice, mix_sources=[
                s for _, s in chain.mix.tracker_sources()] if chain.mix else ()))
        return FeedParts(source, self.loop_fps, duration=self.pacing.duration, idle_fps=self.idle_fps,
                         catch_up=True, wake=self._arrival_wake(source, chain), address=source.address,
                         counters=counters, recorder=recorder, observers=observers, live=True,
                         input_name=inputs.input)

    def _open_source(self, chain: Chain, bus: SessionBus, log: Callable[[str], None]):
        """The live frame source: the UDP receiver of ``--receiver``, or none for ``--input audio``."""
        inputs = self.inputs
        if inputs.voice_only:
            return VoiceOnlySource(None)
        adapter = make_input_adapter(inputs.input, chain.extra_names, log=log, marker_units=self.stages.marker_units,
                                     to_units=chain.marker_units, face_id=inputs.face_id)
        self.adapter = adapter
        cls = UdpProcessSource if inputs.receiver == "process" else UdpSource
        return cls(adapter, host=inputs.host, port=inputs.port, allow=inputs.allow,
                   on_packet=bus.packet_sink(None), watch=CALIBRATE_ADDRESS)

    def _record_info(self, bus: SessionBus) -> dict:
        """The header facts of a recording: enough for ``replay`` to rebuild the same chain (``config``: the live
        config in force when it starts, as TOML, neutral included)."""
        info = {"character": str(self.character_path), **self.inputs.recorded(), "fps": self.loop_fps,
                "idle_fps": self.idle_fps,
                "options": {**self.stages.recorded(),
                            "face_id": None if self.inputs.face_id is None else str(self.inputs.face_id)}}
        if bus.config is not None:
            info["config"] = config_to_toml(bus.config)
        if self.voice_outputs:
            info["voice_channels"] = list(self.voice_outputs)
        return info

    def _open_recorder(self, chain: Chain, bus: SessionBus, source, log) -> SwitchableRecorder:
        """The run's :class:`~facepuppet.runtime.recording.switch.SwitchableRecorder` (``--record`` and the
        panel's Record / Stop): it hears the datagrams, config changes and tracking events on the bus."""
        inputs, record = self.inputs, self.record.record

        def open_recorder(path: Path) -> PacketRecorder:
            info = self._record_info(bus)  # the config in force now
            if holder.ticks_seen:
                info["started_at_t"] = holder.last_t  # a recording the panel started during the run
            return PacketRecorder(path, inputs.input, info=info, overwrite=self.force and path == record)

        make_adapter = None if inputs.voice_only else (
            lambda: make_input_adapter(inputs.input, (), log=lambda s: None, face_id=inputs.face_id))
        holder = SwitchableRecorder(
            open_recorder, record.parent if record is not None else Path.cwd(), make_adapter=make_adapter,
            frames_taken=lambda: source.frames_taken, log=log,
            on_failure=self.stop_event.set,  # a recording that cannot be written stops the run (run says so)
            pipeline=chain.filter if self.midrun else None,  # only the panel starts one mid-run
            refuse_midrun="not with several inputs (their frame counts cannot be aligned mid-run); use --record FILE"
            if inputs.mix else "")

        def packet(data: bytes, t: float, sender, tag: str | None) -> None:
            if tag is None:
                holder.put(data, t, sender)
            else:
                holder.tagged(tag)(data, t, sender)

        bus.on_packet(packet)
        bus.on_config(lambda t, config: holder.put_config(t, config_to_toml(config)))
        bus.on_tracking(holder.put_event)
        bus.on_control(holder.put_control)
        return holder

    def _open_mix(self, stack: contextlib.ExitStack, chain: Chain, bus: SessionBus, log) -> None:
        """Start the other inputs' receivers and put the ``mix`` stage in the chain."""
        inputs = self.inputs
        sources = {}
        for m in inputs.mix:
            if m.kind == "audio":
                if chain.audio is None:
                    raise UsageError("--input audio: no audio level (--audio found no device); the voice input "
                                     "needs one")
                sources[m.name] = VoiceMixSource(chain.audio.level, chain.config.loss, voice=chain.voice)
                continue
            adapter = make_input_adapter(m.kind, chain.extra_names, log=log, face_id=inputs.face_id)
            cls = UdpProcessSource if inputs.receiver == "process" else UdpSource
            src = cls(adapter, host=m.host, port=m.port, allow=inputs.allow, on_packet=bus.packet_sink(m.name),
                      watch=CALIBRATE_ADDRESS)
            src.start()
            stack.callback(src.stop)
            sources[m.name] = src
            log(f"run: listening for {m.kind} ({m.name}) on {src.address[0]}:{src.address[1]}")
        names = (inputs.input, *(m.name for m in inputs.mix))
        settings = chain.config.mix
        if settings.order is None:
            settings = replace(settings, order=tuple(inputs.names))
        check_mix_sources(settings, names, chain.config.path or "(defaults)")
        stage = MixStage(names, sources, settings, chain.config.timeout_s)
        chain.add_mix(stage, label="+".join(inputs.names))
        if chain.filter is not None:  # a config applied live (the panel) changes the mix's orders too
            bus.on_config(follow_config(stage, tuple(inputs.names), log))
        log(f"mix: {len(names)} sources, order {' > '.join(settings.order)}"
            + "".join(f"; {r}: {' > '.join(o)}" for r, o in settings.regions.items())
            + (f"; {len(settings.channels)} channels with their own order" if settings.channels else ""))

    def _start_phone(self, source, log) -> PhoneRequester | None:
        """The running requester of ``--phone`` (None without it; a note when the kind needs one)."""
        adapter = self.adapter
        if not hasattr(adapter, "phone_request"):
            return None
        phone, listen_port = self.inputs.phone, source.address[1]
        if phone is None:
            log(f"run: no --phone: the {adapter.kind} app must be told to send here itself"
                + (" (VTube Studio's phone protocol streams only on request: give --phone IP)"
                   if adapter.kind == "vtubestudio" else ""))
            return None
        host, port = phone
        requester = PhoneRequester(host, port, adapter.phone_request(listen_port), adapter.phone_every_s, log=log)
        log(f"run: asking the phone at {host}:{port} to stream here (every {adapter.phone_every_s:g} s)"
            + (f"; note: iFacialMocap sends to port {adapter.default_port}, this run listens on {listen_port}"
               if adapter.kind == "ifacialmocap" and listen_port != adapter.default_port else ""))
        return requester.start()

    @staticmethod
    def _arrival_wake(source, chain: Chain):
        """With other tracker inputs (the mix), what wakes the loop when any input has a frame; None: the loop's
        own source's ``wait_for_frame``."""
        trackers = [s for _, s in chain.mix.tracker_sources()] if chain.mix is not None else []
        if not trackers or not all(hasattr(s, "pending") for s in (source, *trackers)):
            return None
        return ArrivalWaiter([source, *trackers]).wait

    # -- the loop ----------------------------------------------------------------------------------

    def clock(self, parts: FeedParts, target: GLTarget, paced: bool) -> WallClock:
        return WallClock()

    def stop(self) -> bool:
        return self.stop_event.is_set()

    def run(self, loop: FrameLoop, parts: FeedParts) -> LoopResult:
        """Run the loop until ``--duration``, the window closes or Ctrl-C (which sets the stop event)."""
        # A receive *thread* gives the GIL back on every recvfrom and must win it back from the busy frame
        # loop each time: a short switch interval keeps datagrams from waiting in the kernel (measured, 0.5 ms
        # vs the default 5 ms: arrival -> read p50 3 vs 7 ms, p99 16 vs 30 ms). A receive process needs none.
        # (The microphone's callback thread is left out: a short interval gave it no measured gain.)
        switch = sys.getswitchinterval()
        if isinstance(parts.source, UdpSource) or self.control:  # (``--web``: the control server's thread)
            sys.setswitchinterval(min(switch, THREAD_SWITCH_INTERVAL_S))
        if isinstance(self.audio, MicLevel):
            self.audio.start()
        try:
            return loop.run(parts.source, duration=parts.duration)
        finally:
            sys.setswitchinterval(switch)

    def counters_view(self, parts: FeedParts, groups: dict, chain: Chain) -> dict:
        """The stats' counter groups, the receivers' read afresh each time (they merge on access)."""
        return _LiveCounters(parts.source, groups, dict(chain.mix.tracker_sources()) if chain.mix else {})


class _LiveCounters(dict):
    """The stats' counter groups, with ``udp`` read afresh each time (UdpSource merges on access)."""

    def __init__(self, source, groups: dict, others: dict | None = None):
        super().__init__(groups)
        self._source = source
        self._others = others or {}  # the mix sources of a run with several inputs: "udp:NAME"

    def items(self):
        self["udp"] = self._source.counters
        for name, other in self._others.items():
            self[f"udp:{name}"] = other.counters
        return super().items()
