"""FaceRenderer on a real EGL context: deformation, pose, materials, both paths."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.model.geometry import euler_to_quat
from facepuppet.runtime.render.gl_context import GLUnavailable, create_context
from facepuppet.runtime.render.renderer import FaceRenderer, realistic_weights

from helpers.small_characters import sphere_character

W, H = 160, 120


def render(ctx, character, weights, path="cpu", size=(W, H), **pose):
    r = FaceRenderer(ctx, character, *size, path=path)
    try:
        r.draw(np.asarray(weights, np.float32), **pose)
        r.finish()
        image = r.read_pixels()
        assert ctx.error == "GL_NO_ERROR"
        return image, r.project
    finally:
        r.close()


def changed(a, b, threshold=24):
    return np.abs(a.astype(int) - b.astype(int)).sum(axis=2) > threshold


@pytest.fixture(scope="module")
def sphere():
    return sphere_character()


def test_frame_is_rgb_top_row_first_with_background_in_corners(egl_ctx, sphere):
    image, _ = render(egl_ctx, sphere, [0, 0])
    assert image.shape == (H, W, 3) and image.dtype == np.uint8
    np.testing.assert_allclose(image[0, 0], np.round(np.array([0.16, 0.17, 0.19]) * 255), atol=1)
    # the sphere is framed: centre pixel is lit skin, not background
    assert changed(image[H // 2 : H // 2 + 1, W // 2 : W // 2 + 1], image[:1, :1]).all()


@pytest.mark.parametrize("path", ["gpu", "cpu"])
def test_jaw_open_changes_the_lower_face_only(egl_ctx, sphere, path):
    closed, project = render(egl_ctx, sphere, [0, 0], path)
    opened, _ = render(egl_ctx, sphere, [1, 0], path)
    diff = changed(closed, opened)
    equator = int(project([[0, -0.1, 1]])[0, 1])  # the shape moves vertices below y = -0.1
    assert diff[equator + 2 :].sum() > 200
    assert diff[: equator - 8].sum() == 0


@pytest.mark.parametrize("path", ["gpu", "cpu"])
def test_ict_jaw_open_changes_the_mouth_not_the_forehead(egl_ctx, ict_character, path):
    c = ict_character
    w = np.zeros(c.n_shapes, np.float32)
    closed, project = render(egl_ctx, c, w, path, size=(320, 320))
    w[c.shape_names.index("jawOpen")] = 1.0
    opened, _ = render(egl_ctx, c, w, path, size=(320, 320))
    diff = changed(closed, opened)
    sl = c.shape_slice(c.shape_names.index("jawOpen"))
    big = c.delta_indices[sl][np.linalg.norm(c.delta_positions[sl], axis=1) > 1.0]
    xy = project(c.vertices[big])
    x0, y0 = np.floor(xy.min(axis=0)).astype(int)
    x1, y1 = np.ceil(xy.max(axis=0)).astype(int)
    assert diff[y0 : y1 + 1, x0 : x1 + 1].sum() > 300
    # forehead: front skin above the eyes
    forehead = c.vertices[(c.vertices[:, 1] > 8) & (c.vertices[:, 2] > 8)]
    fxy = project(forehead)
    fx0, fy0 = np.floor(fxy.min(axis=0)).astype(int)
    fx1, fy1 = np.ceil(fxy.max(axis=0)).astype(int)
    assert fy1 < y0  # the regions are apart
    assert diff[fy0 : fy1 + 1, fx0 : fx1 + 1].sum() == 0


def test_gpu_and_cpu_paths_give_the_same_picture(egl_ctx, sphere):
    for weights in ([0.0, 0.0], [0.6, 0.4], [1.0, 1.0]):
        gpu, _ = render(egl_ctx, sphere, weights, "gpu")
        cpu, _ = render(egl_ctx, sphere, weights, "cpu")
        assert np.abs(gpu.astype(int) - cpu.astype(int)).mean() < 0.05
        assert changed(gpu, cpu, threshold=30).sum() <= 3


def test_gpu_and_cpu_paths_agree_on_ict(egl_ctx, ict_character):
    w = realistic_weights(ict_character.n_shapes)
    gpu, _ = render(egl_ctx, ict_character, w, "gpu", size=(256, 256))
    cpu, _ = render(egl_ctx, ict_character, w, "cpu", size=(256, 256))
    assert np.abs(gpu.astype(int) - cpu.astype(int)).mean() < 0.1


def test_head_rotation_and_translation_move_the_image(egl_ctx, sphere):
    still, project = render(egl_ctx, sphere, [0, 0])
    turned, _ = render(egl_ctx, sphere, [0, 0], head_rotation=euler_to_quat(0.6, 0.0, 0.0))
    moved, _ = render(egl_ctx, sphere, [0, 0], head_translation=(0.3, 0.0, 0.0))
    assert changed(still, turned).sum() > 100  # the eyes swing round
    # translation +x (character's left) moves the silhouette right in the picture
    def cols(img):
        return np.flatnonzero(changed(img, np.broadcast_to(img[:1, :1], img.shape)).any(axis=0))
    assert cols(moved)[0] > cols(still)[0] and cols(moved)[-1] > cols(still)[-1]


def test_hidden_material_is_not_drawn(egl_ctx):
    with_hidden, _ = render(egl_ctx, sphere_character(with_hidden=True), [0, 0])
    without, _ = render(egl_ctx, sphere_character(with_hidden=False), [0, 0])
    # the hidden quad sits in front of the face; drawn, it would cover it.
    np.testing.assert_array_equal(with_hidden, without)


def test_eye_material_is_shaded_differently_from_skin(egl_ctx, sphere):
    image, project = render(egl_ctx, sphere, [0, 0], size=(320, 240))
    eye = sphere.vertices[np.unique(sphere.triangles[sphere.triangle_material == 1])]
    ex, ey = project(eye.mean(axis=0, keepdims=True))[0].astype(int)
    sx, sy = project([[0.0, -0.3, 0.95]])[0].astype(int)
    assert abs(int(image[ey, ex].sum()) - int(image[sy, sx].sum())) > 20


def test_auto_path_measures_both_and_reports_once(egl_ctx, sphere):
    lines = []
    r = FaceRenderer(egl_ctx, sphere, W, H, path="auto", log=lines.append)
    try:
        assert r.path in ("gpu", "cpu")
        assert len(lines) == 1 and lines[0] == r.path_report
        assert lines[0].startswith(f"deformation path: {r.path} (") and "gpu" in lines[0] and "cpu" in lines[0]
    finally:
        r.close()
    assert egl_ctx.error == "GL_NO_ERROR"


def test_bad_arguments_are_refused(egl_ctx, sphere):
    with pytest.raises(ValueError, match="path: expected one of"):
        FaceRenderer(egl_ctx, sphere, W, H, path="fast")
    r = FaceRenderer(egl_ctx, sphere, W, H, path="gpu")
    try:
        with pytest.raises(ValueError, match=r"weights: expected shape \(2,\)"):
            r.draw(np.zeros(5, np.float32))
    finally:
        r.close()


@pytest.mark.gl
def test_window_without_display_raises_and_headless_works(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(GLUnavailable, match="--headless"):
        create_context(headless=False)
    try:
        target = create_context(headless=None)
    except GLUnavailable as exc:
        pytest.skip(f"no EGL here: {exc}")
    assert target.headless and target.window is None and not target.should_close()
    target.swap()
    target.poll()
    target.close()


def gpu_deformed(ctx, character, weights):
    """Deformed positions and normals read back from face.glsl's vertex shader (transform feedback)."""
    from facepuppet.runtime.render.cpu_deform import CpuDeformer
    from facepuppet.runtime.render.paths.deltas import active_uniforms, delta_texture
    from facepuppet.runtime.render.paths.gpu import gpu_defines
    from facepuppet.runtime.render.shader_loader import load_program

    prog = load_program(ctx, "face.glsl", gpu_defines(character), varyings=("v_world", "v_normal"))
    texture, steps = delta_texture(ctx, character)
    texture.use(0)
    prog["u_deltas"].value = 0
    count, shapes, values = active_uniforms(weights, steps, gpu_defines(character)["MAX_ACTIVE"])
    prog["u_active_count"].value = count
    prog["u_active_shape"].write(shapes.tobytes())
    prog["u_active_weight"].write(values.tobytes())
    prog["u_model"].write(np.eye(4, dtype=np.float32).tobytes())
    n = character.n_vertices
    rest = ctx.buffer(CpuDeformer(character).rest.tobytes())
    out = ctx.buffer(reserve=n * 6 * 4)
    # colour and material inputs are not captured, so the linker drops them
    vao = ctx.vertex_array(prog, [(rest, "3f 3f", "in_position", "in_normal")])
    previous = ctx.fbo or ctx.detect_framebuffer(0)
    fbo = ctx.simple_framebuffer((1, 1))  # a complete framebuffer bound, though nothing is drawn
    fbo.use()
    vao.transform(out, moderngl_points(), vertices=n)
    result = np.frombuffer(out.read(), np.float32).reshape(n, 6)
    assert ctx.error == "GL_NO_ERROR"
    previous.use()
    for obj in [vao, rest, out, prog, fbo, texture]:
        obj.release()
    return result[:, :3], result[:, 3:]


