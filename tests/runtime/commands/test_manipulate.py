"""Direct manipulation: cursor -> pick -> drag target -> solve -> weights; scripts headless; the glfw window on Xvfb."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.actuation.manipulation import Manipulation, ScreenView, read_script
from facepuppet.runtime.actuation.pair import ActorPair
from facepuppet.runtime.commands import manipulate
from facepuppet.runtime.model.character import MATERIAL_KINDS, Character, sparse_deltas
from facepuppet.runtime.model.geometry import vertex_normals

GRID = 21
CENTRES = [(-3.0, -4.0), (3.0, -4.0), (0.0, 3.0), (-3.5, 4.5)]      # one local actuation around each
DIRECTIONS = [(-0.6, -0.4, 0.3), (0.6, -0.4, 0.3), (0.0, 0.8, 0.2), (0.0, -0.5, 0.5)]
MARKERS = np.array([i * GRID + j for i in range(1, GRID, 3) for j in range(1, GRID, 3)])   # a 7 x 7 layout


def bump_face() -> Character:
    """A curved 21 x 21 sheet facing +z (cm) whose shapes each move one region of the face."""
    x, y = np.meshgrid(np.linspace(-6, 6, GRID), np.linspace(-7, 7, GRID))
    v = np.c_[x.ravel(), y.ravel(), 3.0 - 0.04 * (x.ravel() ** 2 + y.ravel() ** 2)].astype(np.float32)
    idx = np.arange(GRID * GRID).reshape(GRID, GRID)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    tris = np.r_[np.c_[a, b, d], np.c_[a, d, c]].astype(np.uint32)
    if vertex_normals(v, tris)[GRID * GRID // 2, 2] < 0:
        tris = tris[:, ::-1].copy()
    dense = np.stack([np.exp(-((v[:, 0] - cx) ** 2 + (v[:, 1] - cy) ** 2) / 6.0)[:, None] * np.asarray(dv)
                      for (cx, cy), dv in zip(CENTRES, DIRECTIONS)]).astype(np.float32)
    n0 = vertex_normals(v, tris)
    normals = np.stack([vertex_normals(v + dd, tris) - n0 for dd in dense])
    offsets, indices, both = sparse_deltas(np.concatenate([dense, normals], axis=2), tolerance=1e-6)
    return Character(name="bumps", units="cm", vertices=v, triangles=tris,
                     triangle_material=np.zeros(len(tris), np.uint16),
                     vertex_color=np.full((len(v), 3), 0.6, np.float32), material_names=("skin",),
                     material_params=np.array([[0.1, 10, MATERIAL_KINDS["skin"], 0]], np.float32),
                     pivot=np.zeros(3, np.float32), shape_names=("a", "b", "c", "d"), delta_offsets=offsets,
                     delta_indices=indices, delta_positions=np.ascontiguousarray(both[:, :3]),
                     delta_normals=np.ascontiguousarray(both[:, 3:]))


def actor_and_pair(character: Character) -> tuple[Actor, ActorPair]:
    """An actor whose markers sit on MARKERS (mm, 10x the cm) with actuation k = shape k, nonlinear in s."""
    k = character.n_shapes
    dense = character.dense_deltas().astype(np.float64)[:, MARKERS] * 10.0
    cubic = np.zeros((3, k, len(MARKERS), 3))
    cubic[2], cubic[1] = 0.8 * dense, 0.2 * dense                  # x = 0.2 s^2 + 0.8 s per unit of shape
    names = tuple(f"m{i:02d}" for i in range(len(MARKERS)))
    actor = Actor(names=names, units="mm", neutral=character.vertices[MARKERS] * 10.0, cubic=cubic,
                  unmixing=np.eye(k), class_axes=np.eye(3)[[0, 1, 2, 0]], class_marker=np.arange(k),
                  head_markers=np.array([0, 6, 42]), s_lower=np.full(k, -0.3), s_upper=np.full(k, 1.3))
    pair_cubic = np.zeros((3, k, k))
    pair_cubic[2], pair_cubic[1] = 0.8 * np.eye(k), 0.2 * np.eye(k)     # weights follow the marker motion
    pair = ActorPair(cubic=pair_cubic, shape_names=character.shape_names, marker_names=names,
                     marker_vertices=MARKERS, similarity=np.diag([0.1, 0.1, 0.1, 1.0]), s_lower=actor.s_lower,
                     s_upper=actor.s_upper)
    return actor, pair


@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    character = bump_face()
    actor, pair = actor_and_pair(character)
    root = tmp_path_factory.mktemp("manipulate")
    return {"character": character.save(root / "face.npz"), "actor": actor.save(root / "actor.npz"),
            "pair": pair.save(root / "pair.npz"), "objects": (character, actor, pair)}


def nearest_marker(point) -> int:
    return int(np.argmin(np.linalg.norm(bump_face().vertices[MARKERS, :2] - point, axis=1)))


def test_drag_one_point_the_face_follows_and_pins_hold():
    character = bump_face()
    actor, pair = actor_and_pair(character)
    m = Manipulation(actor, pair, character)
    rest = m.marker_positions()
    i = nearest_marker(CENTRES[2])                     # in the middle of actuation "c"
    goal = rest[i] + 0.7 * np.asarray(DIRECTIONS[2])
    m._begin(i)
    for t in range(1, 9):
        m.drag_to(rest[i] + (goal - rest[i]) * t / 8)
    moved = m.marker_positions() - rest
    assert np.linalg.norm(moved[i] - (goal - rest[i])) < 0.25 * np.linalg.norm(goal - rest[i])
    assert m.weights[2] > 0.4 and np.abs(np.delete(m.weights, 2)).max() < 0.2 * m.weights[2]
    dist = np.linalg.norm(rest - rest[i], axis=1)
    near = np.argsort(dist)[1:5]
    cos = moved[near] @ moved[i] / (np.linalg.norm(moved[near], axis=1) * np.linalg.norm(moved[i]))
    assert cos.min() > 0.9                              # neighbours move the same way
    far = dist > 8.0
    assert np.linalg.norm(moved[far], axis=1).max() < 0.1 * np.linalg.norm(moved[i])
    m.release()
    # a pin next to the next drag holds its marker where it was pinned
    m.reset()
    j, pin = nearest_marker(CENTRES[0]), nearest_marker((CENTRES[0][0] + 2.0, CENTRES[0][1]))
    free = Manipulation(actor, pair, character)
    for state in (free, m):
        if state is m:
            assert m.toggle_pin(pin)
        state._begin(j)
        for t in range(1, 9):
            state.drag_to(rest[j] + np.asarray(DIRECTIONS[0]) * 0.8 * t / 8)
    moved_free = np.linalg.norm(free.marker_positions()[pin] - rest[pin])
    moved_pinned = np.linalg.norm(m.marker_positions()[pin] - rest[pin])
    assert moved_free > 0.1 and moved_pinned < 0.3 * moved_free, (moved_free, moved_pinned)
    m.release()
    # with the pin held, a drag elsewhere on the face still reaches its target
    i = nearest_marker(CENTRES[2])
    m._begin(i)
    for t in range(1, 9):
        m.drag_to(rest[i] + np.asarray(DIRECTIONS[2]) * 0.7 * t / 8)
    assert np.linalg.norm(m.marker_positions()[i] - rest[i] - np.asarray(DIRECTIONS[2]) * 0.7) < 0.15
    assert np.linalg.norm(m.marker_positions()[pin] - rest[pin]) < 0.3 * moved_free


def test_cursor_path_picks_unprojects_and_solves(egl_ctx):
    from facepuppet.runtime.render.renderer import FaceRenderer

    character = bump_face()
    actor, pair = actor_and_pair(character)
    renderer = FaceRenderer(egl_ctx, character, 320, 320, path="cpu", framing="face")
    view = ScreenView(renderer.camera.view_projection, 320, 320)
    np.testing.assert_allclose(view.project(character.vertices[:5])[0], renderer.project(character.vertices[:5]),
                               atol=1e-3)
    m = Manipulation(actor, pair, character, view)
    rest = m.marker_positions()
    pixels, depth = view.project(rest)
    np.testing.assert_allclose(view.unproject(pixels[7], depth[7]), rest[7], atol=1e-4)
    i = nearest_marker(CENTRES[2])
    assert m.pick(pixels[i] + [4.0, -3.0]) == i
    assert m.pick([-500.0, -500.0]) is None
    assert m.press(pixels[i] + [2.0, 0.0]) == i
    start_w = m.weights.copy()
    for dy in range(-2, -22, -2):                       # upwards on screen: actuation "c" raises the marker
        assert m.move(pixels[i] + [2.0, dy])
    assert m.weights[2] > start_w[2] + 0.2
    seen = view.project(m.marker_positions()[i])[0][0]
    assert pixels[i][1] - 22 < seen[1] < pixels[i][1] - 10   # the point went up towards the cursor (20 px)
    m.release()
    assert not m.move(pixels[i])                        # no drag, no solve
    renderer.close()


@pytest.mark.gl
def test_headless_script_writes_pictures_and_weights(tables, tmp_path, capsys):
    script = tmp_path / "steps.json"
    pin = f"m{nearest_marker((CENTRES[0][0] + 2.0, CENTRES[0][1])):02d}"
    drag = f"m{nearest_marker(CENTRES[2]):02d}"
    script.write_text(json.dumps([{"pin": pin}, {"drag": drag, "by": [0.0, 0.5, 0.1]},
                                  {"drag": drag, "pixels": [0, -20], "steps": 4}, {"reset": True}]))
    out = tmp_path / "out"
    args = _parse(["manipulate", "-c", str(tables["character"]), "--actor", str(tables["actor"]), "--pair",
                   str(tables["pair"]), "--headless", "--script", str(script), "--out", str(out), "--size",
                   "240x200", "--path", "cpu"])
    assert args.func(args) == 0
    assert "headless (EGL)" in capsys.readouterr().out
    steps = json.loads((out / "manipulate.json").read_text())["steps"]
    assert steps[0]["pins"] == [pin] and steps[3]["pins"] == [] and not any(steps[3]["weights"])
    assert steps[1]["weights"][2] > 0.3 and steps[2]["weights"][2] > steps[1]["weights"][2]
    goal, reached = np.array(steps[1]["actor_goal"]), np.array(steps[1]["actor_reached"])
    assert np.linalg.norm(goal - reached) < 0.3 * 5.0   # within 30 % of the 0.5 cm (5 mm) pull
    images = [np.asarray(Image.open(out / f"step_{n:02d}.png")) for n in range(4)]
    assert images[0].shape == (200, 240, 3)
    assert np.abs(images[1].astype(int) - images[0]).max() > 30          # the face (and the dots) changed
    overlay_yellow = (images[0][..., 0] > 200) & (images[0][..., 1] > 170) & (images[0][..., 2] < 120)
    assert overlay_yellow.sum() > 49 * 10                                # 49 marker dots drawn


def test_script_errors_name_the_file_step_and_field(tables, tmp_path):
    actor = tables["objects"][1]
    path = tmp_path / "bad.json"
    for content, message in [({"drag": "m00"}, "expected a JSON list"),
                             ([{"drag": "nose", "by": [0, 0, 1]}], r"step 0: field 'drag': no marker named 'nose'"),
                             ([{"pin": "m00"}, {"drag": "m01", "by": [0, 1]}], r"step 1: a drag needs one of"),
                             ([{"wave": 1}], r"step 0: expected an object with exactly one of")]:
        path.write_text(json.dumps(content))
        with pytest.raises(ValueError, match=message):
            read_script(path, actor.names)
    args = _parse(["manipulate", "-c", str(tables["character"]), "--actor", str(tables["actor"]), "--pair",
                   str(tables["pair"]), "--headless"])
    with pytest.raises(ValueError, match="--headless needs --script"):
        args.func(args)


def _parse(argv):
    import argparse

    parser = argparse.ArgumentParser()
    manipulate.register(parser.add_subparsers())
    return parser.parse_args(argv)


def window_scenario() -> None:
    """Drive the glfw callbacks of a real window (run in a child process: GLX beside EGL in one process dies)."""
    import glfw

    from facepuppet.runtime.render.gl_context import create_context
    from facepuppet.runtime.render.renderer import FaceRenderer

    character = bump_face()
    actor, pair = actor_and_pair(character)
    target = create_context(headless=False, width=320, height=240, title="test manipulate")
    try:
        assert target.window is not None
        width, height = glfw.get_framebuffer_size(target.window)
        renderer = FaceRenderer(target.ctx, character, width, height, path="cpu", target_fbo=target.ctx.screen,
                                framing="face")
        overlay = manipulate.PointOverlay(target.ctx, renderer.camera.view_projection)
        m = Manipulation(actor, pair, character, ScreenView(renderer.camera.view_projection, width, height))
        controls = manipulate.WindowControls(m, log=lambda line: None)
        controls.install(target.window)
        manipulate.draw_frame(renderer, overlay, m)
        before = renderer.read_pixels()
        i = nearest_marker(CENTRES[2])
        start = m.view.project(m.marker_positions()[i])[0][0]
        win = target.window
        controls.on_cursor_pos(win, *start)
        controls.on_mouse_button(win, glfw.MOUSE_BUTTON_LEFT, glfw.PRESS, 0)
        assert m.dragging == i
        for dy in range(-2, -22, -2):
            controls.on_cursor_pos(win, start[0], start[1] + dy)
        assert controls.dirty and m.weights[2] > 0.2, m.weights
        controls.on_mouse_button(win, glfw.MOUSE_BUTTON_LEFT, glfw.RELEASE, 0)
        manipulate.draw_frame(renderer, overlay, m)
        after = renderer.read_pixels()
        target.swap()
        assert np.abs(after.astype(int) - before).max() > 30
        # right-click pins, R resets (and clears the pins), Escape asks the window to close
        controls.on_cursor_pos(win, *m.view.project(m.marker_positions()[3])[0][0])
        controls.on_mouse_button(win, glfw.MOUSE_BUTTON_RIGHT, glfw.PRESS, 0)
        assert list(m.pins) == [3]
        controls.on_key(win, glfw.KEY_R, 0, glfw.PRESS, 0)
        assert not m.pins and not m.weights.any()
        controls.on_key(win, glfw.KEY_ESCAPE, 0, glfw.PRESS, 0)
        assert target.should_close()
        overlay.release()
        renderer.close()
        print(f"window scenario: ok, weight c {m.weights[2]:.2f} after R")
    finally:
        target.close()


def test_window_callbacks_drag_a_point_on_a_real_glfw_window(x_display):
    env = {**os.environ, "DISPLAY": x_display}
    env.pop("WAYLAND_DISPLAY", None)
    code = ("import runpy, sys; sys.path.insert(0, sys.argv[2]); "
            "runpy.run_path(sys.argv[1])['window_scenario']()")
    tests = next(p for p in Path(__file__).resolve().parents if p.name == "tests")
    result = subprocess.run([sys.executable, "-c", code, str(Path(__file__)), str(tests)], env=env,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "window scenario: ok" in result.stdout


def test_manipulate_command_runs_a_script_in_a_window(x_display, tables, tmp_path):
    env = {**os.environ, "DISPLAY": x_display}
    env.pop("WAYLAND_DISPLAY", None)
    script = tmp_path / "steps.json"
    script.write_text(json.dumps([{"drag": f"m{nearest_marker(CENTRES[1]):02d}", "pixels": [10, 7]}]))
    out = tmp_path / "out"
    result = subprocess.run(
        [sys.executable, "-m", "facepuppet", "manipulate", "-c", str(tables["character"]), "--actor",
         str(tables["actor"]), "--pair", str(tables["pair"]), "--script", str(script), "--out", str(out),
         "--size", "240x200", "--path", "cpu"], env=env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "manipulate: window" in result.stdout
    step = json.loads((out / "manipulate.json").read_text())["steps"][0]
    assert step["weights"][1] > 0.05 and np.asarray(Image.open(out / "step_00.png")).shape == (200, 240, 3)
