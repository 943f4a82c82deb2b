"""Make ``openseeface_sample.fps``: 30 datagrams from the test's own OpenSeeFace sender, as ``run --record``
stores them (a live-packets session), and ``openseeface_sample.json``: what was sent (the truth the tests
compare against). Two faces per datagram (ids 3 and 7); the recording says it followed face 7.

    python tests/runtime/inputs/data/make_openseeface_sample.py   (from the repository root, PYTHONPATH=tests)
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from facepuppet.runtime.recording.recorder import PacketRecorder

from helpers.openseeface_sender import osf_record

HERE = Path(__file__).resolve().parent
N = 30
FPS = 30.0


def main() -> None:
    truth = []
    path = HERE / "openseeface_sample.fps"
    with PacketRecorder(path, "openseeface", info={"fps": FPS, "idle_fps": None, "listen": "127.0.0.1:11573",
                                                   "options": {"face_id": "7"}}, overwrite=True,
                        fsync_every_s=None) as recorder:
        for k in range(N):
            t = k / FPS
            mouth = round(0.5 + 0.5 * math.sin(2 * math.pi * k / N), 4)
            left_open = 0.0 if k in (10, 11) else 1.0
            other = osf_record(time=1.7e9 + t, face_id=3, features={"mouth_open": 0.05})
            ours = osf_record(time=1.7e9 + t, face_id=7, left_open=left_open, features={"mouth_open": mouth})
            recorder.put(other + ours, t)
            truth.append({"t": t, "face_id": 7, "mouth_open": mouth, "left_open": left_open})
    (HERE / "openseeface_sample.json").write_text(json.dumps(truth, indent=1) + "\n")


if __name__ == "__main__":
    main()
