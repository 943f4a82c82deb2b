"""The per-frame marker solve: actuations from any subset of markers (Shin & Lee 2009, §6.1 eq 5).

Paper symbols -> code names:

    s                actuation parameters                 s           (K,)
    x_i(s)           marker i in head coordinates         Actor.evaluate(s) (n_markers, 3)
    a, b, c          cubic coefficients (eq 2)            _m rows [a; b; c]  (3K, 3 n_markers)
    p_i              observed / dragged marker positions  observed    (n_markers, 3), NaN = not given
    w_i              per-marker weights                   weights     (n_markers,)

Eq 5: s* = argmin_s sum_i w_i ||x_i(s) - p_i||^2 (+ damping towards the
previous frame and towards neutral), solved with Levenberg-Marquardt on the
analytic Jacobian dx_i/ds_k = 3 a_ik s_k^2 + 2 b_ik s_k + c_ik, bounded by
projection onto [s_lower, s_upper], warm-started, at most ``iterations``
steps per frame.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np
from scipy.linalg.lapack import dposv as _spd_solve

from facepuppet.runtime.actuation.actor import Actor

_max, _min = np.maximum.reduce, np.minimum.reduce                   # plain ufunc reductions (no method wrapper)


class _Subset(NamedTuple):
    """What eq. 5 needs of one marker subset (and its weights), cached while the subset repeats (see ``_gram``)."""

    ga: np.ndarray               # (3K, 3K + 1): G in the first 3K columns, the residual G phi - mt in the last
    mw: np.ndarray               # (3K, 3 n_sub): the subset's M, weighted
    x0: np.ndarray               # (3 n_sub,): the subset's neutral x^0
    idx: np.ndarray              # (3 n_sub,) intp: the subset's coordinates
    wrep: np.ndarray | None      # (3 n_sub,): per-coordinate weights, None for all 1
    reg: float                   # lam + mu, folded into the s-block of G
    gram: np.ndarray             # ga[:, :3K], G
    resid: np.ndarray            # ga[:, 3K], scratch written by each iteration


class _Point(NamedTuple):
    """An iterate: phi(s) = [s^3, s^2, s] and views into it, so s lives in phi and nothing is copied."""

    phi: np.ndarray              # (3K,)
    s3: np.ndarray               # phi[:K]
    s2: np.ndarray               # phi[K:2K]
    s: np.ndarray                # phi[2K:]
    s21: np.ndarray              # phi[K:] as (2, K): [s^2; s]
    gphi: np.ndarray             # (3K,): G phi


class _Work(NamedTuple):
    """Preallocated per-iteration buffers and views of the LM step."""

    jsel: np.ndarray             # (K, 3K): J^T selector [diag(3 s^2) | diag(2 s) | I]
    jt: np.ndarray               # jsel.T
    jga: np.ndarray              # (K, 3K + 1): jsel @ ga
    jg: np.ndarray               # jga[:, :3K]
    g: np.ndarray                # jga[:, 3K], the gradient J^T W r
    h: np.ndarray                # (K, K): J^T W J (+ damping + prior)
    hdiag: np.ndarray            # the diagonal of h, a strided view
    d32: np.ndarray              # (2, K): the diagonals of jsel's a- and b-blocks, a strided view
    tmp: np.ndarray              # (3K,)
    jscale: np.ndarray           # (2, 1): [3; 2]
    step: np.ndarray             # (K,): the step taken


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
                 tolerance: float = 2e-3, cost_tolerance: float = 1e-2,
                 bounds: tuple[np.ndarray, np.ndarray] | None = None) -> None:
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
        self._points = (self._point(k), self._point(k))             # the current and the trial point
        self._tmp = np.empty(3 * k)
        self._step = np.empty(k)
        jga = self._jga
        self._work = _Work(jsel=self._jsel, jt=self._jsel.T, jga=jga, jg=jga[:, :3 * k], g=jga[:, 3 * k],
                           h=self._h, hdiag=self._hdiag, d32=self._diag32, tmp=self._tmp, jscale=self._jscale,
                           step=self._step)
        self.s = np.zeros(k)
        self.last_iterations = 0
        self.last_cost = float("nan")
        self._cache_key: bytes | None = None                       # NaN pattern (+ weights) of the cached subset
        self._cache: _Subset | None = None
        self._all: _Subset | None = None                           # the cache entry of "all markers, weight 1"
        self._dense = True                                           # try the all-markers path first

    @staticmethod
    def _point(k: int) -> _Point:
        phi = np.empty(3 * k)
        return _Point(phi=phi, s3=phi[:k], s2=phi[k:2 * k], s=phi[2 * k:], s21=phi[k:].reshape(2, k),
                      gphi=np.empty(3 * k))

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper), each (K,) float64: the bounds s is projected onto."""
        return self._lo.copy(), self._hi.copy()

    def reset(self) -> None:
        """Forget the warm start (s = neutral)."""
        self.s = np.zeros(self.actor.n_actuations)

    def _gram(self, present: np.ndarray, w: np.ndarray | None) -> _Subset:
        """Cached quantities of one marker subset (and weights) for eq. 5 (the fields of :class:`_Subset`).

        Because x(s) is linear in phi(s) = [s^3, s^2, s], the Gauss-Newton
        quantities of eq. 5 reduce to (3K, 3K) products with the Gram matrix
        G = M_sub W M_sub^T, whatever the number of markers.  The damping and
        prior terms are quadratic in the s-block of phi, so they are folded
        into G: (lam + mu) is added to the diagonal of its s-block.
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
        return _Subset(ga=ga, mw=mw, x0=self._neutral[idx], idx=idx, wrep=wrep, reg=reg, gram=ga[:, :3 * k],
                       resid=ga[:, 3 * k])

    def solve(self, observed: np.ndarray, weights: np.ndarray | None = None, s0: np.ndarray | None = None,
              iterations: int | None = None) -> np.ndarray:
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
            if entry is None or entry.reg != reg:
                entry = self._all = self._gram(np.ones(n, dtype=bool), None)
            target = flat - entry.x0                             # p_i - x_i^0
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
            if key != self._cache_key or entry.reg != reg:
                present = ~nan.reshape(n, 3).any(axis=1)
                if w is not None:
                    present &= w > 0
                entry = self._cache = None if not present.any() else self._gram(present, w)
                self._cache_key = key
            if entry is None:
                self.last_iterations = 0
                return self.s.copy()
            self._dense = weights is None and len(entry.idx) == 3 * n
            target = flat.take(entry.idx)
            target -= entry.x0
            tt = float(target @ (target if entry.wrep is None else target * entry.wrep))
        k = len(self._lo)
        s_prev = self.s if s0 is None else np.clip(np.asarray(s0, dtype=np.float64), self._lo, self._hi)
        lam, lo, hi, tol = self.damping, self._lo, self._hi, self.tolerance
        # eq. 5 plus damping and prior: sum_i w_i ||x_i(s) - p_i||^2 + lam ||s - s_prev||^2 + mu ||s||^2
        #   = phi'G phi - 2 phi'mt + tt, with G holding lam + mu (see _gram), mt = M W p + lam [0; 0; s_prev]
        mt = entry.mw @ target
        mt[2 * k:] += lam * s_prev
        tt += lam * float(s_prev @ s_prev)
        mt2 = 2.0 * mt
        ga, gram, resid = entry.ga, entry.gram, entry.resid
        jsel, jt, jga, jg, g, h, hdiag, d32, tmp, jscale, step = self._work    # the fields of _Work, in order
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
        s = cur.s.copy()
        self.s = s
        self.last_iterations = used
        self.last_cost = max(cost, 0.0)
        return s.copy()

    def solve_constraints(self, constraints: Sequence[tuple[int, Sequence[float]]],
                          pins: Sequence[int] | Mapping[int, Sequence[float]] = (),
                          pin_weight: float = 10.0, hold: float = 0.0, hold_at: np.ndarray | None = None,
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
