"""The tracker senders of ``bench latency``: a separate process streaming one protocol over loopback.

Each kind of :data:`SENDERS` makes the datagrams of a frame at time ``t``: ``vmc`` (every ARKit channel in
PascalCase plus the Head bone, split into bundles under 1,500 bytes with Apply last, i.e. what
:class:`~facepuppet.runtime.live.vmc_out.VmcSender` sends), ``openseeface`` (one datagram of one 1785-byte
face record per frame, mouth and brows moving), and the phone kinds ``ifacialmocap`` and ``vtubestudio``:
one datagram per frame from a sender that plays the phone: it binds 127.0.0.1, prints ``phone PORT``,
waits for the run's ``--phone`` start payload / data request, then, once told ``go`` on stdin (the run is
ready to draw), streams to the requester, VTube Studio to the ports its request names.
:func:`decode_cost` times the adapter's ``handle`` (what the receiver runs for each datagram) over
``DECODE_PACKETS`` prepared datagrams with ``perf_counter_ns``: p50/p99 in µs, and per frame for VMC's
several datagrams; ``per_frame`` of each class is its datagrams per frame.

Run a sender alone with
``python -m facepuppet.runtime.bench.senders --send HOST PORT RATE SECONDS [KIND]``.
"""

from __future__ import annotations

import math
import socket
import sys
import time
from collections.abc import Iterator

import numpy as np

from facepuppet.runtime.inputs.ifacialmocap import encode_ifm_frame
from facepuppet.runtime.inputs.kinds import make_adapter
from facepuppet.runtime.inputs.openseeface import FEATURES, encode_record
from facepuppet.runtime.inputs.vtubestudio import encode_vts_frame
from facepuppet.runtime.live.vmc_out import VmcSender
from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.model.geometry import euler_to_quat

DECODE_PACKETS = 20_000


class _VmcFrames:
    """VMC frames as :class:`~facepuppet.runtime.live.vmc_out.VmcSender` sends them."""

    def __init__(self, host: str, port: int) -> None:

        self.sender = VmcSender(host, port, ARKIT_NAMES)
        self.phases = np.arange(len(ARKIT_NAMES)) * 0.37
        self.per_frame = len(self.sender.datagrams)

    def datagrams(self, t: float) -> list[bytes]:
        """The datagrams of the frame at ``t`` seconds, as sent (to this object's loopback address)."""
        self.send(t)
        return [bytes(d) for d in self.sender.datagrams]

    def send(self, t: float) -> None:

        weights = 0.5 + 0.5 * np.sin(2 * np.pi * 0.7 * t + self.phases)
        self.sender.send(weights, euler_to_quat(0.2 * math.sin(t), 0.1 * math.sin(1.3 * t), 0.0), (0.0, 0.0, 0.0))

    def close(self) -> None:
        self.sender.close()