def moderngl_points():
    import moderngl

    return moderngl.POINTS


@pytest.mark.parametrize("which", ["sphere", pytest.param("ict", marks=[pytest.mark.data, pytest.mark.slow])])
def test_vertex_shader_deforms_like_the_cpu_deformer(egl_ctx, request, which):
    from facepuppet.runtime.render.cpu_deform import CpuDeformer

    c = sphere_character() if which == "sphere" else request.getfixturevalue("ict_character")
    w = realistic_weights(c.n_shapes) if which == "ict" else np.array([0.7, -0.2], np.float32)
    gpu_pos, gpu_nrm = gpu_deformed(egl_ctx, c, w)
    cpu_pos, cpu_nrm = CpuDeformer(c).deform(w)
    # The texture keeps each delta component to 1/65534 of its shape's largest (16-bit offsets):
    # a component of the sum is off by at most sum_s |w_s| max_s / 65534, plus float32 rounding.
    largest = np.array([[np.abs(d[c.shape_slice(s)]).max(initial=0.0) for d in (c.delta_positions, c.delta_normals)]
                        for s in range(c.n_shapes)])
    bound_pos, bound_nrm = np.abs(w) @ largest / 65534
    np.testing.assert_allclose(gpu_pos, cpu_pos, atol=bound_pos + 2e-6 * max(1.0, float(np.abs(cpu_pos).max())))
    used = np.unique(c.triangles)
    np.testing.assert_allclose(gpu_nrm[used], cpu_nrm[used], atol=bound_nrm + 2e-6)
    # a vertex no active shape moves stays exactly at rest (offset 32768 is exactly zero)
    moved = np.zeros(c.n_vertices, bool)
    for s in np.flatnonzero(w):
        moved[c.delta_indices[c.shape_slice(s)]] = True
    np.testing.assert_array_equal(gpu_pos[~moved], c.vertices[~moved].astype(np.float32))
    # the bound is tight enough to mean something: far below what a picture shows
    assert bound_pos < 1e-4 * np.ptp(c.vertices, axis=0).max() and bound_nrm < 1e-3


