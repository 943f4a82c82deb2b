"""End to end over real UDP on 127.0.0.1: ``run --input ifacialmocap|vtubestudio --phone 127.0.0.1:P --headless``
against a fake phone (a thread on 127.0.0.1 written from the published facts, helpers.phone_senders) that
waits for the start payload / data request, checks it and answers with frames; then the recording of the
run is replayed (frames and ``replay`` itself).

The fake iFacialMocap phone answers on the run's listening port (a real one always sends to 49983, which a
test cannot rely on being free); the fake VTube Studio phone answers on the ports its request names.
"""

from __future__ import annotations

import json
import socket
import threading
import time

import numpy as np
import pytest

from facepuppet.runtime.cli import main
from facepuppet.runtime.recording.replay_source import open_recording
from facepuppet.runtime.recording.session import read_session

from helpers.logs import said
from helpers.phone_senders import IFM_START, ifm_frame, vts_frame
from helpers.small_characters import sphere_character
from helpers.udp_helpers import free_udp_port

DEADLINE_S = 30.0  # waits of the fake phone: a run spawning its receiver on a loaded 2-core machine is slow

CONFIG = """
[filter.mouth]
min_cutoff = 200.0   # next to no smoothing: the test reads the sent values back
[tracking_loss]
timeout_s = 0.2
ease_out_s = 0.1
"""


@pytest.fixture(scope="module")
def character(tmp_path_factory):
    path = tmp_path_factory.mktemp("run_phone") / "sphere.npz"
    sphere_character().save(path)
    return path


class FakePhone(threading.Thread):
    """A phone app on 127.0.0.1: ``script(self)`` runs once the first request is in (kept in ``requests``)."""

    def __init__(self, script):
        super().__init__(daemon=True)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.port = self.sock.getsockname()[1]
        self.script = script
        self.requests: list[tuple[bytes, tuple]] = []
        self.sent = 0
        self.error: BaseException | None = None
        self.done = threading.Event()

    def poll_requests(self) -> None:
        try:
            while True:
                self.requests.append(self.sock.recvfrom(4096))
        except (TimeoutError, BlockingIOError):
            pass

    def wait_requests(self, n: int) -> None:
        end = time.monotonic() + DEADLINE_S
        while len(self.requests) < n:
            if time.monotonic() > end:
                raise AssertionError(f"the fake phone got {len(self.requests)} requests, expected {n}")
            self.poll_requests()

    def send(self, data: bytes, port: int) -> None:
        self.sock.sendto(data, ("127.0.0.1", port))
        self.sent += 1

    def run(self) -> None:
        try:
            self.wait_requests(1)
            self.script(self)
            end = time.monotonic() + 1.0
            while time.monotonic() < end:  # keep counting requests while the run goes on
                self.poll_requests()
        except BaseException as exc:  # reported by the test
            self.error = exc
        finally:
            self.done.set()


def _stats(out: str) -> dict:
    return json.loads(next(line for line in out.splitlines() if line.startswith("stats json: "))[12:])


def _replay_weights(record, character, config, tmp_path) -> np.ndarray:
    w = tmp_path / "replayed.npy"
    assert main(["replay", str(record), "-c", str(character), "--headless", "--size", "64x48",
                 "--config", str(config), "--dump-weights", str(w)]) == 0
    return np.load(w)


@pytest.mark.gl
@pytest.mark.parametrize("receiver", ["process", pytest.param("thread", marks=pytest.mark.slow)])
def test_run_ifacialmocap_triggers_the_phone_and_draws_its_frames(character, tmp_path, capsys, receiver):
    listen = free_udp_port()
    n_frames = 120

    def script(phone):
        for _ in range(n_frames):  # v2 frames, one stray key each, then the same pose held
            phone.send(ifm_frame({"jawOpen": 70, "cheekPuff": 20, "eyeBlinkLeft": 5},
                                 head=(2.0, -3.0, 1.0, 0.0, 0.0, 0.0), extra="hapihapi-0|"), listen)
            time.sleep(0.01)

    phone = FakePhone(script)
    phone.start()
    config, weights, record = tmp_path / "live.toml", tmp_path / "w.npy", tmp_path / "ifm.fps"
    config.write_text(CONFIG.replace("timeout_s = 0.2", "timeout_s = 30.0"))
    try:
        code = main(["run", "-c", str(character), "--input", "ifacialmocap", "--listen", f"127.0.0.1:{listen}",
                     "--phone", f"127.0.0.1:{phone.port}", "--headless", "--duration", "4.0", "--size", "64x48",
                     "--config", str(config), "--stats", "--dump-weights", str(weights), "--record", str(record),
                     "--receiver", receiver])
    finally:
        phone.done.wait(DEADLINE_S)
    out = said(capsys)
    assert phone.error is None, phone.error
    assert code == 0, out
    payload, sender = phone.requests[0]
    assert payload == IFM_START + b"|sendDataVersion=v2" and sender[0] == "127.0.0.1"
    assert "asking the phone at 127.0.0.1" in out
    stats = _stats(out)
    udp = stats["counters"]["udp"]
    assert udp["packets"] == udp["datagrams"] == udp["frames"] == udp["unknown_key"] == n_frames
    assert udp["malformed"] == udp["nonfinite"] == udp["internal_error"] == 0
    assert stats["counters"]["phone"]["sent"] >= 1 and stats["counters"]["phone"]["send_errors"] == 0
    w = np.load(weights)
    assert w.shape[1] == 2
    np.testing.assert_allclose(w[-1], (0.7, 0.0), atol=1e-3)  # jawOpen as sent; "puff" is no ARKit name
    frames = open_recording(record)
    assert len(frames) == n_frames == len(read_session(record).packets)
    assert {round(float(f.weights[f.channels.index("jawOpen")]), 4) for f in frames} == {0.7}
    replayed = _replay_weights(record, character, config, tmp_path)  # tick for tick, as live
    assert replayed.shape == w.shape
    np.testing.assert_allclose(replayed, w, atol=1e-5)


