"""Tick observers that keep what was drawn: PNG frames, the weight log, the recording's per-tick records.

Each is a :class:`~facepuppet.runtime.protocols.TickObserver`: called with the loop's
:class:`~facepuppet.runtime.live.loop.TickInfo` once the GPU is done with the tick. The other observers
are the outputs that send (VMC :mod:`facepuppet.runtime.live.vmc_out`, Live Link Face
:mod:`facepuppet.runtime.live.llf_out`), the video (:mod:`facepuppet.runtime.live.video_out`) and the
live stats (:mod:`facepuppet.runtime.live.stats`).
"""

from __future__ import annotations

import os
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from PIL import Image

from facepuppet.runtime.files.outputs import atomic_path

if TYPE_CHECKING:
    from collections.abc import Sequence

    from facepuppet.runtime.live.loop import TickInfo
    from facepuppet.runtime.live.stages import AudioTap
    from facepuppet.runtime.protocols import FrameSource
    from facepuppet.runtime.recording.recorder import PacketRecorder
    from facepuppet.runtime.voice.stage import VoiceStage


def png_workers() -> int:
    """Threads encoding PNGs beside the frame loop: one core is the loop's (and the driver's), up to four of
    the others encode (zlib gives up the GIL while it compresses, so they run in parallel)."""
    return max(1, min(MAX_PNG_WORKERS, (os.cpu_count() or 2) - 1))


MAX_PNG_WORKERS = 4


class PngSink:
    """Write each drawn tick's image as ``out_dir/frame_00000.png``, numbered 0, 1, 2, ... in drawing order.

    Consecutive numbers are what an image-sequence reader expects (``ffmpeg -i frame_%05d.png``, which stops
    at the first missing number); a tick index would leave gaps (a run drawing on arrival labels its ticks on
    a 1 kHz grid). What each image shows is kept beside them in ``out_dir/frames.csv``: ``frame,tick,t``
    (image number, tick index, tick time in seconds), one line per image, written in order once the image
    is in place.

    Encoding a PNG costs about as much as drawing the frame on a CPU rasteriser and far more than on a GPU,
    so the loop only reads the pixels (which needs its GL context) and ``workers`` threads encode and write
    (0, the default: in the loop's thread, each image in place when the call returns; a session's outputs
    use :func:`png_workers`); at most ``workers + 1`` images wait, so memory stays bounded however slow the
    disk. Each image is written to a temporary file and renamed onto its name, so a process stopped at any
    moment leaves only whole images. :meth:`close` waits for every image and closes ``frames.csv``; an
    image that could not be written raises there or at a later tick.

    Keeps no list of what it wrote (a long run writes many): ``written`` counts the images in place,
    ``last_path`` is the newest.
    """

    INDEX = "frames.csv"

    def __init__(self, out_dir: str | os.PathLike, workers: int = 0) -> None:
        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.written = 0
        self.last_path: Path | None = None
        self.workers = int(workers)
        self._pool = ThreadPoolExecutor(self.workers, thread_name_prefix="png") if self.workers > 0 else None
        self._pending: deque[tuple[Future | None, Path, str]] = deque()
        self._queued = 0
        self._index = open(self.out_dir / self.INDEX, "w", encoding="ascii", newline="")
        self._index.write("frame,tick,t\n")

    def __call__(self, info: TickInfo) -> None:
        n = self._queued
        path = self.out_dir / f"frame_{n:05d}.png"
        pixels = np.ascontiguousarray(info.renderer.read_pixels())
        line = f"{n},{info.k},{info.t!r}\n"
        self._queued += 1
        if self._pool is None:
            _write_png(path, pixels)
            self._pending.append((None, path, line))
        else:
            self._pending.append((self._pool.submit(_write_png, path, pixels), path, line))
        self._settle(keep=self.workers)

    def _settle(self, keep: int) -> None:
        """Index the images done, in order; wait for the oldest while more than ``keep`` are waiting."""
        pending = self._pending
        while pending and (len(pending) > keep or pending[0][0] is None or pending[0][0].done()):
            future, path, line = pending.popleft()
            if future is not None:
                future.result()  # an image that could not be written raises here
            self._index.write(line)
            self._index.flush()
            self.written += 1
            self.last_path = path

    def close(self) -> None:
        """Wait for every image, index them and close ``frames.csv`` (once)."""
        if self._index.closed:
            return
        try:
            self._settle(keep=0)
        finally:
            if self._pool is not None:
                self._pool.shutdown(wait=True, cancel_futures=True)
            self._index.close()


