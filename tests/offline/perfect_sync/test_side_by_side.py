"""The side-by-side picture of a Live Link Face take: the character through its VRM presets over its
perfect-sync version through the ARKit shapes, both replayed by replay's own chain (issue 14, item 4).

Fast: the perfect-sync character here is Godette with two ARKit-named brow shapes added (her artist's
``angled_eyebrows`` under ``browDownLeft``/``browDownRight``), not the clone (that takes the ICT fit; the
bench draws the picture of the real clone). Brows are what the default ARKit→VRM preset mapping cannot show.
"""

import numpy as np
import pytest
from PIL import Image

from facepuppet.runtime.mapping.channels import canonical
from facepuppet.runtime.recording.replay_source import open_recording
from facepuppet.runtime.render.images import LABEL_HEIGHT

from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.perfect_sync.pictures import replay_images, take_moments, take_side_by_side
from facepuppet.offline.perfect_sync.transfer import add_shapes
from tests.conftest import need_shared

pytestmark = [pytest.mark.gl, pytest.mark.data]
CELL = 240


def _rows(path):
    """(top cells, bottom cells) without their labels, (8, h, w, 3) int each."""
    p = np.asarray(Image.open(path).convert("RGB")).astype(int)[:2 * (CELL + LABEL_HEIGHT)]  # without the credits
    h = p.shape[0] // 2
    cells = [[row[:, c * CELL:(c + 1) * CELL] for c in range(p.shape[1] // CELL)]
             for row in (p[:h - LABEL_HEIGHT], p[h:2 * h - LABEL_HEIGHT])]
    return np.stack(cells[0]), np.stack(cells[1])


def _changed(a, b):
    return int((np.abs(a - b).max(axis=-1) > 24).sum())


def test_the_take_replayed_on_the_presets_and_on_arkit_brows_differs_where_the_brows_move(egl_ctx, tmp_path):
    take = need_shared("tracker", "livelinkface_myslate_3.csv")
    godette = read_gltf(need_shared("gltf", "Godette_vrm_v4.vrm"))
    brows = godette.dense_deltas()[godette.shape_names.index("angled_eyebrows")]
    synced, _ = add_shapes(godette, ("browDownLeft", "browDownRight"), np.stack([brows, brows]))

    path = take_side_by_side(godette, synced, take, tmp_path / "side.png", ctx=egl_ctx)
    assert path == tmp_path / "side.png" and path.exists()  # written where asked (and nothing elsewhere)
    picture = np.asarray(Image.open(path).convert("RGB"))
    grid = 2 * (CELL + LABEL_HEIGHT)  # two rows of 8 moments, then her credits (CC BY asks for them)
    assert picture.shape[1] == 8 * CELL and grid < picture.shape[0] < grid + 40
    footer = picture[grid:].astype(int)
    assert (np.abs(footer - footer[0, -1]).max(axis=-1) > 100).sum() > 50  # text drawn
    top, bottom = _rows(path)

    frames = open_recording(take)
    moments = take_moments(frames)
    assert len(moments) == 8 and moments == sorted(moments)
    column = {canonical(c): i for i, c in enumerate(frames[0].channels)}
    brow = np.array([frames[i].weights[column[canonical("browDownLeft")]] for i in moments])
    blink = np.array([frames[i].weights[column[canonical("eyeBlinkLeft")]] for i in moments])
    differs = np.array([_changed(t, b) for t, b in zip(top, bottom)])
    # the bottom row shows the brows the presets cannot: more where the take lowers them more
    assert differs[brow.argmax()] > 200
    assert differs[brow.argmax()] > 1.5 * differs[brow.argmin()], (brow, differs)
    # the top row is driven (the blink preset closes the eyes at the take's strongest blink)
    assert _changed(top[blink.argmax()], top[blink.argmin()]) > 100, blink

    # the same character in both rows: the same pictures (the difference above is the shapes', not the camera's)
    same_top, same_bottom = _rows(take_side_by_side(godette, godette, take, tmp_path / "same.png", ctx=egl_ctx))
    assert all(_changed(t, b) == 0 for t, b in zip(same_top, same_bottom))


def test_the_two_deformation_paths_draw_the_takes_moments_alike(egl_ctx):
    """The cpu path draws the deltas the gpu path's 16-bit texture holds (paths.deltas.on_delta_grid): with the file's
    float deltas one pixel of one moment differed by 225 levels (an edge moved across its centre)."""
    take = need_shared("tracker", "livelinkface_myslate_3.csv")
    godette = read_gltf(need_shared("gltf", "Godette_vrm_v4.vrm"))
    frames = open_recording(take)
    ticks = sorted({int(np.ceil(frames[i].t * 60 - 1e-9)) for i in take_moments(frames)})
    gpu, used = replay_images(godette, take, ticks, 60.0, egl_ctx, (480, 480), path="gpu")
    cpu, _ = replay_images(godette, take, ticks, 60.0, egl_ctx, (480, 480), path="cpu")
    assert used == "gpu" and len(gpu) == len(cpu) == 8
    for a, b in zip(gpu, cpu):
        assert (np.abs(a.astype(int) - b.astype(int)).max(axis=-1) > 2).sum() == 0
