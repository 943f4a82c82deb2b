"""Re-calibrating the vowels during a run: the live voice, taken as silence, A, I, U, E, O in turn.

The operator presses Re-calibrate in the panel; the user then stays quiet, then holds each vowel, for
``seconds`` each, as the panel prompts. The takes are the feature rows the voice's own extractor computes for
every hop (:class:`~facepuppet.runtime.voice.source.VoiceChannels` hands them to :meth:`Recalibration.hop`,
in the thread that pushes the samples: the microphone's callback). Phases advance by hop count, not by a
clock, so a WAV on the run's clock recalibrates the same way every time. When the last take is in, a new
profile is built (:func:`~facepuppet.runtime.voice.vowels.profile_from_rows`) and swapped in at that hop; a take
that cannot make one (a vowel too quiet) leaves the old profile and says why.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.voice.vowels import VOWELS, VowelProfile, profile_from_rows

if TYPE_CHECKING:
    from facepuppet.runtime.voice.source import VoiceChannels

PHASES = ("silence", *VOWELS)


class Recalibration:
    """One re-calibration of a :class:`VoiceChannels` that evaluates a :class:`VowelProfile`.

    Attributes
    ----------
    phase : int, the take being recorded (index into PHASES), len(PHASES) once done
    message : str, what the panel shows: the prompt, then the outcome
    profile : VowelProfile or None, the new profile once built
    """

    def __init__(self, channels: VoiceChannels, seconds: float = 2.0) -> None:
        if not isinstance(channels.table, VowelProfile):
            raise ValueError("re-calibration: the voice is not a vowel profile (--voice PROFILE.toml)")
        self.channels = channels
        self.per_phase = max(1, int(round(seconds / channels.table.spec.hop_s)))
        n = channels.features.spec.n_features
        self._rows = np.zeros((len(PHASES), self.per_phase, n))
        self._count = 0
        self.phase = 0
        self.profile: VowelProfile | None = None
        self.message = self.prompt()
        self.done = False

    def prompt(self) -> str:
        name = PHASES[self.phase]
        return "stay quiet..." if name == "silence" else f"hold the vowel {name}..."

    def start(self) -> Recalibration:
        self.channels.listener = self.hop
        return self

    def cancel(self) -> None:
        self.channels.listener = None
        self.done = True
        self.message = "re-calibration cancelled; the profile is unchanged"

    def hop(self, vector: np.ndarray) -> None:
        """One hop's features (the pushing thread): kept for the take in progress; the last one builds the profile."""
        self._rows[self.phase, self._count] = vector
        self._count += 1
        if self._count < self.per_phase:
            return
        self._count = 0
        self.phase += 1
        if self.phase < len(PHASES):
            self.message = self.prompt()
            return
        self.channels.listener = None
        try:
            profile, _ = profile_from_rows(dict(zip(PHASES, self._rows)), self.channels.features.spec)
        except ValueError as exc:
            self.message = f"re-calibration failed, the profile is unchanged: {exc}"
        else:
            self.profile = profile
            self.channels.use(profile)
            self.message = "new vowel profile in use (Save writes it)"
        self.done = True
