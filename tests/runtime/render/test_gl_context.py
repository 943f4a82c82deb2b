"""create_context: a fallback to offscreen rendering is said in one line; glfw's raw warnings stay off the console."""

from __future__ import annotations

import warnings

import pytest

from facepuppet.runtime.render.gl_context import GLUnavailable, create_context


def _context(headless, said):
    try:
        return create_context(headless=headless, log=said.append)
    except GLUnavailable as exc:
        if "EGL" in str(exc):
            pytest.skip(f"no EGL here: {exc}")
        raise


@pytest.mark.gl
def test_no_display_falls_back_to_egl_saying_so_once(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    said: list[str] = []
    target = _context(None, said)
    target.close()
    assert target.headless
    assert said == ["no display (DISPLAY and WAYLAND_DISPLAY are unset): no window, rendering offscreen "
                    "through EGL (pass --headless to ask for that)"]


@pytest.mark.gl
def test_a_bad_display_is_named_and_glfw_prints_no_raw_warning(monkeypatch):
    pytest.importorskip("glfw")
    monkeypatch.setenv("DISPLAY", ":12345")
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    said: list[str] = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        target = _context(None, said)
        target.close()
        with pytest.raises(GLUnavailable, match=r"the display ':12345' could not be opened \(GLFW 65550: .*"
                                                r":12345\); run with --headless"):
            create_context(headless=False)
    assert [str(w.message) for w in caught] == []
    assert len(said) == 1 and said[0].startswith("the display ':12345' could not be opened")
    assert said[0].endswith("no window, rendering offscreen through EGL (pass --headless to ask for that)")


def test_headless_false_without_display_says_why(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(GLUnavailable, match=r"a window was asked for but no display \(DISPLAY and WAYLAND_DISPLAY "
                                            r"are unset\); run with --headless"):
        create_context(headless=False)
