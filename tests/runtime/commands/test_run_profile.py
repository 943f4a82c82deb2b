"""``run --profile`` over real UDP on 127.0.0.1: the profile's response and neutral drive the face, a live
``apply_config`` takes effect mid-run, and the recording replays to the same weights without being told the
config (it keeps the config in force and each change)."""

from __future__ import annotations

import argparse
import threading
import time
from dataclasses import replace

import numpy as np
import pytest
from pythonosc.udp_client import SimpleUDPClient

from facepuppet.runtime.cli import main
from facepuppet.runtime.commands import run
from facepuppet.runtime.live.profiles import Profile
from facepuppet.runtime.recording.session import read_session

from helpers.logs import logged
from helpers.small_characters import sphere_character
from helpers.udp_helpers import free_udp_port
from helpers.vmc_run import NO_SMOOTHING, send_vmc

# jawOpen sent 0.5, neutral 0.1: x = 0.4; gain 1.5 -> 0.6; input [0.2, 1.0] -> u = 0.5; output [0, 0.8] -> 0.4
PROFILE = NO_SMOOTHING + """
[channels.jawOpen]
gain = 1.5
input_range = [0.2, 1.0]
output_range = [0.0, 0.8]

[neutral]
channels = ["JawOpen"]
weights = [0.1]
rotation = [0.0, 0.0, 0.0, 1.0]

[profile]
character = "sphere.npz"
input = "vmc"
"""
PHASE = 8  # ticks with a drawn frame before the change, and after it


def _run_with_a_live_change(char, record, options, change):
    """``run`` of ``char`` over VMC on loopback (JawOpen 0.5 every 10 ms) with ``options`` and ``--record``;
    after PHASE ticks with a drawn frame ``change(config in force)`` is applied as the panel would, and the run
    stops PHASE ticks later. Returns (LiveRunResult, logs, ticks drawn)."""
    port = free_udp_port()
    parser = argparse.ArgumentParser()
    run.register(parser.add_subparsers())
    ns = parser.parse_args(["run", "-c", str(char), "--input", "vmc", "--listen", f"127.0.0.1:{port}", "--headless",
                            "--size", "48x40", "--duration", "60", *options, "--record", str(record)])
    stop, drawn, chains = threading.Event(), [], []

    def on_ready(address):
        def send():
            client = SimpleUDPClient("127.0.0.1", port)
            while not stop.is_set():
                send_vmc(client, {"JawOpen": 0.5})
                time.sleep(0.01)
        threading.Thread(target=send, daemon=True).start()

    def hook(info):
        if info.raw is None:
            return
        drawn.append(info.k)
        if len(drawn) == PHASE:
            pipeline = chains[0].filter
            pipeline.apply_config(change(pipeline.current_config()))
        if len(drawn) >= 2 * PHASE:
            stop.set()

    logs: list[str] = []
    try:
        with logged(logs):
            result = run.run_live(ns, stop_event=stop, on_ready=on_ready, hooks=[hook],
                                  keep_weights=True, on_chain=chains.append)
    finally:
        stop.set()
    return result, logs, drawn


def _replayed(char, record, tmp_path, *options):
    out = tmp_path / f"replay{len(list(tmp_path.glob('replay*.npy')))}.npy"
    assert main(["replay", str(record), "-c", str(char), "--headless", "--size", "48x40", *options,
                 "--dump-weights", str(out)]) == 0
    return np.load(out)


@pytest.mark.gl
def test_a_recording_made_with_a_profile_and_a_live_change_replays_to_the_same_weights(tmp_path):
    char = sphere_character().save(tmp_path / "sphere.npz")
    profile = tmp_path / "show.toml"
    profile.write_text(PROFILE)
    before = profile.read_bytes()
    record = tmp_path / "live.fps"

    def gain(cfg):  # the panel's move: gain 0.5 on jawOpen, the rest as in force
        return replace(cfg, channels={**cfg.channels, "jawOpen": replace(cfg.channels["jawOpen"], gain=0.5)})

    result, logs, drawn = _run_with_a_live_change(char, record, ["--profile", str(profile)], gain)
    assert len(drawn) >= 2 * PHASE, "\n".join(logs)
    live = result.weights.array[:, 0]  # the sphere's jawOpen
    # x = 0.4 -> gain 0.5: 0.2 -> u = 0 (below the input range) -> 0.0 after the change
    assert np.any(np.isclose(live, 0.4, atol=1e-4)), live
    assert live[-1] == pytest.approx(0.0, abs=1e-4)
    assert not any("warning" in line for line in logs)  # made for this character and input
    assert profile.read_bytes() == before  # a run does not write its profile unasked

    session = read_session(record)
    assert isinstance(session.header["info"]["config"], str) and len(session.configs) == 1
    assert session.header["info"]["options"]["profile"] == str(profile)

    back = _replayed(char, record, tmp_path)
    np.testing.assert_allclose(back[-len(result.weights.array):], result.weights.array, atol=1e-6)

    # the same recording told another config draws something else: the recorded config was what made it match
    plain = tmp_path / "plain.toml"
    plain.write_text(NO_SMOOTHING)
    assert _replayed(char, record, tmp_path, "--config", str(plain))[-1, 0] == pytest.approx(0.5, abs=1e-4)


