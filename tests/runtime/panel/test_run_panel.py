"""``run --headless --panel`` over real UDP: the panel is in the frames; without imgui-bundle ``--panel`` is refused."""

from __future__ import annotations

import sys
import threading
import time

import numpy as np
import pytest
from pythonosc.udp_client import SimpleUDPClient

from facepuppet.runtime.cli import main

from helpers.small_characters import sphere_character
from helpers.udp_helpers import free_udp_port

pytest.importorskip("imgui_bundle", reason="the panel's extra (imgui-bundle) is not installed")

from facepuppet.runtime.panel.channels import METER_COLOURS  # noqa: E402

pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def character(tmp_path_factory):
    path = tmp_path_factory.mktemp("panel-run") / "sphere.npz"
    sphere_character().save(path)
    return path


def _send_jaw(port: int, done: threading.Event) -> None:
    from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
    from pythonosc.osc_message_builder import OscMessageBuilder

    client = SimpleUDPClient("127.0.0.1", port)
    while not done.is_set():
        b = OscBundleBuilder(IMMEDIATELY)
        m = OscMessageBuilder("/VMC/Ext/Blend/Val")
        m.add_arg("JawOpen", "s")
        m.add_arg(0.8, "f")
        b.add_content(m.build())
        b.add_content(OscMessageBuilder("/VMC/Ext/Blend/Apply").build())
        client.send(b.build())
        time.sleep(0.01)


def _meter_colour_pixels(png) -> int:
    from PIL import Image

    image = np.asarray(Image.open(png).convert("RGB")).astype(int)
    want = np.round(np.array(METER_COLOURS[0][:3]) * 255).astype(int)
    return int((np.abs(image - want).max(axis=2) <= 3).sum())


@pytest.mark.slow
@pytest.mark.parametrize("panel", [True, False])
def test_headless_run_draws_the_panel_into_its_frames_only_with_panel(character, tmp_path, capsys, panel):
    port = free_udp_port()
    done = threading.Event()
    sender = threading.Thread(target=_send_jaw, args=(port, done), daemon=True)
    sender.start()
    out = tmp_path / "png"
    try:
        code = main(["run", "-c", str(character), "--input", "vmc", "--listen", f"127.0.0.1:{port}", "--headless",
                     "--duration", "1.0", "--size", "480x400", "--out", str(out), "--draw", "tick", "--fps", "10"]
                    + (["--panel"] if panel else []))
    finally:
        done.set()
        sender.join(timeout=10)
    assert code == 0, capsys.readouterr().out
    last = sorted(out.glob("frame_*.png"))[-1]
    if panel:
        assert _meter_colour_pixels(last) > 50  # the raw meter of JawOpen, in the panel's own colour
    else:
        assert _meter_colour_pixels(last) == 0


def test_panel_without_imgui_bundle_is_exit_2_naming_the_extra(character, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "imgui_bundle", None)  # as if not installed
    code = main(["run", "-c", str(character), "--input", "vmc", "--listen", f"127.0.0.1:{free_udp_port()}",
                 "--headless", "--duration", "0.2", "--size", "160x120", "--panel"])
    captured = capsys.readouterr()
    assert code == 2
    text = captured.out + captured.err
    assert "--panel" in text and "facepuppet[panel]" in text
