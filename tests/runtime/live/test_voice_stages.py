"""``run --voice`` end to end: the voice alone, hybrid over a tracker, tracking loss's learned mouth, replays tick
for tick, a missing microphone said and the run going on, silence a closed mouth."""

from __future__ import annotations

import argparse
import dataclasses
import threading
import time

import numpy as np
import pytest
from pythonosc.udp_client import SimpleUDPClient

from facepuppet.runtime.commands import replay, run
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.recording.session import read_session

from helpers.logs import logged
from helpers.small_characters import grid_face
from helpers.udp_helpers import free_udp_port
from helpers.vmc_run import send_vmc
from helpers.voice_tables import small_table, vowel_buzz, write_wav

pytestmark = pytest.mark.gl


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser()
    sub = p.add_subparsers()
    run.register(sub)
    replay.register(sub)
    return p


def vmc(client, values: dict) -> None:
    send_vmc(client, values)


def live(argv, send, tmp_path):
    """``run ARGV --listen --headless``; ``send(client, stop)`` runs in a thread once the socket is bound."""
    port = free_udp_port()
    args = parser().parse_args(["run", *argv, "--listen", f"127.0.0.1:{port}", "--headless", "--size", "48x40"])
    stop, threads, logs = threading.Event(), [], []

    def on_ready(address):
        t = threading.Thread(target=send, args=(SimpleUDPClient("127.0.0.1", port), stop), daemon=True)
        t.start()
        threads.append(t)

    try:
        with logged(logs):
            result = run.run_live(args, on_ready=on_ready, keep_weights=True)
    finally:
        stop.set()
        for t in threads:
            t.join(timeout=10)
    return result, logs


def _files(tmp_path, samples, shapes=("jawOpen", "mouthFunnel", "browInnerUp", "eyeLookIn_L", "cornerBump")):
    table = small_table("ridge").save(tmp_path / "voice.npz")
    wav = tmp_path / "speech.wav"
    write_wav(wav, samples)
    char = dataclasses.replace(grid_face(extra=True), shape_names=shapes).save(tmp_path / "c.npz")
    return table, wav, char


def test_the_voice_alone_moves_the_mouth_and_its_replay_is_the_run_tick_for_tick(tmp_path):
    table, wav, char = _files(tmp_path, vowel_buzz(1.2))
    record, replay_w = tmp_path / "take.fps", tmp_path / "replay.npy"
    result, logs = live(["-c", str(char), "--input", "audio", "--voice", str(table), "--audio-file", str(wav),
                         "--record", str(record)], lambda client, stop: None, tmp_path)
    assert "stages: voice→audio→voice→filter→map→draw" in logs
    w = result.weights.array
    assert np.ptp(w[:, 0]) > 0.1  # the jaw follows the sound
    session = read_session(record)
    assert len(session.voice) == result.loop.n_ticks
    assert session.header["info"]["voice_channels"] == ["jawOpen", "mouthFunnel"]
    logs = []
    args = parser().parse_args(["replay", str(record), "-c", str(char), "--headless", "--size", "48x40",
                                "--voice", str(table), "--dump-weights", str(replay_w)])
    with logged(logs):
        assert replay.run_replay(args) == 0
    assert "stages: replay(audio)→audio→voice→filter→map→draw" in logs
    np.testing.assert_array_equal(np.load(replay_w), w)
    # without the run's --voice the replay says what to give, not the live run's --audio-file
    args = parser().parse_args(["replay", str(record), "-c", str(char), "--headless", "--size", "48x40"])
    with pytest.raises(UsageError, match=r"give its --voice .*no --audio or --audio-file"):
        replay.run_replay(args)


def test_a_silent_wav_keeps_the_mouth_closed(tmp_path):
    table, wav, char = _files(tmp_path, np.zeros(16000))
    result, _ = live(["-c", str(char), "--input", "audio", "--voice", str(table), "--audio-file", str(wav)],
                     lambda client, stop: None, tmp_path)
    assert result.loop.n_ticks > 10
    assert np.abs(result.weights.array).max() == 0.0


