"""The gl and data markers are enforced: an unmarked test may not open an OpenGL context in this process
nor read the data kit (tests/conftest.py).

Whether a test that uses egl_ctx is marked gl is not tested here: conftest.py marks it from that very
fixture, so such a test could only restate the hook."""

from __future__ import annotations

import pytest

from conftest import need_shared


def test_an_unmarked_test_may_not_open_a_gl_context():
    moderngl = pytest.importorskip("moderngl")
    with pytest.raises(pytest.fail.Exception, match="not marked gl"):
        moderngl.create_standalone_context(backend="egl", require=330)
    with pytest.raises(pytest.fail.Exception, match="not marked gl"):
        moderngl.create_context(require=330)


def test_an_unmarked_test_may_not_read_the_data_kit():
    with pytest.raises(pytest.fail.Exception, match="not marked data"):
        need_shared("ict-facekit")