@pytest.mark.gl
def test_a_mapping_changed_mid_run_maps_from_then_on_and_replays_to_the_same_weights(tmp_path):
    """The panel's "drives" list hands over a [mapping] (jawOpen onto the sphere's puff): the run maps with it
    from the next tick, the recording keeps the change, and its replay draws the same weights."""
    from facepuppet.runtime.mapping.expressions import MappingTarget

    char = sphere_character().save(tmp_path / "sphere.npz")
    config = tmp_path / "plain.toml"
    config.write_text(NO_SMOOTHING)
    record = tmp_path / "live.fps"

    def onto_puff(cfg):
        return replace(cfg, mapping=replace(cfg.mapping, channels={"jawOpen": (MappingTarget("puff"),)},
                                            written={"jawOpen": "JawOpen"}))

    result, logs, _ = _run_with_a_live_change(char, record, ["--config", str(config)], onto_puff)
    live = result.weights.array  # (ticks, [jawOpen, puff])
    assert np.any(np.all(np.isclose(live, [0.5, 0.0], atol=1e-4), axis=1)), live  # by name first
    np.testing.assert_allclose(live[-1], [0.0, 0.5], atol=1e-4)  # then onto puff
    assert any(line.startswith("mapping: 1 channel(s)") for line in logs), logs
    back = _replayed(char, record, tmp_path)
    np.testing.assert_allclose(back[-len(live):], live, atol=1e-6)


@pytest.mark.gl
def test_run_warns_when_the_profile_was_made_for_another_character(tmp_path):
    char = sphere_character().save(tmp_path / "ball.npz")
    profile = tmp_path / "show.toml"
    profile.write_text(PROFILE)  # made for sphere.npz
    logs: list[str] = []
    parser = argparse.ArgumentParser()
    run.register(parser.add_subparsers())
    ns = parser.parse_args(["run", "-c", str(char), "--input", "vmc", "--listen", f"127.0.0.1:{free_udp_port()}",
                            "--headless", "--size", "32x24", "--duration", "0.1", "--profile", str(profile)])
    with logged(logs):
        run.run_live(ns)
    warning = next(line for line in logs if "warning" in line)
    assert "made for character 'sphere.npz'" in warning and "'ball.npz'" in warning


@pytest.mark.gl
def test_a_calibrated_run_saves_its_neutral_to_a_new_profile_by_name(tmp_path, monkeypatch):
    """--profile NAME that does not exist yet, --calibrate, --save-profile: the neutral captured from the frames sent
    over UDP is in the profile afterwards, and a run with that profile starts calibrated."""
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    char = sphere_character().save(tmp_path / "sphere.npz")
    port = free_udp_port()
    parser = argparse.ArgumentParser()
    run.register(parser.add_subparsers())
    ns = parser.parse_args(["run", "-c", str(char), "--input", "vmc", "--listen", f"127.0.0.1:{port}", "--headless",
                            "--size", "32x24", "--duration", "60", "--profile", "rehearsal", "--calibrate",
                            "--save-profile"])
    stop = threading.Event()
    seen = []

    def on_ready(address):
        def send():
            client = SimpleUDPClient("127.0.0.1", port)
            while not stop.is_set():
                send_vmc(client, {"JawOpen": 0.3})
                time.sleep(0.01)
        threading.Thread(target=send, daemon=True).start()

    def hook(info):
        if info.raw is not None:
            seen.append(info.k)
        counters = result_counters[0] if result_counters else None
        if counters is not None and counters["calibrations"] >= 1 and len(seen) > 3:
            stop.set()

    result_counters: list = []
    logs: list[str] = []
    try:
        with logged(logs):
            run.run_live(ns, stop_event=stop, on_ready=on_ready, hooks=[hook],
                         on_chain=lambda chain: result_counters.append(chain.filter.counters))
    finally:
        stop.set()
    path = tmp_path / "xdg" / "facepuppet" / "profiles" / "rehearsal.toml"
    assert path.is_file(), "\n".join(logs)
    saved = Profile(path, log=lambda s: None).load()
    at = [c.lower() for c in saved.neutral.channels].index("jawopen")
    assert saved.neutral.weights[at] == pytest.approx(0.3, abs=1e-6)
    assert any("does not exist yet" in line for line in logs) and any("profile: saved" in line for line in logs)


def test_save_profile_needs_a_profile(tmp_path):
    char = sphere_character().save(tmp_path / "s.npz")
    assert main(["run", "-c", str(char), "--input", "vmc", "--listen", "127.0.0.1:0", "--headless",
                 "--duration", "0.1", "--save-profile"]) == 2
