"""``run --web``'s control API end to end over 127.0.0.1: a real run on a VRM avatar fed by a real VMC sender,
driven by a real WebSocket client and real OSC datagrams, recorded, and replayed to the same weights; then the
server's guards (Origin, Host, token, malformed JSON, oversize messages, rates, a client that stops reading)."""

from __future__ import annotations

import json
import socket
import time

import numpy as np
import pytest
from pythonosc.osc_message_builder import OscMessageBuilder
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

from facepuppet.runtime.cli import main
from facepuppet.runtime.recording.session import read_session

from helpers.web_run import web_run

pytestmark = [pytest.mark.gl, pytest.mark.slow]


def _ask(ws, doc: dict) -> dict:
    """Send ``doc`` and return the first JSON reply that is not a pushed weights message (or a view frame)."""
    ws.send(json.dumps(doc))
    while True:
        message = ws.recv(timeout=20)
        if isinstance(message, bytes):
            continue
        reply = json.loads(message)
        if reply.get("type") != "weights":
            return reply


def _osc(port: int, address: str, *args) -> None:
    m = OscMessageBuilder(address)
    for a in args:
        m.add_arg(a)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.sendto(m.build().dgram, ("127.0.0.1", port))


def test_websocket_and_osc_verbs_drive_the_show_are_recorded_and_replay_to_the_same_weights(tmp_path):
    record = tmp_path / "show.fps"
    with web_run(tmp_path, {"aa": 0.2}, extra=("--record", str(record))) as run:
        smile = run.character.shape_names.index("smile")
        brows = run.character.shape_names.index("angled_eyebrows")
        with connect(f"ws://127.0.0.1:{run.port}/ws") as ws:
            listed = _ask(ws, {"verb": "list", "id": "l1"})
            assert listed["type"] == "list" and listed["id"] == "l1" and "Joy" in listed["expressions"]
            assert run.weight("smile") == 0.0
            reply = _ask(ws, {"verb": "expression", "name": "Joy", "action": "on", "fade": 0, "id": 7})
            assert reply == {"type": "ok", "verb": "expression", "id": 7, "applies": "next tick"}
            run.wait_for(lambda: run.weight("smile") == pytest.approx(1.0), what="Joy on from the WebSocket")
            # OSC: Joy off over 0.2 s, then Angry for 0.3 s at once
            _osc(run.port, "/facepuppet/expression/off", "Joy", 0.2)
            run.wait_for(lambda: run.weight("smile") == 0.0, what="Joy off from OSC")
            _osc(run.port, "/facepuppet/expression/for", "Angry", 0.3, 0.0)  # binds angled_eyebrows at 0.5
            run.wait_for(lambda: run.weight("angled_eyebrows") == pytest.approx(0.5), what="Angry from OSC")
            run.wait_for(lambda: run.weight("angled_eyebrows") == 0.0, what="Angry's end after 0.3 s")
            status = _ask(ws, {"verb": "status"})
            assert status["recording"] and status["tracking"] == "live"
            assert status["control"]["counters"]["commands_applied"] == 3
        live = np.array(run.weights)
    fading = live[:, smile]
    assert np.any((fading > 0.05) & (fading < 0.95)), "the 0.2 s fade shows values between off and on"
    assert run.result.counters["osc_control"]["commands"] == 2

    session = read_session(record)
    assert [doc["verb"] for _, doc in session.controls] == ["expression"] * 3
    assert [doc["action"] for _, doc in session.controls] == ["on", "off", "for"]
    out = tmp_path / "replay.npy"
    assert main(["replay", str(record), "-c", str(tmp_path / "avatar.npz"), "--headless", "--size", "64x48",
                 "--background", "transparent", "--dump-weights", str(out)]) == 0
    back = np.load(out)
    recorded = run.result.weights.array[-len(back):]
    np.testing.assert_allclose(back, recorded, atol=1e-6)
    assert back[:, smile].max() == pytest.approx(1.0) and back[:, brows].max() == pytest.approx(0.5)


