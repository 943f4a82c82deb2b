"""Expressions fired by hand (a button, a hotkey, a Stream Deck): their values over tick time, with fades.

Each triggered expression is a straight ramp in tick time: a command at tick time ``t0`` takes its value from
where it is then, ``v0``, to its target ``g`` over ``fade`` seconds (at once for a fade of 0). ``for N``
holds the target and ramps back to 0 at ``t0 + N``. ``toggle`` turns an expression that is on (its target
above 0) off, else on. Values are functions of tick times only, so a replay that applies the same commands at
the same ticks computes the same values bit for bit.

An expression at rest (value 0, target 0) is *not sent*: its channel carries NaN, and the tracker's own
channels drive the character as if nothing were triggered.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass
class Ramp:
    """One expression's ramp: from ``v0`` at ``t0`` to ``target`` over ``fade`` s; back to 0 at ``off_at``."""

    t0: float = 0.0
    v0: float = 0.0
    target: float = 0.0
    fade: float = 0.0
    off_at: float = math.inf

    def value(self, t: float) -> float:
        if t >= self.off_at:  # a ``for N``'s end: ramp down from where it was then
            self.t0, self.v0, self.target, self.off_at = self.off_at, self._at(self.off_at), 0.0, math.inf
        return self._at(t)

    def _at(self, t: float) -> float:
        if self.fade <= 0.0 or t >= self.t0 + self.fade:
            return self.target
        s = max(0.0, (t - self.t0) / self.fade)
        return self.v0 + (self.target - self.v0) * s

    def resting(self, t: float) -> bool:
        return self.target == 0.0 and self.off_at == math.inf and self._at(t) == 0.0


class ExpressionTriggers:
    """The ramps of a character's triggerable expressions (by name, in the order given).

    Parameters
    ----------
    names : sequence of str, what may be triggered (the character's VRM expressions, else its shapes)
    """

    def __init__(self, names: Sequence[str]) -> None:
        self.names = tuple(names)
        self.index = {n: i for i, n in enumerate(self.names)}
        self.folded = {n.lower(): i for i, n in reversed(list(enumerate(self.names)))}
        self.ramps = [Ramp() for _ in self.names]

    def find(self, name: str) -> int | None:
        """The index of ``name`` (exact, else ignoring case), or None."""
        i = self.index.get(name)
        return i if i is not None else self.folded.get(name.lower())

    def apply(self, i: int, action: str, t: float, value: float = 1.0, fade: float = 0.0,
              seconds: float | None = None) -> None:
        """Start the ramp of expression ``i`` at tick time ``t`` (``action``: on, off, toggle, for)."""
        ramp = self.ramps[i]
        now = ramp.value(t)
        if action == "toggle":
            action = "off" if ramp.target > 0.0 else "on"
        target = 0.0 if action == "off" else float(value)
        ramp.t0, ramp.v0, ramp.target, ramp.fade = t, now, target, float(fade)
        ramp.off_at = t + float(seconds) if action == "for" else math.inf

    def values(self, t: float, out: np.ndarray | None = None) -> np.ndarray:
        """(n_names,) float32: each expression's value at ``t``, NaN for one at rest (not sent)."""
        if out is None:
            out = np.empty(len(self.names), dtype=np.float32)
        for i, ramp in enumerate(self.ramps):
            v = ramp.value(t)
            out[i] = math.nan if ramp.resting(t) else v
        return out

    def active(self) -> dict[str, float]:
        """Name -> target of each expression switched on (for status)."""
        return {n: r.target for n, r in zip(self.names, self.ramps) if r.target > 0.0}
