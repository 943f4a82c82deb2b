"""``facepuppet manipulate``: pull and pin points of a face in a window (Shin & Lee 2009, §6.1).

Window: left-drag pulls a marker, right-click (or shift+left) toggles a pin,
R resets to the neutral (and clears the pins), Escape quits. ``--script``
runs a JSON list of steps through the same code
(:mod:`~facepuppet.runtime.actuation.manipulation`), headless or in the window, and
writes a PNG per step and ``manipulate.json`` (s and weights per step).
Markers, pins and the drag target are drawn as dots over the face
(``shaders/overlay.glsl``).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import moderngl
import numpy as np

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.actuation.manipulation import Manipulation, ScreenView, read_script, run_step
from facepuppet.runtime.actuation.pair import ActorPair
from facepuppet.runtime.commands.options import parse_size
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.files.outputs import check_path, write_atomic
from facepuppet.runtime.model.character import Character

if TYPE_CHECKING:
    import argparse

    from facepuppet.runtime.render.renderer import FaceRenderer


class PointOverlay:
    """Round dots drawn over a renderer's framebuffer (shaders/overlay.glsl, GL_POINTS, no depth test)."""

    def __init__(self, ctx: moderngl.Context, view_projection: np.ndarray, max_points: int = 256,
                 point_size: float = 9.0) -> None:
        from facepuppet.runtime.render.shader_loader import load_program

        self.ctx = ctx
        self.prog = load_program(ctx, "overlay.glsl")
        self.prog["u_view_projection"].write(np.asarray(view_projection, np.float32).T.tobytes())
        self.prog["u_point_size"].value = float(point_size)
        self.max_points = max_points
        self.vbo = ctx.buffer(reserve=max_points * 24, dynamic=True)
        self.vao = ctx.vertex_array(self.prog, [(self.vbo, "3f 3f", "in_position", "in_color")])

    def draw(self, fbo: moderngl.Framebuffer, points: np.ndarray, colours: np.ndarray) -> None:
        """Draw ``points`` (n, 3) float32 in ``colours`` (n, 3) float32 into ``fbo``."""
        n = min(len(points), self.max_points)
        if n == 0:
            return
        self.vbo.write(np.hstack([points[:n], colours[:n]]).astype(np.float32).tobytes())
        fbo.use()
        self.ctx.disable(moderngl.DEPTH_TEST)
        self.ctx.enable(moderngl.PROGRAM_POINT_SIZE)
        self.vao.render(moderngl.POINTS, vertices=n)
        self.ctx.enable(moderngl.DEPTH_TEST)

    def release(self) -> None:
        for obj in (self.vao, self.vbo, self.prog):
            obj.release()


# -- the window -------------------------------------------------------------
class WindowControls:
    """glfw callbacks -> :class:`Manipulation`; ``dirty`` says a redraw is due.

    ``scale`` converts window (screen) coordinates to framebuffer pixels (HiDPI).
    """

    def __init__(self, manipulation: Manipulation, scale: tuple[float, float] = (1.0, 1.0),
                 log: Callable[[str], None] = print) -> None:
        self.m = manipulation
        self.scale = np.asarray(scale, dtype=np.float64)
        self.cursor = np.zeros(2)
        self.dirty = True
        self.log = log

    def install(self, window: Any) -> None:
        import glfw

        glfw.set_cursor_pos_callback(window, self.on_cursor_pos)
        glfw.set_mouse_button_callback(window, self.on_mouse_button)
        glfw.set_key_callback(window, self.on_key)

    def on_cursor_pos(self, window: Any, x: float, y: float) -> None:
        self.cursor = np.array([x, y]) * self.scale
        if self.m.move(self.cursor):
            self.dirty = True

    def on_mouse_button(self, window: Any, button: int, action: int, mods: int) -> None:
        import glfw

        pin = button == glfw.MOUSE_BUTTON_RIGHT or (button == glfw.MOUSE_BUTTON_LEFT and mods & glfw.MOD_SHIFT)
        if action == glfw.PRESS and pin:
            i = self.m.pick(self.cursor)
            if i is not None:
                state = "pinned" if self.m.toggle_pin(i) else "unpinned"
                self.log(f"manipulate: {self.m.actor.names[i]} {state}")
                self.dirty = True
        elif button == glfw.MOUSE_BUTTON_LEFT and action == glfw.PRESS:
            if self.m.press(self.cursor) is not None:
                self.dirty = True
        elif button == glfw.MOUSE_BUTTON_LEFT and action == glfw.RELEASE and self.m.dragging is not None:
            self.log(f"manipulate: pulled {self.m.actor.names[self.m.dragging]}; s = "
                     + " ".join(f"{v:+.2f}" for v in self.m.s))
            self.m.release()
            self.dirty = True

    def on_key(self, window: Any, key: int, scancode: int, action: int, mods: int) -> None:
        import glfw

        if action != glfw.PRESS:
            return
        if key == glfw.KEY_R:
            self.m.reset()
            self.dirty = True
        elif key == glfw.KEY_ESCAPE:
            glfw.set_window_should_close(window, True)