def test_other_origins_hosts_and_missing_tokens_are_refused_before_the_handshake(tmp_path):
    token = "s3cret-token-of-this-show"
    with web_run(tmp_path, extra=("--web-token", token)) as run:
        base = f"ws://127.0.0.1:{run.port}/ws"
        with pytest.raises(InvalidStatus, match="401"):
            connect(base)
        with pytest.raises(InvalidStatus, match="403"):  # a page elsewhere cannot drive the show
            connect(f"{base}?token={token}", origin="http://evil.example")
        # nor a DNS-rebound name for 127.0.0.1 (the page or the upgrade)
        assert _http_status(run.port, f"/?token={token}", f"evil.example:{run.port}") == 403
        assert _http_status(run.port, f"/?token={token}", f"127.0.0.1:{run.port}") == 200
        with connect(f"{base}?token={token}", origin=f"http://127.0.0.1:{run.port}") as ws:
            assert _ask(ws, {"verb": "status"})["type"] == "status"
        # OSC: without the token a message is counted and refused; with it, applied
        _osc(run.port, "/facepuppet/expression/on", "Joy")
        _osc(run.port, "/facepuppet/expression/on", token, "Joy", 0.0)
        run.wait_for(lambda: run.weight("smile") == pytest.approx(1.0), what="Joy from OSC with the token")
    web = run.result.counters["web"]
    assert web["refused_token"] == 1 and web["refused_origin"] == 1 and web["refused_host"] == 1
    assert run.result.counters["osc_control"]["refused_token"] == 1


def _http_status(port: int, path: str, host: str) -> int:
    """The status of a plain GET with this Host header, sent by hand."""
    with socket.create_connection(("127.0.0.1", port), timeout=20) as s:
        s.sendall(f"GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n".encode())
        head = s.recv(64)
    return int(head.split()[1])


def test_malformed_bad_oversize_and_flooding_messages_are_answered_counted_and_never_crash(tmp_path):
    with web_run(tmp_path) as run:
        with connect(f"ws://127.0.0.1:{run.port}/ws") as ws:
            reply = _ask(ws, {"verb": "expression"})  # no name
            assert reply["type"] == "error" and "field 'name'" in reply["error"]
            ws.send("{not json")
            reply = json.loads(ws.recv(timeout=20))
            assert reply["type"] == "error" and reply["error"].startswith("malformed JSON")
            ws.send(b"\xff\xfe")
            assert json.loads(ws.recv(timeout=20))["type"] == "error"
            reply = _ask(ws, {"verb": "profile", "name": "../../etc/passwd"})
            assert reply["type"] == "error" and "never a path" in reply["error"]
            reply = _ask(ws, {"verb": "expression", "name": "NoSuch", "action": "on"})
            assert reply["type"] == "ok"  # checked at the door; the name is checked at the tick, and counted
            for _ in range(120):  # over the burst: some are refused, none crash
                ws.send(json.dumps({"verb": "status"}))
            replies = [json.loads(ws.recv(timeout=20)) for _ in range(120)]
            assert any(r.get("error", "").startswith("rate limit") for r in replies)
        with connect(f"ws://127.0.0.1:{run.port}/ws") as ws:
            ws.send("x" * (100 << 10))
            with pytest.raises(ConnectionClosed) as closed:
                ws.recv(timeout=20)
            assert closed.value.rcvd is not None and closed.value.rcvd.code == 1009
        with connect(f"ws://127.0.0.1:{run.port}/ws") as ws:  # the server still serves
            assert _ask(ws, {"verb": "status"})["control"]["counters"]["commands_failed"] == 1
    web = run.result.counters["web"]
    assert web["malformed"] == 2 and web["bad_commands"] == 2 and web["rate_limited"] > 0
    assert web["closed_oversize"] == 1


def _stalled_client(port: int, doc: dict) -> socket.socket:
    """A WebSocket client that asks for ``doc`` and then never reads (a tiny receive buffer, opened by hand)."""
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    s.connect(("127.0.0.1", port))
    s.sendall(f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
              "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n".encode())
    head = b""
    while b"\r\n\r\n" not in head:
        head += s.recv(1)
    assert head.startswith(b"HTTP/1.1 101"), head
    payload = json.dumps(doc).encode()
    mask = b"\x01\x02\x03\x04"
    s.sendall(bytes([0x81, 0x80 | len(payload)]) + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload)))
    return s


def test_a_client_that_stops_reading_is_dropped_and_the_others_and_the_frame_loop_go_on(tmp_path):
    with web_run(tmp_path, size="640x480") as run:
        stalled = _stalled_client(run.port, {"verb": "view", "fps": 60})
        try:
            with connect(f"ws://127.0.0.1:{run.port}/ws") as ws:
                assert _ask(ws, {"verb": "subscribe", "rate": 20})["type"] == "ok"
                run.wait_for(lambda: _dropped(ws) >= 1, timeout_s=60,
                             what="the stalled client dropped")
                ticks = len(run.ticks)
                reply = _ask(ws, {"verb": "expression", "name": "Joy", "action": "on", "fade": 0})
                assert reply["type"] == "ok"
                run.wait_for(lambda: run.weight("smile") == pytest.approx(1.0), what="Joy after the drop")
                assert len(run.ticks) > ticks
        finally:
            stalled.close()
    assert run.result.counters["web"]["dropped_slow"] == 1


