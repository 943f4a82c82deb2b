"""``[hotkeys]`` in a real window (glfw on Xvfb): a key pressed as a real X event (XTest) fires its expression,
seen over ``run --web``'s WebSocket in the weights the run draws."""

from __future__ import annotations

import ctypes.util
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from pythonosc.udp_client import SimpleUDPClient
from websockets.sync.client import connect

from helpers.udp_helpers import free_udp_port
from helpers.vmc_run import NO_SMOOTHING, send_vmc
from helpers.vrm_characters import preset_character
from helpers.web_run import free_web_port

XK_J = 0x006A

HOTKEYS = '\n[hotkeys]\nJ = { verb = "expression", name = "Joy", action = "on", fade = 0.0 }\n'


@pytest.mark.slow
@pytest.mark.gl
def test_a_hotkey_in_the_window_fires_its_expression(x_display, tmp_path, monkeypatch):
    if ctypes.util.find_library("Xtst") is None and not Path("/usr/lib/x86_64-linux-gnu/libXtst.so.6").exists():
        pytest.skip("libXtst (the X server's test extension client) is not installed: no way to send real X input")
    from helpers.panel_window import XTest

    preset_character().save(tmp_path / "avatar.npz")
    (tmp_path / "live.toml").write_text(NO_SMOOTHING + HOTKEYS)
    udp, web = free_udp_port(), free_web_port()
    env = {**os.environ, "DISPLAY": x_display}
    env.pop("WAYLAND_DISPLAY", None)
    run = subprocess.Popen([sys.executable, "-m", "facepuppet", "run", "-c", str(tmp_path / "avatar.npz"),
                            "--input", "vmc", "--listen", f"127.0.0.1:{udp}", "--size", "320x240", "--duration", "90",
                            "--config", str(tmp_path / "live.toml"), "--web", f"127.0.0.1:{web}"],
                           env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    stop = threading.Event()

    def send():
        client = SimpleUDPClient("127.0.0.1", udp)
        while not stop.is_set():
            send_vmc(client, {"aa": 0.2})
            time.sleep(0.01)
    threading.Thread(target=send, daemon=True).start()
    try:
        ws = _connect(web, run)
        with ws:
            ws.send(json.dumps({"verb": "subscribe", "rate": 20}))
            assert _smile(ws, lambda v: v == 0.0), "the run draws Joy before the key"
            monkeypatch.setenv("DISPLAY", x_display)
            x = XTest()
            fired = False
            try:
                # "on", not "toggle": under load the window may map or take the pointer late, so the key is
                # pressed again until Joy shows (a press that lands twice changes nothing)
                for _ in range(10):
                    x.focus_follows_pointer()
                    x.move(100, 100)  # no window manager: the keyboard follows the pointer
                    x.key(XK_J, True)
                    time.sleep(0.05)
                    x.key(XK_J, False)
                    if _smile(ws, lambda v: v == pytest.approx(1.0), wait_s=4.0):
                        fired = True
                        break
            finally:
                x.close()
            assert fired, "the hotkey J did not fire Joy"
            ws.send(json.dumps({"verb": "status"}))
    finally:
        stop.set()
        run.send_signal(signal.SIGINT)
        out, _ = run.communicate(timeout=60)
    assert "control: hotkeys J (the config's [hotkeys])" in out, out


def _connect(port: int, run: subprocess.Popen):
    end = time.monotonic() + 60
    while time.monotonic() < end:
        if run.poll() is not None:
            raise AssertionError(f"the run ended: {run.stdout.read()}")
        try:
            return connect(f"ws://127.0.0.1:{port}/ws", open_timeout=5)
        except OSError:
            time.sleep(0.2)
    raise AssertionError("the run's WebSocket never answered")


def _smile(ws, want, wait_s: float = 30.0) -> bool:
    """Whether a weights message shows ``smile`` as wanted within a bounded wait for the run."""
    end = time.monotonic() + wait_s
    while time.monotonic() < end:
        doc = json.loads(ws.recv(timeout=wait_s))
        if doc.get("type") == "weights" and doc["weights"] and want(doc["weights"]["smile"]):
            return True
    return False
