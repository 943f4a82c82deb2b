"""Godette drawn with her spring bones: after a head turn stops, her hair keeps moving for a while, then rests.

Low-Poly Godette by SirRichard94, VRM adaptation by Lyuma, CC BY 3.0 (../shared/data/gltf/LICENSE-Godette.txt).
"""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from facepuppet.runtime.cli import main
from facepuppet.runtime.render.renderer import FaceRenderer

from conftest import need_shared
from facepuppet.offline.io.gltf.read import read_gltf

pytestmark = [pytest.mark.data, pytest.mark.gl]

FPS = 30
STOP_S = 0.8


def turn(t: float) -> np.ndarray:
    """The head turns 0.5 rad one way and back in STOP_S seconds, then stays straight."""
    yaw = 0.5 * np.sin(np.pi * min(t, STOP_S) / STOP_S)
    return np.array([0.0, np.sin(yaw / 2), 0.0, np.cos(yaw / 2)])


def frames_after_stop(egl_ctx, character, springs: bool, path: str) -> list[int]:
    """Pixels that change between consecutive frames, each frame after the head stopped (2 s of them)."""
    r = FaceRenderer(egl_ctx, character, 160, 160, path=path, framing="head", springs=springs, log=lambda _: None)
    try:
        w = np.zeros(character.n_shapes, np.float32)
        changes, last = [], None
        for k in range(int((STOP_S + 2.0) * FPS) + 1):
            t = k / FPS
            r.advance(t)
            r.draw(w, head_rotation=turn(t))
            img = r.read_pixels()
            if last is not None and t > STOP_S:
                changes.append(int((np.abs(img.astype(int) - last.astype(int)).max(axis=2) > 8).sum()))
            last = img
        return changes
    finally:
        r.close()


@pytest.mark.slow
@pytest.mark.parametrize("path", ["gpu", "cpu"])
def test_hair_keeps_moving_after_the_head_stops_then_rests(egl_ctx, path):
    c = read_gltf(need_shared("gltf", "Godette_vrm_v4.vrm"))
    moving = frames_after_stop(egl_ctx, c, True, path)
    rigid = frames_after_stop(egl_ctx, c, False, path)
    assert sum(rigid) == 0  # without springs nothing moves once the head is still
    assert sum(moving[:3]) > 20  # the hair swings on after the stop ...
    assert sum(1 for x in moving if x) >= 4  # ... for several frames ...
    assert moving[-10:] == [0] * 10  # ... and comes to rest


@pytest.mark.slow
def test_a_replay_swings_the_hair_the_same_every_time_and_no_springs_turns_it_off(tmp_path):
    take = need_shared("tracker", "livelinkface_myslate_3.csv")
    path = tmp_path / "godette.npz"
    read_gltf(need_shared("gltf", "Godette_vrm_v4.vrm")).save(path)
    runs = {}
    for name, extra in (("a", []), ("b", []), ("rigid", ["--no-springs"])):
        out = tmp_path / name
        assert main(["replay", str(take), "-c", str(path), "--headless", "--size", "96x96", "--duration", "1.5",
                     "--path", "cpu", "--out", str(out), *extra]) == 0
        runs[name] = [np.asarray(Image.open(p)) for p in sorted(out.glob("*.png"))]
    assert len(runs["a"]) == len(runs["b"]) == len(runs["rigid"]) > 30
    for x, y in zip(runs["a"], runs["b"]):
        np.testing.assert_array_equal(x, y)  # recorded time: the same motion every time
    differ = sum(bool((np.abs(x.astype(int) - y.astype(int)) > 8).any()) for x, y in zip(runs["a"], runs["rigid"]))
    assert differ > 5  # the head moves in the take: the hair swings where --no-springs keeps it rigid