def _write_png(path: Path, pixels: np.ndarray) -> None:
    with atomic_path(path) as temp:
        Image.fromarray(pixels).save(temp, format="PNG")


class WeightLog:
    """Keep each tick's rig weights (``--dump-weights``, tests and offline analysis; it grows with every tick,
    so a live run has one only when asked).

    Attributes
    ----------
    array : ndarray of shape (n_ticks, n_shapes), float32
    times : ndarray of shape (n_ticks,), float64, seconds
    """

    def __init__(self) -> None:
        self._rows: list[np.ndarray] = []
        self._times: list[float] = []

    def __call__(self, info: TickInfo) -> None:
        self._rows.append(np.array(info.weights, dtype=np.float32, copy=True))
        self._times.append(info.t)

    @property
    def array(self) -> np.ndarray:
        if not self._rows:
            return np.zeros((0, 0), dtype=np.float32)
        return np.stack(self._rows)

    @property
    def times(self) -> np.ndarray:
        return np.asarray(self._times, dtype=np.float64)


class RecordingHook:
    """``run --record``: per tick, the received datagrams, the tick's audio level and one TICK record.

    Parameters
    ----------
    recorder : PacketRecorder, or a :class:`~facepuppet.runtime.recording.switch.SwitchableRecorder` (the
        run's: records only while a recording is in force, its TICK frame counts aligned for one started mid-run)
    source : the live source; its ``deliver_packets()`` (if any) hands the datagrams received since
        the last tick to the recorder (those the process receiver holds for it), its ``frames_taken`` says which
        frame the tick drew (a faithful replay needs it)
    audio : AudioTap or None, the tick's audio level (recorded as the stages used it)
    voice : VoiceStage or None, the tick's voice channels (recorded as the stages used them)
    mix_sources : sequence of the other tracker inputs of a run with several (the mix stage's sources, in the
        order of the header's ``info.mix_sources``): their datagrams are delivered too, and a SOURCES record
        after each TICK says how many frames each had completed

    The datagrams behind the frame a tick took reach the recorder before that tick's TICK record.
    """

    def __init__(self, recorder: PacketRecorder, source: FrameSource, audio: AudioTap | None = None,
                 mix_sources: Sequence = (), voice: VoiceStage | None = None) -> None:
        self.recorder = recorder
        self.voice = voice
        self.mix_sources = tuple(mix_sources)
        self._mix_deliver = [d for s in self.mix_sources if (d := getattr(s, "deliver_packets", None)) is not None]
        self.source = source
        self.audio = audio
        self._deliver = getattr(source, "deliver_packets", None)
        self._ticks = hasattr(source, "frames_taken")

    def __call__(self, info: TickInfo) -> None:
        recorder = self.recorder
        if self._deliver is not None:  # also while a switchable recorder records nothing: nothing piles up
            self._deliver()
        for deliver in self._mix_deliver:
            deliver()
        saw = getattr(recorder, "saw_tick", None)
        if saw is not None:  # a SwitchableRecorder (run): started and stopped during the run
            saw(info.t)
            if not recorder.recording:
                return
        if self.audio is not None:
            recorder.put_audio(info.t, self.audio.value)
        if self.voice is not None and self.voice.values is not None:
            recorder.put_voice(info.t, self.voice.values)
        if self._ticks:
            frames = self.source.frames_taken
            if saw is not None:  # a recording started mid-run counts only the frames it has the packets of
                frames = recorder.tick_frames(frames, info.raw)
            recorder.put_tick(info.k, info.t, frames, info.stamps[0])
            if self.mix_sources:
                recorder.put_sources(info.k, tuple(s.frames_taken for s in self.mix_sources))
