"""A WAV 'voice' whose loudness swings slowly: a tone with a known envelope, for the voice hand-over tests."""

from __future__ import annotations

import wave

import numpy as np


def write_voice(path, seconds: float = 40.0, rate: int = 16000) -> None:
    """A 180 Hz tone whose loudness swings between about -36 and -9 dBFS at 0.8 Hz, as a 16-bit mono WAV."""
    t = np.arange(int(seconds * rate)) / rate
    envelope = 0.02 + 0.48 * (0.5 + 0.5 * np.sin(2 * np.pi * 0.8 * t))
    samples = (envelope * np.sin(2 * np.pi * 180.0 * t) * 32767).astype("<i2")
    with wave.open(str(path), "wb") as f:
        f.setnchannels(1)
        f.setsampwidth(2)
        f.setframerate(rate)
        f.writeframes(samples.tobytes())
