"""Elastic tables: round trip, eq. 7 blending, and the GPU elastic path against the NumPy reference."""

import numpy as np
import pytest

from facepuppet.runtime.elastic.model import ElasticModel
from facepuppet.runtime.files.tables import TablesError
from facepuppet.runtime.model.geometry import vertex_normals

from helpers.elastic_models import random_model
from helpers.small_characters import sphere_character


def test_round_trip_and_blending(tmp_path):
    c = sphere_character(with_hidden=False)
    model = random_model(c)
    loaded = ElasticModel.load(model.save(tmp_path / "e.npz"))
    w = np.array([0.3, -0.7], np.float32)
    expected = 0.3 * model.arrays["params"][0] - 0.7 * model.arrays["params"][1]
    np.testing.assert_allclose(loaded.blend(w), expected, atol=1e-6)  # eq. 7
    with pytest.raises(ValueError, match=r"weights: expected shape \(2,\)"):
        loaded.blend(np.zeros(3))


def test_bad_index_is_refused():
    c = sphere_character(with_hidden=False)
    model = random_model(c)
    arrays = dict(model.arrays)
    arrays["basis_indices"] = arrays["basis_indices"] + 10
    with pytest.raises(TablesError, match="basis_indices: control index out of range"):
        ElasticModel(arrays, model.shape_names, model.control_names)


def gpu_elastic(ctx, character, model, controls):
    """Deformed positions and normals read back from face.glsl's elastic variant (transform feedback)."""
    import moderngl

    from facepuppet.runtime.render.paths.elastic import basis_textures, elastic_defines
    from facepuppet.runtime.render.shader_loader import load_program

    prog = load_program(ctx, "face.glsl", elastic_defines(model), varyings=("v_world", "v_normal"))
    textures = basis_textures(ctx, model)
    for unit, tex in enumerate(textures):
        tex.use(unit)
    prog["u_basis"].value, prog["u_basis_index"].value = 0, 1
    prog["u_controls"].write(np.ascontiguousarray(controls, np.float32).tobytes())
    if model.n_rigid:
        prog["u_rigid_label"].value = 2
        prog["u_rigid"].write(model.rigid_transforms(controls).tobytes())
    prog["u_model"].write(np.eye(4, dtype=np.float32).tobytes())
    n = character.n_vertices
    rest = np.hstack([character.vertices, vertex_normals(character.vertices, character.triangles)]).astype(np.float32)
    vbo = ctx.buffer(rest.tobytes())
    out = ctx.buffer(reserve=n * 6 * 4)
    vao = ctx.vertex_array(prog, [(vbo, "3f 3f", "in_position", "in_normal")])
    previous = ctx.fbo or ctx.detect_framebuffer(0)
    fbo = ctx.simple_framebuffer((1, 1))
    fbo.use()
    vao.transform(out, moderngl.POINTS, vertices=n)
    result = np.frombuffer(out.read(), np.float32).reshape(n, 6)
    assert ctx.error == "GL_NO_ERROR"
    previous.use()
    for obj in [vao, vbo, out, prog, fbo, *textures]:
        obj.release()
    return result[:, :3], result[:, 3:]


def test_gpu_elastic_path_matches_numpy(egl_ctx):
    c = sphere_character(with_hidden=False)
    model = random_model(c)
    controls = model.blend(np.array([0.8, 0.4], np.float32))
    gpu_pos, gpu_nrm = gpu_elastic(egl_ctx, c, model, controls)
    cpu_pos, cpu_nrm = model.deform(controls, c.vertices, vertex_normals(c.vertices, c.triangles))
    assert np.abs(cpu_pos - c.vertices).max() > 0.01  # the test moves something
    np.testing.assert_allclose(gpu_pos, cpu_pos, atol=1e-5)
    np.testing.assert_allclose(gpu_nrm, cpu_nrm, atol=1e-4)


