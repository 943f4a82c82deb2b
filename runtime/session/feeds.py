"""What feeds a session its frames: the protocol :func:`~facepuppet.runtime.session.assemble.open_session` asks
of a feed, and the simplest feed, a list of frames (the demo's synthetic performance).

A feed answers two questions at two moments of the assembly:

1. :meth:`Feed.prepare`, before the stage chain exists: what the chain needs to know of the input (its kind,
   whether the filter stage runs, the audio level, a recorded config and its changes) as a
   :class:`ChainInputs`;
2. :meth:`Feed.open`, once the chain exists: the frame source and how the loop ticks it, as a
   :class:`FeedParts`; everything it opens (sockets, child processes, a microphone, a recording) goes on
   the session's ``ExitStack``.

The live feed (``run``) is :mod:`~facepuppet.runtime.session.live_feed`, the recording feed (``replay``)
:mod:`~facepuppet.runtime.session.recording_feed`.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from facepuppet.runtime.live.loop import RecordedClock, WallClock
from facepuppet.runtime.recording.replay_source import ReplaySource

if TYPE_CHECKING:
    from facepuppet.runtime.frames import Frame
    from facepuppet.runtime.live.bus import SessionBus
    from facepuppet.runtime.live.loop import FrameLoop, LoopResult
    from facepuppet.runtime.live.stages import Chain
    from facepuppet.runtime.model.character import Character
    from facepuppet.runtime.protocols import FrameSource, TickObserver
    from facepuppet.runtime.render.gl_context import GLTarget
    from facepuppet.runtime.session.options import PacingOptions


@dataclass
class ChainInputs:
    """What the stage chain needs to know of a feed's input (:func:`~facepuppet.runtime.live.stages.build_chain`).

    Attributes
    ----------
    kind : str or None, the input kind of the frames (None: unknown, or the voice alone)
    label : str, what the chain names as its input
    filtered : bool, the filter stage runs
    voice_only : bool, no tracker: the face from the voice
    audio_level : callable t -> dBFS, or None (no ``audio`` stage)
    config_text : (where, TOML) or None, the config to start from (a recording's)
    schedule : list of (tick time, TOML, where), config changes to apply at those ticks (a recording's; ``where``
        names the record for messages)
    keep_snapshots : bool, the filter keeps its state before each tick (a recording may start mid-run)
    packets : bool, the receivers hand every datagram to the bus (a recording is possible)
    voice : the voice's channel source (``outputs``, ``channels(t)``) for ``--voice``, or None
    """

    kind: str | None
    label: str
    filtered: bool = False
    voice_only: bool = False
    audio_level: Callable[[float], float] | None = None
    config_text: tuple[str, str] | None = None
    schedule: list = field(default_factory=list)
    keep_snapshots: bool = False
    packets: bool = False
    voice: Any = None


@dataclass
class FeedParts:
    """The frame source a feed opened and how the frame loop ticks it.

    Attributes
    ----------
    source : FrameSource, the loop's own
    fps : float, ticks per second (the tick-label grid when drawing on arrival)
    ticks : list of int or None, the exact ticks to draw (a live recording replayed tick for tick)
    duration : float or None, seconds (None: the source's own, or until stopped)
    idle_fps : float or None, draw on arrival, redrawing at least this often
    catch_up : bool, a late tick skips the ticks it missed (live)
    wake : callable(timeout_s) -> bool or None, what the loop sleeps in when drawing on arrival
    address : (host, port) or None, where a live feed listens
    counters : dict of counter group -> counters, the feed's (the receivers', the mix's, the recorder's)
    recorder : the session's SwitchableRecorder or None (live)
    observers : list of TickObserver, the feed's own (the recording's per-tick records), called last
    live : bool, a live feed: the session adds the live stats and the operator's panel
    input_name : str, what the panel names as the input
    controls : list of (tick time, JSON object), recorded control commands to apply at those ticks (a replay)
    """

    source: FrameSource
    fps: float
    ticks: list | None = None
    duration: float | None = None
    idle_fps: float | None = None
    catch_up: bool = False
    wake: Callable[[float], bool] | None = None
    address: tuple | None = None
    counters: dict = field(default_factory=dict)
    recorder: Any = None
    observers: list = field(default_factory=list)
    live: bool = False
    input_name: str = ""
    controls: list = field(default_factory=list)


class Feed(Protocol):
    """What feeds a session (see the module docstring)."""

    title: str  # the window's title

    def prepare(self, character: Character, stack: contextlib.ExitStack,
                log: Callable[[str], None]) -> ChainInputs: ...

    def open(self, stack: contextlib.ExitStack, chain: Chain, bus: SessionBus,
             log: Callable[[str], None]) -> FeedParts: ...

    def clock(self, parts: FeedParts, target: GLTarget, paced: bool) -> RecordedClock | WallClock: ...

    def run(self, loop: FrameLoop, parts: FeedParts) -> LoopResult: ...


def recorded_or_wall(target: GLTarget, paced: bool) -> RecordedClock | WallClock:
    """Recorded time headless (as fast as the machine draws), real time in a window or when something is sent
    (a receiver expects real time)."""
    return RecordedClock() if target.headless and not paced else WallClock()


class FramesFeed:
    """A list of frames played on recorded time (the demo's synthetic performance).

    Parameters
    ----------
    frames : sequence of Frame
    pacing : PacingOptions (``fps`` required)
    label : str, what the stage chain names as its input
    title : str, the window's title
    observers : tick observers of the caller's, called last
    """

    def __init__(self, frames: Sequence[Frame], pacing: PacingOptions, label: str, title: str,
                 observers: Sequence[TickObserver] = ()) -> None:
        self.frames = frames
        self.pacing = pacing
        self.label = label
        self.title = title
        self.observers = list(observers)

    def prepare(self, character: Character, stack: contextlib.ExitStack,
                log: Callable[[str], None]) -> ChainInputs:
        return ChainInputs(kind=None, label=self.label)

    def open(self, stack: contextlib.ExitStack, chain: Chain, bus: SessionBus,
             log: Callable[[str], None]) -> FeedParts:
        return FeedParts(ReplaySource(self.frames), float(self.pacing.fps), duration=self.pacing.duration,
                         observers=self.observers)

    def clock(self, parts: FeedParts, target: GLTarget, paced: bool) -> RecordedClock | WallClock:
        return recorded_or_wall(target, paced)

    def run(self, loop: FrameLoop, parts: FeedParts) -> LoopResult:
        return loop.run(parts.source, duration=parts.duration, ticks=parts.ticks)
