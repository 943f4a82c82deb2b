"""Speech intensity at runtime: a voice level in dBFS -> the per-speaker z-score s(t) the gestures are matched on.

:data:`SILENCE_Z` is the floor of that scale (silence, or below the noise
gate); the offline reference intensities (:mod:`facepuppet.offline.gestures.speech_intensity`)
use the same floor.
"""

from __future__ import annotations

import math

SILENCE_Z = -3.0  # normalised intensity of silence (floor)


class SpeakerNormaliser:
    """dBFS -> per-speaker z-score with a noise gate, running statistics of voiced frames.

    Parameters
    ----------
    mean_db, std_db : float, dBFS, starting estimate of the speaker's voiced level
    gate_db : float, dBFS; at or below it (or NaN: not measured) the frame is silence (SILENCE_Z).
        Offline it is derived from the speaker's level distribution (10th percentile + a margin,
        see ``facepuppet.offline.gestures.speech_intensity.speaker_stats``)
    rate : float, weight of a new voiced frame in the running mean/variance (0: frozen)
    """

    def __init__(self, mean_db: float = -30.0, std_db: float = 8.0, gate_db: float = -60.0,
                 rate: float = 0.002) -> None:
        self.mean_db, self.var_db, self.gate_db, self.rate = float(mean_db), float(std_db) ** 2, gate_db, rate

    def __call__(self, level_db: float) -> float:
        if not (level_db > self.gate_db):  # NaN, or below the noise gate: silence
            return SILENCE_Z
        if self.rate > 0:
            d = level_db - self.mean_db
            self.mean_db += self.rate * d
            self.var_db += self.rate * (d * d - self.var_db)
        return max(SILENCE_Z, (level_db - self.mean_db) / math.sqrt(max(self.var_db, 1.0)))