def _dropped(ws) -> int:
    status = _ask(ws, {"verb": "status"})
    time.sleep(0.2)
    return status["web"]["dropped_slow"]


def _coverage(ws) -> int:
    """Pixels with alpha > 0 in the next view frame that arrives."""
    from facepuppet.runtime.control.view_frames import decode

    while True:
        message = ws.recv(timeout=20)
        if isinstance(message, bytes):
            return int((decode(message)[5][..., 3] > 0).sum())


def test_framing_profile_record_and_calibrate_verbs_act_on_the_show(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    monkeypatch.chdir(tmp_path)  # a recording named by a client goes into the run's folder
    profiles = tmp_path / "xdg" / "facepuppet" / "profiles"
    profiles.mkdir(parents=True)
    with web_run(tmp_path, {"JawOpen": 0.2}, size="96x72") as run:  # jawOpen -> A (the default preset mapping)
        (profiles / "loud.toml").write_text((tmp_path / "live.toml").read_text()
                                            + "\n[channels.jawOpen]\ngain = 3.0\n")
        with connect(f"ws://127.0.0.1:{run.port}/ws", max_size=1 << 24) as ws:
            assert "loud" in _ask(ws, {"verb": "list"})["profiles"]
            assert _ask(ws, {"verb": "view", "fps": 30})["fps"] == 30
            before = _coverage(ws)
            assert _ask(ws, {"verb": "framing", "framing": "head", "zoom": 2.0})["type"] == "ok"
            run.wait_for(lambda: _coverage(ws) > 2 * before, what="the picture zoomed in")
            assert _ask(ws, {"verb": "view", "fps": 0})["fps"] == 0
            assert run.weight("ah") == pytest.approx(0.2)
            assert _ask(ws, {"verb": "profile", "name": "loud"})["type"] == "ok"
            run.wait_for(lambda: run.weight("ah") == pytest.approx(0.6), what="the profile's gain in force")
            assert _ask(ws, {"verb": "record", "action": "start", "name": "mid"})["type"] == "ok"
            run.wait_for(lambda: (tmp_path / "mid.fps").exists(), what="the recording started")
            assert _ask(ws, {"verb": "calibrate"})["type"] == "ok"
            run.wait_for(lambda: run.weight("ah") == 0.0, what="the calibrated neutral taken off")
            assert _ask(ws, {"verb": "record", "action": "stop"})["type"] == "ok"
            run.wait_for(lambda: not _ask(ws, {"verb": "status"})["recording"], what="the recording stopped")
            # the stop's effect can show before the frame loop has counted it applied: wait for the count
            run.wait_for(lambda: _ask(ws, {"verb": "status"})["control"]["counters"]["commands_applied"] >= 5,
                         what="the five commands counted")
            status = _ask(ws, {"verb": "status"})
            assert status["profile"] == "loud"
            assert status["control"]["counters"] == {"commands_applied": 5, "commands_failed": 0,
                                                     "commands_dropped": 0}
    session = read_session(tmp_path / "mid.fps")
    # the start is the first record of the file it started; calibrate is replayed through its CONFIG record
    assert session.complete and [doc["verb"] for _, doc in session.controls] == ["record", "calibrate"]
    assert len(session.configs) >= 2  # the config in force at the start, then the calibrated neutral


def test_the_view_frames_are_read_before_the_panel_is_drawn_over_the_picture(tmp_path):
    pytest.importorskip("imgui_bundle", reason="the panel's extra (imgui-bundle) is not installed")
    from facepuppet.runtime.control.view_frames import decode

    with web_run(tmp_path, size="480x360", extra=("--panel",)) as run:
        run.wait_for(lambda: len(run.ticks) > 5, what="ticks with the panel")
        with connect(f"ws://127.0.0.1:{run.port}/ws", max_size=1 << 24) as ws:
            assert _ask(ws, {"verb": "view", "fps": 30})["type"] == "ok"
            while isinstance(message := ws.recv(timeout=20), str):
                pass
            alpha = decode(message)[5][..., 3]
    # the panel is drawn over the picture's left side, opaque; the view page gets the character alone
    assert alpha[:, :40].max() == 0 and alpha.max() == 255