def draw_frame(renderer: FaceRenderer, overlay: PointOverlay, m: Manipulation) -> None:
    """The face at the current weights and the markers over it."""
    renderer.draw(m.weights)
    overlay.draw(renderer.fbo, *m.overlay_points())


# -- the command ------------------------------------------------------------
def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``manipulate`` to the ``facepuppet`` parser."""
    p = subparsers.add_parser(
        "manipulate", help="pull and pin points of the face (actor + pair tables) in a window, or by a script",
        description="Direct manipulation (Shin & Lee 2009): left-drag a marker to pull it, right-click or "
                    "shift+click to pin one, R resets to neutral, Escape quits. --script runs a JSON list of "
                    "steps through the same code and writes a PNG per step and manipulate.json.")
    p.add_argument("-c", "--character", type=Path, required=True, help="character table (.npz)")
    p.add_argument("--actor", type=Path, required=True, help="actor table (.npz) from train-actor")
    p.add_argument("--pair", type=Path, required=True, help="actor-pair table (.npz) from retarget-actor")
    p.add_argument("--script", type=Path, help="JSON list of steps (pin / unpin / drag / reset)")
    p.add_argument("--out", type=Path, help="where a script writes step PNGs and manipulate.json "
                                            "(default manipulate-out)")
    p.add_argument("--headless", action="store_true", help="render offscreen through EGL (needs --script)")
    p.add_argument("--size", default="960x720", help="window / image size WxH (default 960x720)")
    p.add_argument("--path", choices=("auto", "gpu", "cpu"), default="auto", help="deformation path")
    p.add_argument("--framing", choices=("face", "head"), default="face", help="camera framing (default face)")
    p.set_defaults(func=_manipulate)


def _manipulate(args) -> int:
    from facepuppet.runtime.render.gl_context import GLUnavailable, create_context
    from facepuppet.runtime.render.images import save_png
    from facepuppet.runtime.render.renderer import FaceRenderer

    width, height = parse_size(args.size)
    actor, pair, character = Actor.load(args.actor), ActorPair.load(args.pair), Character.load(args.character)
    steps = read_script(args.script, actor.names) if args.script else None
    if args.headless and steps is None:
        raise UsageError("--headless needs --script (there is no window to click in)")
    out = (args.out or _default_out(args)) if steps is not None else None
    target = create_context(headless=True if args.headless else None, width=width, height=height,
                            title="facepuppet manipulate")
    if target.headless and steps is None:
        target.close()
        raise GLUnavailable("no display for a window; run with --headless --script FILE")
    print(f"manipulate: {'headless (EGL)' if target.headless else 'window'}, {actor.n_markers} markers, "
          f"K = {actor.n_actuations}, {character.n_shapes} shapes of {character.name!r}", flush=True)
    renderer = overlay = None
    try:
        screen = None if target.headless else target.ctx.screen
        if screen is not None:
            import glfw

            width, height = glfw.get_framebuffer_size(target.window)
        renderer = FaceRenderer(target.ctx, character, width, height, path=args.path, target_fbo=screen,
                                framing=args.framing)
        vp = renderer.camera.view_projection
        overlay = PointOverlay(target.ctx, vp)
        m = Manipulation(actor, pair, character, ScreenView(vp, width, height))
        if steps is not None:
            _run_script(m, steps, renderer, overlay, target, out, save_png)
        else:
            _interactive(m, renderer, overlay, target)
    finally:
        for obj in (overlay, renderer):
            if obj is not None:
                obj.release() if obj is overlay else obj.close()
        target.close()
    return 0


def _default_out(args) -> Path:
    """``manipulate-out``, under the output policy (refused when not empty, unless --force)."""

    out = Path("manipulate-out")
    check_path("--out (default)", "dir", out, bool(getattr(args, "force", False)))
    return out


def _run_script(m, steps, renderer, overlay, target, out: Path, save_png) -> None:
    out.mkdir(parents=True, exist_ok=True)
    records = []
    started = time.perf_counter()
    for n, step in enumerate(steps):
        def draw(n=n):
            draw_frame(renderer, overlay, m)
            save_png(out / f"step_{n:02d}.png", renderer.read_pixels())
            target.swap()
        records.append(run_step(m, step, draw))

    text = json.dumps({"markers": list(m.actor.names), "shapes": list(m.pair.shape_names), "steps": records})
    write_atomic(out / "manipulate.json", lambda temp: temp.write_text(text))
    print(f"manipulate: {len(steps)} steps in {time.perf_counter() - started:.2f} s; PNGs and manipulate.json "
          f"in {out}")


def _interactive(m, renderer, overlay, target) -> None:
    import glfw

    win_w, win_h = glfw.get_window_size(target.window)
    controls = WindowControls(m, (renderer.width / max(win_w, 1), renderer.height / max(win_h, 1)))
    controls.install(target.window)
    print("manipulate: left-drag pulls a marker, right-click / shift+click pins, R resets, Escape quits", flush=True)
    while not target.should_close():
        if controls.dirty:
            draw_frame(renderer, overlay, m)
            target.swap()
            controls.dirty = False
        glfw.wait_events_timeout(0.05)