def test_face_framing_of_a_character_nothing_moves_frames_it_whole(egl_ctx, sphere):
    still = sphere.__class__(**{**sphere.__dict__, "delta_offsets": np.array([0, 1, 2], np.int64),
                                "delta_indices": np.array([0, 1], np.uint32),
                                "delta_positions": np.zeros((2, 3), np.float32),
                                "delta_normals": np.zeros((2, 3), np.float32)})
    cameras = []
    for framing in ("head", "face"):
        r = FaceRenderer(egl_ctx, still, W, H, path="cpu", framing=framing)
        cameras.append(r.camera)
        r.close()
    assert egl_ctx.error == "GL_NO_ERROR"
    np.testing.assert_array_equal(cameras[1].view, cameras[0].view)
    np.testing.assert_array_equal(cameras[1].projection, cameras[0].projection)
    moving = FaceRenderer(egl_ctx, sphere, W, H, path="cpu", framing="face")
    assert not np.array_equal(moving.camera.view, cameras[0].view)  # a character whose shapes move: framed on them
    moving.close()


def lash_card_character():
    """A skin quad, an eye quad in front of its middle, and a lash card from the eye's lower edge down over
    the skin (the ICT lower-lash layout): vertex rows at 0, 0.1, ..., 0.4 below the eye edge."""
    from facepuppet.runtime.model.character import MATERIAL_KINDS, Character

    skin = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]
    eye = [[-0.4, 0.0, 0.02], [0.4, 0.0, 0.02], [0.4, 0.3, 0.02], [-0.4, 0.3, 0.02]]
    rows = [[[x, -0.1 * k, 0.03] for x in (-0.4, 0.0, 0.4)] for k in range(5)]
    lash = [p for row in rows for p in row]
    v = np.array(skin + eye + lash, np.float32)
    tris = [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]]
    for k in range(4):
        a = 8 + 3 * k
        for j in range(2):
            tris += [[a + j + 3, a + j + 4, a + j + 1], [a + j + 3, a + j + 1, a + j]]
    kinds = [MATERIAL_KINDS["skin"], MATERIAL_KINDS["eye"], MATERIAL_KINDS["lashes"]]
    tri_mat = [0, 0, 1, 1] + [2] * 16
    color = np.array([[0.8, 0.6, 0.5]] * 4 + [[0.9, 0.9, 0.9]] * 4 + [[0.05, 0.04, 0.04]] * 15, np.float32)
    return Character(
        name="lash", units="cm", vertices=v, triangles=np.array(tris, np.uint32),
        triangle_material=np.array(tri_mat, np.uint16), vertex_color=color, material_names=("skin", "eye", "lash"),
        material_params=np.array([[0.05, 18, k, 0] for k in kinds], np.float32), pivot=np.zeros(3, np.float32),
        shape_names=(), delta_offsets=np.zeros(1, np.int64), delta_indices=np.zeros(0, np.uint32),
        delta_positions=np.zeros((0, 3), np.float32), delta_normals=np.zeros((0, 3), np.float32))


