"""A bone look-at avatar's eyes follow the eye-look channels, in the picture (the avatar of tests/helpers/vrm_rigs.py:
a white face, black pupils 5 cm in front of each eye bone; every range map 90° → 90°)."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.model.look_at import GAZE_CHANNELS
from facepuppet.runtime.render.renderer import FaceRenderer

from facepuppet.offline.io.gltf.read import read_gltf
from helpers.vrm_rigs import look_at_vrm

pytestmark = pytest.mark.gl

SIZE = 200


def pupils(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centroids (x, y) in pixels of the dark pixels on the left and right halves of the picture."""
    dark = img[:, :, :3].max(axis=2) < 20  # the pupils are black; the background is (41, 43, 48)
    ys, xs = np.nonzero(dark)
    left = xs < SIZE // 2
    return (np.array([xs[left].mean(), ys[left].mean()]), np.array([xs[~left].mean(), ys[~left].mean()]))


@pytest.mark.parametrize("path", ["gpu", "cpu"])
def test_eyes_follow_the_eye_look_channels(egl_ctx, tmp_path, path):
    c = read_gltf(look_at_vrm(tmp_path / "eyes.vrm"))
    r = FaceRenderer(egl_ctx, c, SIZE, SIZE, path=path, framing="head", log=lambda _: None)
    try:
        def picture(**channels: float) -> tuple[np.ndarray, np.ndarray]:
            w = np.array([channels.get(n, 0.0) for n in GAZE_CHANNELS], np.float32)
            r.advance(0.0, Frame(0.0, "arkit", GAZE_CHANNELS, w))
            r.draw(np.zeros(c.n_shapes, np.float32))
            return pupils(r.read_pixels())

        rest = picture()
        # both eyes to the avatar's left (its left eye out, its right eye in): +x, the picture's right
        to_left = picture(eyeLookOutLeft=1.0, eyeLookInRight=1.0)
        up = picture(eyeLookUpLeft=1.0, eyeLookUpRight=1.0)
        cross = picture(eyeLookInLeft=1.0, eyeLookInRight=1.0)  # both in: cross-eyed
    finally:
        r.close()
    px_per_m = abs(rest[1][0] - rest[0][0]) / 0.10  # the pupils are 10 cm apart
    shift = 0.05 * np.sin(np.radians(30)) * px_per_m  # a 30° turn moves a pupil 5 cm ahead by 2.5 cm
    for eye in (0, 1):
        assert to_left[eye][0] - rest[eye][0] == pytest.approx(shift, rel=0.2)
        assert abs(to_left[eye][1] - rest[eye][1]) < 1.0
        assert rest[eye][1] - up[eye][1] == pytest.approx(shift, rel=0.2)  # rows grow downwards
    # the picture's left pupil is the avatar's right eye: in, it turns to the avatar's left (picture right)
    assert cross[0][0] - rest[0][0] == pytest.approx(shift, rel=0.2)
    assert rest[1][0] - cross[1][0] == pytest.approx(shift, rel=0.2)
