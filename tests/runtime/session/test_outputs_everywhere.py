"""Every output of a session works on ``run`` and ``replay`` alike: the options exist on both commands, and a
replay drives VMC receivers and sends tracking events as a live run does (over real UDP on 127.0.0.1)."""

from __future__ import annotations

import argparse

import numpy as np
import pytest
from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_message import OscMessage

from facepuppet.runtime.cli import build_parser, main
from facepuppet.runtime.commands import replay, run
from facepuppet.runtime.mapping.channels import ARKIT_NAMES, pascal

from helpers.small_characters import sphere_character
from helpers.udp_helpers import drain

OUTPUT_OPTIONS = ("--vmc-out", "--vmc-extra", "--vmc-presets", "--vmc-names", "--llf-out", "--events-out", "--video",
                  "--video-codec", "--out", "--dump-weights", "--stats", "--virtual-camera", "--stream")


def _options(register) -> set[str]:
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    command = next(iter(parser._subparsers._group_actions[0].choices.values()))
    return {s for a in command._actions for s in a.option_strings}


def test_run_and_replay_take_the_same_outputs():
    on_run, on_replay = _options(run.register), _options(replay.register)
    for option in OUTPUT_OPTIONS:
        assert option in on_run and option in on_replay, option


def test_replay_help_lists_every_output():
    text = build_parser()._subparsers._group_actions[0].choices["replay"].format_help()
    for option in OUTPUT_OPTIONS:
        assert option in text, option


def _take(path, rows: list[tuple[float, float]]) -> None:
    """A Live Link Face CSV take: (time s, jawOpen) rows at 60 frames per second timecodes."""
    lines = ["Timecode,BlendShapeCount," + ",".join(pascal(n) for n in ARKIT_NAMES)]
    for t, jaw in rows:
        values = ["0"] * 52
        values[ARKIT_NAMES.index("jawOpen")] = repr(jaw)
        frame = round(t * 60)
        lines.append(f"00:00:{frame // 60:02d}:{frame % 60:02d}.000,52," + ",".join(values))
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.gl
def test_replay_vmc_out_sends_the_drawn_weights_paced_to_real_time(tmp_path, udp_receiver, capsys):
    character = tmp_path / "sphere.npz"
    sphere_character().save(character)
    take = tmp_path / "take.csv"
    jaws = [0.1, 0.25, 0.4, 0.55, 0.7, 0.85]
    _take(take, [(i / 10, jaw) for i, jaw in enumerate(jaws)])
    dumped = tmp_path / "w.npy"
    code = main(["replay", str(take), "-c", str(character), "--headless", "--size", "48x40", "--fps", "10",
                 "--vmc-out", f"127.0.0.1:{udp_receiver.getsockname()[1]}", "--dump-weights", str(dumped)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "vmc-out" in captured.err and "(paced to real time)" in captured.err
    assert f"replay: sent 6 ticks as VMC to 127.0.0.1:{udp_receiver.getsockname()[1]}" in captured.out
    ticks, jaw = [], []
    for datagram in drain(udp_receiver):
        for m in OscBundle(datagram):
            if m.address == "/VMC/Ext/Blend/Val" and m.params[0] == "JawOpen":
                jaw.append(m.params[1])
            if m.address == "/VMC/Ext/T":
                ticks.append(m.params[0])
    drawn = np.load(dumped)[:, list(sphere_character().shape_names).index("jawOpen")]
    assert len(jaw) == len(drawn) == len(jaws)  # one VMC frame a tick, each with the tick's drawn jawOpen
    np.testing.assert_allclose(jaw, drawn, atol=1e-6)
    np.testing.assert_allclose(jaw, jaws, atol=1e-6)
    assert ticks == sorted(ticks)


@pytest.mark.gl
def test_replay_events_out_sends_the_tracking_events_of_the_filter_stage(tmp_path, udp_receiver, capsys):
    """A take with a pause longer than the config's timeout: the replay's filter stage loses tracking and finds
    it again, and says so over OSC as a live run does."""
    character = tmp_path / "sphere.npz"
    sphere_character().save(character)
    take = tmp_path / "take.csv"
    _take(take, [(i / 20, 0.3) for i in range(6)] + [(1.0 + i / 20, 0.6) for i in range(6)])
    config = tmp_path / "live.toml"
    config.write_text("[tracking_loss]\ntimeout_s = 0.2\nease_out_s = 0.1\nease_in_s = 0.1\n")
    code = main(["replay", str(take), "-c", str(character), "--headless", "--size", "48x40", "--fps", "20",
                 "--config", str(config), "--max-gap", "inf",
                 "--events-out", f"127.0.0.1:{udp_receiver.getsockname()[1]}"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "events: tracking lost/found as OSC /facepuppet/tracking" in captured.err
    messages = [OscMessage(d) for d in drain(udp_receiver)]
    assert [(m.address, m.params) for m in messages] == [("/facepuppet/tracking", [0]),
                                                         ("/facepuppet/tracking", [1])]


@pytest.mark.gl
def test_replay_without_the_filter_stage_says_it_has_no_events_to_send(tmp_path, udp_receiver, capsys):
    character = tmp_path / "sphere.npz"
    sphere_character().save(character)
    take = tmp_path / "take.csv"
    _take(take, [(i / 20, 0.3) for i in range(4)])
    code = main(["replay", str(take), "-c", str(character), "--headless", "--size", "48x40",
                 "--events-out", f"127.0.0.1:{udp_receiver.getsockname()[1]}"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "no filter stage" in captured.err
    assert drain(udp_receiver) == []
