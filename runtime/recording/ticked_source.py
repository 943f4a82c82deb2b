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
requested of the pipeline with the first frame that arrived after them, as
live. One race is not reproduced: a calibrate message arriving between a
tick's snapshot and its pipeline call was applied live with that tick's
(older) frame, here with the next one.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

from facepuppet.runtime.frames import Frame

CALIBRATE_ADDRESS = b"/facepuppet/calibrate\x00"  # OSC address with its first padding byte


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
    """

    frames: list
    frame_packets: list
    calibrate_packets: list
    ticks: list
    header: dict


def read_live_recording(path, make_adapter) -> LiveRecording | None:
    """Decode a live recording with ``make_adapter(kind)``; None when ``path`` is not one (no PACKET records).

    Raises
    ------
    ValueError
        naming the file when its packets decode to no frame.
    """
    from facepuppet.runtime.recording.session import MAGIC, read_session

    path = Path(path)
    with open(path, "rb") as f:
        if f.read(len(MAGIC)) != MAGIC:
            return None
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        session = read_session(path)
    if session.frames or not session.packets:
        return None
    from facepuppet.runtime.recording.replay_source import decode_packets

    calibrate = [i for i, packet in enumerate(session.packets) if CALIBRATE_ADDRESS in packet.data]
    decoded = decode_packets(session.packets, make_adapter)
    frames = [frame for _, frame in decoded]
    frame_packets = [i for i, _ in decoded]
    if not frames:
        raise ValueError(f"{path}: the recorded packets decode to no frame")
    return LiveRecording(frames, frame_packets, calibrate, list(session.ticks), dict(session.header))


class TickedSource:
    """The frame each recorded tick took, one per :meth:`latest` call (the loop calls it once per tick).

    Parameters
    ----------
    recording : LiveRecording with ticks
    request_calibration : callable() or None, called before handing over the first frame that
        arrived after a recorded calibrate message

    Attributes
    ----------
    ticks : list of int, the tick indices to draw (``FrameLoop.run(ticks=...)``)
    missing : int, frames the ticks refer to that the recording lacks (packets lost from the recording)
    """

    def __init__(self, recording: LiveRecording, request_calibration=None):
        if not recording.ticks:
            raise ValueError("TickedSource: the recording has no TICK records (recorded before they existed)")
        self.recording = recording
        self.ticks = [t.k for t in recording.ticks]
        self.duration = None
        self.request_calibration = request_calibration
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
        if self._calib and self._calib[0] < packet:
            while self._calib and self._calib[0] < packet:
                self._calib.pop(0)
            if self.request_calibration is not None:
                self.request_calibration()
        return rec.frames[n - 1], stale
