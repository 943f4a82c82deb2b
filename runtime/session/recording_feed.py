"""The recording feed of ``replay``: a session file, a Live Link Face CSV or a marker take, on recorded time.

Headless, a replay ticks as fast as the machine draws (:class:`~facepuppet.runtime.live.loop.RecordedClock`);
in a window, or when something is sent (VMC, Live Link Face, tracking events: a receiver expects real time),
it is paced to the wall clock. Either way tick ``k`` shows the recording at ``k / fps`` seconds, so two
replays give the same weights and the same images. Without ``--fps`` a take ticks at its own frame rate
(:mod:`~facepuppet.runtime.recording.take_rate`), window or not, so each frame is drawn once and the same
command gives the same pictures on a screen and headless.

A live recording (``run --record``) with TICK records replays tick for tick
(:class:`~facepuppet.runtime.recording.ticked_source.TickedSource`): the frames each live tick took, at its
tick times, at the live ``--fps`` (another ``--fps`` resamples instead). Its file is read once: the header
says the input kind and the options the live run had, so the stage chain is built first and the packets
are then decoded once, with the adapter the chain needs (the avatar's expression names for VMC, marker
units, the OpenSeeFace face the run followed). The audio levels it kept feed the ``audio`` stage, its
config and config changes the filter stage, its STATE record (a recording started mid-run) the filter's
starting state, so the same options give the live run's weights.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from facepuppet.runtime.cli.progress import Progress
from facepuppet.runtime.errors import InputFileError, UsageError
from facepuppet.runtime.files.json_limits import JsonLimitError, loads_limited
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.inputs.markers import UNIT_METRES
from facepuppet.runtime.live.loop import RecordedClock, WallClock
from facepuppet.runtime.live.mix import MixStage, VoiceMixSource, check_mix_sources, follow_config
from facepuppet.runtime.live.stages import RecordedLevels, make_input_adapter
from facepuppet.runtime.recording.readers import find_reader
from facepuppet.runtime.recording.replay_source import ReplaySource, check_time_order, open_recording
from facepuppet.runtime.recording.take_rate import take_rate
from facepuppet.runtime.recording.ticked_source import TickedSource, decode_live_recording, read_live_session
from facepuppet.runtime.session.feeds import ChainInputs, FeedParts
from facepuppet.runtime.session.stop_signals import StopOnSignals
from facepuppet.runtime.voice.source import load_voice
from facepuppet.runtime.voice.stage import RecordedVoice

if TYPE_CHECKING:
    from facepuppet.runtime.live.bus import SessionBus
    from facepuppet.runtime.live.loop import FrameLoop, LoopResult
    from facepuppet.runtime.live.pipeline import LivePipeline
    from facepuppet.runtime.live.stages import Chain
    from facepuppet.runtime.model.character import Character
    from facepuppet.runtime.recording.session import Session
    from facepuppet.runtime.recording.ticked_source import LiveRecording
    from facepuppet.runtime.render.gl_context import GLTarget
    from facepuppet.runtime.session.input_options import ReplayInputOptions
    from facepuppet.runtime.session.options import PacingOptions, StageOptions


FALLBACK_FPS = 60.0  # ticks per second of a replay whose take has no steady rate and no --fps
PIPED_EVERY_S = 30.0  # off a terminal, a progress line in the log this often


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


def _info(session: Session | None) -> dict:
    info = session.header.get("info") if session is not None and isinstance(session.header, dict) else None
    return info if isinstance(info, dict) else {}


def _recorded_face_id(info: dict) -> int | None:
    """The ``--face-id`` a live recording was made with (openseeface); None when it has none."""
    options = info.get("options")
    value = options.get("face_id") if isinstance(options, dict) else None
    try:
        return None if value is None else int(value)
    except (TypeError, ValueError):
        return None


def marker_take(path: Path) -> Any:
    """The recording a registered reader (a marker capture: TRC, C3D, CSV) makes of ``path``, or None."""
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except IsADirectoryError:
        return None
    reader = find_reader(path, head)
    return reader.read(path) if reader is not None else None


def compare_events(recorded: list, replayed: list) -> str:
    """The report line on the tracking events: as recorded, or where the replay's first differ."""
    def text(events):
        return ", ".join(f"{'found' if f else 'lost'} at {t:.3f} s" for t, f in events[:6]) + (
            ", ..." if len(events) > 6 else "")

    if [(round(t, 9), f) for t, f in recorded] == [(round(t, 9), f) for t, f in replayed]:
        return f"replay: tracking events as recorded ({len(replayed)}" + (f": {text(replayed)})" if replayed else ")")
    return (f"replay: warning: tracking events differ from the recording's: recorded {len(recorded)} "
            f"({text(recorded) or 'none'}), replayed {len(replayed)} ({text(replayed) or 'none'})")


