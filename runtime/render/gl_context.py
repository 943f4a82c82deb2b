"""OpenGL context: a glfw window when a display exists, headless EGL otherwise."""

from __future__ import annotations

import os
from typing import Any

import moderngl

from facepuppet.runtime.errors import FacepuppetError

EGL_HELP = (
    "headless OpenGL needs libEGL and Mesa's drivers; install them with "
    "`apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri`"
)


class GLUnavailable(FacepuppetError, RuntimeError):
    """No OpenGL context could be made; the message says what is missing."""


class GLTarget:
    """A context and, when windowed, its glfw window.

    Attributes
    ----------
    ctx : moderngl.Context
    window : glfw window handle or None (headless)
    headless : bool
    """

    def __init__(self, ctx: moderngl.Context, window: Any = None) -> None:
        self.ctx = ctx
        self.window = window
        self.headless = window is None

    def should_close(self) -> bool:
        if self.window is None:
            return False
        import glfw

        return bool(glfw.window_should_close(self.window))

    def swap(self) -> None:
        if self.window is not None:
            import glfw

            glfw.swap_buffers(self.window)

    def poll(self) -> None:
        if self.window is not None:
            import glfw

            glfw.poll_events()

    def close(self) -> None:
        if self.window is not None:
            import glfw

            glfw.destroy_window(self.window)
            glfw.terminate()
            self.window = None
        else:
            self.ctx.release()


def display_available() -> bool:
    """True when DISPLAY or WAYLAND_DISPLAY is set (glfw may still fail to open it)."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _glfw_init() -> bool:
    if not display_available():
        return False
    try:
        import glfw
    except Exception:  # no glfw shared library: treat as no display
        return False
    return bool(glfw.init())


def _window(width: int, height: int, title: str) -> GLTarget:
    import glfw

    glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 3)
    glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
    glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
    glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
    window = glfw.create_window(width, height, title, None, None)
    if not window:
        glfw.terminate()
        raise GLUnavailable("glfw could not open an OpenGL 3.3 core window; try --headless")
    glfw.make_context_current(window)
    glfw.swap_interval(0)
    return GLTarget(moderngl.create_context(require=330), window)


def _egl() -> GLTarget:
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=330)
    except Exception as exc:
        raise GLUnavailable(f"no headless EGL OpenGL 3.3 context ({exc}); {EGL_HELP}") from None
    return GLTarget(ctx)


def create_context(
    headless: bool | None = None, width: int = 1280, height: int = 720, title: str = "facepuppet"
) -> GLTarget:
    """Make an OpenGL 3.3+ context.

    Parameters
    ----------
    headless : bool or None
        True: EGL, no window. False: a glfw window (GLUnavailable without a
        display). None: a window if a display exists and glfw starts, else EGL.
    width, height : int, window size in pixels (ignored headless)
    title : str, window title

    Raises
    ------
    GLUnavailable
    """
    if headless is False:
        if not _glfw_init():
            raise GLUnavailable(
                "a window was asked for but there is no display (DISPLAY / WAYLAND_DISPLAY unset "
                "or glfw could not start); run with --headless to render offscreen through EGL"
            )
        return _window(width, height, title)
    if headless is None and _glfw_init():
        return _window(width, height, title)
    return _egl()
