"""OpenGL context: a glfw window when a display exists, headless EGL otherwise."""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from typing import Any

import moderngl

from facepuppet.runtime.errors import FacepuppetError

logger = logging.getLogger(__name__)

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
    transparent : bool, the window's framebuffer is transparent (its clear alpha shows the desktop); False
        headless (offscreen frames carry their own alpha) or when the platform refused
    samples : int, the window's multisample count (0 headless: the renderer multisamples offscreen)
    """

    def __init__(self, ctx: moderngl.Context, window: Any = None, transparent: bool = False,
                 samples: int = 0) -> None:
        self.ctx = ctx
        self.window = window
        self.headless = window is None
        self.transparent = transparent
        self.samples = samples

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
    """Start glfw; False (with the reason in ``_glfw_problem``) when there is no display it can open.

    glfw's own error reports go to ``_glfw_errors`` instead of the console (pyGLFW
    would print them as raw Python warnings); callers say what happened in one line.
    """
    global _glfw_problem
    if not display_available():
        _glfw_problem = "no display (DISPLAY and WAYLAND_DISPLAY are unset)"
        return False
    try:
        import glfw
    except Exception as exc:  # no glfw shared library: treat as no display
        _glfw_problem = f"glfw is not available ({exc})"
        return False
    _glfw_errors.clear()
    glfw.set_error_callback(_glfw_error)
    if glfw.init():
        return True
    shown = os.environ.get("WAYLAND_DISPLAY") or os.environ.get("DISPLAY")
    why = _glfw_errors[-1] if _glfw_errors else "glfw.init failed"
    _glfw_problem = f"the display {shown!r} could not be opened ({why})"
    return False


_glfw_errors: list[str] = []
_glfw_problem = ""


def _glfw_error(code: int, description: bytes) -> None:
    text = description.decode("utf-8", "replace") if isinstance(description, bytes) else str(description)
    del _glfw_errors[:-7]  # the few latest; glfw reports once per failing call, never per frame
    _glfw_errors.append(f"GLFW {code}: {text}")


def _window(width: int, height: int, title: str, samples: int = 0, transparent: bool = False,
            log: Callable[[str], None] | None = None) -> GLTarget:
    import glfw

    glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 3)
    glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
    glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
    glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
    glfw.window_hint(glfw.SAMPLES, max(int(samples), 0))
    glfw.window_hint(glfw.TRANSPARENT_FRAMEBUFFER, bool(transparent))
    window = glfw.create_window(width, height, title, None, None)
    if not window and samples:  # no multisampled visual: try without
        (log or logger.warning)(f"no {samples}x multisampled window on this display; opening one without MSAA")
        glfw.window_hint(glfw.SAMPLES, 0)
        samples = 0
        window = glfw.create_window(width, height, title, None, None)
    if not window:
        glfw.terminate()
        raise GLUnavailable("glfw could not open an OpenGL 3.3 core window; try --headless")
    granted = bool(transparent) and bool(glfw.get_window_attrib(window, glfw.TRANSPARENT_FRAMEBUFFER))
    if transparent and not granted:
        (log or logger.warning)("the display gives no transparent window framebuffer (a compositor is needed); "
                                "the background is drawn opaque in the window (headless --out frames keep alpha)")
    glfw.make_context_current(window)
    glfw.swap_interval(0)
    return GLTarget(moderngl.create_context(require=330), window, transparent=granted, samples=int(samples))


def _egl() -> GLTarget:
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=330)
    except Exception as exc:
        raise GLUnavailable(f"no headless EGL OpenGL 3.3 context ({exc}); {EGL_HELP}") from None
    return GLTarget(ctx)


def create_context(
    headless: bool | None = None, width: int = 1280, height: int = 720, title: str = "facepuppet",
    log: Callable[[str], None] | None = None, samples: int = 0, transparent: bool = False,
) -> GLTarget:
    """Make an OpenGL 3.3+ context.

    Parameters
    ----------
    headless : bool or None
        True: EGL, no window. False: a glfw window (GLUnavailable without a
        display). None: a window if a display exists and glfw starts, else EGL.
    width, height : int, window size in pixels (ignored headless)
    title : str, window title
    log : where the one line goes when ``headless=None`` falls back to EGL, or a window lacks the asked
        samples or transparency (default: this module's logger, at WARNING)
    samples : int, multisamples of a window's framebuffer (glfw SAMPLES hint; ignored headless, where the
        renderer multisamples its own framebuffer)
    transparent : bool, ask for a transparent window framebuffer (glfw TRANSPARENT_FRAMEBUFFER)

    Raises
    ------
    GLUnavailable
    """
    if headless is False:
        if not _glfw_init():
            raise GLUnavailable(
                f"a window was asked for but {_glfw_problem}; run with --headless to render offscreen through EGL"
            )
        return _window(width, height, title, samples, transparent, log)
    if headless is None:
        if _glfw_init():
            return _window(width, height, title, samples, transparent, log)
        target = _egl()
        (log or logger.warning)(f"{_glfw_problem}: no window, rendering offscreen through EGL "
                                f"(pass --headless to ask for that)")
        return target
    return _egl()