def restore_state(pipeline: LivePipeline, state: tuple[float, str], path: Path | str,
                  log: Callable[[str], None]) -> None:
    """A recording started mid-run: the filter stage goes on from the state it had then (its STATE record).
    One over the JSON limits is refused (JsonLimitError naming the file and the record); one that cannot be
    used otherwise is said and left: the replay then starts the stage afresh."""
    t, text = state
    try:
        pipeline.restore_state(loads_limited(text, f"{path}: STATE record (the filter stage's state at t = {t:.3f} s)"))
    except JsonLimitError:
        raise
    except ValueError as exc:
        log(f"replay: warning: {path}: the filter stage's state at the recording's start (t = {t:.3f} s) is not "
            f"usable ({exc}); its first ticks may differ from the run")
        return
    log(f"replay: the filter stage goes on from its state at the recording's start (t = {t:.3f} s)")


class RecordingFeed:
    """A recording played through the session (see the module docstring).

    Parameters
    ----------
    replay, stages, pacing : the replay's option groups
    character_path : Path, named in the log lines
    progress_label : str, the progress line's label (the video's name when one is written)
    """

    def __init__(self, replay: ReplayInputOptions, stages: StageOptions, pacing: PacingOptions,
                 character_path: Path, progress_label: str = "replay") -> None:
        self.replay, self.stages, self.pacing = replay, stages, pacing
        self.path = replay.session
        self.character_path = character_path
        self.progress_label = progress_label
        self.title = f"facepuppet replay {self.path.name}"
        self.session: Session | None = None
        self.live: LiveRecording | None = None
        self.take: Any = None
        self.events: list = []  # the replay's tracking events, compared with the recording's at the end
        self.stop_event = threading.Event()
        self.signals: StopOnSignals | None = None
        self.progress: Progress | None = None

    # -- before the chain --------------------------------------------------------------------------

    def prepare(self, character: Character, stack: contextlib.ExitStack,
                log: Callable[[str], None]) -> ChainInputs:
        # from here on Ctrl-C or SIGTERM stops the replay at its next tick; what was written is completed
        self.signals = stack.enter_context(StopOnSignals(self.stop_event))
        self.session = session = read_live_session(self.path)
        info = _info(session)
        kind = info.get("input") if session is not None else None
        if session is None:
            self.take = marker_take(self.path)
            if self.take is not None:
                kind = self.take.kind
        self.kind = kind
        if kind == "audio" and self.stages.voice is None and getattr(self.stages, "gestures", None) is None:
            raise UsageError("replay: this recording's run drove the face from the voice (--input audio); give its "
                             "--voice VOICE.npz|PROFILE.toml or --gestures GESTURES.npz again (the sound and the "
                             "voice's channels are in the recording: no --audio or --audio-file)")
        self.filtered = filtered = self._filtered(info, log)
        levels = RecordedLevels(session.audio_levels) if session is not None and session.audio_levels else None
        config_text, schedule = self._recorded_config(info, filtered, log)
        return ChainInputs(kind=kind, label=f"replay({kind or 'frames'})", filtered=filtered,
                           voice_only=kind == "audio", audio_level=levels, config_text=config_text,
                           schedule=schedule, voice=self._recorded_voice(info))

    def _recorded_voice(self, info: dict) -> RecordedVoice | None:
        """The voice channels a ``--voice`` run kept, for ``replay --voice`` (its table names the channels)."""
        if self.stages.voice is None:
            return None
        table = load_voice(self.stages.voice)
        if self.session is None or not self.session.voice:
            raise InputFileError(f"{self.path}: --voice {self.stages.voice}: the recording kept no voice channels "
                                 "(it was not made by run --voice)")
        names = tuple(info.get("voice_channels") or table.outputs)
        n = {len(v) for _, v in self.session.voice}
        if n != {len(names)}:
            raise InputFileError(f"{self.path}: VOICE records: expected {len(names)} channels "
                                 f"(info.voice_channels), found {sorted(n)}")
        return RecordedVoice(names, self.session.voice)

    def _filtered(self, info: dict, log: Callable[[str], None]) -> bool:
        """Whether the filter stage runs: asked for, implied, or (by default) a live run's or a take's."""
        if self.replay.pipeline is False:
            return False
        if self.replay.implied_pipeline(self.stages):
            return True
        live_ticks = self.session is not None and bool(self.session.ticks)
        if live_ticks:
            recorded = dict(info.get("options", {}) or {})
            if isinstance(info.get("config"), str):  # the config itself is in the recording
                recorded.pop("config", None)
                recorded.pop("profile", None)
            recorded.pop("face_id", None)  # followed from the recording itself
            given = vars(self.stages)
            lacking = [f"--{name.replace('_', '-')} {value}" if value not in ("True", "False") else f"--{name}"
                       for name, value in recorded.items()
                       if value not in (None, "False", "0") and given.get(name) in (None, False, 0)]
            log("replay: a live recording: the filter stage runs as in the live run (--no-pipeline: the raw frames)"
                + (f"; the live run also had {' '.join(lacking)}: give the same to reproduce it" if lacking else ""))
        return live_ticks or self.take is not None

    def _recorded_config(self, info: dict, filtered: bool, log) -> tuple[tuple[str, str] | None, list]:
        """(where, TOML) of the config a live run started with, and its changes as (tick time, TOML, where), for
        a replay without --config or --profile (they win, and the live run's changes are not applied over
        them)."""
        text = info.get("config") if self.session is not None else None
        if not filtered or not isinstance(text, str):
            return None, []
        if self.stages.config is not None or self.stages.profile is not None:
            log("replay: the live run's recorded config (and its changes) is not used: --config/--profile given")
            return None, []
        changes = [(t, text, f"{self.path}: CONFIG record {i} (the config change at t={t:.3f} s)")
                   for i, (t, text) in enumerate(self.session.configs)]
        log("replay: the live run's config in force (recorded)"
            + (f" and its {len(changes)} change{'s' if len(changes) != 1 else ''} during the run" if changes else ""))
        return (f"{self.path}: session header field 'info.config' (the live run's config)", text), changes

    # -- once the chain exists ---------------------------------------------------------------------

    def open(self, stack: contextlib.ExitStack, chain: Chain, bus: SessionBus,
             log: Callable[[str], None]) -> FeedParts:
        if self.take is not None:
            self._check_take_layouts(chain)
            source, ticks, fps = self._take_source(chain.marker_units, log)
        else:
            if self.session is not None:
                face_id = _recorded_face_id(_info(self.session))
                units = self.stages.marker_units
                self.live = decode_live_recording(self.session, lambda k: make_input_adapter(
                    k, chain.extra_names, log=log, marker_units=units, to_units=chain.marker_units, face_id=face_id))
            source, ticks, fps = self._source(log)
            if isinstance(source, TickedSource):
                bus.count_requests(lambda: source.watched)
        live = self.live
        if live is not None and _info(self.session).get("mix_sources") is not None:
            self._replay_mix(chain, bus, ticks, log)
        if live is not None and live.states and chain.filter is not None:
            restore_state(chain.filter, live.states[0], self.path, log)
        if chain.filter is not None:
            bus.on_tracking(lambda t, found: self.events.append((t, found)))
        self.source = source
        total = self._expected_ticks(source, ticks, fps)
        self.progress = Progress(self.progress_label, total=total, unit="ticks", piped_every_s=PIPED_EVERY_S)
        done = lambda info: self.progress.update(info.k + 1 if ticks is None else self.progress.done + 1)  # noqa: E731
        controls = list(self.session.controls) if self.session is not None else []
        if controls:
            log(f"replay: the live run's {len(controls)} control command{'s' if len(controls) != 1 else ''} "
                "(expressions fired, framing) applied at their ticks")
        return FeedParts(source, fps, ticks=ticks, duration=self.pacing.duration, observers=[done],
                         controls=controls)

    def _source(self, log):
        """(frame source, the live tick schedule or None, ticks per second) for the recording."""
        live, fps = self.live, self.pacing.fps
        if live is not None and live.ticks:
            info = live.header.get("info", {})
            live_fps = float(info.get("fps", 60.0))
            if fps is None or fps == live_fps:
                source = TickedSource(live)
                pace = (f"drawn on arrival, tick labels at {live_fps:g} Hz" if info.get("idle_fps")
                        else f"at {live_fps:g} fps")
                log(f"replay: {self.path} tick for tick ({len(source.ticks)} live ticks {pace}, "
                    f"{len(live.frames)} frames) on {self.character_path}")
                return source, source.ticks, live_fps
        limit = self.replay.max_gap
        frames = check_time_order(self.path, live.frames) if live is not None else open_recording(self.path)
        fps, grid = self._rate(frames, fps, log)
        source = ReplaySource(frames, max_gap=limit, grid_fps=grid)
        log(f"replay: {self.path} ({len(source.frames)} frames, {source.duration:.2f} s) on {self.character_path}")
        if source.gaps:
            log(f"replay: {source.describe_gaps()}; --max-gap SECONDS changes the limit ({limit:g} s), "
                f"--max-gap inf keeps them")
        return source, None, fps

    def _rate(self, frames: list[Frame], fps: float | None, log) -> tuple[float, float | None]:
        """(ticks per second, the grid the frames are delivered on or None): ``--fps`` when given; else the
        take's own rate (:mod:`~facepuppet.runtime.recording.take_rate`), each frame drawn once, on its nearest
        tick; else (no steady rate in the times) the fallback, said."""
        if fps is not None:
            return fps, None
        rate = take_rate([f.t for f in frames])
        if rate is None:
            log(f"replay: no steady frame rate in {self.path.name}'s times; drawing at {FALLBACK_FPS:g} fps "
                "(--fps to choose)")
            return FALLBACK_FPS, None
        log(f"replay: at the take's own rate, {rate:g} fps: each frame drawn once (--fps to choose another)")
        return rate, rate

    def _expected_ticks(self, source, ticks, fps: float) -> int | None:
        """How many ticks the replay will draw, for the progress line (None when unknown)."""
        if ticks is not None:
            return len(ticks)
        seconds = getattr(source, "duration", None)
        if self.pacing.duration is not None:
            seconds = self.pacing.duration if seconds is None else min(seconds, self.pacing.duration)
        return None if seconds is None else int(seconds * fps) + 1

    def _replay_mix(self, chain: Chain, bus: SessionBus, ticks, log) -> None:
        """The ``mix`` stage of a recording of a run with several inputs: each mix source's frames at the ticks
        the live run took them (its SOURCES records), the voice from the recorded levels, the order of the
        config."""
        live = self.live
        info = live.header["info"]
        names = tuple(info.get("inputs") or ())
        if ticks is None or not names:
            raise InputFileError("replay: a recording of several inputs replays tick for tick only; this one has no "
                             "TICK records or no list of its inputs")
        sources = {}
        for name in names[1:]:
            if name == "audio":
                if chain.audio is None:
                    raise InputFileError("replay: the recording mixed the voice but kept no audio levels")
                sources[name] = VoiceMixSource(chain.audio.level, chain.config.loss, voice=chain.voice)
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
            bus.on_config(follow_config(stage, names, log))

    def _check_take_layouts(self, chain: Chain) -> None:
        """Refuse a marker take none of whose layouts the solve can use, before drawing a neutral face to its
        end."""
        solve = next((stage for stage in chain.stages if getattr(stage, "name", None) == "solve"), None)
        if solve is None:
            return
        layouts = {tuple(f.marker_names) for f in self.take.frames if f.marker_names is not None}
        if layouts and not any(solve.accepts_layout(names) for names in layouts):
            raise InputFileError(f"{self.path}: the actor's markers are not in this take (its marker layout is "
                                 "refused, see above): train the actor on a take with these marker names, or rename "
                                 "them")

    def _take_source(self, to_units, log):
        """(frame source, None, ticks per second) of a marker take, its positions in the actor's units."""
        take = self.take
        units = self.stages.marker_units or take.units
        frames = take.frames
        note = ""
        if units in UNIT_METRES and to_units in UNIT_METRES and units != to_units:
            factor = np.float32(UNIT_METRES[units] / UNIT_METRES[to_units])
            frames = [Frame(t=f.t, source=f.source, markers=f.markers * factor, marker_names=f.marker_names,
                            t_sender=f.t_sender, number=f.number) for f in frames]
            note = f", converted {units} -> {to_units}"
        fps, grid = self._rate(frames, self.pacing.fps, log)
        source = ReplaySource(frames, grid_fps=grid)
        log(f"replay: {self.path} ({take.description}{note}; {source.duration:.2f} s) on {self.character_path}, "
            "through the solve as --input markers")
        return source, None, fps

    # -- the loop ----------------------------------------------------------------------------------

    def clock(self, parts: FeedParts, target: GLTarget, paced: bool) -> RecordedClock | WallClock:
        return RecordedClock() if target.headless and not paced else replay_wall_clock(parts.ticks, parts.fps)

    def stop(self) -> bool:
        """Whether Ctrl-C or SIGTERM asked the replay to stop (the loop checks before each tick)."""
        return self.stop_event.is_set()

    @property
    def stopped_by(self) -> str | None:
        """The name of the signal that stopped the replay (``SIGINT``, ``SIGTERM``), None when it ran to its
        end."""
        received = self.signals.received if self.signals is not None else None
        return None if received is None else received.name

    def run(self, loop: FrameLoop, parts: FeedParts) -> LoopResult:
        # on a terminal: ticks done, rate, time left, redrawn in place; in a log: the same as a line now and then
        with self.progress:
            return loop.run(parts.source, duration=parts.duration, ticks=parts.ticks)

    def missing_line(self) -> str | None:
        """The warning on frames the live ticks drew that the recording lacks (None: none lacked)."""
        if not getattr(self.source, "missing", 0):
            return None
        return (f"replay: warning: the live ticks drew {self.source.missing} frames the recording lacks "
                "(packets dropped by the recorder); the weights differ from the live run's from there on")

    def events_line(self) -> str | None:
        """The tracking events replayed compared with the recording's (None: no filter stage, or not a live
        recording)."""
        if not self.filtered or self.live is None:
            return None
        return compare_events(self.live.events, self.events)
