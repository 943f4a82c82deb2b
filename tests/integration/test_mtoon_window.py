"""MToon on the window path and on recorded time: ``replay`` of a take in a real glfw window (Xvfb) and
headless draws the same outlines and the same UV scroll, frame for frame."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from facepuppet.runtime.mapping.channels import ARKIT_NAMES, pascal

from conftest import need_shared
from facepuppet.offline.io.gltf.read import read_gltf
from helpers.mtoon_vrms import ball_vrm


def take(path, seconds: float, fps: int = 10) -> None:
    """A Live Link Face CSV take of a still face, ``seconds`` long."""
    lines = ["Timecode,BlendShapeCount," + ",".join(pascal(n) for n in ARKIT_NAMES)]
    for k in range(int(seconds * fps) + 1):
        frame = round(k / fps * 60)
        lines.append(f"00:00:{frame // 60:02d}:{frame % 60:02d}.000,52," + ",".join(["0"] * 52))
    path.write_text("\n".join(lines) + "\n")


def replay(character, csv, out, env, *extra) -> list[np.ndarray]:
    argv = ["replay", "-c", str(character), str(csv), "--out", str(out), "--size", "240x160", "--framing", "body",
            "--fps", "10", "--path", "cpu", "--msaa", "0", *extra]
    done = subprocess.run([sys.executable, "-m", "facepuppet", *argv], env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    return [np.asarray(Image.open(f).convert("RGB")) for f in sorted(out.glob("frame_*.png"))]


@pytest.mark.slow
@pytest.mark.data
def test_window_and_headless_replays_draw_the_same_outlines_and_uv_scroll(x_display, tmp_path):
    env = {**os.environ, "DISPLAY": x_display}
    env.pop("WAYLAND_DISPLAY", None)
    uv = tmp_path / "uv.npz"
    read_gltf(need_shared("gltf", "VRMC_materials_mtoon_UV_Animation_Test.vrm")).save(uv)
    ball = tmp_path / "ball.npz"
    read_gltf(ball_vrm(tmp_path / "ball.vrm", outline_width=0.03)).save(ball)
    csv = tmp_path / "still.csv"
    take(csv, 1.0)
    for character in (uv, ball):
        window = replay(character, csv, tmp_path / f"{character.stem}_window", env)
        headless = replay(character, csv, tmp_path / f"{character.stem}_headless", env, "--headless")
        assert len(window) == len(headless) == 11
        for a, b in zip(window, headless):
            assert np.abs(a.astype(int) - b.astype(int)).mean() < 0.5
    frames = replay(uv, csv, tmp_path / "uv_again", env, "--headless")
    first, half, last = frames[0].astype(int), frames[5].astype(int), frames[10].astype(int)
    assert np.abs(first - half).mean() > 3  # the textures move on recorded time
    ball_frame = replay(ball, csv, tmp_path / "ball_again", env, "--headless")[0]
    assert ((ball_frame[..., 0] > 200) & (ball_frame[..., 1] < 40)).sum() > 50  # the red outline, drawn
    # scroll (1 UV/s) is back after 1 s, the rotation (1 rad/s) is not: the picture differs only where it turns
    assert 0 < np.abs(first - last).mean() < np.abs(first - half).mean()
