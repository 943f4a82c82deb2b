"""Replay a live recording tick for tick: the same frames at the same tick times as the live run.

A live run ticks on the wall clock and takes whatever frame has arrived by
then, so which frame each tick saw is a fact of that run, not of the frame
times. ``run --record`` writes one TICK record per drawn tick (tick index,
tick time, how many frames the source had completed at the snapshot; see
:mod:`~facepuppet.runtime.recording.session`). :class:`TickedSource` hands the frame
loop exactly those frames at exactly those ticks (``FrameLoop.run(ticks=...)``),
so the live pipeline (filters, calibration, tracking loss), which works on
tick times and receive times only, computes the same weights bit for bit.

Calibrate messages (``/facepuppet/calibrate``) recorded among the packets are
counted in :attr:`TickedSource.watched` with the first frame that arrived after
them, as the live receiver counted them; the filter stage reads that count each
tick and calibrates when it grows, as live. One race is not reproduced: a
calibrate message arriving between a tick's snapshot and its filter stage was
applied live with that tick's (older) frame, here with the next one.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.files.input_files import regular_file
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.inputs.osc import CALIBRATE_ADDRESS
from facepuppet.runtime.inputs.udp import count_messages, watch_needle
from facepuppet.runtime.recording.records import Tick
from facepuppet.runtime.recording.replay_source import decode_packets
from facepuppet.runtime.recording.session import MAGIC, Session, read_session

if TYPE_CHECKING:
    import os

    from facepuppet.runtime.protocols import InputAdapter



@dataclass
class LiveRecording:
    """The decoded packets and ticks of a ``run --record`` file.

    Attributes
    ----------
    frames : list of Frame, the frames the packets decode to, in arrival order
    frame_packets : list of int, the packet index of each frame
    calibrate_packets : list of int, packet indices of calibrate messages
    ticks : list of Tick
    header : dict
    audio_levels : list of (t, level_db), the audio level of each live tick (the tick's time)
    configs : list of (t, TOML text), the config changes of the live run and the tick times they took effect
    events : list of (t, found), the tracking lost / found events of the live run (EVENT records)
    states : list of (t, JSON text), the filter stage's state where the recording started mid-run (STATE)
    mix : dict of source name -> LiveRecording, the other tracker inputs of a run with several
        (``info.mix_sources``): each one's frames and, per tick, how many it had completed (SOURCES records)
    """

    frames: list
    frame_packets: list
    calibrate_packets: list
    ticks: list
    header: dict
    audio_levels: list = field(default_factory=list)
    configs: list = field(default_factory=list)
    events: list = field(default_factory=list)
    mix: dict = field(default_factory=dict)
    states: list = field(default_factory=list)


def read_live_session(path: str | os.PathLike) -> Session | None:
    """The session file of a live recording, read once (its header says the input kind and the options a
    replay needs before decoding); None when ``path`` is not one (not a session file, or one holding frames
    rather than PACKET or TICK records). A torn tail is kept up to the tear, with a warning."""
    path = regular_file(path, "recording (session file or Live Link Face CSV)")
    with open(path, "rb") as f:
        if f.read(len(MAGIC)) != MAGIC:
            return None
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        session = read_session(path)
    if session.frames or not (session.packets or session.ticks):
        return None
    return session


def decode_live_recording(session: Session, make_adapter: Callable[[str], InputAdapter]) -> LiveRecording:
    """Decode a live recording's packets with ``make_adapter(kind)``. A run whose tracker sent nothing (or
    ``--input audio``) has ticks and no frames: it replays too.

    Raises
    ------
    InputFileError (a ValueError)
        naming the file when its packets decode to no frame and it has no ticks, when a packet's input kind
        has no adapter, or when its tick indices do not increase from 0 up.
    """
    info = session.header.get("info", {}) if isinstance(session.header, dict) else {}
    mix_sources = info.get("mix_sources") or []
    packets = session.packets
    mix = {}
    _check_ticks(session)
    if mix_sources:  # a run with several inputs: the loop's own input, then each mix source's packets
        packets = [p for p in session.packets if p.kind == info.get("input")]
        for j, m in enumerate(mix_sources):
            name, kind = str(m["name"]), str(m["kind"])
            own = decode_packets([p for p in session.packets if p.kind == name],
                                 lambda _, kind=kind: make_adapter(kind), session.path)
            ticks = [Tick(t.k, t.t, counts[j] if j < len(counts) else 0, t.t_clock)
                     for t, (_, counts) in zip(session.ticks, session.sources)]
            mix[name] = LiveRecording([f for _, f in own], [i for i, _ in own], [], ticks, {})
    needle = watch_needle(CALIBRATE_ADDRESS)  # what the live receivers count: decoded messages, not the bytes
    calibrate = [i for i, packet in enumerate(packets) if count_messages(packet.data, CALIBRATE_ADDRESS, needle)]
    decoded = decode_packets(packets, make_adapter, session.path)
    frames = [frame for _, frame in decoded]
    frame_packets = [i for i, _ in decoded]
    if not frames and not session.ticks:
        raise InputFileError(f"{session.path}: the recorded packets decode to no frame")
    return LiveRecording(frames, frame_packets, calibrate, list(session.ticks), dict(session.header),
                         list(session.audio_levels), list(session.configs), list(session.events), mix,
                         list(session.states))


def _check_ticks(session: Session) -> None:
    """The TICK records' indices are the ticks a replay draws, in order: non-negative and increasing (the
    live loop's were; a damaged file's may not be)."""
    previous = -1
    for n, tick in enumerate(session.ticks):
        if tick.k <= previous:
            where = f"after {previous}" if n else "the first"
            raise InputFileError(f"{session.path}: TICK record {n}: tick index {tick.k} ({where}); a live "
                                 "recording's tick indices are non-negative and increase")
        previous = tick.k


def read_live_recording(path: str | os.PathLike,
                        make_adapter: Callable[[str], InputAdapter]) -> LiveRecording | None:
    """:func:`read_live_session` then :func:`decode_live_recording`; None when ``path`` is not a live
    recording."""
    session = read_live_session(path)
    return None if session is None else decode_live_recording(session, make_adapter)


class TickedSource:
    """The frame each recorded tick took, one per :meth:`latest` call (the loop calls it once per tick).

    Parameters
    ----------
    recording : LiveRecording with ticks

    Attributes
    ----------
    ticks : list of int, the tick indices to draw (``FrameLoop.run(ticks=...)``)
    missing : int, frames the ticks refer to that the recording lacks (packets lost from the recording)
    watched : int, recorded calibrate messages before the newest frame handed over (the live
        receiver's count of them, as the filter stage read it)
    """

    def __init__(self, recording: LiveRecording) -> None:
        if not recording.ticks:
            raise ValueError("TickedSource: the recording has no TICK records (recorded before they existed)")
        self.recording = recording
        self.ticks = [t.k for t in recording.ticks]
        self.duration = None
        self.watched = 0
        self.missing = 0
        self._i = 0
        self._seen = 0
        self._calib = list(recording.calibrate_packets)

    def latest(self, t: float) -> tuple[Frame | None, int]:
        """(the frame the live tick took, or None; frames it skipped as stale)."""
        rec = self.recording
        n = rec.ticks[self._i].frames
        self._i += 1
        if n > len(rec.frames):
            self.missing = max(self.missing, n - len(rec.frames))
            n = len(rec.frames)
        if n <= self._seen:
            return None, 0
        stale = n - self._seen - 1
        self._seen = n
        packet = rec.frame_packets[n - 1]
        while self._calib and self._calib[0] < packet:
            self._calib.pop(0)
            self.watched += 1
        return rec.frames[n - 1], stale
