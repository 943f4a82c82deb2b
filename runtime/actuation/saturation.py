"""How often the marker solve runs into its limits: per channel and per actuation, counted over solved frames.

A weight held at 1.0 or an actuation held at a bound looks like any other strong expression in the
picture; only a count tells the user that the character (or the actor table) ran out of range. The
``solve`` stage counts every frame it solves; ``run --stats`` and ``replay --stats`` print the fractions by
name, and without ``--stats`` a channel held at 1.0 in a tenth of the frames is still warned about.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

#: a channel or actuation at its limit in at least this fraction of the solved frames is named in the summary
REPORT_FRACTION = 0.01
#: a channel at 1.0 in at least this fraction of the solved frames is warned about even without ``--stats``
WARN_FRACTION = 0.1


class SaturationCount:
    """Frames at the limit, per character channel (weight clipped to 1.0) and per actuation (s at a bound).

    Parameters
    ----------
    channel_names : the character's channel names (the pair's shapes)
    n_actuations : K
    lower, upper : ndarray of shape (K,), the bounds s is held to (the solver's, narrowed by the pair's fitted
        range where the pair clamps s before its cubic)
    """

    def __init__(self, channel_names: Sequence[str], n_actuations: int, lower: np.ndarray,
                 upper: np.ndarray) -> None:
        self.channel_names = tuple(channel_names)
        self.frames = 0
        self.channels_at_one = np.zeros(len(self.channel_names), np.int64)
        self.actuations_at_bound = np.zeros(n_actuations, np.int64)
        self._lo = np.asarray(lower, np.float64)
        self._hi = np.asarray(upper, np.float64)

    def add(self, s: np.ndarray, weights: np.ndarray) -> None:
        """Count one solved frame: s (K,) and the character weights (n_channels,) drawn from it."""
        self.frames += 1
        self.channels_at_one += weights >= 1.0
        self.actuations_at_bound += (s <= self._lo) | (s >= self._hi)

    def fractions(self, at_least: float = REPORT_FRACTION) -> dict:
        """``{"frames", "channels_at_1": {name: fraction}, "actuations_at_bound": {"s01": fraction}}``, each
        dict the names at their limit in at least ``at_least`` of the frames, largest first."""
        n = max(self.frames, 1)

        def named(counts, names):
            order = np.argsort(-counts, kind="stable")
            return {names[i]: round(float(counts[i]) / n, 4) for i in order if counts[i] / n >= at_least}

        k = len(self.actuations_at_bound)
        return {"frames": self.frames,
                "channels_at_1": named(self.channels_at_one, self.channel_names),
                "actuations_at_bound": named(self.actuations_at_bound, [f"s{i + 1:02d}" for i in range(k)])}

    def line(self, at_least: float = REPORT_FRACTION, shown: int = 12) -> str:
        """One line for a person: the channels and actuations at their limit, with the fraction of frames."""
        f = self.fractions(at_least)

        def some(d):
            items = [f"{name} {value:.0%}" for name, value in list(d.items())[:shown]]
            return ", ".join(items) + (f", ... ({len(d)} in all)" if len(d) > shown else "") if d else "none"

        return (f"solve saturation over {f['frames']} solved frames (>= {at_least:.0%} of them): channels at 1.0: "
                f"{some(f['channels_at_1'])}; actuations at a bound: {some(f['actuations_at_bound'])}")


def report_line(count: SaturationCount | None, stats: bool) -> str | None:
    """What a command prints about saturation at its end: the count with ``--stats``; without, a warning when a
    channel sat at 1.0 in at least :data:`WARN_FRACTION` of the solved frames (it looks like expression in
    the picture otherwise); None when there is nothing to say (or no solve)."""
    if count is None:
        return None
    if stats:
        return count.line()
    if count.fractions(WARN_FRACTION)["channels_at_1"]:
        return "warning: " + count.line()
    return None
