"""Shader loader: includes, defines, #line mapping, and file-named errors, on a real EGL context."""

from __future__ import annotations

import pytest

from facepuppet.runtime.render.shader_loader import ShaderError, load_program, preprocess

MAIN = """#version 330 core
#include "common.glsl"
#ifdef VERTEX_SHADER
in vec3 in_position;
void main() { gl_Position = vec4(in_position * SCALE * half_of(2.0), 1.0); }
#endif
#ifdef FRAGMENT_SHADER
out vec4 f_color;
void main() { f_color = vec4(tint(), 1.0); }
#endif
"""
COMMON = """#include "deeper.glsl"
float half_of(float x) { return 0.5 * x; }
"""
DEEPER = "vec3 tint() { return vec3(0.2, 0.4, 0.6); }\n"


@pytest.fixture
def shader_dir(tmp_path):
    (tmp_path / "main.glsl").write_text(MAIN)
    (tmp_path / "common.glsl").write_text(COMMON)
    (tmp_path / "deeper.glsl").write_text(DEEPER)
    return tmp_path


def test_includes_resolve_recursively_and_program_links(egl_ctx, shader_dir):
    source, names = preprocess("main.glsl", "VERTEX_SHADER", {"SCALE": 2.0}, shader_dir)
    assert source.startswith("#version 330 core\n#define VERTEX_SHADER 1\n#define SCALE 2.0\n")
    assert "vec3 tint()" in source and "float half_of" in source
    assert set(names.values()) == {"main.glsl", "common.glsl", "deeper.glsl"}
    assert '#include' not in source
    prog = load_program(egl_ctx, "main.glsl", {"SCALE": 2.0}, search_path=shader_dir)
    assert "in_position" in prog
    assert egl_ctx.error == "GL_NO_ERROR"


def test_error_in_included_file_names_that_file_and_line(egl_ctx, shader_dir):
    (shader_dir / "deeper.glsl").write_text("// fine\n// fine\nvec3 tint() { return vec3(0.2, 0.4) }\n")
    with pytest.raises(ShaderError, match=r"deeper\.glsl:3:\d+: error"):
        load_program(egl_ctx, "main.glsl", {"SCALE": 1.0}, search_path=shader_dir)


def test_error_in_main_file_after_an_include_keeps_main_line_numbers(egl_ctx, shader_dir):
    (shader_dir / "main.glsl").write_text(MAIN.replace("gl_Position = vec4", "gl_Position = vec5"))
    with pytest.raises(ShaderError, match=r"main\.glsl:5:\d+: error"):
        load_program(egl_ctx, "main.glsl", {"SCALE": 1.0}, search_path=shader_dir)


def test_missing_define_is_a_compile_error_naming_the_file(egl_ctx, shader_dir):
    with pytest.raises(ShaderError, match=r"main\.glsl:5:\d+: error: .*SCALE"):
        load_program(egl_ctx, "main.glsl", search_path=shader_dir)


def test_missing_file_and_missing_include(egl_ctx, shader_dir):
    with pytest.raises(ShaderError, match=r"'nothere\.glsl' not found"):
        load_program(egl_ctx, "nothere.glsl", search_path=shader_dir)
    (shader_dir / "common.glsl").unlink()
    with pytest.raises(ShaderError, match=r"'common\.glsl' not found .*included from main\.glsl"):
        load_program(egl_ctx, "main.glsl", search_path=shader_dir)


def test_include_cycle_is_an_error(egl_ctx, shader_dir):
    (shader_dir / "deeper.glsl").write_text('#include "common.glsl"\n')
    cycle = r"include cycle .*main\.glsl -> common\.glsl -> deeper\.glsl -> common\.glsl"
    with pytest.raises(ShaderError, match=cycle):
        load_program(egl_ctx, "main.glsl", search_path=shader_dir)


def test_bad_define_name_is_refused(egl_ctx, shader_dir):
    with pytest.raises(ShaderError, match="not a GLSL identifier"):
        load_program(egl_ctx, "main.glsl", {"1BAD": 1}, search_path=shader_dir)


@pytest.mark.parametrize("defines", [None, {"GPU_DEFORM": 1, "MAX_ACTIVE": 8, "N_VERTICES": 100,
                                            "DELTA_TEXTURE_WIDTH": 4096}])
def test_packaged_face_program_builds_in_both_variants(egl_ctx, defines):
    prog = load_program(egl_ctx, "face.glsl", defines)
    assert "u_model" in prog and "u_eye" in prog
    assert ("u_active_weight" in prog) == bool(defines)
    assert egl_ctx.error == "GL_NO_ERROR"