class _OpenSeeFaceFrames:
    """OpenSeeFace datagrams: one face record per frame, mouth, brows and eyes moving, head turning."""

    per_frame = 1

    def __init__(self, host: str, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.address = (host, port)

    @staticmethod
    def datagrams(t: float) -> list[bytes]:

        features = [0.8 * math.sin(2 * np.pi * 0.7 * t + 0.37 * i) for i in range(len(FEATURES))]
        half = 0.1 * math.sin(t)
        quaternion = (math.sin(half) * math.sqrt(0.5), math.sin(half) * math.sqrt(0.5),
                      math.cos(half) * math.sqrt(0.5), math.cos(half) * math.sqrt(0.5))
        openness = 0.5 + 0.5 * math.cos(2 * np.pi * 0.3 * t)
        return [encode_record(time=t, face_id=0, right_open=openness, left_open=openness, quaternion=quaternion,
                              translation=(0.1, 0.0, 5.0), features=features)]

    def send(self, t: float) -> None:
        for d in self.datagrams(t):
            self.sock.sendto(d, self.address)

    def close(self) -> None:
        self.sock.close()


PHONE_WAIT_S = 60.0  # the phone sender waits this long for the run's first request


def _phone_weights(t: float) -> np.ndarray:
    return 0.5 + 0.5 * np.sin(2 * np.pi * 0.7 * t + np.arange(52) * 0.37)


class _PhoneFrames:
    """A phone app's frames, one datagram each, sent from the socket the app's request arrives on.

    ``plays_phone``: :func:`send` binds :meth:`listen`, waits for the run's request and lets
    :meth:`answer` pick where the frames go (before that, to ``(host, port)``).
    """

    per_frame = 1
    plays_phone = True

    def __init__(self, host: str, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.port = port
        self.targets = [(host, port)]

    def listen(self) -> int:
        """Bind the phone's socket on 127.0.0.1 (a free port, returned)."""
        self.sock.bind(("127.0.0.1", 0))
        return self.sock.getsockname()[1]

    def answer(self, request: bytes, requester: tuple) -> None:
        """Stream to the requester's IP at the run's port (iFacialMocap answers there whatever asked)."""
        self.targets = [(requester[0], self.port)]

    def datagrams(self, t: float) -> list[bytes]:
        return [self.encode(t)]

    def send(self, t: float) -> None:
        data = self.encode(t)
        for target in self.targets:
            try:
                self.sock.sendto(data, target)
            except BlockingIOError:  # a full send buffer drops the datagram (counted as lost by the bench)
                pass

    def close(self) -> None:
        self.sock.close()


class _IFacialMocapFrames(_PhoneFrames):
    """iFacialMocap v2 text frames: the 52 weights and the head (degrees)."""

    @staticmethod
    def encode(t: float) -> bytes:

        yaw, pitch = math.degrees(0.2 * math.sin(t)), math.degrees(0.1 * math.sin(1.3 * t))
        return encode_ifm_frame(_phone_weights(t), head=(pitch, yaw, 0.0, 0.0, 0.0, 0.0))


class _VTubeStudioFrames(_PhoneFrames):
    """VTube Studio phone-protocol JSON frames, sent to each port the data request names."""

    @staticmethod
    def encode(t: float) -> bytes:

        yaw, pitch = math.degrees(0.2 * math.sin(t)), math.degrees(0.1 * math.sin(1.3 * t))
        return encode_vts_frame(_phone_weights(t), rotation=(pitch, yaw, 0.0), timestamp_ms=int(t * 1000))

    def answer(self, request: bytes, requester: tuple) -> None:
        import json

        self.targets = [(requester[0], int(p)) for p in json.loads(request)["ports"]]


#: input kind -> the frames the bench's sender streams for it
SENDERS: dict[str, type] = {"vmc": _VmcFrames, "openseeface": _OpenSeeFaceFrames,
                            "ifacialmocap": _IFacialMocapFrames, "vtubestudio": _VTubeStudioFrames}


def decode_cost(kind: str, n: int = DECODE_PACKETS) -> dict:
    """Per-datagram cost of ``kind``'s adapter ``handle`` over ``n`` prepared datagrams: p50/p99/max µs."""

    frames = SENDERS[kind]("127.0.0.1", 9)  # loopback's discard port: VMC's sender fills its bytes by sending
    try:
        per_frame = frames.per_frame
        distinct = [frames.datagrams(k / 60.0) for k in range(200)]
    finally:
        frames.close()
    adapter = make_adapter(kind)
    handle, clock = adapter.handle, time.perf_counter_ns
    cost = np.empty(n, dtype=np.int64)
    i = 0
    while i < n:
        for d in distinct[(i // per_frame) % len(distinct)]:
            if i >= n:
                break
            t0 = clock()
            handle(d, 0.0)
            cost[i] = clock() - t0
            i += 1
    sizes = [len(d) for frame in distinct for d in frame]
    us = cost / 1e3
    p50, p99 = np.percentile(us, [50, 99])
    per_frame_us = us[: n - n % per_frame].reshape(-1, per_frame).sum(axis=1)
    f50, f99 = np.percentile(per_frame_us, [50, 99])
    return {"datagrams": n, "n": n, "bytes": int(np.mean(sizes)), "datagrams_per_frame": per_frame,
            "p50_us": float(p50), "p99_us": float(p99),
            "max_us": float(us.max()), "per_frame_p50_us": float(f50), "per_frame_p99_us": float(f99),
            "frames": adapter.counters.get("frames"), "internal_error": adapter.counters.get("internal_error")}


def send(host: str, port: int, rate: float, seconds: float, kind: str = "vmc") -> int:
    """Stream ``kind`` frames (:data:`SENDERS`) at ``rate`` Hz for ``seconds``; returns the number of frames sent.

    For the phone kinds ``port`` is the run's listening port and this process plays the phone: it prints
    ``phone PORT`` (its own port on 127.0.0.1), waits for the first request, then for a line on stdin
    ("go": the run is ready to draw; frames sent while it sets up would only go stale) and streams to the
    requester (VTube Studio: to the ports the request names).
    """
    frames = SENDERS[kind](host, port)
    if getattr(frames, "plays_phone", False):
        print(f"phone {frames.listen()}", flush=True)
        frames.sock.settimeout(PHONE_WAIT_S)
        request, requester = frames.sock.recvfrom(4096)
        sys.stdin.readline()
        frames.answer(request, requester)
        frames.sock.setblocking(False)
    k = 0
    for t in paced(rate, seconds):
        frames.send(t)
        k += 1
    frames.close()
    return k


def paced(rate: float, seconds: float) -> Iterator[float]:
    """The times 0, 1/rate, 2/rate, ... below ``seconds``, each yielded when the wall clock (monotonic) reaches it
    from the first; a late one is yielded at once (the schedule is kept, not shifted)."""
    start = time.monotonic()
    k = 0
    while (t := k / rate) < seconds:
        ahead = start + t - time.monotonic()
        if ahead > 0:
            time.sleep(ahead)
        yield t
        k += 1


if __name__ == "__main__":
    if len(sys.argv) in (6, 7) and sys.argv[1] == "--send":
        print(send(sys.argv[2], int(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5]),
                   *(sys.argv[6:7])), flush=True)
    else:
        print("usage: python -m facepuppet.runtime.bench.senders --send HOST PORT RATE SECONDS [KIND]",
              file=sys.stderr)
        raise SystemExit(2)