@pytest.mark.gl
@pytest.mark.parametrize("receiver", ["process", pytest.param("thread", marks=pytest.mark.slow)])
def test_run_vtubestudio_requests_repeatedly_and_face_lost_is_tracking_loss(character, tmp_path, capsys, receiver):
    n_found, n_lost = 60, 30
    seen = {}

    def script(phone):
        request = json.loads(phone.requests[0][0])
        seen["request"] = request
        for _ in range(n_found):
            for port in request["ports"]:
                phone.send(vts_frame({"jawOpen": 0.6, "cheekPuff": 0.3}, rotation=(5.0, 10.0, 0.0)), port)
            time.sleep(0.01)
        phone.wait_requests(2)  # the request comes again before its time runs out
        for _ in range(n_lost):
            for port in request["ports"]:
                phone.send(vts_frame({}, found=False), port)
            time.sleep(0.01)

    phone = FakePhone(script)
    phone.start()
    listen = free_udp_port()
    config, weights, record = tmp_path / "live.toml", tmp_path / "w.npy", tmp_path / "vts.fps"
    config.write_text(CONFIG)
    try:
        code = main(["run", "-c", str(character), "--input", "vtubestudio", "--listen", f"127.0.0.1:{listen}",
                     "--phone", f"127.0.0.1:{phone.port}", "--headless", "--duration", "5.0", "--size", "64x48",
                     "--config", str(config), "--stats", "--dump-weights", str(weights), "--record", str(record),
                     "--receiver", receiver])
    finally:
        phone.done.wait(DEADLINE_S)
    out = said(capsys)
    assert phone.error is None, phone.error
    assert code == 0, out
    request = seen["request"]
    assert request["messageType"] == "iOSTrackingDataRequest" and request["ports"] == [listen]
    assert request["sentBy"] == "facepuppet" and 0.5 <= request["time"] <= 10
    assert len(phone.requests) >= 2 and all(p == phone.requests[0][0] for p, _ in phone.requests)
    stats = _stats(out)
    udp = stats["counters"]["udp"]
    assert udp["frames"] == n_found and udp["face_lost"] == n_lost and udp["packets"] == n_found + n_lost
    assert udp["malformed"] == udp["internal_error"] == 0
    assert stats["counters"]["phone"]["sent"] >= len(phone.requests) >= 2  # every one the phone saw was counted
    assert stats["counters"]["pipeline"]["tracking_lost"] >= 1  # FaceFound false: tracking lost, eased out
    w = np.load(weights)
    assert np.any(np.abs(w[:, 0] - 0.6) < 1e-3)  # the face was drawn as sent ...
    np.testing.assert_allclose(w[-1], (0.0, 0.0), atol=1e-3)  # ... then eased to neutral, not frozen
    frames = open_recording(record)  # the lost datagrams are recorded but give no frames
    assert len(frames) == n_found and len(read_session(record).packets) == n_found + n_lost
    replayed = _replay_weights(record, character, config, tmp_path)  # tick for tick, as live
    assert replayed.shape == w.shape
    np.testing.assert_allclose(replayed, w, atol=1e-5)


@pytest.mark.parametrize("argv, match", [
    (["--input", "vmc", "--phone", "127.0.0.1"], "--phone: only for --input ifacialmocap or vtubestudio"),
    (["--input", "ifacialmocap", "--phone", "192.168.1.20"], "cannot reach 127.0.0.1"),  # nothing is sent there
    (["--input", "vtubestudio", "--phone", "localhost"], "is not an IP address"),
    (["--input", "vtubestudio", "--phone", "255.255.255.255"], "broadcast"),
])
def test_bad_phone_options_exit_2_with_a_message(character, capsys, argv, match):
    code = main(["run", "-c", str(character), "--headless", "--duration", "0.1", *argv])
    assert code == 2
    assert match in capsys.readouterr().err
