"""The One Euro filter (Casiez, Roussel & Vogel, CHI 2012), vectorised over channels.

A first-order low-pass filter whose cutoff rises with the signal's speed, so
jitter is removed when the signal moves slowly and lag stays small when it
moves fast. Symbols of the paper and their names here:

==============  =====================  =========================================
paper           code                   meaning
==============  =====================  =========================================
X_i, X̂_i        ``x``, ``x_hat``       raw and filtered value
Ẋ_i, dX̂_i       ``dx``, ``dx_hat``     raw and filtered derivative (units / s)
T_e             ``dt``                 sampling period (s)
f_cmin          ``min_cutoff``         cutoff at zero speed (Hz)
β               ``beta``               speed coefficient (Hz per unit/s)
f_cd            ``d_cutoff``           cutoff of the derivative filter (Hz)
α               ``alpha``              smoothing factor 1 / (1 + τ / T_e),
                                       τ = 1 / (2π f_c)
==============  =====================  =========================================

Each channel may have its own settings (the per-region settings of the live
pipeline: eyes light, mouth heavier). A NaN input means "no sample for this
channel": its output is NaN and its state is left as it was.
"""

from __future__ import annotations

import math

import numpy as np


def smoothing_factor(cutoff: float | np.ndarray, dt: float | np.ndarray) -> float | np.ndarray:
    """α = 1 / (1 + τ / T_e) with τ = 1 / (2π f_c) (Casiez et al. 2012, eq. 1 and §4)."""
    tau = 1.0 / (2.0 * np.pi * cutoff)
    return 1.0 / (1.0 + tau / dt)


def _settings(value, n: int, name: str) -> np.ndarray:
    arr = np.broadcast_to(np.asarray(value, dtype=np.float64), (n,)).copy()
    if not np.all(np.isfinite(arr)) or np.any(arr < 0) or (name != "beta" and np.any(arr <= 0)):
        raise ValueError(f"OneEuroFilter {name}: expected {'non-negative' if name == 'beta' else 'positive'} "
                         f"finite values, got {value!r}")
    return arr


class OneEuroFilter:
    """One Euro filters for ``n`` channels at once.

    Parameters
    ----------
    n : int, number of channels
    min_cutoff : float or ndarray of shape (n,), Hz, > 0
    beta : float or ndarray of shape (n,), Hz per (unit / s), >= 0
    d_cutoff : float or ndarray of shape (n,), Hz, > 0 (default 1 Hz, as in the paper)

    ``filter(x, dt)`` returns the filtered values, float64 (n,). The first
    finite sample of a channel passes through unchanged and starts its state.
    """

    def __init__(self, n: int, min_cutoff: float | np.ndarray = 1.0, beta: float | np.ndarray = 0.0,
                 d_cutoff: float | np.ndarray = 1.0) -> None:
        if not (isinstance(n, (int, np.integer)) and n >= 0):
            raise ValueError(f"OneEuroFilter n: expected a non-negative int, got {n!r}")
        self.n = int(n)
        self.min_cutoff = _settings(min_cutoff, self.n, "min_cutoff")
        self.beta = _settings(beta, self.n, "beta")
        self.d_cutoff = _settings(d_cutoff, self.n, "d_cutoff")
        self.x_hat = np.full(self.n, np.nan)
        self.dx_hat = np.zeros(self.n)
        self._out = np.empty(self.n)
        self._ready = self.n == 0  # every channel has state

    def reset(self) -> None:
        """Forget every channel's state: the next sample of each passes through."""
        self.x_hat.fill(np.nan)
        self.dx_hat.fill(0.0)
        self._ready = self.n == 0

    def set_state(self, x_hat: np.ndarray, dx_hat: np.ndarray) -> None:
        """Take another filter's state (a recording started mid-run): X̂ (NaN: no sample yet) and dX̂, (n,) each."""
        x_hat, dx_hat = np.asarray(x_hat, np.float64), np.asarray(dx_hat, np.float64)
        if x_hat.shape != (self.n,) or dx_hat.shape != (self.n,) or not np.isfinite(dx_hat).all() or \
                np.isinf(x_hat).any():
            raise ValueError(f"OneEuroFilter.set_state: expected X̂ (finite or NaN) and finite dX̂ of shape "
                             f"({self.n},), got {x_hat.shape} and {dx_hat.shape}")
        self.x_hat[:], self.dx_hat[:] = x_hat, dx_hat
        self._ready = not np.isnan(self.x_hat).any()

    def filter(self, x: np.ndarray, dt: float) -> np.ndarray:
        """Filter one sample per channel.

        Parameters
        ----------
        x : ndarray of shape (n,), any float dtype; NaN where a channel has no sample
        dt : float, seconds since the previous sample (> 0; a non-positive or
            non-finite ``dt`` is treated as 1 ms so a repeated timestamp cannot
            divide by zero)

        Returns
        -------
        ndarray of shape (n,), float64, owned by the filter (copy it to keep it)
        """
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (self.n,):
            raise ValueError(f"OneEuroFilter.filter x: expected shape ({self.n},), got {x.shape}")
        if not (math.isfinite(dt) and dt > 0):
            dt = 1e-3
        x_hat, dx_hat = self.x_hat, self.dx_hat
        present = np.isfinite(x)
        if present.all() and self._ready:  # the usual case: no masks, no temporaries kept
            dx = (x - x_hat) / dt
            dx_hat += smoothing_factor(self.d_cutoff, dt) * (dx - dx_hat)
            cutoff = self.min_cutoff + self.beta * np.abs(dx_hat)  # f_c = f_cmin + β|dX̂|
            x_hat += smoothing_factor(cutoff, dt) * (x - x_hat)  # X̂ = α X + (1 - α) X̂_prev
            np.copyto(self._out, x_hat)
            return self._out
        # channels without a sample keep their state; a channel's first sample starts it
        first = present & np.isnan(x_hat)
        np.copyto(x_hat, x, where=first)
        np.copyto(dx_hat, 0.0, where=first)
        step = present & ~first
        xs = np.where(step, x, x_hat)  # where no step: x = x̂, so the update below is a no-op there...
        dx = (xs - x_hat) / dt
        new_dx_hat = dx_hat + smoothing_factor(self.d_cutoff, dt) * (dx - dx_hat)
        np.copyto(dx_hat, new_dx_hat, where=step)  # ...except for dX̂, which is kept explicitly
        cutoff = self.min_cutoff + self.beta * np.abs(dx_hat)
        np.copyto(x_hat, x_hat + smoothing_factor(cutoff, dt) * (xs - x_hat), where=step)
        self._ready = not np.isnan(x_hat).any()
        out = self._out
        out.fill(np.nan)
        np.copyto(out, x_hat, where=present)
        return out
