"""The gl and data markers are enforced: an unmarked test may not open an OpenGL context in this process
nor read the data kit (tests/conftest.py), and the markers kept for files edited elsewhere name real tests.

Whether a test that uses egl_ctx is marked gl is not tested here: conftest.py marks it from that very
fixture, so such a test could only restate the hook."""

from __future__ import annotations

import ast

import pytest

from conftest import PENDING_MARKS, REPO, need_shared


def test_an_unmarked_test_may_not_open_a_gl_context():
    moderngl = pytest.importorskip("moderngl")
    with pytest.raises(pytest.fail.Exception, match="not marked gl"):
        moderngl.create_standalone_context(backend="egl", require=330)
    with pytest.raises(pytest.fail.Exception, match="not marked gl"):
        moderngl.create_context(require=330)


def test_an_unmarked_test_may_not_read_the_data_kit():
    with pytest.raises(pytest.fail.Exception, match="not marked data"):
        need_shared("ict-facekit")


def test_pending_marks_name_tests_that_exist():
    missing = []
    for key in sorted(PENDING_MARKS):
        path, name = key.split("::")
        tree = ast.parse((REPO / path).read_text(encoding="utf-8"))
        if name not in {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}:
            missing.append(key)
    assert missing == [], f"no such test functions: {missing}; update PENDING_MARKS in tests/conftest.py"
