"""The panel in a real window (glfw on Xvfb, not --headless): Tab and mouse clicks as real X events (XTest)."""

from __future__ import annotations

import ctypes.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from helpers.small_characters import sphere_character

pytest.importorskip("imgui_bundle", reason="the panel's extra (imgui-bundle) is not installed")

HELPER = Path(__file__).resolve().parent.parent / "helpers" / "panel_window.py"


@pytest.mark.slow
def test_tab_toggles_the_panel_and_clicks_reach_its_controls_in_a_real_window(x_display, tmp_path):
    if ctypes.util.find_library("Xtst") is None and not Path("/usr/lib/x86_64-linux-gnu/libXtst.so.6").exists():
        pytest.skip("libXtst (the X server's test extension client) is not installed: no way to send real X input")
    character = tmp_path / "sphere.npz"
    sphere_character().save(character)
    png = tmp_path / "panel.png"
    env = {**os.environ, "DISPLAY": x_display}
    env.pop("WAYLAND_DISPLAY", None)
    result = subprocess.run([sys.executable, str(HELPER), "-c", str(character), "--png", str(png), "--size", "960x700",
                             "--record", str(tmp_path / "take.fps")],
                            env=env, capture_output=True, text=True, timeout=300)
    lines = [line for line in result.stdout.splitlines() if line.startswith("{")]
    assert lines, result.stdout + result.stderr
    out = json.loads(lines[-1])
    assert result.returncode == 0, out
    assert out["window"]  # a glfw window, not the EGL fallback
    assert out["visible_seen"] == [False, True]  # Tab hid the panel, Tab showed it again
    # clicks on a channel row and on a radio button of its response: a config change applied by the pipeline
    assert out["selected"] == "jawOpen" and out["curve"] == "threshold"
    assert out["steps"]["click response.curve.threshold"]
    image = np.asarray(Image.open(png).convert("RGB"))
    assert image.shape == (700, 960, 3)
    left = image[:, :300].astype(int)  # the panel's window over the left of the frame: many distinct colours
    assert len(np.unique(left.reshape(-1, 3), axis=0)) > 50