def test_hybrid_the_tracker_drives_the_rest_the_voice_the_mouth_and_the_replay_agrees(tmp_path):
    table, wav, char = _files(tmp_path, vowel_buzz(1.5))

    def send(client, stop):
        while not stop.is_set():
            vmc(client, {"JawOpen": 0.9, "BrowInnerUp": 0.5})
            time.sleep(0.01)

    record, replay_w = tmp_path / "take.fps", tmp_path / "replay.npy"
    options = ["--voice", str(table), "--voice-mode", "hybrid"]
    result, logs = live(["-c", str(char), "--input", "vmc", "--duration", "1.5", "--audio-file", str(wav),
                         "--record", str(record), *options], send, tmp_path)
    assert "stages: vmc→audio→voice→filter→hybrid→map→draw" in logs
    w = result.weights.array[-30:]
    assert np.ptp(w[:, 0]) > 0.1  # the jaw is the voice's, not the tracker's steady 0.9
    assert np.abs(w[:, 2] - 0.5).max() < 0.05  # the brows stay the tracker's
    args = parser().parse_args(["replay", str(record), "-c", str(char), "--headless", "--size", "48x40",
                                *options, "--dump-weights", str(replay_w)])
    with logged([]):
        assert replay.run_replay(args) == 0
    np.testing.assert_array_equal(np.load(replay_w), result.weights.array)


def test_while_tracking_is_lost_mouth_voice_is_the_learned_mouth(tmp_path):
    table, wav, char = _files(tmp_path, vowel_buzz(3.0, on_off_hz=2.0))
    config = tmp_path / "c.toml"
    config.write_text('[tracking_loss]\ntimeout_s = 0.1\nease_out_s = 0.1\nmouth = "voice"\n')

    def send(client, stop):  # a few frames, then the tracker goes away
        for _ in range(20):
            vmc(client, {"JawOpen": 0.0, "BrowInnerUp": 0.2})
            time.sleep(0.01)

    result, logs = live(["-c", str(char), "--input", "vmc", "--duration", "2.0", "--audio-file", str(wav),
                         "--config", str(config), "--voice", str(table)], send, tmp_path)
    w = result.weights.array[-40:]
    assert np.ptp(w[:, 1]) > 0.05  # mouthFunnel moves: the level's jaw alone never drives it


def test_a_missing_microphone_is_said_and_the_run_goes_on(tmp_path):
    table, wav, char = _files(tmp_path, np.zeros(100))
    result, logs = live(["-c", str(char), "--input", "vmc", "--duration", "0.3", "--audio", "no-such-device-xyz",
                         "--voice", str(table)], lambda client, stop: None, tmp_path)
    assert any("no audio" in line for line in logs), logs
    assert any("no voice; the run goes on" in line for line in logs), logs
    assert result.loop.n_ticks > 0


def test_with_several_inputs_the_voice_is_a_mix_source_of_its_channels_and_the_replay_agrees(tmp_path):
    table, wav, char = _files(tmp_path, vowel_buzz(1.5))

    def send(client, stop):  # the tracker has only the brows: the mouth comes from the voice
        while not stop.is_set():
            vmc(client, {"BrowInnerUp": 0.5})
            time.sleep(0.01)

    record, replay_w = tmp_path / "take.fps", tmp_path / "replay.npy"
    result, logs = live(["-c", str(char), "--input", "vmc", "--input", "audio", "--duration", "1.5", "--audio-file",
                         str(wav), "--voice", str(table), "--record", str(record)], send, tmp_path)
    assert any(line.startswith("stages: vmc+audio→audio→voice→mix") for line in logs), logs
    w = result.weights.array[-40:]
    assert np.ptp(w[:, 0]) > 0.1 and np.ptp(w[:, 1]) > 0.02  # jawOpen and mouthFunnel from the voice
    assert np.abs(w[:, 2] - 0.5).max() < 0.05  # the brows from the tracker
    args = parser().parse_args(["replay", str(record), "-c", str(char), "--headless", "--size", "48x40",
                                "--voice", str(table), "--dump-weights", str(replay_w)])
    with logged([]):
        assert replay.run_replay(args) == 0
    np.testing.assert_array_equal(np.load(replay_w), result.weights.array)
