"""The window path: a real glfw window on a virtual X display (Xvfb), not the EGL fallback."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from helpers.small_characters import sphere_character
from helpers.udp_helpers import free_udp_port


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



@pytest.mark.slow
def test_a_transparent_window_background_is_asked_for_and_its_refusal_reported(x_display, tmp_path):
    """Xvfb has no compositor: glfw's TRANSPARENT_FRAMEBUFFER is not granted and the run says so; the
    window's frames written with --out still carry the cleared alpha 0 where nothing is drawn."""
    env = {**os.environ, "DISPLAY": x_display}
    env.pop("WAYLAND_DISPLAY", None)
    out = tmp_path / "frames"
    result = subprocess.run(
        [sys.executable, "-m", "facepuppet", "demo", "--duration", "0.2", "--fps", "10", "--size", "160x90",
         "--out", str(out), "--background", "transparent", "--msaa", "4", "--no-frames"],
        env=env, capture_output=True, text=True, timeout=300,
    )
    assert result.returncode == 0, result.stderr
    assert "demo: window" in result.stdout
    assert "no transparent window framebuffer" in result.stdout + result.stderr


@pytest.mark.slow
def test_a_live_window_on_a_software_rasteriser_is_opened_again_without_msaa_and_says_so_once(x_display, tmp_path):
    """--quality auto: the first window is asked for with 4x samples; its renderer turns out to be llvmpipe, so
    the window is opened again without them and the run goes on (said once; --quality full keeps them)."""
    env = {**os.environ, "DISPLAY": x_display}
    env.pop("WAYLAND_DISPLAY", None)
    char = sphere_character().save(tmp_path / "sphere.npz")

    def run(*extra):
        return subprocess.run(
            [sys.executable, "-m", "facepuppet", "run", "-c", str(char), "--input", "vmc", "--listen",
             f"127.0.0.1:{free_udp_port()}", "--duration", "0.3", "--size", "160x120", *extra],
            env=env, capture_output=True, text=True, timeout=300)

    auto = run()
    assert auto.returncode == 0, auto.stderr
    if "llvmpipe" not in auto.stderr and "software rasteriser" not in auto.stderr:
        pytest.skip("this display's OpenGL is not a software rasteriser")
    assert auto.stderr.count("picture quality auto:") == 1 and "MSAA off" in auto.stderr
    assert "ticks" in auto.stdout
    full = run("--quality", "full")
    assert full.returncode == 0, full.stderr
    assert "picture quality" not in full.stderr
