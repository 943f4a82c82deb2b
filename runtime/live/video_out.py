"""``--video FILE``: the drawn ticks encoded as a video file, with a sound track, through PyAV.

PyAV (``av`` on PyPI, the optional extra ``video``) binds FFmpeg and ships it in
its wheel, so no system FFmpeg is needed. What is written:

* **One video frame per drawn tick**, at the tick's time: presentation time
  ``k − k0`` in a time base of ``1 / fps`` (``k`` the tick index, ``k0`` the
  first one), so a replay or the demo (every tick drawn) gives a constant frame
  rate of ``fps`` and a live run drawing on arrival (tick labels on a 1 kHz
  grid) a variable one with each frame at the moment it was drawn. Frame count
  = ticks drawn.
* **Codec by container** (the file's suffix), ``--video-codec`` to choose another:

  =========  ===============================  ====================================
  suffix     opaque frames (h, w, 3)          frames with alpha (h, w, 4)
  =========  ===============================  ====================================
  ``.mp4``   H.264 (libx264), yuv420p          refused: H.264 carries no alpha
  ``.mkv``   H.264 (libx264), yuv420p          VP9 (libvpx-vp9), yuva420p
  ``.mov``   H.264 (libx264), yuv420p          ProRes 4444 (prores_ks), yuva444p10le
  ``.webm``  VP9 (libvpx-vp9), yuv420p         VP9 (libvpx-vp9), yuva420p
  =========  ===============================  ====================================

  4:2:0 formats need an even width and height: an odd ``--size`` is refused.
  H.264 is encoded with CRF 18 and preset ``veryfast``, without x264's
  macroblock-tree rate control: with it, the same frames encoded twice in one
  process came out different now and then (found by the determinism test: its
  SIMD path depends on memory it did not write; with ``no-asm`` or ``mbtree=0``
  the output is always the same). VP9 with CRF 24 at
  libvpx's realtime speed (8), which a live run can afford; ProRes 4444 with
  ``prores_ks`` profile 4444 (large files, about 47 ms a 1280x720 frame on two
  cores: ``facepuppet bench video --alpha``). The same frames give the same
  decoded frames with each (encoder threads included; tested).
* **Sound** (``--audio-file WAV``): the WAV's samples, mixed to mono
  (:func:`~facepuppet.runtime.inputs.audio.read_wav`), resampled to 48 kHz,
  from the first tick's time on, cut or padded with silence to the video's
  duration, as AAC (``.mp4``, ``.mov``, ``.mkv``) or Opus (``.webm``). Audio is
  encoded as the frames come, up to each frame's end, so the file interleaves and
  nothing grows with the run. A recording (``run --record``) keeps the audio
  *levels* of its ticks, not samples: to give a replay its sound, pass the WAV
  again.

**Before any work** (:func:`plan_video`): PyAV missing, an unknown suffix, an
unknown encoder or one that is not a video encoder, a codec the container or
the frames cannot take, an odd size for a 4:2:0 format, and an unreadable WAV
are refused with a message naming the option; the output file itself goes
through the common policy (exists without ``--force``, missing folder:
:mod:`facepuppet.runtime.files.outputs`). The file is written beside its final path
and renamed into place when the run ends well; a failed run leaves none.

**Alpha.** The sink takes frames of (h, w, 3) or (h, w, 4) uint8 and picks the
alpha column of the table for 4-channel ones. A command that knows its frames
will carry alpha (``--background transparent``) passes ``alpha=True`` to
:func:`plan_video`, so ``.mp4`` is refused before the run.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.errors import FacepuppetError
from facepuppet.runtime.files.outputs import OutputSet
from facepuppet.runtime.inputs.audio import read_wav

if TYPE_CHECKING:
    from facepuppet.runtime.cli.progress import Progress
    from facepuppet.runtime.live.loop import TickInfo

AUDIO_RATE = 48000
H264_OPTIONS = {"crf": "18", "preset": "veryfast", "x264-params": "mbtree=0"}  # mbtree: see the module doc

#: suffix -> (container format, opaque codec, alpha codec or None, audio codec)
CONTAINERS: dict[str, tuple[str, str, str | None, str]] = {
    ".mp4": ("mp4", "libx264", None, "aac"),
    ".mkv": ("matroska", "libx264", "libvpx-vp9", "aac"),
    ".mov": ("mov", "libx264", "prores_ks", "aac"),
    ".webm": ("webm", "libvpx-vp9", "libvpx-vp9", "libopus"),
}
_OPAQUE_FORMATS = ("yuv420p", "yuv422p10le", "yuv444p", "rgb24", "bgr0")
_ALPHA_FORMATS = ("yuva420p", "yuva444p10le", "yuva444p", "rgba", "bgra", "argb")
_CODEC_OPTIONS = {"libx264": H264_OPTIONS, "prores_ks": {"profile": "4"},       # profile 4: ProRes 4444
                  "libvpx-vp9": {"crf": "24", "b": "0", "deadline": "realtime", "cpu-used": "8",
                                 "row-mt": "1"}}


class VideoError(FacepuppetError, ValueError):
    """``--video`` cannot be written as asked (no PyAV, unknown codec, odd size, ...); the message says why."""


@dataclass
class VideoPlan:
    """What ``--video`` will write, checked before any work (:func:`plan_video`).

    Attributes
    ----------
    path : Path, the final file
    width, height : int, pixels
    container : str, FFmpeg's format name
    codec, pix_fmt : the encoder and pixel format of opaque frames
    alpha_codec, alpha_pix_fmt : those of frames with alpha (None: refused)
    audio_codec : str
    audio : ndarray of shape (n,), float32, the sound track at ``AUDIO_RATE`` Hz, or None
    audio_path : Path or None, where it came from
    """

    path: Path
    width: int
    height: int
    container: str
    codec: str
    pix_fmt: str
    alpha_codec: str | None
    alpha_pix_fmt: str | None
    audio_codec: str
    audio: np.ndarray | None = field(default=None, repr=False)
    audio_path: Path | None = None

    def describe(self, fps: float) -> str:
        """One line for the start of a run."""
        sound = (f", sound from {self.audio_path} ({len(self.audio) / AUDIO_RATE:.2f} s, {self.audio_codec})"
                 if self.audio is not None else ", no sound (--audio-file WAV adds it)")
        alpha = f"; frames with alpha as {self.alpha_codec} {self.alpha_pix_fmt}" if self.alpha_codec else ""
        return (f"video: {self.path}, {self.width}x{self.height} {self.codec} {self.pix_fmt}, one frame per tick "
                f"(time base 1/{fps:g} s){sound}{alpha}")


def _av():
    try:
        import av
    except ImportError:
        raise VideoError("--video: needs PyAV, which is not installed: pip install 'facepuppet[video]' "
                         "(or pip install av)") from None
    return av


def _encoder(av, name: str, option: str):
    try:
        codec = av.codec.Codec(name, "w")
    except Exception:
        raise VideoError(f"{option} {name}: FFmpeg (PyAV {av.__version__}) has no encoder of that name; "
                         "try libx264, libvpx-vp9, prores_ks, ffv1") from None
    if codec.type != "video":
        raise VideoError(f"{option} {name}: is a {codec.type} encoder, not a video one")
    return codec


def _pick_format(codec, alpha: bool) -> str | None:
    offered = [f.name for f in (codec.video_formats or ())]
    wanted = _ALPHA_FORMATS if alpha else _OPAQUE_FORMATS
    return next((f for f in wanted if f in offered), None if alpha else (offered[0] if offered else None))


def _check_encodes(av, container: str, codec: str, pix_fmt: str, width: int, height: int, what: str) -> None:
    """Encode one black frame into memory: the catch-all check that this codec, format and size go together."""
    import io

    buffer = io.BytesIO()
    try:
        with av.open(buffer, mode="w", format=container) as out:
            stream = out.add_stream(codec, rate=30, options=_CODEC_OPTIONS.get(codec, {}))
            stream.width, stream.height, stream.pix_fmt = width, height, pix_fmt
            frame = av.VideoFrame(width, height, pix_fmt)
            for plane in frame.planes:
                plane.update(bytes(plane.buffer_size))
            frame.pts = 0
            for packet in stream.encode(frame):
                out.mux(packet)
            for packet in stream.encode(None):
                out.mux(packet)
    except (av.FFmpegError, ValueError) as exc:
        raise VideoError(f"--video: {what}: FFmpeg cannot write {codec} {pix_fmt} {width}x{height} into "
                         f"{container}: {exc}") from None


def plan_video(path: str | Path, width: int, height: int, codec: str | None = None,
               alpha: bool | None = None, audio_file: str | Path | None = None) -> VideoPlan:
    """Check everything ``--video`` needs before any work; the plan, or :class:`VideoError` naming what is wrong.

    Parameters
    ----------
    path : the output file; its suffix picks the container (:data:`CONTAINERS`)
    width, height : int, pixels of every frame
    codec : str or None, ``--video-codec`` (default: the container's)
    alpha : True when the frames will carry alpha (refused where no alpha codec is known), False when they
        will not, None when unknown (both are prepared; a 4-channel frame without an alpha codec is
        then refused at the first frame)
    audio_file : WAV path or None, the sound track
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in CONTAINERS:
        raise VideoError(f"--video {path}: unknown container {suffix or '(no suffix)'!r}; name a "
                         f"{', '.join(CONTAINERS)} file")
    av = _av()
    container, opaque, alpha_codec, audio_codec = CONTAINERS[suffix]
    if codec is not None:
        opaque = alpha_codec = codec
    pix_fmt = _pick_format(_encoder(av, opaque, "--video-codec"), alpha=False)
    alpha_fmt = None if alpha_codec is None else _pick_format(_encoder(av, alpha_codec, "--video-codec"), alpha=True)
    if alpha_fmt is None:
        alpha_codec = None
    if alpha and alpha_codec is None:
        why = (f"{opaque} has no pixel format with alpha" if codec is not None
               else f"{opaque} in {suffix} carries no alpha")
        raise VideoError(f"--video {path}: the frames carry alpha and {why}; name a .webm (VP9) or .mov "
                         "(ProRes 4444) file")
    for name, fmt, needed in ((opaque, pix_fmt, alpha is not True), (alpha_codec, alpha_fmt, alpha is not False)):
        if not needed or name is None:
            continue
        if "420" in fmt and (width % 2 or height % 2):
            raise VideoError(f"--video: {name} {fmt} needs an even width and height, got --size {width}x{height}; "
                             f"try --size {width + width % 2}x{height + height % 2}")
        _check_encodes(av, container, name, fmt, width, height, f"--video {path}")
    audio = None
    if audio_file is not None:
        audio = _read_track(Path(audio_file))
    return VideoPlan(path, width, height, container, opaque, pix_fmt, alpha_codec, alpha_fmt, audio_codec,
                     audio, None if audio_file is None else Path(audio_file))


def _read_track(path: Path) -> np.ndarray:
    """The WAV's samples mixed to mono, at ``AUDIO_RATE``, float32 (InputFileError naming the file)."""
    from scipy.signal import resample_poly


    samples, rate = read_wav(path)
    if rate != AUDIO_RATE:
        g = math.gcd(int(rate), AUDIO_RATE)
        samples = resample_poly(samples, AUDIO_RATE // g, int(rate) // g)
    return np.clip(samples, -1.0, 1.0).astype(np.float32)


def add_video_arguments(parser: argparse.ArgumentParser, audio_help: str | None) -> None:
    """``--video FILE`` and ``--video-codec``; with ``audio_help``, also ``--audio-file WAV`` (the sound track)."""
    parser.add_argument("--video", type=Path, default=None, metavar="FILE",
                        help="encode the drawn ticks as a video: .mp4 (H.264, default), .mkv, .mov, .webm (VP9); "
                             "with --audio-file as its sound; frames with alpha as VP9 (.webm) or ProRes 4444 (.mov)")
    parser.add_argument("--video-codec", default=None, metavar="CODEC",
                        help="with --video, the FFmpeg encoder (default: the container's, e.g. libx264 for .mp4)")
    if audio_help is not None:
        parser.add_argument("--audio-file", type=Path, default=None, metavar="WAV", help=audio_help)


class VideoSink:
    """The frame loop's ``--video`` sink: each tick's pixels encoded as one frame (see the module doc).

    Parameters
    ----------
    plan : VideoPlan, from :func:`plan_video`
    fps : float, ticks per second of the tick grid (the time base is 1 / fps)
    progress : Progress or None, told the count of frames written

    Attributes
    ----------
    frames : int, frames written; ``duration`` : float, seconds of video so far
    audio_samples : int, samples of sound written
    """

    def __init__(self, plan: VideoPlan, fps: float, progress: Progress | None = None) -> None:

        self.av = _av()
        self.plan = plan
        self.rate = Fraction(fps).limit_denominator(1001)
        if not self.rate > 0:
            raise VideoError(f"--video: expected a positive frame rate, got {fps!r}")
        self.progress = progress
        self._outputs = OutputSet()
        self._temp = self._outputs.path(plan.path)
        self._out = None
        self._video = self._audio = None
        self._k0: int | None = None
        self._last = -1
        self.frames = 0
        self.audio_samples = 0
        self.channels: int | None = None
        self._closed = False

    @property
    def duration(self) -> float:
        """Seconds of video written: (last pts + 1) / fps."""
        return 0.0 if self._k0 is None else float((self._last + 1) / self.rate)

    def _open(self, channels: int) -> None:
        av, plan = self.av, self.plan
        if channels == 4:
            if plan.alpha_codec is None:
                raise VideoError(f"--video {plan.path}: the frames carry alpha and {plan.codec} in "
                                 f"{plan.path.suffix} has none; name a .webm (VP9) or .mov (ProRes 4444) file")
            codec, pix_fmt = plan.alpha_codec, plan.alpha_pix_fmt
        else:
            codec, pix_fmt = plan.codec, plan.pix_fmt
        self._out = av.open(str(self._temp), mode="w", format=plan.container)
        stream = self._out.add_stream(codec, rate=self.rate, options=_CODEC_OPTIONS.get(codec, {}))
        stream.width, stream.height, stream.pix_fmt = plan.width, plan.height, pix_fmt
        stream.codec_context.time_base = 1 / self.rate
        self._video = stream
        self._rgb_format = "rgba" if channels == 4 else "rgb24"
        if plan.audio is not None:
            audio = self._out.add_stream(plan.audio_codec, rate=AUDIO_RATE)
            audio.layout = "mono"
            audio.format = "fltp" if plan.audio_codec == "aac" else "flt"
            self._audio = audio
        self.channels = channels

    def __call__(self, info: TickInfo) -> None:
        """Tick observer: encode the tick's picture (``renderer.read_pixels()``) as the frame of tick ``k``."""
        self.write(info.k, info.renderer.read_pixels())

    def write(self, k: int, pixels: np.ndarray) -> None:
        """Encode ``pixels`` (h, w, 3) or (h, w, 4) uint8, top row first, as the frame of tick ``k``."""
        if self._closed:
            raise VideoError(f"--video {self.plan.path}: written after close")
        pixels = np.asarray(pixels)
        h, w = self.plan.height, self.plan.width
        if pixels.dtype != np.uint8 or pixels.ndim != 3 or pixels.shape[:2] != (h, w) or pixels.shape[2] not in (3, 4):
            raise VideoError(f"--video {self.plan.path}: expected frames of ({h}, {w}, 3) or ({h}, {w}, 4) uint8, "
                             f"got {pixels.shape} {pixels.dtype}")
        if self._out is None:
            self._open(pixels.shape[2])
            self._k0 = k
        elif pixels.shape[2] != self.channels:
            raise VideoError(f"--video {self.plan.path}: the frames changed from {self.channels} to "
                             f"{pixels.shape[2]} channels")
        pts = k - self._k0
        if pts <= self._last:
            raise VideoError(f"--video {self.plan.path}: tick {k} comes after tick {self._last + self._k0}")
        frame = self.av.VideoFrame.from_ndarray(np.ascontiguousarray(pixels), format=self._rgb_format)
        frame.pts = pts
        frame.time_base = self._video.codec_context.time_base
        for packet in self._video.encode(frame):
            self._out.mux(packet)
        self._last = pts
        self.frames += 1
        if self._audio is not None:
            self._write_audio(self._sample_at(pts + 1), whole_frames=True)
        if self.progress is not None:
            self.progress.update(self.frames)

    def _sample_at(self, pts: int) -> int:
        """The sound sample (from the first tick) at video time ``pts`` / fps."""
        return int(round(float(pts / self.rate) * AUDIO_RATE))

    def _write_audio(self, until: int, whole_frames: bool) -> None:
        """Encode the sound track up to sample ``until`` (silence past the WAV's end)."""
        audio = self._audio
        size = audio.codec_context.frame_size or 1024
        start = int(round(float(self._k0 / self.rate) * AUDIO_RATE))  # the first tick's time in the WAV
        track = self.plan.audio
        while self.audio_samples < until:
            n = min(size, until - self.audio_samples)
            if whole_frames and n < size:
                break
            at = start + self.audio_samples
            chunk = np.zeros(n, dtype=np.float32)
            got = track[at:at + n]
            chunk[:len(got)] = got
            frame = self.av.AudioFrame.from_ndarray(chunk.reshape(1, n), format=audio.format.name, layout="mono")
            frame.sample_rate = AUDIO_RATE
            frame.pts = self.audio_samples
            frame.time_base = Fraction(1, AUDIO_RATE)
            for packet in audio.encode(frame):
                self._out.mux(packet)
            self.audio_samples += n

    def close(self) -> None:
        """Flush the encoders, finish the file and rename it into place (once). No frame written: no file."""
        if self._closed:
            return
        self._closed = True
        if self._out is None:
            self._outputs.abort()
            return
        try:
            for packet in self._video.encode(None):
                self._out.mux(packet)
            if self._audio is not None:
                self._write_audio(self._sample_at(self._last + 1), whole_frames=False)
                for packet in self._audio.encode(None):
                    self._out.mux(packet)
            self._out.close()
        except BaseException:
            self._outputs.abort()
            raise
        self._outputs.commit()

    def abort(self) -> None:
        """Stop without a file: a failed run leaves no half-written video."""
        if self._closed:
            return
        self._closed = True
        if self._out is not None:
            try:
                self._out.close()
            except Exception:  # the file is removed either way
                pass
        self._outputs.abort()
