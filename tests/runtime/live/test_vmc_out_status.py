"""--vmc-out's /VMC/Ext/OK and /VMC/Ext/T (issue 16 item 6): the status follows the run's tracking state.

The status bundle is read back from a UDP socket on 127.0.0.1 and its bytes are decoded here by hand from
the OSC 1.0 rules (no OSC library)."""

from __future__ import annotations

import socket
import struct
import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.live.config import LiveConfig
from facepuppet.runtime.live.pipeline import LivePipeline
from facepuppet.runtime.live.vmc_out import VmcSender, pipeline_status

from helpers.small_characters import sphere_character
from helpers.udp_helpers import free_udp_port


def _string(data: bytes, at: int) -> tuple[str, int]:
    end = data.index(b"\0", at)
    return data[at:end].decode(), at + ((end - at) // 4 + 1) * 4


def messages_of(bundle: bytes) -> list[tuple[str, list]]:
    """The messages of one flat OSC bundle: ints and floats decoded by their type tags."""
    assert bundle.startswith(b"#bundle\0")
    out, at = [], 16
    while at < len(bundle):
        (size,) = struct.unpack_from(">i", bundle, at)
        m = bundle[at + 4:at + 4 + size]
        address, pos = _string(m, 0)
        tags, pos = _string(m, pos)
        args = []
        for tag in tags[1:]:
            if tag == "i":
                args.append(struct.unpack_from(">i", m, pos)[0])
                pos += 4
            elif tag == "f":
                args.append(struct.unpack_from(">f", m, pos)[0])
                pos += 4
            elif tag == "s":
                value, pos = _string(m, pos)
                args.append(value)
        out.append((address, args))
        at += 4 + size
    return out


def status_messages(receiver: socket.socket, tracking: list | None = None) -> list[dict]:
    """Every status bundle waiting on ``receiver``: {address: args} of its messages; the arguments of
    ``/facepuppet/tracking`` bundles (the run's tracking events) go to ``tracking``."""
    got = []
    while True:
        try:
            data = receiver.recv(65536)
        except BlockingIOError:
            return got
        msgs = messages_of(data)
        if msgs and msgs[0][0] == "/VMC/Ext/OK":
            got.append(dict(msgs))
        elif msgs and msgs[0][0] == "/facepuppet/tracking" and tracking is not None:
            tracking.append(msgs[0][1])


@pytest.fixture()
def receiver():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.setblocking(False)
    yield s
    s.close()


def test_ok_carries_the_status_callable_and_t_the_sender_time(receiver):
    state = {"value": (2, False)}
    sender = VmcSender("127.0.0.1", receiver.getsockname()[1], ("jawOpen",), status=lambda: state["value"],
                       clock=iter([10.0, 10.25, 11.5]).__next__)
    try:
        info = SimpleNamespace(weights=np.array([0.5], np.float32), rotation=None, translation=None, frame=None,
                               expressions=None)
        sender.on_tick(info)
        state["value"] = (3, True)
        sender.on_tick(info)
        time.sleep(0.05)
        got = status_messages(receiver)
    finally:
        sender.close()
    assert [g["/VMC/Ext/OK"] for g in got] == [[1, 2, 0, 0], [1, 3, 0, 1]]
    assert [g["/VMC/Ext/T"] for g in got] == [pytest.approx([0.25]), pytest.approx([1.5])]


def test_without_a_status_callable_tracking_is_a_frame_on_screen(receiver):
    sender = VmcSender("127.0.0.1", receiver.getsockname()[1], ("jawOpen",))
    try:
        w = np.array([0.5], np.float32)
        sender.on_tick(SimpleNamespace(weights=w, rotation=None, translation=None, frame=None, expressions=None))
        sender.on_tick(SimpleNamespace(weights=w, rotation=None, translation=None, frame=object(), expressions=None))
        time.sleep(0.05)
        got = status_messages(receiver)
    finally:
        sender.close()
    assert [g["/VMC/Ext/OK"] for g in got] == [[1, 3, 0, 0], [1, 3, 0, 1]]


def test_pipeline_status_follows_waiting_live_lost_and_calibrating():
    stage = LivePipeline(LiveConfig(timeout_s=0.5), log=lambda s: None)
    status = pipeline_status(stage)
    assert status() == (3, False)                     # waiting: no frame yet
    frame = Frame(t=0.0, source="vmc", channels=("jawOpen",), weights=np.array([0.4], np.float32))
    stage(frame, 0.0)
    assert status() == (3, True)                      # live
    stage(None, 1.0)                                  # quiet past the timeout
    assert stage.state == "lost" and status() == (3, False)
    stage(Frame(t=1.1, source="vmc", channels=("jawOpen",), weights=np.array([0.4], np.float32)), 1.1)
    assert status() == (3, True)                      # returning: frames arrive again
    stage.request_calibration()
    assert status() == (2, True)                      # capturing the neutral


@pytest.mark.gl
def test_run_vmc_out_reports_tracking_lost_after_the_input_goes_quiet(tmp_path, capsys):
    """A real run: VMC frames for a while, then none. The OK messages go 0 (waiting) -> 1 -> 0 (lost), while
    the face eases to neutral (ticks still drawn); the old status (a frame on screen) stayed 1."""
    from facepuppet.runtime.cli import main

    from helpers.osc_helpers import vmc_frame

    character = tmp_path / "sphere.npz"
    sphere_character().save(character)
    config = tmp_path / "live.toml"
    config.write_text("[tracking_loss]\ntimeout_s = 0.2\n")
    port = free_udp_port()
    done = threading.Event()
    got: list[dict] = []
    events: list[list] = []

    def send_while_listening(rx: socket.socket):
        """Collect the status bundles; send frames for 0.6 s once 5 status bundles (ticks) have come."""
        sending_until = None
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            while not done.is_set():
                got.extend(status_messages(rx, events))
                if sending_until is None and len(got) >= 5:
                    sending_until = time.monotonic() + 0.6
                if sending_until is not None and time.monotonic() < sending_until:
                    s.sendto(vmc_frame(0.5), ("127.0.0.1", port))
                time.sleep(0.02)
            got.extend(status_messages(rx, events))

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as rx:
        rx.bind(("127.0.0.1", 0))
        rx.setblocking(False)
        thread = threading.Thread(target=send_while_listening, args=(rx,), daemon=True)
        thread.start()
        try:
            code = main(["run", "-c", str(character), "--input", "vmc", "--listen", f"127.0.0.1:{port}",
                         "--headless", "--duration", "2.5", "--size", "64x48", "--draw", "tick", "--fps", "20",
                         "--config", str(config), "--vmc-out", f"127.0.0.1:{rx.getsockname()[1]}"])
        finally:
            done.set()
            thread.join(timeout=10)
    assert code == 0, capsys.readouterr()
    tracking = [g["/VMC/Ext/OK"][3] for g in got]
    assert all(g["/VMC/Ext/OK"][:3] == [1, 3, 0] for g in got)
    runs = [tracking[0]] + [b for a, b in zip(tracking, tracking[1:]) if a != b]
    assert runs == [0, 1, 0], tracking
    assert events == [[0]]  # the tracking-lost event, in a bundle of its own on the VMC stream
    times = [g["/VMC/Ext/T"][0] for g in got]
    assert times == sorted(times) and len(got) >= 30
