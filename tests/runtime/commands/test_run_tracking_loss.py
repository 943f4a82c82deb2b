"""``run`` over real UDP: the tracker goes silent, the jaw hands over to the voice (an audio file), then back.

A VMC sender on 127.0.0.1 sends JawOpen = 0.2, stops once the run has drawn its frames, and starts again a
second after the run announced the loss on ``--events-out`` (a real socket on 127.0.0.1); the run records
(``--record``) and the recording is replayed with the same options.
"""

from __future__ import annotations

import argparse
import math
import socket
import threading
import time

import numpy as np
import pytest

from facepuppet.runtime.commands import replay, run
from facepuppet.runtime.inputs.osc import decode
from facepuppet.runtime.live.tracking_loss import LossSettings, voice_jaw
from facepuppet.runtime.recording.session import read_session

from helpers.logs import logged
from helpers.osc_helpers import vmc_frame
from helpers.small_characters import sphere_character
from helpers.swinging_voice import write_voice
from helpers.udp_helpers import free_udp_port

FPS = 60
TRACKED = 0.2
EASE_OUT, EASE_IN = 0.2, 0.3
CONFIG = "\n".join(f"[filter.{r}]\nmin_cutoff = 500.0\nbeta = 0.0" for r in ("eyes", "brows", "mouth", "other",
                                                                             "head")) + f"""
[tracking_loss]
timeout_s = 0.2
ease_out_s = {EASE_OUT}
ease_in_s = {EASE_IN}
mouth = "voice"
voice_floor_db = -40.0
voice_ceiling_db = -10.0
"""
LOSS = LossSettings(voice_floor_db=-40.0, voice_ceiling_db=-10.0)


def parse(command, argv):
    parser = argparse.ArgumentParser()
    command.register(parser.add_subparsers())
    return parser.parse_args(argv)


@pytest.mark.gl
def test_jaw_hands_over_to_the_voice_while_the_tracker_is_silent_and_back_without_a_jump(tmp_path):
    character = tmp_path / "sphere.npz"
    sphere_character().save(character)
    config, wav, rec = tmp_path / "live.toml", tmp_path / "voice.wav", tmp_path / "show.fps"
    config.write_text(CONFIG)
    write_voice(wav)
    port = free_udp_port()
    events_rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    events_rx.bind(("127.0.0.1", 0))
    events_rx.settimeout(0.05)
    ns = parse(run, ["run", "-c", str(character), "--input", "vmc", "--listen", f"127.0.0.1:{port}", "--headless",
                     "--size", "48x40", "--draw", "tick", "--fps", str(FPS), "--duration", "30", "--config",
                     str(config), "--audio-file", str(wav), "--record", str(rec),
                     "--events-out", f"127.0.0.1:{events_rx.getsockname()[1]}"])
    stop, phase = threading.Event(), {"drawn": 0, "after": 0, "resumed": False}
    heard: list[int] = []
    ticks: list[tuple[float, float, float]] = []  # tick time, audio level on the frame, jaw drawn

    def sender():
        client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        with client:
            while not stop.is_set() and phase["drawn"] < 20:  # 1: live until 20 ticks drew frames
                client.sendto(vmc_frame(TRACKED), ("127.0.0.1", port))
                time.sleep(0.01)
            lost_at = None
            while not stop.is_set():
                try:
                    data = events_rx.recv(512)
                    heard.extend(args[0] for address, args in decode(data) if address == "/facepuppet/tracking")
                except TimeoutError:
                    pass
                if lost_at is None and heard[:1] == [0]:
                    lost_at = time.monotonic()  # 2: silent until a second after the run said "lost"
                if lost_at is not None and time.monotonic() > lost_at + 1.0:
                    phase["resumed"] = True
                    client.sendto(vmc_frame(TRACKED), ("127.0.0.1", port))  # 3: live again
                    time.sleep(0.01)

    def hook(info):
        ticks.append((info.t, info.frame.audio_level if info.frame is not None else math.nan,
                      float(info.weights[0])))
        if info.raw is not None:
            phase["drawn"] += 1
            if phase["resumed"]:
                phase["after"] += 1
                if phase["after"] >= 40:
                    stop.set()

    thread = threading.Thread(target=sender, daemon=True)
    try:
        thread.start()
        result = run.run_live(ns, stop_event=stop, hooks=[hook])
    finally:
        stop.set()
        thread.join(timeout=10)
        events_rx.close()
    assert phase["after"] >= 40, "the run ended before the tracker came back"
    assert heard == [0, 1]  # over OSC: lost, then found
    assert result.counters["pipeline"]["tracking_lost"] == 1 and result.counters["pipeline"]["tracking_found"] == 1
    assert result.counters["events_out"]["events_sent"] == 2

    events = read_session(rec).events
    assert [f for _, f in events] == [False, True]
    (t_lost, _), (t_found, _) = events
    t, level, jaw = (np.array(c) for c in zip(*ticks))
    before = (t > 0.1) & (t < t_lost - 0.25)
    assert before.sum() >= 5
    np.testing.assert_allclose(jaw[before & np.isfinite(jaw)], TRACKED, atol=1e-5)
    # while lost (eased out): the jaw is the voice level's, and it moves with it
    voiced = (t >= t_lost + EASE_OUT + 1e-6) & (t < t_found)
    assert voiced.sum() >= 10
    expected = np.array([voice_jaw(x, LOSS) for x in level[voiced]])
    np.testing.assert_allclose(jaw[voiced], expected, atol=1e-5)
    assert np.ptp(jaw[voiced]) > 0.15 and np.abs(jaw[voiced] - TRACKED).max() > 0.1
    # back to the tracker: each tick steps at most the smoothstep's slope x the distance x the tick's length
    i0 = int(np.flatnonzero(t >= t_found)[0])
    ret = (t >= t_found) & (t <= t_found + EASE_IN + 1e-9)
    idx = np.flatnonzero(ret)
    distance = abs(jaw[i0 - 1] - TRACKED)
    for i in idx[1:]:
        assert abs(jaw[i] - jaw[i - 1]) <= 1.5 * distance * (t[i] - t[i - 1]) / EASE_IN + 1e-5, (t[i], jaw[i])
    assert abs(jaw[i0] - jaw[i0 - 1]) <= 1.5 * distance * (t[i0] - t[i0 - 1]) / EASE_IN + 1e-5
    np.testing.assert_allclose(jaw[t > t_found + EASE_IN + 0.02], TRACKED, atol=1e-5)

    # the replay of the recording runs the same chain and reproduces the events and the weights
    dump = tmp_path / "replay.npy"
    lines: list[str] = []
    args = parse(replay, ["replay", str(rec), "-c", str(character), "--headless", "--size", "48x40", "--config",
                          str(config), "--dump-weights", str(dump)])
    with logged(lines):
        assert replay.run_replay(args) == 0
    assert any(line.startswith("replay: tracking events as recorded (2: lost at") for line in lines), lines
    replayed = np.load(dump)[:, 0]
    np.testing.assert_allclose(replayed, jaw[:len(replayed)], atol=1e-6)
    assert len(replayed) == len(jaw)
