"""What the tests of the virtual camera and the stream share: a pyvirtualcam backend that keeps the frames it is
sent (registered through pyvirtualcam's own ``register_backend``, chosen by name as any backend is), a small
Live Link Face take to replay, and an MPEG-TS byte stream decoded by PyAV."""

from __future__ import annotations

import io
import socket
import threading
import time

import numpy as np

from facepuppet.runtime.mapping.channels import ARKIT_NAMES, pascal

BACKEND = "facepuppet-recording"


class RecordingBackend:
    """A pyvirtualcam backend (the interface of ``pyvirtualcam.camera.Backend``) that keeps every frame sent.

    ``opened`` lists every instance made, newest last, so a test reads what a run's camera received after the
    run closed it."""

    opened: list[RecordingBackend] = []

    def __init__(self, *, width: int, height: int, fps: float, fourcc: int, device: str | None, **kw) -> None:
        self.width, self.height, self.fps, self.fourcc = width, height, fps, fourcc
        self._device = device or "/dev/video-recording"
        self.frames: list[np.ndarray] = []
        self.closed = False
        self.lock = threading.Lock()
        RecordingBackend.opened.append(self)

    def send(self, frame: np.ndarray) -> None:
        with self.lock:
            channels = frame.size // (self.width * self.height)   # RGB or RGBA, as the fourcc says
            self.frames.append(np.array(frame, copy=True).reshape(self.height, self.width, channels))

    def close(self) -> None:
        self.closed = True

    def device(self) -> str:
        return self._device

    def native_fourcc(self):
        return None


def register_recording_backend() -> str:
    import pyvirtualcam

    pyvirtualcam.register_backend(BACKEND, RecordingBackend)
    return BACKEND


def write_take(path, jaws) -> None:
    """A Live Link Face CSV take at 60 frames a second's timecodes, one row per tenth of a second, jawOpen from
    ``jaws``."""
    lines = ["Timecode,BlendShapeCount," + ",".join(pascal(n) for n in ARKIT_NAMES)]
    for i, jaw in enumerate(jaws):
        values = ["0"] * 52
        values[ARKIT_NAMES.index("jawOpen")] = repr(float(jaw))
        frame = i * 6
        lines.append(f"00:00:{frame // 60:02d}:{frame % 60:02d}.000,52," + ",".join(values))
    path.write_text("\n".join(lines) + "\n")


def decode_ts(data: bytes):
    """(RGB frames, their times in s from the first) of an MPEG-TS byte stream, decoded by PyAV."""
    import av

    frames, times = [], []
    with av.open(io.BytesIO(data), format="mpegts") as container:
        for frame in container.decode(video=0):
            frames.append(frame.to_ndarray(format="rgb24"))
            times.append(float(frame.pts * frame.time_base))
    return frames, [t - times[0] for t in times]


class Receiver:
    """A UDP socket on 127.0.0.1 bound before anything is sent, and a thread keeping every datagram."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.1)
        self.port = self.sock.getsockname()[1]
        self.datagrams: list[bytes] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self.datagrams.append(self.sock.recv(65536))
            except TimeoutError:
                continue

    def stop(self) -> bytes:
        time.sleep(0.2)  # what is still in flight on loopback
        self._stop.set()
        self._thread.join()
        self.sock.close()
        return b"".join(self.datagrams)
