"""The real VRM avatar of the data kit, Low-Poly Godette, through every part of issue 13 at once.

Low-Poly Godette by SirRichard94, VRM adaptation by Lyuma, CC BY 3.0 (../shared/data/gltf/LICENSE-Godette.txt).

Imported with the glTF reader, drawn (textured, toon, skinned) by the renderer, driven over real UDP on
127.0.0.1 by VMC names and a Live Link Face take, exported and read back. Pixel regions come from the
avatar's own shapes: the eyes are what its blink morphs move, the mouth what its "ah" morph moves,
projected with the renderer's camera.
"""

from __future__ import annotations

import csv

import numpy as np
import pytest
from PIL import Image

from facepuppet.runtime.render.renderer import FaceRenderer

from conftest import need_shared
from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.io.gltf.write import export_character
from facepuppet.offline.io.gltf_check import check_gltf
from helpers.vmc_run import drive, last_weights

pytestmark = [pytest.mark.data, pytest.mark.gl]

SIZE = 256


@pytest.fixture(scope="module")
def godette():
    return read_gltf(need_shared("gltf", "Godette_vrm_v4.vrm"))


def region(renderer, character, shape: str, pad: int = 3) -> tuple[slice, slice]:
    """Pixel box (rows, columns) of the vertices ``shape`` moves by a fifth of its largest move or more,
    in ``renderer``'s picture at rest."""
    sl = character.shape_slice(character.shape_names.index(shape))
    length = np.linalg.norm(character.delta_positions[sl], axis=1)
    moved = character.delta_indices[sl][length > 0.2 * length.max()]  # what it visibly moves
    xy = renderer.project(character.vertices[moved])
    x0, y0 = np.floor(xy.min(axis=0)).astype(int) - pad
    x1, y1 = np.ceil(xy.max(axis=0)).astype(int) + pad
    return slice(max(y0, 0), y1), slice(max(x0, 0), x1)


def changed(a: np.ndarray, b: np.ndarray, box) -> int:
    """Pixels of ``box`` that differ by more than 24 in some channel."""
    rows, cols = box
    return int((np.abs(a[rows, cols].astype(int) - b[rows, cols].astype(int)).max(axis=2) > 24).sum())


def expression_weights(character, **values: float) -> np.ndarray:
    """Shape weights of some expressions at the given values, from the file's own binds (clipped like VRM)."""
    e = character.expressions
    dense = e.dense(character.n_shapes)
    w = np.zeros(character.n_shapes, np.float32)
    for name, v in values.items():
        w += v * dense[e.names.index(name)]
    return np.clip(w, 0.0, 1.0)


@pytest.mark.parametrize("path", ["cpu", "gpu"])
def test_blink_closes_the_eyes_and_leaves_the_mouth_and_aa_opens_the_mouth(egl_ctx, godette, path):
    r = FaceRenderer(egl_ctx, godette, SIZE, SIZE, path=path, log=lambda s: None)
    try:
        eyes = [region(r, godette, "blink_left"), region(r, godette, "blink_right")]
        mouth = region(r, godette, "ah")
        r.draw(np.zeros(godette.n_shapes, np.float32))
        neutral = r.read_pixels()
        r.draw(expression_weights(godette, Blink=1.0))
        blink = r.read_pixels()
        r.draw(expression_weights(godette, A=1.0))
        aa = r.read_pixels()
    finally:
        r.close()
    # the picture is Godette (textured, not a flat or empty frame): many distinct colours on the face
    assert len(np.unique(neutral.reshape(-1, 3), axis=0)) > 200
    for eye in eyes:
        assert changed(neutral, blink, eye) > 20, "an eye did not change with the Blink expression"
        assert changed(neutral, aa, eye) == 0
    assert changed(neutral, blink, mouth) == 0, "Blink moved the mouth"
    assert changed(neutral, aa, mouth) > 5, "A did not open the mouth"