def test_renderer_elastic_path_draws_and_checks_its_table(egl_ctx):
    from facepuppet.runtime.render.renderer import FaceRenderer

    c = sphere_character(with_hidden=False)
    model = random_model(c)
    r = FaceRenderer(egl_ctx, c, 64, 48, path="elastic", elastic=model, log=lambda s: None)
    r.draw(np.zeros(2, np.float32))
    still = r.read_pixels()
    r.draw(np.array([1.0, 1.0], np.float32))
    moved = r.read_pixels()
    r.prepare_controls(np.zeros((model.n_controls, 3), np.float32))
    r.submit()
    assert (r.read_pixels() == still).all() and (moved != still).any()
    assert egl_ctx.error == "GL_NO_ERROR"
    r.close()
    with pytest.raises(ValueError, match="path 'elastic' needs an ElasticModel"):
        FaceRenderer(egl_ctx, c, 64, 48, path="elastic", log=lambda s: None)


def rigid_model(character, seed=1) -> ElasticModel:
    """random_model with the upper half of the vertices a rigid part anchored to controls 0-3 (no basis weight)."""
    model = random_model(character, n_controls=6, seed=seed)
    arrays = dict(model.arrays)
    upper = character.vertices[:, 1] > 0
    arrays["basis_weights"] = np.where(upper[:, None], 0, arrays["basis_weights"]).astype(np.float32)
    arrays["rigid_labels"] = np.where(upper, 0, -1).astype(np.int32)
    arrays["rigid_anchors"] = np.array([[1, 1, 1, 1, 0, 0]], np.uint8)
    arrays["control_positions"] = np.random.default_rng(seed).uniform(-1, 1, (6, 3)).astype(np.float32)
    return ElasticModel(arrays, model.shape_names, model.control_names)


def test_rigid_part_follows_its_anchors_exactly_on_cpu_and_gpu(egl_ctx):
    c = sphere_character(with_hidden=False)
    model = rigid_model(c)
    angle = 0.3
    r = np.array([[1, 0, 0], [0, np.cos(angle), -np.sin(angle)], [0, np.sin(angle), np.cos(angle)]], np.float32)
    t = np.array([0.1, -0.2, 0.05], np.float32)
    rest = model.arrays["control_positions"]
    controls = np.zeros((model.n_controls, 3), np.float32)
    controls[:4] = rest[:4] @ r.T + t - rest[:4]  # the anchors move rigidly
    controls[4:] = 0.3  # the others do anything
    normals = vertex_normals(c.vertices, c.triangles)
    pos, nrm = model.deform(controls, c.vertices, normals)
    on = model.arrays["rigid_labels"] == 0
    np.testing.assert_allclose(pos[on], c.vertices[on] @ r.T + t, atol=1e-5)
    unit = normals[on] / np.linalg.norm(normals[on], axis=1, keepdims=True)
    np.testing.assert_allclose(nrm[on], unit @ r.T, atol=1e-5)
    gpu_pos, gpu_nrm = gpu_elastic(egl_ctx, c, model, controls)
    np.testing.assert_allclose(gpu_pos, pos, atol=1e-5)
    np.testing.assert_allclose(gpu_nrm, nrm, atol=1e-4)


def test_rigid_sections_are_checked():
    c = sphere_character(with_hidden=False)
    arrays = dict(rigid_model(c).arrays)
    arrays["rigid_anchors"] = np.array([[1, 1, 0, 0, 0, 0]], np.uint8)
    with pytest.raises(TablesError, match="rigid_anchors: each rigid part needs at least 3 anchor controls"):
        ElasticModel(arrays, tuple(c.shape_names), tuple(f"c{i}" for i in range(6)))
    del arrays["rigid_anchors"]
    with pytest.raises(TablesError, match="rigid_labels and rigid_anchors come together"):
        ElasticModel(arrays, tuple(c.shape_names), tuple(f"c{i}" for i in range(6)))
