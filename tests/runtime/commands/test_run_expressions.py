"""``run --input vmc`` on VRM-like characters over real UDP on 127.0.0.1: perfect-sync ARKit names, VRM preset
names and plain ARKit names onto an avatar with only VRM presets, and ``--vmc-out`` with the avatar's own names.

The characters are built in code (tests/helpers/vrm_characters.py) until the glTF reader makes real ones;
expected weights are worked out by hand from their bind weights and the documented ARKit -> VRM table.
"""

from __future__ import annotations

import socket

import numpy as np
import pytest
from pythonosc.osc_bundle import OscBundle

from helpers.udp_helpers import free_udp_port
from helpers.vmc_run import drive, last_weights
from helpers.vrm_characters import preset_character, sync_character


@pytest.mark.gl
def test_perfect_sync_arkit_names_drive_the_arkit_named_morphs(tmp_path):
    c = sync_character()
    result, log = drive(c, {"EyeBlinkLeft": 0.9, "JawOpen": 0.6, "MouthSmileLeft": 0.2}, tmp_path)
    assert last_weights(c, result) == pytest.approx(dict(
        eyeBlink_L=0.9, eyeBlink_R=0.0, jawOpen=0.6, mouthFunnel=0.0, mouthPucker=0.0, mouthSmile_L=0.2,
        mouthSmile_R=0.0, browInnerUp=0.0), abs=1e-5)
    assert "morph (" in log and "eyeBlinkLeft→eyeBlink_L" in log


@pytest.mark.gl
def test_vrm_preset_names_drive_the_expressions_and_vmc_out_sends_the_avatars_names(tmp_path):
    c = preset_character()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
        receiver.bind(("127.0.0.1", 0))
        receiver.settimeout(0.0)
        result, log = drive(c, {"Blink": 1.0, "aa": 0.5, "happy": 0.3, "oh": 0.4}, tmp_path,
                            extra=("--vmc-out", f"127.0.0.1:{receiver.getsockname()[1]}"))
        datagrams = []
        while True:
            try:
                datagrams.append(receiver.recv(65536))
            except BlockingIOError:
                break
    got = last_weights(c, result)
    # Blink 1 -> both lids 1; A 0.5 + O 0.4*0.5 -> ah 0.7; O 0.4*0.6 -> oh 0.24; happy = Joy 0.3 -> smile 0.3
    assert got["blink_left"] == pytest.approx(1.0) and got["blink_right"] == pytest.approx(1.0)
    assert got["ah"] == pytest.approx(0.7) and got["oh"] == pytest.approx(0.24) and got["smile"] == pytest.approx(0.3)
    assert got["look_up"] == got["ih"] == got["HideBlush"] == 0.0
    assert "expression (" in log and "Blink→Blink" in log
    assert "(--vmc-names both), 52 ARKit (perfect sync) + the avatar's 18 VRM expressions" in log
    messages = [(m.address, m.params) for d in datagrams for m in OscBundle(d)]
    end = max(i for i, (a, _) in enumerate(messages) if a == "/VMC/Ext/Blend/Apply")
    start = max(i for i, (a, _) in enumerate(messages[:end]) if a == "/VMC/Ext/OK")
    tick = dict(p for a, p in messages[start:end] if a == "/VMC/Ext/Blend/Val")
    # the avatar's VRM 0.x preset names, with the values it showed; the ARKit names are 0 (no ARKit morph)
    assert tick["Blink"] == pytest.approx(1.0) and tick["A"] == pytest.approx(0.5) and tick["O"] == pytest.approx(0.4)
    assert tick["Joy"] == pytest.approx(0.3) and tick["HideBlush"] == 0.0 and tick["EyeBlinkLeft"] == 0.0
    assert len(tick) == 52 + 18


@pytest.mark.gl
def test_arkit_names_onto_an_avatar_with_only_presets_take_the_default_mapping(tmp_path):
    c = preset_character()
    result, log = drive(c, {"EyeBlinkLeft": 0.9, "EyeBlinkRight": 0.4, "JawOpen": 0.6, "MouthSmileLeft": 0.8},
                        tmp_path, extra=("--vmc-out", f"127.0.0.1:{free_udp_port()}", "--vmc-names", "vrm"))
    got = last_weights(c, result)
    # Blink = 0.4, Blink_L = 0.5 -> blink_left 0.9, blink_right 0.4; A = jawOpen 0.6 -> ah 0.6 (U = 0.6 - ... < 0)
    # MouthSmileLeft: Joy is an emotion, off by default -> smile 0
    assert got["blink_left"] == pytest.approx(0.9) and got["blink_right"] == pytest.approx(0.4)
    assert got["ah"] == pytest.approx(0.6) and got["uu"] == 0.0 and got["smile"] == 0.0
    assert "default preset mapping (" in log and "jawOpen→A+U" in log
    assert "(--vmc-names vrm), the avatar's 18 VRM expressions" in log


