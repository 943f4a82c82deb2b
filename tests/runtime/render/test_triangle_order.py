"""Triangle order in compact patches: the same triangles, fewer vertices per draw-module segment, and
fewer vertex shader runs counted by the GL itself (GL_VERTEX_SHADER_INVOCATIONS, real EGL)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from facepuppet.runtime.render.triangle_order import PATCH_TRIANGLES, cache_order


def grid(n: int = 120) -> tuple[np.ndarray, np.ndarray]:
    """An n x n vertex grid in the plane z = 0 (x, y in [-1, 1]), 2 (n - 1)^2 counter-clockwise triangles."""
    xs = np.linspace(-1, 1, n)
    v = np.array([(x, y, 0.0) for y in xs for x in xs], np.float32)
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()
    t = np.vstack([np.c_[a, b, c], np.c_[a, c, d]]).astype(np.uint32)
    return v, t


def segment_vertices(tris: np.ndarray) -> int:
    """Sum over consecutive segments of PATCH_TRIANGLES triangles of their distinct vertices."""
    return sum(len(np.unique(tris[s:s + PATCH_TRIANGLES])) for s in range(0, len(tris), PATCH_TRIANGLES))


def test_cache_order_keeps_every_triangle_once_with_its_winding():
    v, t = grid(40)
    shuffled = t[np.random.default_rng(1).permutation(len(t))]
    out = cache_order(shuffled, v)
    assert out.shape == t.shape and out.dtype == t.dtype
    assert sorted(map(tuple, out.tolist())) == sorted(map(tuple, shuffled.tolist()))  # rows intact: windings kept


def test_cache_order_puts_compact_patches_in_each_segment():
    v, t = grid(120)  # 28,322 triangles, 14,400 vertices
    shuffled = t[np.random.default_rng(2).permutation(len(t))]
    before, after = segment_vertices(shuffled), segment_vertices(cache_order(shuffled, v))
    # a random order has nearly 3 distinct vertices per triangle in a segment; patches well under 1
    assert before > 2.5 * len(t)
    assert after < 0.75 * len(t)


def test_cache_order_of_a_small_or_disconnected_mesh():
    v, t = grid(5)
    assert np.array_equal(cache_order(t, v), t)  # fewer triangles than a patch: unchanged
    v2, t2 = grid(30)
    apart = np.vstack([t2, t2 + len(v2)])  # two separate sheets, interleaved row by row
    apart = apart[np.argsort(np.r_[np.arange(len(t2)), np.arange(len(t2))], kind="stable")]
    out = cache_order(apart, np.vstack([v2, v2 + np.float32([5, 0, 0])]))
    assert sorted(map(tuple, out.tolist())) == sorted(map(tuple, apart.tolist()))


# Counted in a child interpreter of its own: the count needs the GL's own entry points (libOpenGL through
# ctypes), and once that library is loaded into a test process, a context another test opens and releases
# later leaves the shared context's transform feedback failing (GL_INVALID_OPERATION, seen under xdist).
_COUNT = """
import ctypes, json, sys
import moderngl, numpy as np
sys.path.insert(0, sys.argv[1])
from test_triangle_order import grid
from facepuppet.runtime.render.triangle_order import cache_order
ctx = moderngl.create_standalone_context(backend="egl", require=330)
try:
    gl = ctypes.CDLL("libOpenGL.so.0")
    gl.glGenQueries, gl.glBeginQuery, gl.glEndQuery, gl.glGetQueryObjectui64v
except (OSError, AttributeError) as exc:
    print(json.dumps({"skip": f"no libOpenGL.so.0 entry points to count shader runs with: {exc}"})); raise SystemExit
if "GL_ARB_pipeline_statistics_query" not in ctx.extensions and ctx.version_code < 460:
    print(json.dumps({"skip": "this GL has no pipeline statistics queries (GL_ARB_pipeline_statistics_query)"}))
    raise SystemExit
v, t = grid(120)
shuffled = t[np.random.default_rng(3).permutation(len(t))]
prog = ctx.program(vertex_shader="#version 330\\nin vec3 p; void main() { gl_Position = vec4(p, 1.0); }",
                   fragment_shader="#version 330\\nout vec4 f; void main() { f = vec4(1.0); }")
vbo = ctx.buffer(v.tobytes())
fbo = ctx.simple_framebuffer((64, 64))
fbo.use()
query = (ctypes.c_uint * 1)()
gl.glGenQueries(1, query)

def runs(tris):
    ibo = ctx.buffer(np.ascontiguousarray(tris, np.uint32).tobytes())
    vao = ctx.vertex_array(prog, [(vbo, "3f", "p")], index_buffer=ibo, index_element_size=4)
    gl.glBeginQuery(0x82F0, query[0])  # GL_VERTEX_SHADER_INVOCATIONS
    vao.render()
    gl.glEndQuery(0x82F0)
    out = ctypes.c_uint64()
    gl.glGetQueryObjectui64v(query[0], 0x8866, ctypes.byref(out))  # GL_QUERY_RESULT
    vao.release()
    ibo.release()
    return int(out.value)

random_order, patches = runs(shuffled), runs(cache_order(shuffled, v))
print(json.dumps({"vertices": len(v), "random": random_order, "patches": patches, "error": ctx.error}))
"""


@pytest.mark.gl  # the child opens an EGL context
def test_the_gl_runs_the_vertex_shader_fewer_times_in_cache_order():
    done = subprocess.run([sys.executable, "-c", _COUNT, str(Path(__file__).parent)], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout.strip().splitlines()[-1])
    if "skip" in got:
        pytest.skip(got["skip"])
    assert got["error"] == "GL_NO_ERROR"
    assert got["patches"] >= got["vertices"]            # every vertex is shaded at least once
    assert got["patches"] < 0.6 * got["random"]         # and far fewer times than in a random order
