"""``--stream URL``: the drawn ticks as a live MPEG-TS video stream over the network, for OBS's Media Source.

What goes out: H.264 (libx264, preset ``ultrafast``, tune ``zerolatency``: no B-frames, no look-ahead, each
frame leaves as soon as it is encoded) in 4:2:0, a keyframe every second so a viewer that joins late starts
within one, in MPEG-TS, through PyAV (the optional extra ``video``). Each picture carries its tick's time
(90 kHz, from the first picture sent), so a live run drawing on arrival streams a variable frame rate as
drawn, at most ``--fps`` pictures a second (the ticks between are left out, counted as ``over_rate``). A
picture with alpha is composited over the key colour (green), as the virtual camera does; an opaque
one goes as drawn.

Destinations (``--stream``), nothing else:

* ``udp://HOST:PORT``: datagrams of 7 TS packets (``pkt_size=1316``, the size every TS-over-UDP receiver
  reads) sent to HOST:PORT; in OBS, a Media Source with the input ``udp://@:PORT`` (local file off) plays it.
  Nothing is bound or listened on here: the stream goes where the user points it, a multicast address
  included.
* ``srt://HOST:PORT`` (caller mode): needs an FFmpeg built with libsrt. PyAV's wheels are built without it,
  so on those ``srt://`` is refused before the run naming what is missing and the protocols this FFmpeg has
  (read from ``avio_enum_protocols`` of the libavformat PyAV loaded). A listener (``mode=listener``) is
  refused: facepuppet sends, it does not listen.

A URL that is not one of these (another scheme, no host, no port, a port out of range, a query FFmpeg
options cannot be) is refused with exit 2 naming ``--stream``, before any work; an odd ``--size`` too (4:2:0).

The frame loop reads the pixels back and hands them over (:mod:`~facepuppet.runtime.live.frame_handoff`);
the encoder and the socket run in the stream's worker thread, and what they cannot take in time is dropped
and counted (``--stats``: ``stream: sent=... dropped=...``).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import logging
import re
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import parse_qsl, urlsplit

import numpy as np

from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.live.frame_handoff import FrameHandoff, TickReadback, over_key

if TYPE_CHECKING:
    from facepuppet.runtime.live.loop import TickInfo

logger = logging.getLogger(__name__)

SCHEMES = ("udp", "srt")
TS_PACKETS = 1316  # 7 x 188-byte TS packets: one datagram, under any Ethernet MTU
TIME_BASE = Fraction(1, 90000)  # MPEG-TS's clock
H264_LIVE = {"preset": "ultrafast", "tune": "zerolatency", "crf": "20"}
KEY_GREEN = (0, 255, 0)
_QUERY = re.compile(r"[A-Za-z0-9_]{1,32}")
_VALUE = re.compile(r"[A-Za-z0-9_.:/-]{0,128}")


@dataclass(frozen=True)
class StreamPlan:
    """What ``--stream`` will send, checked before any work (:func:`plan_stream`).

    Attributes
    ----------
    url : str, what FFmpeg opens (``pkt_size`` added to a udp:// one)
    given : str, the URL as the user gave it (what is said)
    scheme, host : str; port : int
    width, height : int, pixels
    fps : float or None, the rate the encoder is told (None: the session's); a keyframe every ``fps`` pictures
    key : tuple of 3 int, the colour pictures with alpha are composited over
    transparent : bool, the picture has alpha (``--background transparent``): composited over ``key``; else
        encoded from the framebuffer's RGBA as it is (the conversion to 4:2:0 ignores the alpha)
    """

    url: str
    given: str
    scheme: str
    host: str
    port: int
    width: int
    height: int
    fps: float | None = None
    key: tuple[int, int, int] = KEY_GREEN
    transparent: bool = False

    def describe(self, fps: float) -> str:
        return (f"stream: {self.given}, MPEG-TS H.264 (libx264 ultrafast zerolatency) {self.width}x{self.height}, "
                f"keyframe every {max(1, round(fps))} frames; nothing listens here (OBS: Media Source, input "
                f"{self.scheme}://@:{self.port})")


@functools.cache
def output_protocols() -> frozenset[str] | None:
    """The output protocols of the FFmpeg PyAV loaded (None when its libavformat cannot be found to ask)."""
    import av

    wheel_libs = Path(av.__file__).resolve().parent.parent / "av.libs"
    found = sorted(wheel_libs.glob("libavformat*.so*")) if wheel_libs.is_dir() else []
    name = str(found[0]) if found else ctypes.util.find_library("avformat")
    if name is None:
        return None
    try:
        enum = ctypes.CDLL(name).avio_enum_protocols
    except (OSError, AttributeError):
        return None
    enum.restype = ctypes.c_char_p
    enum.argtypes = [ctypes.POINTER(ctypes.c_void_p), ctypes.c_int]
    opaque = ctypes.c_void_p(None)
    names = []
    while (protocol := enum(ctypes.byref(opaque), 1)) is not None:
        names.append(protocol.decode("ascii", "replace"))
    return frozenset(names)


def _refuse(given: str, why: str) -> UsageError:
    return UsageError(f"--stream {given}: {why}")


def plan_stream(given: str, width: int, height: int, fps: float | None,
                background: tuple[float, float, float], transparent: bool) -> StreamPlan:
    """Check ``--stream URL`` (see the module doc); the plan, or UsageError naming ``--stream``."""
    text = (given or "").strip()
    expected = "expected udp://HOST:PORT or srt://HOST:PORT"
    try:
        parts = urlsplit(text)
        port = parts.port
    except ValueError as exc:
        raise _refuse(text, f"{expected} ({exc})") from None
    scheme = parts.scheme.lower()
    if scheme not in SCHEMES:
        raise _refuse(text, f"{expected}, not {scheme + '://' if scheme else 'a URL without a scheme'}")
    host = parts.hostname
    if not host or port is None or not 0 < port < 65536:
        raise _refuse(text, f"{expected}: needs a host and a port (1..65535)")
    if parts.path not in ("", "/") or parts.fragment or parts.username or parts.password:
        raise _refuse(text, f"{expected}, with at most a ?key=value query of FFmpeg's {scheme} options")
    try:
        query = parse_qsl(parts.query, keep_blank_values=True, strict_parsing=bool(parts.query))
    except ValueError:
        raise _refuse(text, "the query is not key=value pairs") from None
    for key, value in query:
        if not _QUERY.fullmatch(key) or not _VALUE.fullmatch(value):
            raise _refuse(text, f"the query option {key!r} is not a plain key=value")
        if key in ("listen", "mode") and value not in ("", "0", "caller"):
            raise _refuse(text, f"{key}={value}: facepuppet sends a stream, it does not listen for one")
    try:
        import av  # the optional extra: PyAV
    except ImportError:
        raise _refuse(text, "needs PyAV, which is not installed: pip install 'facepuppet[video]' (or pip install "
                            "av)") from None
    protocols = output_protocols()
    if scheme == "srt" and protocols is not None and "srt" not in protocols:
        raise _refuse(text, f"this PyAV's FFmpeg ({av.__version__}, FFmpeg {av.ffmpeg_version_info}) was built "
                            "without SRT (libsrt); its output protocols are " + ", ".join(sorted(protocols))
                      + "; send udp://HOST:PORT instead, or install a PyAV built against an FFmpeg with libsrt")
    if "mpegts" not in av.formats_available:
        raise _refuse(text, "this PyAV's FFmpeg has no MPEG-TS muxer")
    if "libx264" not in av.codecs_available:
        raise _refuse(text, "this PyAV's FFmpeg has no libx264 encoder")
    if width % 2 or height % 2:
        raise _refuse(text, f"H.264 4:2:0 needs an even width and height, got --size {width}x{height}; try "
                            f"--size {width + width % 2}x{height + height % 2}")
    keys = {k for k, _ in query}
    url = text if scheme != "udp" or "pkt_size" in keys else text + ("&" if parts.query else "?") + \
        f"pkt_size={TS_PACKETS}"
    key = KEY_GREEN if transparent else tuple(int(round(min(max(c, 0.0), 1.0) * 255)) for c in background)
    return StreamPlan(url, text, scheme, host, port, int(width), int(height), fps, key,  # type: ignore[arg-type]
                      bool(transparent))


class StreamSink:
    """The frame loop's ``--stream`` output: a tick observer handing pictures to the encoder's thread.

    The container is opened here (a host that does not resolve is refused, naming ``--stream``, before the
    first tick); the encoder and the sends run in the worker.

    Attributes
    ----------
    counters : dict, the handoff's counts (``sent`` = pictures encoded and sent)
    packets, bytes : int, TS packets muxed and their payload bytes
    recent : deque of (pts, GPU-finished stamp) of the last ``RECENT`` pictures sent: what a viewer's
        latency is measured against (``bench latency --stream``)
    """

    RECENT = 1 << 14

    name = "stream"

    def __init__(self, plan: StreamPlan, fps: float, readback: TickReadback | None = None) -> None:
        import av  # the optional extra: PyAV

        self.av = av
        self.plan = plan
        self.readback = readback or TickReadback()
        rate = Fraction(fps).limit_denominator(1001)
        try:
            self._out = av.open(plan.url, mode="w", format="mpegts")
        except (av.FFmpegError, OSError) as exc:
            raise UsageError(f"--stream {plan.given}: cannot open it: {exc}") from None
        stream = self._out.add_stream("libx264", rate=rate, options=dict(H264_LIVE))
        stream.width, stream.height, stream.pix_fmt = plan.width, plan.height, "yuv420p"
        stream.codec_context.time_base = TIME_BASE
        stream.codec_context.gop_size = max(1, round(fps))
        self._video = stream
        self._t0: float | None = None
        self._last = -1
        self.packets = self.bytes = 0
        self.recent: deque[tuple[int, float]] = deque(maxlen=self.RECENT)
        self._closed = False
        self.handoff = FrameHandoff(self._send, "stream", fps=fps)
        self.counters = self.handoff.counters

    def __call__(self, info: TickInfo) -> None:
        self.handoff.take(info, self.readback)

    def _send(self, k: int, t: float, stamp: float, pixels: np.ndarray) -> None:
        if self._t0 is None:
            self._t0 = t
        pts = max(self._last + 1, int(round((t - self._t0) / TIME_BASE)))
        if self.plan.transparent or pixels.shape[2] == 3:
            frame = self.av.VideoFrame.from_ndarray(np.ascontiguousarray(over_key(pixels, self.plan.key)),
                                                    format="rgb24")
        else:  # RGBA converts to 4:2:0 faster than RGB, and the loop read it so
            frame = self.av.VideoFrame.from_ndarray(np.ascontiguousarray(pixels), format="rgba")
        frame.pts = pts
        frame.time_base = TIME_BASE
        self._mux(self._video.encode(frame))
        self._last = pts
        self.recent.append((pts, stamp))

    def _mux(self, packets) -> None:
        for packet in packets:
            self.packets += 1
            self.bytes += packet.size
            self._out.mux(packet)

    def costs(self) -> dict:
        return {**self.handoff.costs(), "packets": self.packets, "bytes": self.bytes}

    def close(self) -> None:
        """Encode what is waiting, flush the encoder, close the stream (once)."""
        if self._closed:
            return
        self._closed = True
        if not self.handoff.close():  # the encoder or the socket still busy: left to the process's end
            return
        try:
            if self.handoff.failure is None and self._t0 is not None:
                self._mux(self._video.encode(None))
        finally:
            self._out.close()


def open_stream(plan: StreamPlan, fps: float, readback: TickReadback | None = None,
                log: Callable[[str], None] = logger.info) -> StreamSink:
    """The sink, its destination said once."""
    sink = StreamSink(plan, fps, readback)
    log(plan.describe(fps))
    return sink