def test_vmc_names_needs_vmc_out_and_a_bad_mapping_target_is_named(tmp_path, capsys):
    from facepuppet.runtime.cli import main

    path = preset_character().save(tmp_path / "avatar.npz")
    code = main(["run", "-c", str(path), "--input", "vmc", "--headless", "--duration", "0.1", "--vmc-names", "vrm"])
    assert code == 2 and "--vmc-names: needs --vmc-out HOST:PORT" in capsys.readouterr().err
    config = tmp_path / "map.toml"
    config.write_text('[mapping.channels]\njawOpen = "Surprised"\n')
    code = main(["run", "-c", str(path), "--input", "vmc", "--headless", "--duration", "0.1", "--listen",
                 f"127.0.0.1:{free_udp_port()}", "--config", str(config)])
    err = capsys.readouterr().err
    assert code == 2 and "map.toml: key 'mapping.channels.jawOpen': target 'Surprised' is neither" in err


@pytest.mark.gl
def test_a_recorded_run_on_the_avatar_replays_to_the_same_weights(tmp_path):
    """The recording keeps the raw datagrams; replay decodes them again with the avatar's expression names, so
    preset names sent live drive the same expressions on replay, tick for tick."""
    from facepuppet.runtime.cli import main

    c = preset_character()
    record = tmp_path / "live.fps"
    result, _ = drive(c, {"Blink_L": 0.8, "JawOpen": 0.5, "ou": 0.6}, tmp_path, extra=("--record", str(record)))
    live = result.weights.array
    replayed = tmp_path / "replay.npy"
    code = main(["replay", str(record), "-c", str(tmp_path / "avatar.npz"), "--headless", "--size", "48x40",
                 "--dump-weights", str(replayed)])
    assert code == 0
    back = np.load(replayed)
    at = {n: i for i, n in enumerate(c.shape_names)}
    # Blink_L 0.8 -> blink_left 0.8; ou = U 0.6 -> uu 0.6; JawOpen 0.5 -> A 0.5 - ... (no funnel/pucker) -> ah 0.5
    assert back[-1, at["blink_left"]] == pytest.approx(0.8) and back[-1, at["uu"]] == pytest.approx(0.6)
    assert back[-1, at["ah"]] == pytest.approx(0.5)
    np.testing.assert_allclose(back[-len(live):], live, atol=1e-6)


@pytest.mark.gl
@pytest.mark.data
def test_a_live_link_face_take_replayed_on_a_preset_only_avatar_blinks_and_talks(tmp_path):
    """A real Live Link Face take (ARKit PascalCase columns) through the default ARKit -> VRM preset mapping. Each
    drawn tick shows one recorded row, so every drawn weight must be that row's value by the hand formulas:
    blink_left = Blink + Blink_L = eyeBlinkLeft; ah = A + 0.5 O = clip(jaw - funnel/2 - pucker/2) + funnel/2."""
    import csv

    from facepuppet.runtime.cli import main

    from conftest import need_shared

    take = need_shared("tracker", "livelinkface_myslate_3.csv")
    with open(take, newline="") as f:
        rows = list(csv.DictReader(f))
    col = {k: np.clip(np.array([float(r[k]) for r in rows]), 0.0, 1.0)
           for k in ("EyeBlinkLeft", "JawOpen", "MouthFunnel", "MouthPucker")}
    blink = col["EyeBlinkLeft"]
    ah = np.minimum(1.0, np.clip(col["JawOpen"] - col["MouthFunnel"] / 2 - col["MouthPucker"] / 2, 0.0, 1.0)
                    + col["MouthFunnel"] / 2)
    c = preset_character()
    c.save(tmp_path / "avatar.npz")
    out = tmp_path / "w.npy"
    assert main(["replay", str(take), "-c", str(tmp_path / "avatar.npz"), "--headless", "--size", "48x40",
                 "--dump-weights", str(out)]) == 0
    w = np.load(out)
    at = {n: i for i, n in enumerate(c.shape_names)}
    drawn_blink, drawn_ah = w[:, at["blink_left"]], w[:, at["ah"]]
    assert drawn_blink.max() > 0.5 and drawn_ah.max() > 0.1, "no blink or no open mouth drawn"
    for k in range(len(w)):
        row = np.flatnonzero(np.abs(blink - drawn_blink[k]) < 1e-5)
        assert len(row) and np.any(np.abs(ah[row] - drawn_ah[k]) < 1e-5), f"tick {k} is no row of the take"