def test_lash_cards_fade_from_the_lid_margin_instead_of_a_grey_band(egl_ctx):
    """Issue 13: the ICT lower lash card lies on the cheek; drawn at one opacity it was a grey band under
    every eye. Its opacity now falls from the eye's edge to the tips (renderer.vertex_opacity)."""
    import dataclasses

    from facepuppet.runtime.model.character import MATERIAL_KINDS
    from facepuppet.runtime.render.layers import vertex_opacity

    c = lash_card_character()
    opacity = vertex_opacity(c)
    assert (opacity[:8] == 1).all()                       # surfaces opaque
    rows = opacity[8:].reshape(5, 3)[:, 0]
    assert rows[0] > 0.8 and np.all(np.diff(rows) < 0) and rows[-1] < 0.02
    params = c.material_params.copy()
    params[2, 2] = MATERIAL_KINDS["hidden"]
    bare = dataclasses.replace(c, material_params=params)
    with_lash, project = render(egl_ctx, c, [], size=(200, 200))
    without, _ = render(egl_ctx, bare, [], size=(200, 200))
    (x, y_root), (_, y_tip) = project([[0.2, -0.02, 0.03], [0.2, -0.36, 0.03]]).astype(int)
    d = np.abs(with_lash.astype(int) - without.astype(int)).sum(axis=2)
    assert d[y_root, x] > 60       # a dark lash line at the lid margin
    assert d[y_tip, x] < 12        # the cheek shows through near the tips (a 0.55 band: > 100)


@pytest.mark.data
def test_ict_eye_layers_are_drawn_as_thin_blended_layers(egl_ctx, ict_character):
    """The re-imported ICT head: the eye occlusion and the films are drawn (not hidden) and see-through."""
    from facepuppet.runtime.model.character import MATERIAL_KINDS
    from facepuppet.runtime.render.face_mesh import visible_triangles
    from facepuppet.runtime.render.layers import vertex_opacity

    c = ict_character
    kinds = c.material_params[:, 2].round().astype(int)
    tris, _ = visible_triangles(c)
    drawn = set(np.unique(tris).tolist())
    opacity = vertex_opacity(c)
    for kind in ("occlusion", "film"):
        m = np.flatnonzero(kinds == MATERIAL_KINDS[kind])
        assert len(m)
        v = np.unique(c.triangles[np.isin(c.triangle_material, m)])
        assert set(v.tolist()) <= drawn and opacity[v].max() < 0.7 and opacity[v].max() > 0.1


@pytest.mark.data
def test_ict_without_the_subtle_eye_layers_changes_only_the_eyes_and_keeps_the_lashes(egl_ctx, ict_character):
    """``subtle_layers=False`` (fast quality) leaves out the lid shadow and the films: the picture changes,
    only where those layers lie on screen, and the lashes are still drawn."""
    import dataclasses

    from facepuppet.runtime.model.character import MATERIAL_KINDS
    from facepuppet.runtime.render.layers import SUBTLE_LAYER_KINDS

    c = ict_character
    kinds = c.material_params[:, 2].round().astype(int)

    def picture(character, **kw):
        r = FaceRenderer(egl_ctx, character, 320, 240, path="cpu", framing="face", log=lambda _: None, **kw)
        r.draw(np.zeros(character.n_shapes, np.float32))
        image, n, screen = r.read_pixels().astype(int), r.n_indices, r.project(character.vertices)
        r.close()
        return image, n, screen

    full, _, screen = picture(c)
    fast, _, _ = picture(c, subtle_layers=False)
    changed = np.abs(full - fast).max(axis=2) > 2
    assert changed.sum() > 20  # the layers were drawn at full quality and left out at fast
    layer_tris = np.isin(kinds[c.triangle_material], SUBTLE_LAYER_KINDS)
    xy = screen[np.unique(c.triangles[layer_tris])]
    ys, xs = np.nonzero(changed)
    assert xs.min() >= xy[:, 0].min() - 2 and xs.max() <= xy[:, 0].max() + 2
    assert ys.min() >= xy[:, 1].min() - 2 and ys.max() <= xy[:, 1].max() + 2
    # the lashes stay: hiding them too changes the fast picture
    params = c.material_params.copy()
    params[kinds == MATERIAL_KINDS["lashes"], 2] = MATERIAL_KINDS["hidden"]
    no_lashes, _, _ = picture(dataclasses.replace(c, material_params=params), subtle_layers=False)
    assert (np.abs(no_lashes - fast).max(axis=2) > 2).sum() > 20
