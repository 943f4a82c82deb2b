"""The window path: a real glfw window on a virtual X display (Xvfb), not the EGL fallback."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest
from PIL import Image


@pytest.fixture
def x_display():
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        pytest.skip("Xvfb is not installed (make test installs it through .ci/system-deps); "
                    "the window path needs an X display")
    for number in range(91, 120):
        if not os.path.exists(f"/tmp/.X{number}-lock"):
            break
    proc = subprocess.Popen([xvfb, f":{number}", "-screen", "0", "1024x768x24", "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 10
    while not os.path.exists(f"/tmp/.X11-unix/X{number}") and time.monotonic() < deadline:
        time.sleep(0.05)
    try:
        yield f":{number}"
    finally:
        proc.terminate()
        proc.wait(timeout=10)


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

