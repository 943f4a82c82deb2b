"""The frame rate a take was recorded at, read from its frame times.

A replay that draws faster than its take draws every frame several times (a 30 Hz take on a 60 Hz grid: half
the ticks show nothing new, and half the PNGs are copies); one that draws slower drops frames. So ``replay``
without ``--fps`` draws on the take's own rate, which this module finds:

* the period is the median step between frames that advance in time (a few dropped frames, a pause or a
  burst of two packets in one millisecond do not move a median);
* the rate is one over the mean of the steps within half a period of it: that mean keeps the sub-frame
  precision a single median step lacks (Live Link Face stamps frames on a 60 fps timecode with a
  millisecond sub-frame, so its 29.97 and 30 Hz steps differ in the fourth digit), while gaps and bursts
  are left out;
* a rate within ``SNAP`` of a common video or capture rate is that rate: a take's clock is that rate read
  by a slightly drifting device clock, and a video's time base wants the exact fraction.

The answer is None (the caller then says so and uses its own default) when the take has fewer than
``MIN_STEPS`` regular steps or its rate is outside ``[MIN_RATE, MAX_RATE]``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

COMMON_RATES = (23.976, 24.0, 25.0, 29.97, 30.0, 48.0, 50.0, 59.94, 60.0, 72.0, 90.0, 100.0, 119.88, 120.0,
                180.0, 200.0, 239.76, 240.0)
SNAP = 2e-3          # relative distance to a common rate under which the take is taken to run at it
MIN_STEPS = 2        # regular steps needed before a rate is believed
MIN_RATE, MAX_RATE = 1.0, 1000.0  # Hz; outside, the times are not a frame clock (or a tick grid would be absurd)


def take_rate(times: Sequence[float] | np.ndarray) -> float | None:
    """Frames per second of a take from its frame times (see the module docstring), or None when unsure.

    Parameters
    ----------
    times : sequence of float, seconds, in non-decreasing order (frames' ``t``)
    """
    t = np.asarray(times, dtype=np.float64)
    if t.ndim != 1 or t.size < MIN_STEPS + 1 or not np.all(np.isfinite(t)):
        return None
    steps = np.diff(t)
    steps = steps[steps > 0]
    if steps.size < MIN_STEPS:
        return None
    period = float(np.median(steps))
    regular = steps[np.abs(steps / period - 1.0) < 0.5]
    if regular.size < MIN_STEPS:
        return None
    rate = 1.0 / float(regular.mean())
    if not MIN_RATE <= rate <= MAX_RATE:
        return None
    nearest = min(COMMON_RATES, key=lambda r: abs(rate / r - 1.0))
    return nearest if abs(rate / nearest - 1.0) < SNAP else round(rate, 3)
