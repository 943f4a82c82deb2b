"""Direct manipulation of a face through the actor's parameters (Shin & Lee 2009, §6.1).

The chain for every cursor event is small and testable without a window:

    cursor (pixels) -> :meth:`Manipulation.pick` (nearest shown marker, screen space)
    -> :meth:`Manipulation.move` (unproject at the marker's depth: a point in the view plane)
    -> drag target in the actor's head coordinates (inverse of the pair's similarity)
    -> :meth:`MarkerSolver.solve_constraints` (eq 5, warm-started, pins held)
    -> s -> :meth:`ActorPair.weights` -> the character's weights.

The markers shown are the character vertices the actor's markers were mapped
to (``pair.marker_vertices``), on the deformed mesh. A drag moves the mesh
point by Δ in character space; the actor marker's target is its position at
the press plus the similarity's inverse of Δ. Pins hold the actor marker where
it was when pinned. Scripts (:func:`read_script`, :func:`run_step`) make the
same calls; the window and the command are :mod:`~facepuppet.runtime.commands.manipulate`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.actuation.pair import ActorPair
from facepuppet.runtime.actuation.solver import MarkerSolver
from facepuppet.runtime.errors import InputFileError, UsageError
from facepuppet.runtime.files.input_files import regular_file
from facepuppet.runtime.files.json_limits import JsonTextError, loads_limited
from facepuppet.runtime.model.character import Character

PICK_RADIUS = 30.0   # pixels: a click farther than this from every marker picks nothing
DRAG_STEPS = 8       # cursor events a scripted drag is cut into
_COLOURS = {"marker": (1.0, 0.85, 0.2), "pinned": (0.25, 0.55, 1.0), "dragged": (1.0, 0.25, 0.2),
            "target": (0.3, 1.0, 0.4)}


class ScreenView:
    """Pixels <-> character space for a still head, from a renderer's camera.

    Parameters
    ----------
    view_projection : ndarray of shape (4, 4), float, character space -> clip space
    width, height : int, pixels
    """

    def __init__(self, view_projection: np.ndarray, width: int, height: int) -> None:
        self.matrix = np.asarray(view_projection, dtype=np.float64)
        self.inverse = np.linalg.inv(self.matrix)
        self.width, self.height = int(width), int(height)

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (n, 2) float64 (x right, y down) and NDC depth (n,) of points (n, 3), character units."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        clip = np.c_[p, np.ones(len(p))] @ self.matrix.T
        ndc = clip[:, :3] / clip[:, 3:4]
        return np.c_[(ndc[:, 0] + 1) / 2 * self.width, (1 - ndc[:, 1]) / 2 * self.height], ndc[:, 2]

    def unproject(self, pixel: np.ndarray, depth: float) -> np.ndarray:
        """The character-space point (3,) float64 under ``pixel`` (x, y) at NDC depth ``depth``."""
        x, y = float(pixel[0]), float(pixel[1])
        ndc = np.array([2 * x / self.width - 1, 1 - 2 * y / self.height, depth, 1.0])
        p = self.inverse @ ndc
        return p[:3] / p[3]


class Manipulation:
    """Direct-manipulation state: actuations s, pins, the drag in progress.

    Parameters
    ----------
    actor : Actor
    pair : ActorPair, made for ``actor`` and ``character``
    character : Character
    view : ScreenView or None (only the pixel methods need it)
    iterations : int, LM budget per solve (one solve per cursor event)
    pick_radius : float, pixels
    hold : float, weight of every other marker at its place at the press (the dragged one weighs 1):
        the face changes as little as it can. 0 lets the far face swing freely (on the AnimFace
        actor the far markers then moved up to 4x the drag); 0.005 keeps them near 0.2x the drag
        while the dragged marker gets within ~6 % (median) of its target

    Attributes
    ----------
    s : ndarray of shape (K,), float64
    weights : ndarray of shape (n_shapes,), float32, the character's weights
    pins : dict {marker index: (3,) float64 actor head-coordinate position held}
    dragging : int or None, the marker being pulled
    target : ndarray of shape (3,), float64, the drag target in character space, or None
    """

    def __init__(self, actor: Actor, pair: ActorPair, character: Character, view: ScreenView | None = None,
                 iterations: int = 30, pick_radius: float = PICK_RADIUS, hold: float = 0.005) -> None:
        if tuple(pair.marker_names) != tuple(actor.names) or pair.cubic.shape[1] != actor.n_actuations:
            raise UsageError(f"manipulate: the pair table was not made for this actor ({len(pair.marker_names)} "
                             f"markers, K={pair.cubic.shape[1]} vs {actor.n_markers}, K={actor.n_actuations})")
        if tuple(pair.shape_names) != tuple(character.shape_names):
            raise UsageError(f"manipulate: the pair table drives {len(pair.shape_names)} shapes, the character "
                             f"has {character.n_shapes} (or other names); retarget the actor to this character")
        if pair.marker_vertices.max(initial=0) >= character.n_vertices:
            raise UsageError("manipulate: pair marker_vertices index past the character's vertices")
        self.actor, self.pair, self.view = actor, pair, view
        self.solver = MarkerSolver(actor)
        self.iterations = iterations
        self.pick_radius = pick_radius
        self.hold = hold
        mv = pair.marker_vertices.astype(np.int64)
        self._rest = character.vertices[mv].astype(np.float64)                 # (m, 3)
        self._basis = character.dense_deltas()[:, mv, :].astype(np.float64)    # (S, m, 3)
        self._to_actor = np.linalg.inv(pair.similarity[:3, :3].astype(np.float64))
        self.reset()

    def reset(self) -> None:
        """Neutral face, no pins, no drag."""
        self.solver.reset()
        self.s = np.zeros(self.actor.n_actuations)
        self.weights = self.pair.weights(self.s)
        self.pins: dict[int, np.ndarray] = {}
        self.release()

    def marker_positions(self) -> np.ndarray:
        """Shown markers: the mapped vertices on the deformed mesh, (n_markers, 3) float64, character units."""
        return self._rest + np.tensordot(self.weights.astype(np.float64), self._basis, axes=1)

    def index(self, name: str) -> int:
        """Marker index of an actor marker name (ValueError naming the known ones)."""
        try:
            return self.actor.names.index(name)
        except ValueError:
            raise ValueError(f"no marker named {name!r}; the actor has {', '.join(self.actor.names)}") from None

    # -- cursor events ------------------------------------------------------
    def pick(self, cursor: np.ndarray) -> int | None:
        """The marker nearest ``cursor`` (x, y pixels) on screen, or None beyond ``pick_radius``."""
        pixels, _ = self._need_view().project(self.marker_positions())
        d = np.linalg.norm(pixels - np.asarray(cursor, dtype=np.float64), axis=1)
        i = int(np.argmin(d))
        return i if d[i] <= self.pick_radius else None

    def press(self, cursor: np.ndarray) -> int | None:
        """Start pulling the marker under ``cursor``; returns it (None: nothing picked)."""
        i = self.pick(cursor)
        if i is not None:
            pixels, depth = self._need_view().project(self.marker_positions()[i])
            self._begin(i)
            self._grab = (np.asarray(cursor, dtype=np.float64) - pixels[0], float(depth[0]))
        return i

    def move(self, cursor: np.ndarray) -> bool:
        """Cursor moved to (x, y) pixels: drag target in the view plane at the marker's depth; solve. True if solved."""
        if self.dragging is None:
            return False
        offset, depth = self._grab
        return self.drag_to(self._need_view().unproject(np.asarray(cursor, dtype=np.float64) - offset, depth))

    def release(self) -> None:
        """End the drag (s stays)."""
        self.dragging = None
        self.target = None
        self._start = None

    def toggle_pin(self, marker: int) -> bool:
        """Pin ``marker`` where it is now, or unpin it; returns True when it is now pinned."""
        if marker in self.pins:
            del self.pins[marker]
            return False
        self.pins[marker] = self.actor.evaluate(self.s)[marker]
        return True

    # -- the same path without pixels (scripts) ------------------------------
    def _begin(self, marker: int) -> None:
        self.dragging = int(marker)
        self._held = self.actor.evaluate(self.s)
        self._start = (self.marker_positions()[marker], self._held[marker])

    def drag_to(self, target: np.ndarray) -> bool:
        """Pull the dragged marker towards ``target`` (3,) character units; solve eq 5 and update the weights."""
        if self.dragging is None:
            return False
        self.target = np.asarray(target, dtype=np.float64)
        shown, actor_start = self._start
        goal = actor_start + self._to_actor @ (self.target - shown)      # character Δ -> actor head coordinates
        pins = {i: p for i, p in self.pins.items() if i != self.dragging}
        self.s = self.solver.solve_constraints([(self.dragging, goal)], pins=pins, hold=self.hold,
                                               hold_at=self._held, iterations=self.iterations)
        self.weights = self.pair.weights(self.s)                         # Shin & Lee §6.2
        return True

    def actor_goal(self) -> np.ndarray | None:
        """The dragged actor marker's current target, (3,) float64 actor head coordinates, or None."""
        if self.dragging is None:
            return None
        shown, actor_start = self._start
        return actor_start + self._to_actor @ (self.target - shown) if self.target is not None else actor_start

    def overlay_points(self) -> tuple[np.ndarray, np.ndarray]:
        """Points (n, 3) float32 character units and colours (n, 3) float32 to draw over the face."""
        pos = self.marker_positions()
        colour = np.tile(np.asarray(_COLOURS["marker"], np.float32), (len(pos), 1))
        for i in self.pins:
            colour[i] = _COLOURS["pinned"]
        if self.dragging is not None:
            colour[self.dragging] = _COLOURS["dragged"]
            if self.target is not None:
                pos = np.vstack([pos, self.target])
                colour = np.vstack([colour, _COLOURS["target"]])
        return pos.astype(np.float32), colour.astype(np.float32)

    def _need_view(self) -> ScreenView:
        if self.view is None:
            raise ValueError("Manipulation: pixel events need a ScreenView (view=...)")
        return self.view


