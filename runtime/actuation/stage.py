"""The ``solve`` stage of the live chain: marker frames -> actuations s -> character weights and head pose.

Each accepted frame's markers (capture coordinates, NaN = occluded) are
matched to the actor's markers by name, brought into head coordinates by a
Kabsch fit of the visible head markers to the actor's neutral, solved for s
(:class:`~facepuppet.runtime.actuation.solver.MarkerSolver`, eq 5, warm-started) and
mapped to the character's weights through the pair table (§6.2). The Kabsch
rotation is the head's turn away from the actor's neutral; carried into the
character's axes through the pair's similarity, it becomes the frame's head
rotation, so the character's head turns with the performer's.

A new layout (marker-name tuple) is checked once against the actor's names:
names the actor lacks and actor markers the layout lacks are reported once;
a layout that shares fewer than the solve needs (:meth:`ActorRetarget.needs`:
3 of the actor's head markers for the pose and ceil(K / 3) others, three
coordinates each, for K actuations) is refused, its frames counted in
``layout_refused``. The first usable frame of each layout is also checked for
scale: when its shared markers spread more than 3x more or less than the
actor's neutral (frames in mm to an actor in cm), the stage warns once.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

import numpy as np

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.actuation.pair import ActorPair
from facepuppet.runtime.actuation.saturation import SaturationCount
from facepuppet.runtime.actuation.solver import MarkerSolver
from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.model.geometry import matrix_to_quat
from facepuppet.runtime.model.rigid import kabsch

MAX_COORDINATE = 1e6  # capture units (mm: a kilometre): a marker beyond it is a damaged sample, not a face
logger = logging.getLogger(__name__)
#: how far (as a ratio either way) a frame's marker spread may be from the actor's before a warning
SCALE_WARN_RATIO = 3.0


class ActorRetarget:
    """The ``solve`` stage (a :class:`~facepuppet.runtime.protocols.Stage`): marker frame -> weights frame.

    Parameters
    ----------
    actor : Actor
    pair : ActorPair, made for this actor (same markers and K)
    solver : MarkerSolver or None (default settings)
    log : callable taking one line: the layout reports and the scale warning

    Attributes
    ----------
    target_names : tuple of n_shapes str
    s : ndarray of shape (K,), float64, the last solved actuations
    head_rotation : ndarray of shape (4,), float64, quaternion (x, y, z, w) in the character's axes: the
        last frame's head rotation away from the actor's neutral (identity before any frame)
    counters : dict, ``frames``, ``no_markers``, ``no_head_pose``, ``layout_refused``; ``out_of_range``: frames
        with a marker coordinate beyond ``MAX_COORDINATE`` or infinite (those markers are treated as occluded);
        ``no_solution``: frames whose head fit or solve came out non-finite (skipped, previous weights kept)
    saturation : SaturationCount, the solved frames whose weights sit at 1.0 or whose s sits at a bound, per name
    """

    name = "solve"

    def __init__(self, actor: Actor, pair: ActorPair, solver: MarkerSolver | None = None,
                 log: Callable[[str], None] = logger.warning) -> None:
        if tuple(pair.marker_names) != tuple(actor.names) or pair.cubic.shape[1] != actor.n_actuations:
            raise UsageError("ActorRetarget: the pair table was not made for this actor "
                             f"({len(pair.marker_names)} markers / K={pair.cubic.shape[1]} vs "
                             f"{actor.n_markers} / K={actor.n_actuations})")
        self.actor = actor
        self.pair = pair
        self.solver = solver or MarkerSolver(actor)
        self.target_names = tuple(pair.shape_names)
        self.s = np.zeros(actor.n_actuations)
        self.counters = {"frames": 0, "no_markers": 0, "no_head_pose": 0, "layout_refused": 0,
                         "out_of_range": 0, "no_solution": 0}
        self.log = log
        self._names: tuple[str, ...] | None = None
        self._index: np.ndarray | None = None
        self._refused = False
        self._checked: set[tuple[str, ...]] = set()      # layouts reported (bounded: see _order)
        self._scaled: set[tuple[str, ...]] = set()
        self._scale_pending = False  # the current layout's first usable frame is still to be checked for units
        self._head = np.asarray(actor.head_markers, dtype=np.int64)
        self._neutral = actor.neutral.astype(np.float64)
        self.head_rotation = np.array([0.0, 0.0, 0.0, 1.0])
        # the similarity's rotation (actor head axes -> character axes), its scale divided out
        linear = np.asarray(pair.similarity, np.float64)[:3, :3]
        scale = abs(np.linalg.det(linear)) ** (1.0 / 3.0)
        self._axes = linear / scale if scale > 0 else np.eye(3)
        lower, upper = self.solver.bounds          # and the pair's fitted range, to which weights() clamps s
        self.saturation = SaturationCount(self.target_names, actor.n_actuations, np.maximum(lower, pair.s_lower),
                                          np.minimum(upper, pair.s_upper))

    def needs(self) -> tuple[int, int]:
        """(head markers, other markers) a layout must share with the actor for the solve."""
        return 3, max(1, math.ceil(self.actor.n_actuations / 3))

    def accepts_layout(self, names: tuple[str, ...]) -> bool:
        """Whether frames of this marker layout can be solved (reported once, as a live layout would be)."""
        self._order(tuple(names))
        return not self._refused

    def _order(self, names) -> np.ndarray:
        """Frame marker index of each actor marker (-1 when the frame lacks it), cached per name tuple."""
        if names != self._names:
            lookup = {n: i for i, n in enumerate(names)}
            self._index = np.array([lookup.get(n, -1) for n in self.actor.names])
            self._names = names
            self._refused = self._check_layout(names, self._index)
            self._scale_pending = names not in self._scaled
        return self._index

    def _check_layout(self, names: tuple[str, ...], index: np.ndarray) -> bool:
        """Report a new layout's unmatched and missing names once; True when it shares too few to solve."""
        head = np.zeros(self.actor.n_markers, bool)
        head[self._head] = True
        shared_head = int(np.sum(index[head] >= 0))
        shared_other = int(np.sum(index[~head] >= 0))
        need_head, need_other = self.needs()
        refused = shared_head < need_head or shared_other < need_other
        if names in self._checked:
            return refused
        if len(self._checked) >= 64:           # a sender cycling layouts: keep the set bounded
            self._checked.clear()
        self._checked.add(names)
        known = set(self.actor.names)
        unmatched = [n for n in names if n not in known]
        missing = [n for n, i in zip(self.actor.names, index) if i < 0]
        if refused:
            self.log(f"markers: layout of {len(names)} markers refused: it shares {shared_head} of the actor's "
                     f"{len(self._head)} head markers and {shared_other} others with the actor; the solve needs "
                     f"{need_head} head markers and {need_other} others (K = {self.actor.n_actuations})"
                     + _names_line(unmatched, missing))
        elif unmatched or missing:
            self.log(f"markers: layout of {len(names)} markers matches {len(names) - len(unmatched)} of the "
                     f"actor's {self.actor.n_markers}" + _names_line(unmatched, missing))
        return refused

    def _check_scale(self, names: tuple[str, ...], obs: np.ndarray) -> None:
        """Warn once per layout when the frame's spread is off from the actor neutral's by more than 3x.

        Checked on a layout's first frame only (``_order`` arms it when the layout changes): nothing per frame.
        """
        if not self._scale_pending:
            return
        self._scale_pending = False
        if len(self._scaled) >= 64:
            self._scaled.clear()
        self._scaled.add(names)
        ok = ~np.isnan(obs).any(axis=1)
        if ok.sum() < 3:
            return
        spread = lambda x: float(np.sqrt(np.mean(np.sum((x - x.mean(axis=0)) ** 2, axis=1))))  # noqa: E731
        ours, theirs = spread(obs[ok]), spread(self._neutral[ok])
        if not (ours > 0 and theirs > 0):
            return
        ratio = ours / theirs
        if ratio > SCALE_WARN_RATIO or ratio < 1 / SCALE_WARN_RATIO:
            self.log(f"markers: warning: the frames spread {ratio:.3g}x the actor's neutral ({self.actor.units}): "
                     f"are they in other units? declare them (/facepuppet/markers/units, or --marker-units "
                     f"mm|cm|m) and the run converts them to {self.actor.units}")

    def observed(self, frame: Frame) -> np.ndarray | None:
        """The frame's markers in the actor's order and head coordinates, (n_markers, 3) float64; None if unusable."""
        if frame.markers is None:
            return None
        names = frame.marker_names or tuple(self.actor.names[:len(frame.markers)])
        names = tuple(names)
        index = self._order(names)
        if self._refused:
            self.counters["layout_refused"] += 1
            return None
        obs = np.full((self.actor.n_markers, 3), np.nan)
        ok = index >= 0
        obs[ok] = frame.markers[index[ok]]
        with np.errstate(invalid="ignore"):  # NaN (occluded) compares False, quietly
            absurd = (np.abs(obs) > MAX_COORDINATE).any(axis=1)
        if absurd.any():  # counted once per frame here, where the bad values enter; never warned about
            self.counters["out_of_range"] += 1
            obs[absurd] = np.nan
        self._check_scale(names, obs)
        head_visible = ~np.isnan(obs[self._head]).any(axis=1)
        if head_visible.sum() < 3:
            self.counters["no_head_pose"] += 1
            return None
        h = self._head[head_visible]
        with np.errstate(all="ignore"):
            try:
                r, t = kabsch(self._neutral[h], obs[h])
            except np.linalg.LinAlgError:
                r = t = None
            if r is None or not (np.isfinite(r).all() and np.isfinite(t).all()):
                self.counters["no_solution"] += 1
                return None
            # r takes capture axes to head axes, so the head turned by r^T; in the character's axes A r^T A^T
            self.head_rotation = matrix_to_quat(self._axes @ r.T @ self._axes.T)
            return obs @ r.T + t

    def __call__(self, frame: Frame | None, t: float) -> Frame | None:
        """The stage: the character's weights and head rotation for a new marker frame, else None.

        A frame the solve cannot use (no markers, fewer than 3 head markers visible) counts as no new frame.
        """
        if frame is None:
            return None
        weights = self.apply(frame)
        if weights is None:
            return None
        return Frame(t=frame.t, source=frame.source, channels=self.target_names,
                     weights=np.asarray(weights, np.float32), head_rotation=self.head_rotation,
                     audio_level=frame.audio_level, t_sender=frame.t_sender, number=frame.number)

    def apply(self, frame: Frame) -> np.ndarray | None:
        """Character weights (n_shapes,) float32 for a marker frame, or None to keep the previous ones."""
        self.counters["frames"] += 1
        obs = self.observed(frame)
        if obs is None or np.isnan(obs).all():
            self.counters["no_markers"] += obs is not None
            return None
        with np.errstate(all="ignore"):
            s = self.solver.solve(obs)
            weights = self.pair.weights(s)
        if not (np.isfinite(s).all() and np.isfinite(weights).all()):
            self.counters["no_solution"] += 1
            return None
        self.s = s
        self.saturation.add(s, weights)
        return weights


def _names_line(unmatched: list[str], missing: list[str], shown: int = 8) -> str:
    def some(names):
        return ", ".join(names[:shown]) + (f", ... ({len(names)} in all)" if len(names) > shown else "")
    return ((f"; not the actor's (ignored): {some(unmatched)}" if unmatched else "")
            + (f"; the actor's, not in the layout: {some(missing)}" if missing else ""))
