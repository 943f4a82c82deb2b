"""FaceRenderer on characters with glTF / VRM parts, real EGL: textures, alpha, sides, skinning, framing,
transparency, MSAA. The characters are built in code (tests/helpers/part_characters.py)."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.model.character_parts import CLAMP_TO_EDGE, MIRRORED_REPEAT, NEAREST, REPEAT
from facepuppet.runtime.render.parts_path import HeadPose, draw_groups, uv_matrix
from facepuppet.runtime.render.renderer import FaceRenderer

from helpers.part_characters import figure, material, part_character, quad

pytestmark = pytest.mark.gl
W, H = 96, 96


def srgb_to_linear(c):
    c = np.asarray(c, float) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def draw(ctx, character, weights=None, rotation=None, size=(W, H), **kw):
    kw.setdefault("path", "cpu")
    kw.setdefault("log", lambda s: None)
    r = FaceRenderer(ctx, character, *size, **kw)
    try:
        r.draw(np.zeros(character.n_shapes, np.float32) if weights is None else np.asarray(weights, np.float32),
               head_rotation=rotation)
        r.finish()
        image = r.read_pixels()
        assert ctx.error == "GL_NO_ERROR"
        return image, r
    finally:
        r.close()


def textured_quad(texel, **mat):
    v, t, uv = quad()
    tex = np.tile(np.asarray(texel, np.uint8), (4, 4, 1))
    return part_character(v, t, [0, 0], [material(texture=0, **mat)], uv=uv, textures=[tex],
                          samplers=[(NEAREST, NEAREST, REPEAT, REPEAT)])


@pytest.mark.parametrize("path", ["gpu", "cpu"])
def test_an_unlit_mid_grey_texel_shows_as_that_grey(egl_ctx, path):
    image, _ = draw(egl_ctx, textured_quad([128, 128, 128, 255]), path=path, framing="body")
    # sRGB decode, linear, sRGB encode: the texel's own value (a gamma-2.2 or no-decode path would not give it)
    np.testing.assert_allclose(image[H // 2, W // 2].astype(int), [128, 128, 128], atol=1)


def test_a_texture_shows_its_colours_where_the_uv_puts_them(egl_ctx):
    v, t, uv = quad()
    tex = np.zeros((2, 2, 4), np.uint8)
    tex[..., 3] = 255
    tex[0, 0, :3] = (255, 0, 0)    # top left
    tex[0, 1, :3] = (0, 255, 0)    # top right
    tex[1, 0, :3] = (0, 0, 255)    # bottom left
    tex[1, 1, :3] = (255, 255, 0)  # bottom right
    c = part_character(v, t, [0, 0], [material(texture=0)], uv=uv, textures=[tex],
                       samplers=[(NEAREST, NEAREST, CLAMP_TO_EDGE, CLAMP_TO_EDGE)])
    image, r = draw(egl_ctx, c, framing="body")
    (tlx, tly), (brx, bry) = r.project([[-0.25, 0.25, 0], [0.25, -0.25, 0]]).astype(int)
    assert tuple(image[tly, tlx]) == (255, 0, 0) and tuple(image[tly, brx]) == (0, 255, 0)
    assert tuple(image[bry, tlx]) == (0, 0, 255) and tuple(image[bry, brx]) == (255, 255, 0)


def test_base_colour_factor_and_vertex_colour_multiply_the_texel(egl_ctx):
    c = textured_quad([255, 255, 255, 255], base=(0.5, 1.0, 1.0, 1.0))
    image, _ = draw(egl_ctx, c, framing="body")
    expected = np.round(255 * np.array([1.055 * 0.5 ** (1 / 2.4) - 0.055, 1, 1]))
    np.testing.assert_allclose(image[H // 2, W // 2].astype(int), expected, atol=1)


def test_texture_transform_and_mirrored_repeat(egl_ctx):
    # a 2x1 texture: left red, right green; scale u by 2 and mirror: u in [0, 2) reads red green | green red
    v, t, uv = quad()
    tex = np.array([[[255, 0, 0, 255], [0, 255, 0, 255]]], np.uint8)
    c = part_character(v, t, [0, 0], [material(texture=0, uv_transform=(0, 0, 0, 2, 1))], uv=uv, textures=[tex],
                       samplers=[(NEAREST, NEAREST, MIRRORED_REPEAT, CLAMP_TO_EDGE)])
    image, r = draw(egl_ctx, c, framing="body")
    xs = r.project([[x, 0, 0] for x in (-0.4, -0.15, 0.15, 0.4)]).astype(int)
    assert [tuple(image[y, x][:2]) for x, y in xs] == [(255, 0), (0, 255), (0, 255), (255, 0)]
    np.testing.assert_allclose(uv_matrix(0.5, 0.25, 0.0, 2.0, 3.0) @ [1, 1, 1], [2.5, 3.25])


def test_emissive_is_added(egl_ctx):
    dark, _ = draw(egl_ctx, textured_quad([0, 0, 0, 255]), framing="body")
    glow, _ = draw(egl_ctx, textured_quad([0, 0, 0, 255], emissive=(0.0, 0.5, 0.0)), framing="body")
    assert tuple(dark[H // 2, W // 2]) == (0, 0, 0)
    assert glow[H // 2, W // 2, 1] > 180 and glow[H // 2, W // 2, 0] == 0


def two_layers(front_alpha: float, mode: str):
    """A green back quad at z = 0 and a red front quad at z = 0.1 of alpha ``front_alpha``, material ``mode``."""
    bv, bt, buv = quad(0.0, 1.0)
    fv, ft, fuv = quad(0.1, 0.6)
    v = np.vstack([bv, fv])
    t = np.vstack([bt, ft + 4])
    # the blended front layer comes first in the file: drawn in file order it would hide the back one
    mats = [material(base=(1, 0, 0, front_alpha), alpha=mode, cutoff=0.5), material(base=(0, 1, 0, 1))]
    return part_character(v, np.vstack([t[2:], t[:2]]), [0, 0, 1, 1], mats, uv=np.vstack([buv, fuv]))


def test_mask_discards_below_the_cutoff_and_keeps_above(egl_ctx):
    below, _ = draw(egl_ctx, two_layers(0.4, "MASK"), framing="body")
    above, _ = draw(egl_ctx, two_layers(0.6, "MASK"), framing="body")
    assert tuple(below[H // 2, W // 2]) == (0, 255, 0)     # discarded: the green back shows
    assert tuple(above[H // 2, W // 2]) == (255, 0, 0)     # kept, drawn opaque (alpha ignored)


@pytest.mark.parametrize("path", ["gpu", "cpu"])
def test_blend_is_drawn_after_opaque_and_mixes_both_colours(egl_ctx, path):
    image, _ = draw(egl_ctx, two_layers(0.5, "BLEND"), path=path, framing="body")
    r, g, b = (int(x) for x in image[H // 2, W // 2])
    # alpha over the encoded colours (an 8-bit framebuffer, as glTF viewers draw): half red over green
    assert abs(r - 128) <= 1 and abs(g - 128) <= 1 and b == 0


def test_blended_groups_are_sorted_far_to_near():
    # two blended quads, the near one first in the file
    nv, nt, _ = quad(0.2, 0.6)
    fv, ft, _ = quad(0.0, 1.0)
    c = part_character(np.vstack([nv, fv]), np.vstack([nt, ft + 4]), [0, 0, 1, 1],
                       [material(alpha="BLEND"), material(alpha="BLEND")])
    _, groups = draw_groups(c, np.array([0.0, 0.0, -1.0]))
    assert [g.blend for g in groups] == [True, True]
    # inside draw_groups the order is material order; the renderer sorts them per frame by distance
    eye = np.array([0.0, 0.0, 3.0])
    order = sorted(groups, key=lambda g: -float(np.dot(g.centre - eye, g.centre - eye)))
    assert [g.material for g in order] == [1, 0]


def card(double_sided: bool):
    v, t, uv = quad(reverse=True)  # faces -z: the camera on +z sees its back
    return part_character(v, t, [0, 0], [material(base=(1, 0, 0, 1), double_sided=double_sided)], uv=uv)


@pytest.mark.parametrize("path", ["gpu", "cpu"])
def test_a_double_sided_card_is_seen_from_behind_a_single_sided_one_is_not(egl_ctx, path):
    seen, _ = draw(egl_ctx, card(True), path=path, framing="body")
    culled, _ = draw(egl_ctx, card(False), path=path, framing="body")
    assert tuple(seen[H // 2, W // 2]) == (255, 0, 0)
    assert tuple(culled[H // 2, W // 2]) == tuple(culled[0, 0])   # background


@pytest.mark.parametrize("shift, expected", [(0.0, 1.0), (-0.70181, 0.5), (-1.0, 0.0)])
def test_toon_shading_steps_from_shade_to_lit_colour_at_the_shading_shift(egl_ctx, shift, expected):
    # a quad facing +z: N.L of the key light is 0.7018; toony 0.9 steps over N.L + shift in [-0.1, 0.1]
    v, t, uv = quad()
    lit, shade = np.array([0.8, 0.4, 0.2]), np.array([0.1, 0.2, 0.4])
    c = part_character(v, t, [0, 0], [material(base=(*lit, 1), shading="toon", shade=shade, shift=shift,
                                               toony=0.9)], uv=uv)
    image, _ = draw(egl_ctx, c, framing="body")
    linear = expected * lit + (1 - expected) * shade
    encoded = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
    np.testing.assert_allclose(image[H // 2, W // 2].astype(int), np.round(255 * encoded), atol=2)


def pixels_of(image, background):
    return np.abs(image.astype(int) - np.asarray(background, int)).sum(axis=2) > 12


@pytest.mark.parametrize("path", ["gpu", "cpu"])
def test_a_head_bone_turn_moves_the_head_and_not_the_feet(egl_ctx, path):
    c = figure()
    turn = np.array([0, np.sin(np.radians(15)), 0, np.cos(np.radians(15))])  # 30 degrees about +y
    rest, r = draw(egl_ctx, c, path=path, framing="body", size=(80, 160))
    turned, _ = draw(egl_ctx, c, rotation=turn, path=path, framing="body", size=(80, 160))
    diff = np.abs(rest.astype(int) - turned.astype(int)).sum(axis=2) > 24
    (_, y_head), (_, y_neck), (_, y_feet) = r.project([[0, 1.6, 0], [0, 1.45, 0], [0, 0.3, 0]]).astype(int)
    assert diff[: y_neck].sum() > 40             # the head moved
    assert diff[y_feet - 20:].sum() == 0         # the body (legs and feet) did not
    assert pixels_of(turned, turned[0, 0])[y_feet].any()   # and is still drawn there


def test_gpu_and_cpu_paths_agree_on_a_skinned_morphed_figure(egl_ctx):
    c = figure()
    turn = np.array([0.1, 0.3, 0.05, 1.0])
    turn = turn / np.linalg.norm(turn)
    gpu, _ = draw(egl_ctx, c, [0.7], turn, path="gpu", framing="head", size=(120, 120))
    cpu, _ = draw(egl_ctx, c, [0.7], turn, path="cpu", framing="head", size=(120, 120))
    diff = np.abs(gpu.astype(int) - cpu.astype(int)).max(axis=2)
    assert diff.max() <= 40 and (diff > 8).sum() <= 20   # edge pixels may round differently


def test_morph_targets_move_on_the_parts_path(egl_ctx):
    c = figure()
    closed, _ = draw(egl_ctx, c, [0.0], path="gpu", framing="head")
    opened, _ = draw(egl_ctx, c, [1.0], path="gpu", framing="head")
    assert (np.abs(closed.astype(int) - opened.astype(int)).sum(axis=2) > 24).sum() > 30


def test_head_pose_matches_the_skeletons_pose_matrices_and_splits_into_neck_and_head():
    c = figure()
    hp = HeadPose(c)
    q = np.array([0.2, -0.3, 0.1, 0.9])
    q = q / np.linalg.norm(q)
    np.testing.assert_allclose(hp.matrices(q), c.skeleton.pose_matrices(hp.rotations(q)), atol=1e-5)
    d = hp.matrices(q)
    np.testing.assert_allclose(d[:2], np.tile(np.eye(4), (2, 1, 1)), atol=1e-6)   # hips, spine stay
    # the head ends turned by the whole rotation, the neck by 30 % of it
    from facepuppet.runtime.model.geometry import quat_to_matrix

    np.testing.assert_allclose(d[3, :3, :3], quat_to_matrix(q), atol=1e-5)
    angle = lambda m: np.degrees(np.arccos((np.trace(m[:3, :3]) - 1) / 2))  # noqa: E731
    assert abs(angle(d[2]) - 0.3 * angle(d[3])) < 1e-3


def test_transparent_background_gives_alpha_0_in_the_corners_and_255_on_the_character(egl_ctx):
    image, r = draw(egl_ctx, figure(), framing="body", transparent=True, size=(64, 128))
    assert image.shape == (128, 64, 4)
    assert image[0, 0, 3] == image[-1, -1, 3] == image[0, -1, 3] == 0
    x, y = r.project([[0, 1.0, 0.1]]).astype(int)[0]
    assert image[y, x, 3] == 255 and image[y, x, 2] > 150  # the blue body, opaque


def test_transparent_background_keeps_a_blended_layers_alpha_and_straight_colour(egl_ctx):
    v, t, uv = quad()
    c = part_character(v, t, [0, 0], [material(base=(1, 0, 0, 0.5), alpha="BLEND")], uv=uv)
    image, _ = draw(egl_ctx, c, framing="body", transparent=True)
    r, g, b, a = (int(x) for x in image[H // 2, W // 2])
    assert abs(a - 128) <= 1 and r >= 253 and g == b == 0   # straight alpha: full red at half coverage


def edge_values(image):
    grey = image[..., :3].astype(int).sum(axis=2)
    return set(np.unique(grey).tolist())


def test_msaa_gives_intermediate_values_along_an_edge_that_no_msaa_does_not(egl_ctx):
    # a white unlit quad turned 20 degrees in the image plane: slanted edges over a black background
    from facepuppet.runtime.model.geometry import quat_to_matrix

    v, t, uv = quad()
    turn = quat_to_matrix([0, 0, np.sin(np.radians(10)), np.cos(np.radians(10))])
    v = (v @ turn.T).astype(np.float32)
    c = part_character(v, t, [0, 0], [material()], uv=uv)
    plain, _ = draw(egl_ctx, c, framing="body", background=(0, 0, 0), msaa=0)
    smooth, _ = draw(egl_ctx, c, framing="body", background=(0, 0, 0), msaa=4)
    assert edge_values(plain) <= {0, 765}
    assert len(edge_values(smooth) - {0, 765}) >= 3


def test_framing_body_and_head_frame_different_boxes(egl_ctx):
    c = figure()
    _, body = draw(egl_ctx, c, framing="body")
    _, head = draw(egl_ctx, c, framing="head")
    feet = [0, 0.0, 0]
    top = [0, 1.78, 0]
    by = body.project([feet, top])[:, 1]
    hy = head.project([[0, 1.5, 0], top])[:, 1]
    assert 0 < by[1] < by[0] < H            # the body framing shows feet to crown
    assert 0 <= hy[1] < hy[0] <= H and head.project([feet])[0, 1] > 2 * H   # the head framing: feet far below
    assert (hy[0] - hy[1]) > 2.5 * (by[0] - by[1]) * (0.28 / 1.78)


def test_a_character_without_a_head_bone_turns_whole_about_its_pivot(egl_ctx):
    v, t, uv = quad()
    c = part_character(v, t, [0, 0], [material(base=(1, 0, 0, 1))], uv=uv)
    turn = np.array([0, 0, np.sin(np.radians(20)), np.cos(np.radians(20))])
    rest, _ = draw(egl_ctx, c, framing="body")
    turned, _ = draw(egl_ctx, c, rotation=turn, framing="body")
    assert (np.abs(rest.astype(int) - turned.astype(int)).sum(axis=2) > 24).sum() > 100


@pytest.mark.parametrize("path", ["gpu", "cpu"])
def test_a_skeleton_without_a_look_draws_its_vertex_colours_and_turns_its_head(egl_ctx, path):
    from dataclasses import replace

    c = replace(figure(morph=False), look=None)
    turn = np.array([0, np.sin(np.radians(15)), 0, np.cos(np.radians(15))])
    rest, r = draw(egl_ctx, c, path=path, framing="body", size=(80, 160))
    turned, _ = draw(egl_ctx, c, rotation=turn, path=path, framing="body", size=(80, 160))
    x, y = r.project([[0, 0.7, 0.1]]).astype(int)[0]
    assert rest[y, x, 2] > rest[y, x, 0] + 60             # the blue body, lit
    diff = np.abs(rest.astype(int) - turned.astype(int)).sum(axis=2) > 24
    _, y_neck = r.project([[0, 1.45, 0]]).astype(int)[0]
    assert diff[:y_neck].sum() > 40 and diff[y_neck + 10:].sum() == 0


@pytest.mark.parametrize("path", ["gpu", "cpu"])
def test_each_material_draws_with_its_own_variant_in_one_frame(egl_ctx, path):
    # Four quads side by side, one frame: OPAQUE and MASK with the same alpha 0.3 (cutoff 0.5), an unlit
    # BLEND one at alpha 0.5 over the background, and a lit one. Each group must run its own fragment
    # variant: the opaque one ignores alpha, the mask one discards, the blend one mixes, the lit one is shaded.
    pieces = [quad(0.0, 0.4) for _ in range(4)]
    xs = (-0.75, -0.25, 0.25, 0.75)
    v = np.vstack([p[0] + np.float32([x, 0, 0]) for p, x in zip(pieces, xs)])
    t = np.vstack([p[1] + 4 * i for i, p in enumerate(pieces)])
    mats = [material(base=(1, 0, 0, 0.3)), material(base=(1, 0, 0, 0.3), alpha="MASK"),
            material(base=(1, 0, 0, 0.5), alpha="BLEND"), material(base=(0.3, 0.3, 0.3, 1), shading="lit")]
    c = part_character(v, t, [0, 0, 1, 1, 2, 2, 3, 3], mats, uv=np.vstack([p[2] for p in pieces]))
    image, r = draw(egl_ctx, c, path=path, framing="body", size=(192, 64), background=(0.0, 0.0, 1.0))
    assert len(r._deformation.programs) == 4  # four distinct (alpha, shading, textured, mirrored) variants
    px = [tuple(int(c) for c in image[y, x]) for x, y in r.project([[x, 0, 0] for x in xs]).astype(int)]
    assert px[0] == (255, 0, 0)                      # OPAQUE: alpha ignored
    assert px[1] == (0, 0, 255)                      # MASK below the cutoff: the background shows
    assert abs(px[2][0] - 128) <= 1 and px[2][1] == 0 and abs(px[2][2] - 128) <= 1  # BLEND: half over blue
    unlit_grey = round(255 * (1.055 * 0.3 ** (1 / 2.4) - 0.055))  # 149: what an unlit variant would draw
    assert abs(px[3][0] - unlit_grey) > 10  # lit: the lights change the grey


def test_every_grey_level_of_an_unlit_texture_comes_out_as_itself(egl_ctx):
    # 256 sRGB grey levels on a 16 x 16 texture (nearest): decoded by the sampler, encoded by the shader
    levels = np.arange(256, dtype=np.uint8).reshape(16, 16)
    tex = np.dstack([levels, levels, levels, np.full_like(levels, 255)])
    v, t, uv = quad()
    c = part_character(v, t, [0, 0], [material(texture=0)], uv=uv, textures=[tex],
                       samplers=[(NEAREST, NEAREST, CLAMP_TO_EDGE, CLAMP_TO_EDGE)])
    image, r = draw(egl_ctx, c, framing="body", size=(320, 320))
    centres = [[-0.5 + (j + 0.5) / 16, 0.5 - (i + 0.5) / 16, 0] for i in range(16) for j in range(16)]
    got = np.array([image[y, x, 0] for x, y in r.project(centres).round().astype(int)], int)
    off = np.abs(got - np.arange(256))
    assert off.max() <= 1 and np.count_nonzero(off) <= 3, np.flatnonzero(off)
