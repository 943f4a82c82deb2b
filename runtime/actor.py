"""The actor tables and the per-frame marker solve (Shin & Lee 2009, §5 eq 2 and §6.1 eq 5).

Paper symbols -> code names:

    s                actuation parameters                 s           (K,)
    x_i(s)           marker i in head coordinates         evaluate(s) (n_markers, 3)
    a, b, c          cubic coefficients                   actor.cubic[0|1|2]   (3, K, n_markers, 3)
    p_i              observed / dragged marker positions  observed    (n_markers, 3), NaN = not given
    w_i              per-marker weights                   weights     (n_markers,)

Eq 2: x_i(s) = x_i^0 + sum_k a_ik s_k^3 + b_ik s_k^2 + c_ik s_k.
Eq 5: s* = argmin_s sum_i w_i ||x_i(s) - p_i||^2 (+ damping towards the
previous frame and towards neutral), solved with Levenberg-Marquardt on the
analytic Jacobian dx_i/ds_k = 3 a_ik s_k^2 + 2 b_ik s_k + c_ik, bounded by
projection onto [s_lower, s_upper], warm-started, at most ``iterations``
steps per frame.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from scipy.linalg.lapack import dposv as _spd_solve

from .tables import Section, TableSchema, TablesError, hash_inputs, load_tables, register_schema, save_tables

_max, _min = np.maximum.reduce, np.minimum.reduce                   # plain ufunc reductions (no method wrapper)

ACTOR_SCHEMA = register_schema(TableSchema(
    kind="actor",
    sections={
        "neutral": Section("float32", ("n_markers", 3), "marker positions at s = 0, head coordinates"),
        "cubic": Section("float32", (3, "n_actuations", "n_markers", 3), "a, b, c of eq 2"),
        "linear": Section("float32", ("n_actuations", "n_markers", 3), "linear ICA model (comparison)", True),
        "unmixing": Section("float32", ("n_actuations", "n_classes"), "ICA unmixing, normalised"),
        "class_axes": Section("float32", ("n_classes", 3), "class axes on the unit sphere"),
        "class_marker": Section("int32", ("n_classes",), "marker of each class"),
        "head_markers": Section("int32", ("n_head",), "rigid head marker indices"),
        "s_lower": Section("float32", ("n_actuations",), "solver lower bounds"),
        "s_upper": Section("float32", ("n_actuations",), "solver upper bounds"),
    },
    channels=("markers", "actuations"),
    channel_dims={"markers": "n_markers", "actuations": "n_actuations"},
))

PAIR_SCHEMA = register_schema(TableSchema(
    kind="actor_pair",
    sections={
        "cubic": Section("float32", (3, "n_actuations", "n_shapes"), "a, b, c: s -> character weights"),
        "marker_vertices": Section("int32", ("n_markers",), "character vertex of each actor marker"),
        "similarity": Section("float32", (4, 4), "actor head coords -> character coords"),
        "s_lower": Section("float32", ("n_actuations",), "fitted range of s (weights() clamps to it)"),
        "s_upper": Section("float32", ("n_actuations",), "fitted range of s (weights() clamps to it)"),
    },
    channels=("markers", "actuations", "shapes"),
    channel_dims={"markers": "n_markers", "actuations": "n_actuations", "shapes": "n_shapes"},
))


def _f32(a) -> np.ndarray:
    out = np.ascontiguousarray(a, dtype=np.float32)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class Actor:
    """An actor's deformation model, validated against the ``actor`` schema when built.

    Attributes
    ----------
    names : tuple of n_markers str
    units : str, the capture's units
    neutral : ndarray of shape (n_markers, 3), float32, units, head coordinates
    cubic : ndarray of shape (3, K, n_markers, 3), float32, units ([a, b, c] of eq 2)
    unmixing : ndarray of shape (K, n_classes), float32
    class_axes : ndarray of shape (n_classes, 3), float32
    class_marker : ndarray of shape (n_classes,), int32
    head_markers : ndarray of shape (n_head,), int32
    s_lower, s_upper : ndarray of shape (K,), float32
    linear : ndarray of shape (K, n_markers, 3), float32, or None
    metadata : dict with "settings", "metrics", "input_hash"
    """

    names: tuple[str, ...]
    units: str
    neutral: np.ndarray
    cubic: np.ndarray
    unmixing: np.ndarray
    class_axes: np.ndarray
    class_marker: np.ndarray
    head_markers: np.ndarray
    s_lower: np.ndarray
    s_upper: np.ndarray
    linear: np.ndarray | None = None
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        for name in ("neutral", "cubic", "unmixing", "class_axes", "s_lower", "s_upper", "linear"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, _f32(getattr(self, name)))
        for name in ("class_marker", "head_markers"):
            object.__setattr__(self, name, np.ascontiguousarray(getattr(self, name), dtype=np.int32))
        object.__setattr__(self, "names", tuple(self.names))
        from .tables import _check_channels, _resolve_dims

        dims = _resolve_dims(ACTOR_SCHEMA, self._arrays(), None)
        _check_channels(ACTOR_SCHEMA, self._channels(), dims, None)
        if np.any(self.s_lower > 0) or np.any(self.s_upper < 0):
            raise TablesError(None, "s_lower/s_upper", "bounds must contain s = 0 (the neutral)")

    @property
    def n_markers(self) -> int:
        return len(self.names)

    @property
    def n_actuations(self) -> int:
        return self.cubic.shape[1]

    def _arrays(self) -> dict[str, np.ndarray]:
        arrays = {name: getattr(self, name) for name in ACTOR_SCHEMA.sections if getattr(self, name) is not None}
        return arrays

    def _channels(self) -> dict[str, list[str]]:
        return {"markers": list(self.names), "actuations": [f"s{k + 1:02d}" for k in range(self.n_actuations)]}

    def save(self, path: str | os.PathLike) -> Path:
        meta = dict(self.metadata)
        return save_tables(path, "actor", self._arrays(), units=self.units, channels=self._channels(),
                           settings=meta.get("settings", {}), metrics=meta.get("metrics", {}),
                           input_hash=meta.get("input_hash", "") or hash_inputs(self.cubic))

    @classmethod
    def load(cls, path: str | os.PathLike) -> "Actor":
        t = load_tables(path, "actor")
        return cls(names=tuple(t.channels["markers"]), units=t.units,
                   **{name: np.array(t[name]) for name in ACTOR_SCHEMA.sections if name in t.arrays},
                   metadata={"settings": dict(t.settings), "metrics": dict(t.metrics),
                             "input_hash": t.manifest.get("input_hash", "")})

    def evaluate(self, s) -> np.ndarray:
        """Markers x(s) (eq 2): ndarray of shape (n_markers, 3), float64, units, head coordinates."""
        s = np.asarray(s, dtype=np.float64)
        if s.shape != (self.n_actuations,):
            raise ValueError(f"Actor.evaluate: s must have shape ({self.n_actuations},), got {s.shape}")
        c = self.cubic.reshape(3, self.n_actuations, -1).astype(np.float64)
        x = (s ** 3) @ c[0] + (s ** 2) @ c[1] + s @ c[2]           # Shin & Lee eq. 2
        return self.neutral + x.reshape(-1, 3)


class MarkerSolver:
    """Solve s from any subset of markers (eq 5) by bounded, warm-started Levenberg-Marquardt.

    Parameters
    ----------
    actor : Actor
    iterations : int, the fixed budget of LM steps per :meth:`solve` (accepted or not)
    damping : float, weight of ||s - s_previous||^2 (temporal smoothness, warm start)
    prior : float, weight of ||s||^2 (pull towards neutral where markers say nothing)
    tolerance : float, stop early when the largest step is below this (actuation units)
    cost_tolerance : float, stop early when an accepted step lowers the cost by less than this fraction
    bounds : (lower, upper) arrays of shape (K,) within the actor's bounds, or None for the actor's

    The cost is in squared capture units; ``damping`` and ``prior`` are
    scaled by the mean squared column norm of the linear term, so their
    defaults do not depend on units or marker count.
    """

    def __init__(self, actor: Actor, iterations: int = 8, damping: float = 1e-3, prior: float = 1e-4,
                 tolerance: float = 2e-3, cost_tolerance: float = 1e-2, bounds=None):
        if not (isinstance(iterations, int) and iterations >= 1):
            raise ValueError(f"MarkerSolver iterations: expected an int >= 1, got {iterations!r}")
        self.actor = actor
        self.iterations = iterations
        self.tolerance = tolerance
        self.cost_tolerance = cost_tolerance
        k = actor.n_actuations
        self._m = actor.cubic.astype(np.float64).reshape(3 * k, -1)   # rows [a; b; c], (3K, 3m)
        self._neutral = actor.neutral.astype(np.float64).ravel()
        self._lo = actor.s_lower.astype(np.float64)
        self._hi = actor.s_upper.astype(np.float64)
        if bounds is not None:
            lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
            if lo.shape != (k,) or hi.shape != (k,) or np.any(lo > 0) or np.any(hi < 0):
                raise ValueError(f"MarkerSolver bounds: expected (lower, upper) of shape ({k},) around s = 0")
            self._lo, self._hi = np.maximum(lo, self._lo), np.minimum(hi, self._hi)
        unit = float(np.mean(np.sum(self._m[2 * k:] ** 2, axis=1))) or 1.0
        self.damping = damping * unit
        self.prior = prior * unit
        # J^T (K, 3K) = [diag(3 s^2) | diag(2 s) | I]: its block diagonals are strided views, written in place
        self._jsel = np.zeros((k, 3 * k))
        flat = self._jsel.reshape(-1)
        # diagonals of its a- and b-blocks as one (2, K) strided view: [j, i] -> flat[j K + i (3K + 1)]
        self._diag32 = np.lib.stride_tricks.as_strided(flat, (2, k), (k * flat.itemsize, (3 * k + 1) * flat.itemsize))
        self._jscale = np.array([[3.0], [2.0]])                      # d32 = [3 s^2; 2 s]
        flat[2 * k::3 * k + 1] = 1.0                                 # c-block: identity
        self._jga = np.empty((k, 3 * k + 1))                         # preallocated per-iteration buffers
        self._h = np.empty((k, k))
        self._hdiag = self._h.reshape(-1)[::k + 1]
        # the current and the trial point: (phi = [s^3, s^2, s], its blocks s^3, s^2, s, the view [s^2; s]
        # of shape (2, K), G phi): s lives in phi, so no copies between them
        self._points = tuple(self._point(k) for _ in range(2))
        self._tmp = np.empty(3 * k)
        self._step = np.empty(k)
        jga = self._jga
        self._work = (self._jsel, self._jsel.T, jga, jga[:, :3 * k], jga[:, 3 * k], self._h, self._hdiag,
                      self._diag32, self._tmp, self._jscale, self._step)
        self.s = np.zeros(k)
        self.last_iterations = 0
        self.last_cost = float("nan")
        self._cache_key: bytes | None = None                       # NaN pattern (+ weights) of the cached subset
        self._cache = None
        self._all = None                                             # the cache entry of "all markers, weight 1"
        self._dense = True                                           # try the all-markers path first

    @staticmethod
    def _point(k: int) -> tuple:
        phi = np.empty(3 * k)
        return phi, phi[:k], phi[k:2 * k], phi[2 * k:], phi[k:].reshape(2, k), np.empty(3 * k)

    def reset(self) -> None:
        """Forget the warm start (s = neutral)."""
        self.s = np.zeros(self.actor.n_actuations)

    def _gram(self, present: np.ndarray, w: np.ndarray | None):
        """Cached quantities of one marker subset (and weights) for eq. 5.

        Because x(s) is linear in phi(s) = [s^3, s^2, s], the Gauss-Newton
        quantities of eq. 5 reduce to (3K, 3K) products with the Gram matrix
        G = M_sub W M_sub^T, whatever the number of markers.  The damping and
        prior terms are quadratic in the s-block of phi, so they are folded
        into G: (lam + mu) is added to the diagonal of its s-block.

        Returns (ga, mw, x0, idx, wrep, reg, gram, resid): ga (3K, 3K + 1) holds
        that G in its first 3K columns, ``gram``, and the residual G phi - mt
        in its last, ``resid`` (scratch, written by each iteration), mw the
        weighted M_sub (3K, 3 n_sub), x0 the neutral of the subset (3 n_sub,),
        idx the integer indices of the subset's coordinates (3 n_sub,), intp,
        wrep the per-coordinate weights (3 n_sub,) or None, reg = lam + mu.
        """
        reg = self.damping + self.prior
        k = len(self._lo)
        idx = (3 * np.flatnonzero(present)[:, None] + np.arange(3)).ravel()
        m = self._m[:, idx]
        wrep = None if w is None else np.repeat(w[present], 3)
        mw = m if w is None else m * wrep
        ga = np.empty((3 * k, 3 * k + 1))
        ga[:, :3 * k] = mw @ m.T
        ga.reshape(-1)[2 * k * (3 * k + 2)::3 * k + 2][:k] += reg
        return ga, mw, self._neutral[idx], idx, wrep, reg, ga[:, :3 * k], ga[:, 3 * k]

    def solve(self, observed, weights=None, s0=None, iterations: int | None = None) -> np.ndarray:
        """Actuations s (K,), float64, that best explain the observed markers.

        Parameters
        ----------
        observed : ndarray of shape (n_markers, 3), float, units, head coordinates; NaN rows = missing
        weights : ndarray of shape (n_markers,), float >= 0, or None for 1
        s0 : ndarray of shape (K,) to start from (default: the previous solution)
        iterations : override of the per-frame budget

        No marker at all returns the previous solution unchanged.
        """
        obs = np.asarray(observed, dtype=np.float64)
        n = self.actor.n_markers
        if obs.shape != (n, 3):
            raise ValueError(f"MarkerSolver.solve: observed must be ({n}, 3), got {obs.shape}")
        flat = obs.ravel()
        reg = self.damping + self.prior
        tt = float("nan")
        if weights is None and self._dense:
            # fast path, the common case: no NaN, so every marker is present with weight 1; a NaN
            # anywhere makes ||p - x^0||^2 NaN, so that sum doubles as the test (while frames come
            # with NaN, they go straight to the subset path until one comes complete again)
            entry = self._all
            if entry is None or entry[5] != reg:
                entry = self._all = self._gram(np.ones(n, dtype=bool), None)
            ga, mw, x0 = entry[0], entry[1], entry[2]
            target = flat - x0                                   # p_i - x_i^0
            tt = float(target @ target)
        if tt != tt:
            # the cache key is the NaN pattern of the coordinates (+ the weights): when it repeats,
            # as it does frame after frame, no mask is built at all
            nan = np.isnan(flat)
            w = None
            if weights is None:
                key = nan.tobytes()
            else:
                w = np.asarray(weights, dtype=np.float64)
                if w.shape != (n,) or not (_min(w) >= 0.0 and _max(w) < np.inf):
                    raise ValueError(f"MarkerSolver.solve: weights must be ({n},) finite >= 0")
                key = nan.tobytes() + w.tobytes()
            entry = self._cache
            if key != self._cache_key or entry[5] != reg:
                present = ~nan.reshape(n, 3).any(axis=1)
                if w is not None:
                    present &= w > 0
                entry = self._cache = None if not present.any() else self._gram(present, w)
                self._cache_key = key
            if entry is None:
                self.last_iterations = 0
                return self.s.copy()
            self._dense = weights is None and len(entry[3]) == 3 * n
            ga, mw, x0, idx, wrep = entry[0], entry[1], entry[2], entry[3], entry[4]
            target = flat.take(idx)
            target -= x0
            tt = float(target @ (target if wrep is None else target * wrep))
        k = len(self._lo)
        s_prev = self.s if s0 is None else np.clip(np.asarray(s0, dtype=np.float64), self._lo, self._hi)
        lam, lo, hi, tol = self.damping, self._lo, self._hi, self.tolerance
        # eq. 5 plus damping and prior: sum_i w_i ||x_i(s) - p_i||^2 + lam ||s - s_prev||^2 + mu ||s||^2
        #   = phi'G phi - 2 phi'mt + tt, with G holding lam + mu (see _gram), mt = M W p + lam [0; 0; s_prev]
        mt = mw @ target
        mt[2 * k:] += lam * s_prev
        tt += lam * float(s_prev @ s_prev)
        mt2 = 2.0 * mt
        gram, resid = entry[6], entry[7]
        jsel, jt, jga, jg, g, h, hdiag, d32, tmp, jscale, step = self._work
        cur, new = self._points
        phi, s3, s2, s, s21, gphi = cur
        # every array op below is one NumPy call on a preallocated buffer: per frame the call count, not the
        # (3K)^2 arithmetic, is the cost
        s[:] = s_prev
        np.multiply(s, s, out=s2)
        np.multiply(s2, s, out=s3)                                   # phi = [s^3, s^2, s]
        np.matmul(gram, phi, out=gphi)
        np.subtract(gphi, mt2, out=tmp)
        cost = float(phi @ tmp) + tt
        budget = self.iterations if iterations is None else iterations
        nu, used, cost_tol = 1e-3, 0, self.cost_tolerance
        while used < budget:
            used += 1
            phi_new, s3_new, s2_new, s_new, s21_new, gphi_new = new
            np.multiply(s21, jscale, out=d32)                        # dx/ds_k = 3 a s_k^2 + 2 b s_k + c
            np.subtract(gphi, mt, out=resid)
            np.matmul(jsel, ga, out=jga)                             # [J^T W J-half | J^T W r] in one product
            np.matmul(jg, jt, out=h)                                 # J^T W J (+ damping + prior)
            hdiag *= 1.0 + nu                                        # Marquardt scaling
            np.subtract(s, _spd_solve(h.T, g, overwrite_a=1)[1], out=s_new)   # h symmetric: h.T its Fortran view
            s_new.clip(lo, hi, out=s_new)                            # bounded by projection
            np.subtract(s_new, s, out=step)                          # the step actually taken
            if max(map(abs, step.tolist())) < tol:                   # converged: take the tiny step
                cur, new = new, cur
                break
            np.multiply(s_new, s_new, out=s2_new)
            np.multiply(s2_new, s_new, out=s3_new)
            np.matmul(gram, phi_new, out=gphi_new)
            np.subtract(gphi_new, mt2, out=tmp)
            new_cost = float(phi_new @ tmp) + tt
            if new_cost <= cost:
                gain = cost - new_cost
                cost = new_cost
                cur, new = new, cur
                phi, s3, s2, s, s21, gphi = cur
                nu = max(nu * 0.3, 1e-7)
                if gain <= cost_tol * (cost + 1e-300):               # converged: cost barely moves
                    break
            else:
                nu *= 10.0
        self._points = (cur, new)
        s = cur[3].copy()
        self.s = s
        self.last_iterations = used
        self.last_cost = max(cost, 0.0)
        return s.copy()

    def solve_constraints(self, constraints: Sequence[tuple[int, Sequence[float]]],
                          pins: Sequence[int] | Mapping[int, Sequence[float]] = (),
                          pin_weight: float = 10.0, hold: float = 0.0, hold_at=None,
                          iterations: int = 30) -> np.ndarray:
        """Direct manipulation: drag markers to targets while pinned markers stay where they are.

        Parameters
        ----------
        constraints : sequence of (marker_index, (x, y, z) target in head coordinates, units)
        pins : marker indices held at their current position x_i(s_current), or a mapping
            {marker index: (x, y, z) position to hold, head coordinates, units}
        pin_weight : weight of a pin relative to a dragged point
        hold : weight of every other marker at its current position x_i(s_current) (or at ``hold_at``):
            with hold > 0 the face changes as little as it can while the dragged points move
        hold_at : ndarray of shape (n_markers, 3), head coordinates, units, or None (current positions)
        iterations : LM budget for this edit

        Returns s (K,), float64; also kept as the warm start of the next call.
        """
        n = self.actor.n_markers
        observed = np.full((n, 3), np.nan)
        weights = np.zeros(n)
        held = pins.items() if isinstance(pins, Mapping) else [(i, None) for i in pins]
        current = self.actor.evaluate(self.s)
        if hold > 0:
            observed[:] = current if hold_at is None else np.asarray(hold_at, dtype=np.float64).reshape(n, 3)
            weights[:] = hold
        for i, position in held:
            if not 0 <= int(i) < n:
                raise ValueError(f"solve_constraints: pin index {i} out of range 0..{n - 1}")
            p = current[int(i)] if position is None else np.asarray(position, dtype=np.float64)
            if p.shape != (3,) or not np.isfinite(p).all():
                raise ValueError(f"solve_constraints: pin of marker {i} must be 3 finite numbers, got {position!r}")
            observed[int(i)] = p
            weights[int(i)] = pin_weight
        for i, target in constraints:
            if not 0 <= int(i) < n:
                raise ValueError(f"solve_constraints: constraint marker {i} out of range 0..{n - 1}")
            t = np.asarray(target, dtype=np.float64)
            if t.shape != (3,) or not np.isfinite(t).all():
                raise ValueError(f"solve_constraints: target of marker {i} must be 3 finite numbers, got {target!r}")
            observed[int(i)] = t
            weights[int(i)] = 1.0
        return self.solve(observed, weights, iterations=iterations)


@dataclass(frozen=True, eq=False)
class ActorPair:
    """Actuations -> a character's blendshape weights (Shin & Lee §6.2), from an ``actor_pair`` table.

    Attributes
    ----------
    cubic : ndarray of shape (3, K, n_shapes), float32
    shape_names : tuple of n_shapes str
    marker_names : tuple of n_markers str
    marker_vertices : ndarray of shape (n_markers,), int32
    similarity : ndarray of shape (4, 4), float32, actor head coordinates -> character coordinates
    s_lower, s_upper : ndarray of shape (K,), float32
    metadata : dict
    """

    cubic: np.ndarray
    shape_names: tuple[str, ...]
    marker_names: tuple[str, ...]
    marker_vertices: np.ndarray
    similarity: np.ndarray
    s_lower: np.ndarray
    s_upper: np.ndarray
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        for name in ("cubic", "similarity", "s_lower", "s_upper"):
            object.__setattr__(self, name, _f32(getattr(self, name)))
        object.__setattr__(self, "marker_vertices", np.ascontiguousarray(self.marker_vertices, dtype=np.int32))
        from .tables import _check_channels, _resolve_dims

        dims = _resolve_dims(PAIR_SCHEMA, self._arrays(), None)
        _check_channels(PAIR_SCHEMA, self._channels(), dims, None)
        object.__setattr__(self, "_flat", self.cubic.astype(np.float64).reshape(-1, self.cubic.shape[2]))

    def _arrays(self):
        return {name: getattr(self, name) for name in PAIR_SCHEMA.sections}

    def _channels(self):
        k = self.cubic.shape[1]
        return {"markers": list(self.marker_names), "actuations": [f"s{i + 1:02d}" for i in range(k)],
                "shapes": list(self.shape_names)}

    def save(self, path: str | os.PathLike) -> Path:
        meta = dict(self.metadata)
        return save_tables(path, "actor_pair", self._arrays(), channels=self._channels(),
                           settings=meta.get("settings", {}), metrics=meta.get("metrics", {}),
                           input_hash=meta.get("input_hash", ""))

    @classmethod
    def load(cls, path: str | os.PathLike) -> "ActorPair":
        t = load_tables(path, "actor_pair")
        return cls(shape_names=tuple(t.channels["shapes"]), marker_names=tuple(t.channels["markers"]),
                   **{name: np.array(t[name]) for name in PAIR_SCHEMA.sections},
                   metadata={"settings": dict(t.settings), "metrics": dict(t.metrics)})

    def weights(self, s) -> np.ndarray:
        """Character weights w(s) (n_shapes,), float32, clipped to [0, 1] (cubic of eq 2 on weights).

        s is first clamped to [s_lower, s_upper]: the range the tables were fitted over, so a solve
        that runs past it holds the last fitted pose instead of extrapolating the cubic.
        """
        s = np.clip(np.asarray(s, dtype=np.float64), self.s_lower, self.s_upper)
        w = np.concatenate([s ** 3, s ** 2, s]) @ self._flat        # Shin & Lee eq. 2, §6.2 target
        return np.clip(w, 0.0, 1.0).astype(np.float32)
