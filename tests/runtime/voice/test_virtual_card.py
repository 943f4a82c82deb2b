"""The microphone path for real, on a virtual sound card (a private PulseAudio null sink, its monitor opened by
``run --audio vcard`` through PortAudio): a voice played into the card opens the mouth and silence keeps it
closed; a device the card does not have is said and the run goes on; the latency measure sees every onset
of the card, and says why it is not available where pulseaudio is absent."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import threading

import numpy as np
import pytest

from facepuppet.offline.voice.card_latency import card_alone, card_latency
from facepuppet.offline.voice.virtual_card import visible
from helpers.small_characters import grid_face
from helpers.udp_helpers import free_udp_port
from helpers.virtual_sound_card import play
from helpers.voice_tables import small_table, vowel_buzz, write_wav

SHAPES = ("jawOpen", "mouthFunnel", "browInnerUp", "eyeLookIn_L", "cornerBump")


def _files(tmp_path):
    table = small_table("ridge").save(tmp_path / "voice.npz")
    char = dataclasses.replace(grid_face(extra=True), shape_names=SHAPES).save(tmp_path / "c.npz")
    return table, char


def _run(argv, card, on_line=None, timeout=180):
    """``facepuppet run ARGV`` as a subprocess seeing the card; ``on_line(line)`` sees each output line as it
    comes. Returns (exit status, all the output)."""
    proc = subprocess.Popen([sys.executable, "-m", "facepuppet", "run", *argv], env=card.env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    lines = []

    def read():
        for line in proc.stdout:
            lines.append(line)
            if on_line is not None:
                on_line(line)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        proc.wait(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        reader.join(timeout=10)
    return proc.returncode, "".join(lines)


@pytest.mark.gl
@pytest.mark.slow
def test_a_voice_played_into_the_card_opens_the_mouth_and_silence_keeps_it_closed(tmp_path, virtual_sound_card):
    card = virtual_sound_card
    table, char = _files(tmp_path)
    wav = tmp_path / "voice.wav"
    rate = 16000
    write_wav(wav, np.concatenate([np.zeros(2 * rate), vowel_buzz(1.0, rate, on_off_hz=0.25), np.zeros(rate)]), rate)
    players = []

    def on_line(line):
        if line.startswith("stages:") and not players:  # the microphone is open: play while the run listens
            players.append(play(card, wav))

    weights = tmp_path / "w.npy"  # 12 s: on a busy machine PulseAudio's null sink can fall seconds behind
    code, out = _run(["-c", str(char), "--input", "audio", "--voice", str(table), "--audio", card.name, "--headless",
                      "--size", "48x40", "--duration", "12", "--dump-weights", str(weights)], card, on_line)
    assert players, out
    player = players[0]
    player.wait(timeout=60)
    assert player.returncode == 0, player.stderr.read()
    assert code == 0, out
    assert f"listening to the voice on {card.name}" in out and "no audio" not in out, out
    jaw = np.load(weights)[:, SHAPES.index("jawOpen")]
    opened = np.flatnonzero(jaw > 0.1)
    assert len(opened), f"the mouth never opened: jawOpen max {jaw.max():.3f}"
    assert opened[0] >= 30 and (jaw[:opened[0]] < 0.01).all()  # the silence before the voice: closed
    assert (jaw[-20:] < 0.01).all()  # and after it: closed again
    assert jaw.max() <= 1.0


@pytest.mark.gl
@pytest.mark.slow
def test_a_device_the_card_does_not_have_is_said_and_the_run_goes_on(tmp_path, virtual_sound_card):
    table, char = _files(tmp_path)
    weights = tmp_path / "w.npy"
    code, out = _run(["-c", str(char), "--input", "vmc", "--listen", f"127.0.0.1:{free_udp_port()}", "--audio",
                      "no-such-card-4242", "--voice", str(table), "--headless", "--size", "48x40", "--duration", "0.5",
                      "--dump-weights", str(weights)], virtual_sound_card)
    assert code == 0, out
    assert "could not open input device 'no-such-card-4242'" in out, out
    assert "no voice; the run goes on" in out, out
    assert len(np.load(weights)) > 0


@pytest.mark.slow
def test_the_card_alone_hears_every_onset_the_player_plays(virtual_sound_card):
    with visible(virtual_sound_card) as sd:
        got = card_alone(sd, virtual_sound_card, 3, log=lambda line: None)
    assert got["detected"] == 3, got
    assert got["played_to_arrived"]["n"] == 3


def test_without_pulseaudio_the_card_latency_is_not_available_and_says_why(tmp_path, monkeypatch):
    empty = tmp_path / "bin"
    empty.mkdir()
    monkeypatch.setenv("PATH", str(empty))
    got = card_latency(tmp_path / "voice.npz", tmp_path)
    assert got == {"available": False, "reason": got["reason"]}
    assert "pulseaudio not installed" in got["reason"]
