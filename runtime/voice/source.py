"""Where the voice's mouth channels come from at run time: a WAV on the run's clock, or the microphone's blocks.

:class:`VoiceChannels` owns one table's feature extractor and evaluator; every completed hop of samples is
evaluated at once (in the thread that pushed the samples: the microphone's callback, or the frame loop for a
WAV) into a slot of preallocated buffers, through a ring of ``delay`` hops (``--voice-delay``), so the frame
loop only copies the slot once per tick. Nothing is allocated per audio block beyond NumPy scalars.

* :class:`WavVoice` (``--audio-file``): at tick time ``t`` the samples up to ``t`` are pushed, so it plays on
  the frame clock and a replay of the same ticks gives the same channels; a sound onset reaches the weights
  at the first tick after the hop that holds it (one hop plus at most one tick).
* the microphone: :func:`attach_to_mic` hands every block :class:`~facepuppet.runtime.inputs.audio.MicLevel`
  receives to a :class:`VoiceChannels` at the microphone's own rate (the table's features are defined in
  seconds and Hz, so another rate computes the same quantities).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.inputs.audio import read_wav
from facepuppet.runtime.voice.features import VoiceFeatures
from facepuppet.runtime.voice.table import VoiceTable
from facepuppet.runtime.voice.vowels import VowelProfile

if TYPE_CHECKING:
    import os

    from facepuppet.runtime.inputs.audio import MicLevel

MAX_DELAY_S = 1.0


def load_voice(path: str | os.PathLike) -> VoiceTable | VowelProfile:
    """What ``--voice`` names: a calibrated vowel profile (``.toml``, calibrate-voice) or a voice table (fit-voice)."""
    if Path(path).suffix.lower() == ".toml":
        return VowelProfile.load(path)
    return VoiceTable.load(path)


class VoiceChannels:
    """The table's channels after the newest hop of samples pushed (see the module docstring).

    Parameters
    ----------
    table : VoiceTable
    sample_rate : float, Hz, of the samples pushed
    delay_s : float, seconds (0..1) the channels are held back (``--voice-delay``), rounded to hops
    """

    def __init__(self, table: VoiceTable, sample_rate: float, delay_s: float = 0.0) -> None:
        if not (math.isfinite(delay_s) and 0.0 <= delay_s <= MAX_DELAY_S):
            raise ValueError(f"voice delay: expected 0..{MAX_DELAY_S * 1000:g} ms, got {delay_s * 1000:g} ms")
        self.table = table
        self.features = VoiceFeatures(table.spec.at_rate(sample_rate), on_hop=self._on_hop)
        self.evaluate = table.evaluator()
        self.delay_hops = int(round(delay_s / table.spec.hop_s))
        self._ring = np.zeros((self.delay_hops + 1, len(table.outputs)), np.float32)
        self._at = 0
        self.slot = self._ring[0]  # the channels in force (a row of the ring: read, never written, by the loop)
        self.hops = 0

    @property
    def outputs(self) -> tuple[str, ...]:
        return self.table.outputs

    def push(self, samples: np.ndarray) -> None:
        """Feed samples (shape (k,), float in [-1, 1]); evaluates each hop completed."""
        self.features.push(samples)

    listener = None  # callable taking each hop's feature vector (a view), in the pushing thread: a recalibration

    def use(self, model: VoiceTable | VowelProfile) -> None:
        """Evaluate ``model`` (a table or profile with the same outputs) from the next hop; call it from the thread
        that pushes (a recalibration finishing in its listener), so no hop sees half of the change."""
        if tuple(model.outputs) != tuple(self.table.outputs):
            raise ValueError("voice: a new model must give the same channels")
        self.table = model
        self.evaluate = model.evaluator()

    def _on_hop(self, features: VoiceFeatures) -> None:
        if self.listener is not None:
            self.listener(features.vector())
        d = self.delay_hops + 1
        self._at = (self._at + 1) % d
        np.copyto(self._ring[self._at], self.evaluate(features.vector()))
        self.slot = self._ring[(self._at + 1) % d] if self.delay_hops else self._ring[self._at]
        self.hops += 1

    def values(self) -> np.ndarray:
        """A copy of the channels in force, shape (n_outputs,), float32."""
        return self.slot.copy()


class WavVoice:
    """The voice channels of a WAV file played on the frame clock (``--audio-file`` with ``--voice``).

    ``channels(t)`` pushes the samples of ``[t_prev, t)`` (silence past the end) and returns the channels.
    """

    def __init__(self, path: str | os.PathLike, table: VoiceTable, delay_s: float = 0.0) -> None:
        self.path = Path(path)
        self.samples, self.sample_rate = read_wav(self.path)
        self.voice = VoiceChannels(table, self.sample_rate, delay_s)
        self._pos = 0
        self._silence = np.zeros(self.voice.features.hop_n)

    @property
    def outputs(self) -> tuple[str, ...]:
        return self.voice.outputs

    def channels(self, t: float) -> np.ndarray:
        end = int(round(t * self.sample_rate))
        n = len(self.samples)
        if end > self._pos:
            if self._pos < n:
                self.voice.push(self.samples[self._pos:min(end, n)])
            k = end - max(self._pos, n)
            while k > 0:  # past the end: silence, a hop at a time
                step = min(k, len(self._silence))
                self.voice.push(self._silence[:step])
                k -= step
            self._pos = end
        return self.voice.values()

    def close(self) -> None:
        pass


class MicVoice:
    """The voice channels of the microphone: the blocks a MicLevel receives, pushed in its callback."""

    def __init__(self, mic: MicLevel, table: VoiceTable, delay_s: float = 0.0) -> None:
        self.voice = VoiceChannels(table, mic.meter.sample_rate, delay_s)
        self.mic = mic
        mic.on_block = self.voice.push

    @property
    def outputs(self) -> tuple[str, ...]:
        return self.voice.outputs

    def channels(self, t: float) -> np.ndarray:
        return self.voice.values()

    def close(self) -> None:
        self.mic.on_block = None