# -- scripts ----------------------------------------------------------------
_ACTIONS = ("pin", "unpin", "drag", "reset")
MAX_SCRIPT_BYTES = 4 << 20  # a script of a few thousand steps is a few hundred kB


def read_script(path: str | Path, names: Sequence[str]) -> list[dict]:
    """A manipulation script: a JSON list of steps, checked against the actor's marker names.

    Steps: ``{"pin": NAME}``, ``{"unpin": NAME}``, ``{"reset": true}``, ``{"drag": NAME, "to": [x, y, z]}``
    (character units), ``{"drag": NAME, "by": [dx, dy, dz]}`` (character units) or
    ``{"drag": NAME, "pixels": [dx, dy]}`` (through the cursor path); a drag may give ``"steps": n``.
    """
    path = regular_file(path, "manipulation script")
    size = path.stat().st_size
    if size > MAX_SCRIPT_BYTES:
        raise InputFileError(f"{path}: {size} bytes; a manipulation script is at most {MAX_SCRIPT_BYTES}")
    try:
        steps = loads_limited(path.read_bytes(), str(path), max_bytes=MAX_SCRIPT_BYTES)
    except JsonTextError as exc:
        raise InputFileError(f"{path}: not a readable JSON list of steps ({exc.problem})") from None
    if not isinstance(steps, list):
        raise InputFileError(f"{path}: expected a JSON list of steps, got {type(steps).__name__}")
    for n, step in enumerate(steps):
        where = f"{path}: step {n}"
        actions = [a for a in _ACTIONS if isinstance(step, dict) and a in step]
        if len(actions) != 1:
            raise InputFileError(f"{where}: expected an object with exactly one of {_ACTIONS}, got {step!r}")
        action = actions[0]
        if action != "reset" and step[action] not in names:
            raise InputFileError(f"{where}: field {action!r}: no marker named {step[action]!r}")
        if action == "drag":
            moves = [m for m in ("to", "by", "pixels") if m in step]
            size = 2 if moves == ["pixels"] else 3
            if len(moves) != 1 or not _numbers(step[moves[0]], size):
                raise InputFileError(f"{where}: a drag needs one of 'to' / 'by' (3 numbers) or 'pixels' (2 numbers), "
                                     f"got {step!r}")
            if not (isinstance(step.get("steps", DRAG_STEPS), int) and step.get("steps", DRAG_STEPS) >= 1):
                raise InputFileError(f"{where}: field 'steps': expected an int >= 1, got {step['steps']!r}")
    return steps