def test_the_transparent_background_is_alpha_0_in_the_corners(egl_ctx, godette):
    r = FaceRenderer(egl_ctx, godette, SIZE, SIZE, path="cpu", log=lambda s: None, transparent=True)
    try:
        r.draw(np.zeros(godette.n_shapes, np.float32))
        rgba = r.read_pixels()
    finally:
        r.close()
    assert rgba.shape == (SIZE, SIZE, 4)
    for corner in (rgba[:4, :4], rgba[:4, -4:], rgba[-4:, :4], rgba[-4:, -4:]):
        assert (corner[..., 3] == 0).all()
    assert rgba[SIZE // 2, SIZE // 2, 3] == 255  # the face in the middle of the head framing


def unity_yaw(degrees: float) -> tuple:
    """A VMC Head bone pose turned about Unity's up axis: (x, y, z, qx, qy, qz, qw)."""
    half = np.radians(degrees) / 2
    return (0.0, 1.4, 0.0, 0.0, float(np.sin(half)), 0.0, float(np.cos(half)))


def test_a_vmc_head_bone_turns_the_head_and_not_the_feet(godette, tmp_path):
    frames = {}
    for name, bones in (("rest", None), ("turned", {"Head": unity_yaw(30.0)})):
        out = tmp_path / name
        drive(godette, {"Blink": 0.0}, tmp_path, bones=bones, size="160x256",
              extra=("--framing", "body", "--out", str(out)))
        frames[name] = np.asarray(Image.open(sorted(out.glob("*.png"))[-1]).convert("RGB"))
    rest, turned = frames["rest"], frames["turned"]
    h = rest.shape[0]
    head, feet = (slice(0, h // 3), slice(None)), (slice(h - h // 6, h), slice(None))
    assert changed(rest, turned, head) > 200, "the head did not turn"
    assert changed(rest, turned, feet) == 0, "the feet moved with the head"


def test_vmc_names_drive_godette_by_preset_and_by_perfect_sync_arkit_names(godette, tmp_path):
    at = {n: i for i, n in enumerate(godette.shape_names)}
    # VRM preset names (both VRM spellings): Blink binds blink_left and blink_right at 1, A binds ah at 1
    result, log = drive(godette, {"Blink": 1.0, "aa": 0.5}, tmp_path)
    got = last_weights(godette, result)
    assert got["blink_left"] == pytest.approx(1.0) and got["blink_right"] == pytest.approx(1.0)
    assert got["ah"] == pytest.approx(0.5) and got["oh"] == 0.0
    # ARKit PascalCase (what a perfect-sync tracker sends); Godette has no ARKit morphs, so the default
    # ARKit -> VRM table applies: Blink = min(0.9, 0.4) = 0.4 -> both lids 0.4; Blink_L = 0.5 is binary on
    # this avatar (isBinary, > 0.5 only) -> 0; A = jawOpen 0.6 -> ah 0.6
    result, log = drive(godette, {"EyeBlinkLeft": 0.9, "EyeBlinkRight": 0.4, "JawOpen": 0.6}, tmp_path)
    got = last_weights(godette, result)
    assert got["blink_left"] == pytest.approx(0.4) and got["blink_right"] == pytest.approx(0.4)
    assert got["ah"] == pytest.approx(0.6)
    assert "default preset mapping" in log
    assert len(at) == 15


def test_a_live_link_face_take_on_godette_blinks_and_talks(egl_ctx, godette, tmp_path):
    from facepuppet.runtime.cli import main

    take = need_shared("tracker", "livelinkface_myslate_3.csv")
    with open(take, newline="") as f:
        rows = list(csv.DictReader(f))
    assert max(float(r["EyeBlinkLeft"]) for r in rows) > 0.5  # the take does blink
    path = tmp_path / "godette.npz"
    godette.save(path)
    out = tmp_path / "w.npy"
    assert main(["replay", str(take), "-c", str(path), "--headless", "--size", "64x64",
                 "--dump-weights", str(out)]) == 0
    w = np.load(out)
    at = {n: i for i, n in enumerate(godette.shape_names)}
    assert w[:, at["blink_left"]].max() > 0.5 and w[:, at["blink_right"]].max() > 0.5, "no blink drawn"
    mouth = [at[n] for n in ("ah", "ih", "uu", "ee", "oh")]
    assert w[:, mouth].max() > 0.2, "no mouth shape drawn"
    assert (w[:, mouth].max(axis=0) > 0.05).sum() >= 3, "the mouth took fewer than three vowel shapes"
    # the tick with the most closed eyes, drawn: its eyes differ from the neutral picture's
    k = int(np.argmax(w[:, at["blink_left"]] + w[:, at["blink_right"]]))
    r = FaceRenderer(egl_ctx, godette, SIZE, SIZE, path="cpu", log=lambda s: None)
    try:
        eye = region(r, godette, "blink_left")
        r.draw(np.zeros(godette.n_shapes, np.float32))
        neutral = r.read_pixels()
        r.draw(w[k])
        closed = r.read_pixels()
    finally:
        r.close()
    assert changed(neutral, closed, eye) > 20


def test_godette_exported_as_vrm_reads_back_the_same_and_faces_minus_z_in_the_file(godette, tmp_path):
    out = tmp_path / "godette_out.vrm"
    export_character(godette, out)
    assert check_gltf(out) == []
    back = read_gltf(out)
    assert back.source["format"] == "vrm0" and back.source["turned_y180"]
    np.testing.assert_allclose(back.vertices, godette.vertices, atol=1e-6)
    np.testing.assert_allclose(back.dense_deltas(), godette.dense_deltas(), atol=1e-6)
    assert back.expressions.names == godette.expressions.names
    for e in range(godette.n_expressions):
        s, wt = godette.expressions.binds(e)
        bs, bw = back.expressions.binds(e)
        assert dict(zip(bs.tolist(), bw.tolist())) == pytest.approx(dict(zip(s.tolist(), wt.tolist())))
    assert back.credits == godette.credits and "SirRichard94" in back.credits


def test_godettes_own_normals_are_kept_drawn_and_exported(egl_ctx, godette, tmp_path):
    from facepuppet.runtime.model.geometry import vertex_normals

    # the file's normals (hard edges of a low-poly avatar), not area-weighted ones from the triangles
    assert godette.normals is not None
    computed = vertex_normals(godette.vertices, godette.triangles)
    angle = np.degrees(np.arccos(np.clip(np.sum(godette.normals * computed, axis=1), -1, 1)))
    assert np.median(angle) > 5.0
    # kept through export (VRM 0.x turned back and forth) and import
    out = tmp_path / "g.vrm"
    export_character(godette, out)
    np.testing.assert_allclose(read_gltf(out).normals, godette.normals, atol=1e-5)
    # and drawn: the same avatar with computed normals shades differently
    pictures = []
    for c in (godette, godette.with_parts(normals=None)):
        r = FaceRenderer(egl_ctx, c, 128, 128, path="cpu", log=lambda s: None)
        try:
            r.draw(np.zeros(c.n_shapes, np.float32))
            pictures.append(r.read_pixels().astype(int))
        finally:
            r.close()
    assert (np.abs(pictures[0] - pictures[1]).max(axis=2) > 24).sum() > 20  # toon shading: few steps move
