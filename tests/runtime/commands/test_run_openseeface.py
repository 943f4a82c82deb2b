"""``run --input openseeface --headless`` over real UDP on 127.0.0.1, its recording, and the committed sample.

The datagrams come from the test's own sender (helpers/openseeface_sender.py), two faces each; the run
follows ``--face-id 7`` and the replay of its recording must follow the same face.
"""

from __future__ import annotations

import json
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from facepuppet.runtime.cli import main
from facepuppet.runtime.recording.session import read_session

from helpers.logs import said
from helpers.openseeface_sender import osf_record
from helpers.small_characters import sphere_character
from helpers.udp_helpers import free_udp_port

SAMPLE = Path(__file__).resolve().parents[1] / "inputs" / "data" / "openseeface_sample.fps"
TRUTH = SAMPLE.with_suffix(".json")
FAST_CONFIG = """
[filter.mouth]
min_cutoff = 200.0   # next to no smoothing: the test reads the sent values back
[tracking_loss]
timeout_s = 30.0
"""


@pytest.fixture(scope="module")
def character(tmp_path_factory):
    path = tmp_path_factory.mktemp("osf") / "sphere.npz"
    sphere_character().save(path)
    return path


@pytest.mark.gl
def test_run_follows_the_chosen_face_and_its_replay_does_too(character, tmp_path, capsys):
    port = free_udp_port()
    config = tmp_path / "live.toml"
    config.write_text(FAST_CONFIG)
    done = threading.Event()
    sent = [0]

    def sender():
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            while not done.is_set():
                data = (osf_record(face_id=3, features={"mouth_open": 0.2})
                        + osf_record(face_id=7, features={"mouth_open": 0.6}))
                sock.sendto(data, ("127.0.0.1", port))
                sent[0] += 1
                time.sleep(0.01)

    weights, record = tmp_path / "w.npy", tmp_path / "live.fps"
    thread = threading.Thread(target=sender, daemon=True)
    thread.start()
    try:
        code = main(["run", "-c", str(character), "--input", "openseeface", "--face-id", "7",
                     "--listen", f"127.0.0.1:{port}", "--headless", "--duration", "1.5", "--size", "64x48",
                     "--config", str(config), "--stats", "--dump-weights", str(weights), "--record", str(record)])
    finally:
        done.set()
        thread.join(timeout=30)
    out = said(capsys)
    assert code == 0, out
    assert "listening for openseeface on 127.0.0.1:" in out
    stats = json.loads(next(line for line in out.splitlines() if line.startswith("stats json: "))[12:])
    udp = stats["counters"]["udp"]
    assert udp["packets"] >= 10 and udp["malformed"] == 0 and udp["other_face"] == 0 and udp["internal_error"] == 0
    w = np.load(weights)
    assert w[-1, 0] == pytest.approx(0.6, abs=1e-3)          # face 7's mouth, not face 3's 0.2
    assert not np.any(np.abs(w[:, 0] - 0.2) < 1e-3)
    session = read_session(record)
    assert session.header["info"]["input"] == "openseeface"
    assert session.header["info"]["options"]["face_id"] == "7"
    assert len(session.packets) == udp["packets"]

    replayed = tmp_path / "r.npy"
    code = main(["replay", str(record), "-c", str(character), "--headless", "--size", "64x48",
                 "--config", str(config), "--dump-weights", str(replayed)])
    assert code == 0, capsys.readouterr()
    r = np.load(replayed)
    assert r[-1, 0] == pytest.approx(0.6, abs=1e-3) and not np.any(np.abs(r[:, 0] - 0.2) < 1e-3)


def test_face_id_is_only_for_openseeface(character, capsys):
    code = main(["run", "-c", str(character), "--input", "vmc", "--face-id", "2", "--headless", "--duration", "0.1"])
    assert code == 2 and "--face-id: only for --input openseeface" in capsys.readouterr().err


def test_the_committed_sample_decodes_to_what_its_sender_sent():
    """The sample (made by make_openseeface_sample.py with the test sender) read back through the recording
    reader and a face-7 adapter: every packet a frame, jawOpen and the left blink as the truth file says."""
    from facepuppet.runtime.inputs.openseeface import OpenSeeFaceAdapter
    from facepuppet.runtime.mapping.channels import ARKIT_NAMES
    from facepuppet.runtime.recording.ticked_source import read_live_recording

    truth = json.loads(TRUTH.read_text())
    live = read_live_recording(SAMPLE, lambda kind: OpenSeeFaceAdapter(face_id=7))
    assert live.header["info"]["input"] == "openseeface" and live.header["info"]["options"]["face_id"] == "7"
    frames = [f for f in live.frames]
    assert len(frames) == len(truth) == 30
    jaw, blink = ARKIT_NAMES.index("jawOpen"), ARKIT_NAMES.index("eyeBlinkLeft")
    for frame, want in zip(frames, truth):
        assert float(frame.weights[jaw]) == pytest.approx(min(max(want["mouth_open"], 0.0), 1.0), abs=1e-6)
        assert float(frame.weights[blink]) == (1.0 if want["left_open"] == 0.0 else 0.0)
        assert frame.t == pytest.approx(want["t"])


@pytest.mark.gl
def test_the_committed_sample_replays_following_its_recorded_face(character, tmp_path, capsys):
    out = tmp_path / "w.npy"
    config = tmp_path / "live.toml"
    config.write_text(FAST_CONFIG)
    code = main(["replay", str(SAMPLE), "-c", str(character), "--headless", "--size", "64x48",
                 "--config", str(config), "--dump-weights", str(out)])
    assert code == 0, capsys.readouterr()
    w = np.load(out)
    truth = [min(max(t["mouth_open"], 0.0), 1.0) for t in json.loads(TRUTH.read_text())]
    assert w[:, 0].max() == pytest.approx(max(truth), abs=2e-3)   # face 7's mouth (face 3's is 0.05)
    assert w[-1, 0] == pytest.approx(truth[-1], abs=0.01)  # (the mouth filter still smooths a little)
