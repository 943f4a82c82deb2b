"""Packet recording: round trip, never blocking, crash safety (kill -9), and replay = the live frame stream."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
import warnings

import numpy as np
import pytest
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder

from facepuppet.runtime.inputs.kinds import make_adapter
from facepuppet.runtime.inputs.udp import UdpSource
from facepuppet.runtime.recording.recorder import PacketRecorder
from facepuppet.runtime.recording.replay_source import open_recording
from facepuppet.runtime.recording.session import read_session

from helpers.small_characters import sphere_character


def vmc_bundle(jaw: float, blink: float, yaw: float = 0.0) -> bytes:
    b = OscBundleBuilder(IMMEDIATELY)
    for name, value in (("JawOpen", jaw), ("EyeBlinkLeft", blink)):
        m = OscMessageBuilder("/VMC/Ext/Blend/Val")
        m.add_arg(name, "s")
        m.add_arg(value, "f")
        b.add_content(m.build())
    m = OscMessageBuilder("/VMC/Ext/Bone/Pos")
    m.add_arg("Head", "s")
    for v in (0.0, 0.1, 0.0, 0.0, np.sin(yaw / 2), 0.0, np.cos(yaw / 2)):
        m.add_arg(float(v), "f")
    b.add_content(m.build())
    b.add_content(OscMessageBuilder("/VMC/Ext/Blend/Apply").build())
    return b.build().dgram


def test_packets_and_audio_levels_round_trip(tmp_path):
    path = tmp_path / "rec.fps"
    packets = [(vmc_bundle(0.1 * k, 0.5), 100.0 + k / 60) for k in range(20)]
    with PacketRecorder(path, "vmc", info={"test": True}) as rec:
        for data, t in packets:
            rec.put(data, t, ("127.0.0.1", 5000))
        rec.put_audio(0.5, -20.0)
        rec.put_event(0.75, False)  # tracking lost, then found (the filter stage's listeners)
        rec.put_event(1.25, True)
    s = read_session(path)
    assert s.complete and s.header["info"]["input"] == "vmc" and s.header["info"]["test"] is True
    assert [(p.data, p.t, p.kind) for p in s.packets] == [(d, t, "vmc") for d, t in packets]
    assert s.audio_levels == [(0.5, -20.0)]
    assert s.events == [(0.75, False), (1.25, True)]
    assert rec.counters == {"packets_recorded": 20, "audio_recorded": 1, "ticks_recorded": 0,
                            "configs_recorded": 0, "events_recorded": 2, "record_dropped": 0}


def test_config_event_and_sources_records_have_kinds_of_their_own_and_each_round_trips(tmp_path):
    from facepuppet.runtime.recording.records import RESERVED_KINDS, RecordKind

    kinds = [RecordKind.PACKET, RecordKind.AUDIO, RecordKind.TICK, RecordKind.CONFIG, RecordKind.EVENT,
             RecordKind.SOURCES, RecordKind.STATE, RecordKind.VOICE, RecordKind.CONTROL]
    assert len(set(kinds)) == len(kinds) and set(kinds) == RESERVED_KINDS
    assert (RecordKind.CONFIG, RecordKind.EVENT, RecordKind.SOURCES, RecordKind.STATE, RecordKind.VOICE,
            RecordKind.CONTROL) == (6, 7, 8, 9, 10, 11)
    path = tmp_path / "all.fps"
    with PacketRecorder(path, "vmc") as rec:  # one live run's worth of each: a tuned, lost, mixed show
        rec.put_tick(0, 0.0, 1, 10.0)
        rec.put_sources(0, (1, 0))
        rec.put_config(0.5, '[face]\nmirror = true\n')
        rec.put_event(0.75, False)
        rec.put_event(1.25, True)
        rec.put_config(1.5, '[face]\nmirror = false\n')
        rec.put_state(1.75, '{"version": 1}')
        rec.put_control(2.0, {"verb": "expression", "name": "Joy", "action": "on", "value": 1.0, "fade": 0.15})
    s = read_session(path)
    assert s.states == [(1.75, '{"version": 1}')]
    assert s.controls == [(2.0, {"verb": "expression", "name": "Joy", "action": "on", "value": 1.0, "fade": 0.15})]
    assert s.configs == [(0.5, "[face]\nmirror = true\n"), (1.5, "[face]\nmirror = false\n")]
    assert s.events == [(0.75, False), (1.25, True)]
    assert s.sources == [(0, (1, 0))] and len(s.ticks) == 1 and not s.skipped
    assert rec.counters["configs_recorded"] == 2 and rec.counters["events_recorded"] == 2


def test_a_full_queue_drops_and_counts_instead_of_blocking(tmp_path):
    rec = PacketRecorder(tmp_path / "rec.fps", "vmc", capacity=4)
    gate = threading.Event()
    write = rec.writer.write_record
    rec.writer.write_record = lambda kind, payload: (gate.wait(), write(kind, payload))  # a stalled disk
    started = time.monotonic()
    for k in range(50):
        rec.put(b"x" * 10, float(k))
    assert time.monotonic() - started < 5.0  # (a hang guard, not a timing claim)
    dropped = rec.counters["record_dropped"]
    assert 50 - 4 - 1 <= dropped <= 50 - 4
    gate.set()
    rec.close()
    assert rec.counters["packets_recorded"] + dropped == 50
    assert len(read_session(rec.path).packets) == 50 - dropped


def test_replaying_a_recording_reproduces_the_live_frame_stream(tmp_path):
    """Frames the live UDP thread decoded == frames re-decoded from the recording, one for one."""
    live_frames = []

    class Capturing:
        def __init__(self, adapter):
            self.adapter, self.kind, self.default_port = adapter, adapter.kind, adapter.default_port
            self.counters = adapter.counters

        def handle(self, data, t):
            frame = self.adapter.handle(data, t)
            if frame is not None:
                live_frames.append(frame)
            return frame

    path = tmp_path / "live.fps"
    rng = np.random.default_rng(7)
    sent = [vmc_bundle(float(j), float(b), float(y)) for j, b, y in rng.random((150, 3))]
    with PacketRecorder(path, "vmc") as rec:
        source = UdpSource(Capturing(make_adapter("vmc")), host="127.0.0.1", port=0, on_packet=rec.put).start()
        try:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:
                for data in sent:
                    out.sendto(data, source.address)
                    out.sendto(b"\x00garbage", source.address)  # recorded too, decodes to nothing
                    time.sleep(0.001)
            deadline = time.monotonic() + 5
            while source.counters["packets"] < 2 * len(sent) and time.monotonic() < deadline:
                time.sleep(0.01)
        finally:
            source.stop()
    assert len(live_frames) == len(sent)  # loopback, paced: nothing lost
    replayed = open_recording(path)
    assert len(replayed) == len(live_frames)
    for a, b in zip(live_frames, replayed):
        assert a.t == b.t and a.channels == b.channels and a.source == b.source
        np.testing.assert_array_equal(a.weights, b.weights)
        np.testing.assert_array_equal(a.head_rotation, b.head_rotation)
        np.testing.assert_array_equal(a.head_translation, b.head_translation)
    assert read_session(path).skipped == {}


@pytest.mark.gl  # the `facepuppet run --headless` it starts opens an EGL context
def test_kill_9_mid_record_leaves_a_file_that_replays_up_to_the_last_complete_record(tmp_path):
    character = tmp_path / "sphere.npz"
    sphere_character().save(character)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    path = tmp_path / "crash.fps"
    proc = subprocess.Popen(
        [sys.executable, "-u", "-m", "facepuppet.runtime.cli", "run", "-c", str(character), "--input", "vmc",
         "--listen", f"127.0.0.1:{port}", "--headless", "--size", "64x48", "--record", str(path),
         "--duration", "60"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        lines = [proc.stdout.readline()]
        while lines[-1] and "listening for" not in lines[-1]:  # the stage chain and the like come first
            lines.append(proc.stdout.readline())
        assert "listening for vmc on 127.0.0.1" in lines[-1], lines
        sent = 0
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:
            deadline = time.monotonic() + 20
            while time.monotonic() < deadline:
                out.sendto(vmc_bundle(sent % 100 / 100, 0.5), ("127.0.0.1", port))
                sent += 1
                time.sleep(0.002)
                if sent >= 200 and path.stat().st_size > 50_000:
                    break
            os.kill(proc.pid, signal.SIGKILL)  # mid-stream: the sender is still going
            for _ in range(20):
                out.sendto(vmc_bundle(0.0, 0.0), ("127.0.0.1", port))
    finally:
        proc.kill()
        proc.wait(timeout=10)
    assert proc.returncode == -signal.SIGKILL
    session = read_session(path)  # every complete record; a torn last one would be reported
    assert 100 <= len(session.packets) <= sent
    frames = open_recording(path)
    assert len(frames) == len(session.packets)
    jaw = frames[0].channels.index("jawOpen")
    np.testing.assert_allclose([f.weights[jaw] for f in frames[:100]], np.arange(100) / 100, atol=1e-6)

    # a tear inside the last record (a write cut short): everything before it still replays
    data = path.read_bytes()
    torn = tmp_path / "torn.fps"
    torn.write_bytes(data[:-7])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        partial = read_session(torn)
    assert not partial.complete and "torn record" in partial.tail_error and caught
    assert partial.n_records == session.n_records - 1  # the last record may be a packet or a tick
    assert len(partial.packets) + len(partial.ticks) == len(session.packets) + len(session.ticks) - 1
    with pytest.warns(UserWarning, match="torn record"):
        assert len(open_recording(torn)) == len(partial.packets)


def test_a_replay_finds_the_calibrate_requests_the_live_receivers_counted_not_the_bytes(tmp_path):
    """The recording's calibrate requests are the decoded OSC messages to the address, as the receivers count
    them: a Live Link Face device whose name carries the address's bytes is a frame, not a request (a byte
    search took it for one, so a replay calibrated where the run did not)."""
    from facepuppet.runtime.inputs.livelinkface import encode_llf_packet
    from facepuppet.runtime.mapping.channels import ARKIT_NAMES
    from facepuppet.runtime.recording.ticked_source import read_live_recording

    path = tmp_path / "take.fps"
    rec = PacketRecorder(path, "livelinkface")
    tricky = encode_llf_packet([0.2] * len(ARKIT_NAMES), name="phone /facepuppet/calibrate\x00\x00\x00,\x00\x00\x00")
    assert b"/facepuppet/calibrate\x00" in tricky
    request = OscMessageBuilder("/facepuppet/calibrate").build().dgram
    for i, data in enumerate((tricky, request, tricky)):
        rec.put(data, 0.01 * i)
    rec.close()
    live = read_live_recording(path, lambda kind: make_adapter(kind))
    assert live.calibrate_packets == [1]
    assert len(live.frames) == 2


def test_voice_records_round_trip_and_a_torn_one_is_skipped(tmp_path):
    from facepuppet.runtime.recording.records import decode_voice, encode_voice

    path = tmp_path / "voice.fps"
    with PacketRecorder(path, "audio") as rec:
        rec.put_voice(0.25, np.array([0.5, 0.125], np.float32))
        rec.put_voice(0.5, np.array([0.0, 1.0], np.float32))
    s = read_session(path)
    assert [(t, v.tolist()) for t, v in s.voice] == [(0.25, [0.5, 0.125]), (0.5, [0.0, 1.0])]
    payload = encode_voice(1.0, np.array([0.5, 0.25], np.float32))
    assert decode_voice(payload[:-1]) is None and decode_voice(b"X1" + payload[2:]) is None