def _numbers(value, size: int) -> bool:
    return (isinstance(value, list) and len(value) == size
            and all(isinstance(v, (int, float)) and np.isfinite(v) for v in value))


def run_step(m: Manipulation, step: dict, draw: Callable[[], None] = lambda: None) -> dict:
    """Apply one script step to ``m`` (the same calls the window makes); ``draw`` is called before a drag ends.

    Returns a record: the step, s, the weights, and for a drag the dragged marker's actor goal and reached position.
    """
    record: dict = {"step": step}
    if "reset" in step:
        m.reset()
    elif "pin" in step:
        i = m.index(step["pin"])
        if i not in m.pins:
            m.toggle_pin(i)
    elif "unpin" in step:
        m.pins.pop(m.index(step["unpin"]), None)
    else:
        i, n = m.index(step["drag"]), int(step.get("steps", DRAG_STEPS))
        if "pixels" in step:
            start = m._need_view().project(m.marker_positions()[i])[0][0]
            if m.press(start) != i:
                raise InputFileError(f"script drag {step['drag']!r}: another marker is nearer its own pixel")
            for t in range(1, n + 1):
                m.move(start + np.asarray(step["pixels"], dtype=np.float64) * t / n)
        else:
            m._begin(i)
            start = m.marker_positions()[i]
            goal = np.asarray(step["to"], dtype=np.float64) if "to" in step else start + np.asarray(step["by"])
            for t in range(1, n + 1):
                m.drag_to(start + (goal - start) * t / n)
        goal = m.actor_goal()
        record.update(marker=step["drag"], actor_goal=goal.tolist(),
                      actor_reached=m.actor.evaluate(m.s)[i].tolist(), shown=m.marker_positions()[i].tolist(),
                      target=None if m.target is None else m.target.tolist())
        draw()
        m.release()
        record.update(s=m.s.tolist(), weights=m.weights.tolist(), pins=sorted(m.actor.names[p] for p in m.pins))
        return record
    draw()
    record.update(s=m.s.tolist(), weights=m.weights.tolist(), pins=sorted(m.actor.names[p] for p in m.pins))
    return record
