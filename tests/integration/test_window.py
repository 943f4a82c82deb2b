"""The window path: a real glfw window on a virtual X display (Xvfb), not the EGL fallback."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image


@pytest.mark.slow
def test_demo_opens_a_window_when_a_display_exists(x_display, tmp_path):
    env = {**os.environ, "DISPLAY": x_display}
    env.pop("WAYLAND_DISPLAY", None)
    out = tmp_path / "frames"
    result = subprocess.run(
        [sys.executable, "-m", "facepuppet", "demo", "--duration", "0.5", "--fps", "10",
         "--size", "320x180", "--out", str(out)],
        env=env, capture_output=True, text=True, timeout=300,
    )
    assert result.returncode == 0, result.stderr
    assert "demo: window" in result.stdout
    frames = sorted(out.glob("frame_*.png"))
    assert len(frames) == 6
    image = np.asarray(Image.open(frames[0]).convert("RGB"))
    assert image.shape == (180, 320, 3) and image.std() > 5  # the head was drawn into the window

