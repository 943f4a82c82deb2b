"""Frame sources for the frame loop: recorded frames replayed on recorded time.

A source answers one question per tick, ``latest(t)``: the newest frame that
has arrived by time ``t`` and how many older ones arrived since the last tick
and were skipped. The loop never queues: the newest frame wins and the rest
are counted as stale (DESIGN.md, Threads). Live sources (OSC) answer the same
question from their own slots.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING

from facepuppet.runtime.errors import InputFileError, UsageError
from facepuppet.runtime.files.input_files import regular_file
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.inputs import kinds
from facepuppet.runtime.recording.livelinkface_csv import looks_like_llf_csv, read_llf_csv
from facepuppet.runtime.recording.session import MAGIC, read_session

if TYPE_CHECKING:
    import os

    from facepuppet.runtime.protocols import InputAdapter
    from facepuppet.runtime.recording.records import Packet


DEFAULT_MAX_GAP_S = 10.0  # a recording pausing longer than this is cut (replay --max-gap)


class ReplaySource:
    """Recorded frames delivered by recorded time.

    Parameters
    ----------
    frames : sequence of Frame, in non-decreasing ``t`` order (at least one)
    max_gap : float, seconds; a pause between two frames longer than this is cut to
        this length (a frame at t = 1e300, a timecode jumping by hours), counted in
        ``gaps`` and ``cut_s``. ``math.inf`` keeps every pause.
    grid_fps : float or None; a replay ticking at the take's own rate: each frame is delivered at the tick of
        that rate nearest its time, so a clock jittering by less than half a period (a timecode's sub-frame,
        a network's arrival) neither leaves a tick without a new frame nor makes the next one skip a frame.
        Times stay in order; two frames nearest the same tick make the newer one win there (the older is
        counted stale), as the take's own clock says.

    Times passed to :meth:`latest` and :meth:`done` are seconds since the first
    frame (``frames[0].t`` is time 0), so a session recorded on a monotonic
    clock and a CSV starting at 0 replay alike; after a cut gap they are the
    recording's times less the seconds cut before them.

    Attributes
    ----------
    gaps : list of (frame index, seconds), each pause that was cut, with its recorded length
    cut_s : float, seconds cut in all
    """

    def __init__(self, frames: Iterable[Frame], max_gap: float = DEFAULT_MAX_GAP_S,
                 grid_fps: float | None = None) -> None:
        self.frames = list(frames)
        if not self.frames:
            raise ValueError("ReplaySource: expected at least one frame, got none")
        if not max_gap > 0:
            raise ValueError(f"ReplaySource max_gap: expected a positive number of seconds, got {max_gap!r}")
        for i in range(1, len(self.frames)):
            if self.frames[i].t < self.frames[i - 1].t:
                raise ValueError(
                    f"ReplaySource: frames must be in time order; frame {i} has t={self.frames[i].t} "
                    f"after t={self.frames[i - 1].t}"
                )
        self.t0 = self.frames[0].t
        self.gaps: list[tuple[int, float]] = []
        self.cut_s = 0.0
        self._times = [0.0]
        for i in range(1, len(self.frames)):
            step = self.frames[i].t - self.frames[i - 1].t
            if step > max_gap:
                self.gaps.append((i, step))
                self.cut_s += step - max_gap
                step = max_gap
            self._times.append(self._times[-1] + step)
        if grid_fps is not None:
            if not (math.isfinite(grid_fps) and grid_fps > 0):
                raise ValueError(f"ReplaySource grid_fps: expected a positive rate, got {grid_fps!r}")
            # k / grid_fps is the loop's own expression for tick k's time, so the frame is due exactly then
            self._times = [round(x * grid_fps) / grid_fps for x in self._times]
        self._next = 0

    def describe_gaps(self) -> str:
        """One line about the cut pauses ("" when none was cut)."""
        if not self.gaps:
            return ""
        longest = max(g for _, g in self.gaps)
        return (f"cut {len(self.gaps)} pauses longer than the gap limit (first at frame {self.gaps[0][0]}, "
                f"longest {longest:.6g} s, {self.cut_s:.6g} s cut in all)")

    @property
    def duration(self) -> float:
        """Seconds from the first frame to the last."""
        return self._times[-1]

    def latest(self, t: float) -> tuple[Frame | None, int]:
        """(newest frame with time <= t not yet delivered, number of older ones skipped).

        Returns (None, 0) when no new frame has arrived since the last call.
        """
        start = self._next
        end = start
        n = len(self._times)
        while end < n and self._times[end] <= t:
            end += 1
        if end == start:
            return None, 0
        self._next = end
        return self.frames[end - 1], end - start - 1

    def done(self, t: float) -> bool:
        """True when every frame has been delivered and ``t`` is at or past the last one."""
        return self._next >= len(self._times) and t >= self._times[-1]

    def rewind(self) -> None:
        """Start again from the first frame."""
        self._next = 0


def decode_packets(packets: Iterable[Packet], make_adapter: Callable[[str], InputAdapter] | None = None,
                   path: str | os.PathLike = "recording") -> list[tuple[int, Frame]]:
    """(packet index, frame) for each packet that completes a frame, decoded as the live run did.

    Each packet goes, in recorded order and with its recorded receive time,
    through a fresh adapter of its input kind (``make_adapter(kind)``, by
    default :func:`~facepuppet.runtime.inputs.kinds.make_adapter`). A kind no
    adapter decodes (``make_adapter`` refuses it with a UsageError) is refused
    as an InputFileError naming ``path``, the recording.
    """
    if make_adapter is None:
        make_adapter = kinds.make_adapter
    adapters: dict = {}
    decoded = []
    for i, packet in enumerate(packets):
        adapter = adapters.get(packet.kind)
        if adapter is None:
            try:
                adapter = adapters[packet.kind] = make_adapter(packet.kind)
            except UsageError as exc:
                raise InputFileError(f"{path}: packet {i}: {exc}") from None
        frame = adapter.handle(packet.data, packet.t)
        if frame is not None:
            decoded.append((i, frame))
    return decoded


def frames_from_packets(packets: Iterable[Packet], path: str | os.PathLike = "recording") -> list[Frame]:
    """The frames a live run decoded from its packets, decoded again.

    Each packet goes, in recorded order and with its recorded receive time,
    through a fresh adapter of its input kind
    (:func:`~facepuppet.runtime.inputs.kinds.make_adapter`), as the UDP thread
    did live; adapters are deterministic, so the frames are the live ones.

    packets : sequence of :class:`~facepuppet.runtime.recording.records.Packet`
    path : the recording, named when a packet's kind has no adapter
    """
    return [frame for _, frame in decode_packets(packets, path=path)]


def check_time_order(path: str | os.PathLike, frames: Sequence[Frame]) -> list[Frame]:
    """``frames`` as a list, when their times never go back; else an InputFileError naming ``path``, the
    recording they were read from (a replay plays them in order; a live recording's are, a damaged one's
    may not be)."""
    frames = list(frames)
    for i in range(1, len(frames)):
        if frames[i].t < frames[i - 1].t:
            raise InputFileError(f"{path}: frame {i} has t={frames[i].t} after t={frames[i - 1].t}; a "
                                 "recording's frames must be in time order")
    return frames


def open_recording(path: str | os.PathLike) -> list[Frame]:
    """Frames of a recording: a session file (by its magic) or a Live Link Face CSV (by its header).

    A live recording (PACKET records, ``run --record``) gives the frames its
    packets decode to (:func:`frames_from_packets`).

    A session whose tail was torn gives the frames before the tear (with a
    warning from :func:`~facepuppet.runtime.recording.session.read_session`).

    Raises
    ------
    ValueError
        naming the file when it is neither, or holds no frames.
    FileNotFoundError
        when it does not exist.
    """
    path = regular_file(path, "recording (session file or Live Link Face CSV)")
    with open(path, "rb") as f:
        head = f.read(4096)
    if head.startswith(MAGIC):
        with warnings.catch_warnings():
            warnings.simplefilter("always")
            session = read_session(path)
        if not session.frames and session.packets:
            frames = frames_from_packets(session.packets, path)
            if frames:
                return check_time_order(path, frames)
            raise InputFileError(f"{path}: the recorded packets decode to no frame")
        if not session.frames:
            raise InputFileError(f"{path}: session file holds no complete frame "
                                 f"({session.tail_error or 'none written'})")
        return check_time_order(path, session.frames)
    first_line = head.split(b"\n", 1)[0].decode("utf-8", errors="replace")
    if looks_like_llf_csv(first_line):
        return read_llf_csv(path)
    raise InputFileError(
        f"{path}: not a recording facepuppet can replay (expected a session file starting with {MAGIC!r} "
        f"or a Live Link Face CSV whose header has Timecode and BlendShapeCount; found {head[:24]!r})"
    )
