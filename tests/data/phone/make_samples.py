"""Make the committed samples (see README.md): our own sender over loopback UDP into a real UdpSource,
recorded by PacketRecorder. Run from the repository with facepuppet importable."""

import math
import socket
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from facepuppet.runtime.inputs.kinds import make_adapter  # noqa: E402
from facepuppet.runtime.inputs.udp import UdpSource  # noqa: E402
from facepuppet.runtime.recording.recorder import PacketRecorder  # noqa: E402

from helpers.phone_senders import ARKIT_52, ifm_frame, vts_frame  # noqa: E402

N = 40


def value(k: int, i: int) -> float:
    return 0.5 + 0.5 * math.sin(0.3 * k + 0.1 * i)


def datagram(kind: str, k: int) -> bytes:
    if kind == "ifacialmocap":
        return ifm_frame({n: round(100 * value(k, i)) for i, n in enumerate(ARKIT_52)},
                         head=(k * 0.5, -k * 0.25, 1.0, 0.0, 0.01 * k, 0.0), right_eye=(k % 7, 2, 0),
                         left_eye=(k % 5, -2, 0), extra="hapihapi-0|", version=2 if k % 2 else 1)
    return vts_frame({n: round(value(k, i), 4) for i, n in enumerate(ARKIT_52)}, found=k < N - 5,
                     rotation=(k * 0.5, -k * 0.25, 1.0), position=(0.0, 0.01 * k, 0.0),
                     timestamp=1_700_000_000_000 + 16 * k)


def main() -> None:
    for kind in ("ifacialmocap", "vtubestudio"):
        path = Path(__file__).with_name(f"{kind}_sample.fps")
        recorder = PacketRecorder(path, kind, info={"made_by": "tests/data/phone/make_samples.py"}, overwrite=True)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        with UdpSource(make_adapter(kind), port=0, on_packet=recorder.put) as source:
            for k in range(N):
                sock.sendto(datagram(kind, k), source.address)
                time.sleep(0.005)
            end = time.monotonic() + 5
            while source.counters["packets"] < N and time.monotonic() < end:
                time.sleep(0.01)
            print(kind, source.counters)
        recorder.close()
        sock.close()


if __name__ == "__main__":
    main()
