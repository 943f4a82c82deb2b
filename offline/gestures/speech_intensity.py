"""Speech intensity (Ju & Lee 2008, §5.1 input): a WAV file -> dB per animation frame, normalised per speaker.

Frame *i* belongs to audio time *i* / fps (the FACEGOOD curves' convention):
its level is the RMS of a Hann window of ``window_s`` seconds centred there,
in dB relative to full scale (``20 log10(rms)``), floored at ``floor_db``.
The speaker normalisation is a z-score over the voiced frames:
``s(t) = (dB(t) - mean_voiced) / std_voiced``, silence at
:data:`~facepuppet.runtime.gestures.layer.SILENCE_Z`. Voiced means above a noise
gate derived from the speaker's own level distribution: the 10th percentile
of the frame levels estimates the noise floor (a take with at least 10 %
pauses), and the gate sits ``GATE_MARGIN_DB`` (6 dB) above it, capped at
``GATE_BELOW_PEAKS_DB`` (20 dB) under the 90th percentile (the speech peaks)
for a take with no pauses, and never below the absolute floor + 1 dB. E.g. the CMU ARCTIC
utterance has -46..-52 dBFS of room noise before and after the words (10th
percentile -49.4 dBFS, gate -43.4 dBFS): those frames are silence, so the
lips close there.

Symbols: s(t) -> ``intensity`` (normalised), dB(t) -> ``level_db``.

Inputs are checked at the door (decoding by the runtime's
:func:`~facepuppet.runtime.inputs.audio.read_wav`): mono int16/int32/uint8/float WAV at any rate
(resampled to ``rate`` Hz with :func:`scipy.signal.resample_poly`); stereo is
refused unless ``stereo="mix"``; NaN or infinite samples are refused;
all-silent audio gives floor levels (and a warning from the normaliser).
"""

from __future__ import annotations

import math
import os
import warnings
from fractions import Fraction

import numpy as np
from scipy.signal import resample_poly

from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.gestures.layer import SILENCE_Z
from facepuppet.runtime.inputs.audio import read_wav

DEFAULT_RATE = 16000
FLOOR_DB = -60.0
GATE_PERCENTILE = 10.0
GATE_MARGIN_DB = 6.0
GATE_BELOW_PEAKS_DB = 20.0


class SpeechInputError(InputFileError):
    """A speech WAV that cannot be used; the message names the file and says why."""


def read_speech(path: str | os.PathLike, rate: int = DEFAULT_RATE, stereo: str = "refuse") -> np.ndarray:
    """Mono float64 samples in [-1, 1] of ``path`` at ``rate`` Hz.

    Parameters
    ----------
    path : WAV file
    rate : int, Hz, the rate to return (another rate is resampled, polyphase)
    stereo : "refuse" (SpeechInputError) or "mix" (average the channels)

    Returns
    -------
    samples : ndarray of shape (n,), float64
    """
    if stereo not in ("refuse", "mix"):
        raise ValueError(f"stereo: expected 'refuse' or 'mix', got {stereo!r}")
    try:
        x, file_rate = read_wav(path, stereo=stereo, finite=True)
    except OSError as exc:
        raise SpeechInputError(f"{path}: not a readable WAV file ({exc})") from None
    except ValueError as exc:  # the runtime reader's message names the file and the problem
        raise SpeechInputError(str(exc)) from None
    if file_rate != rate:
        f = Fraction(int(rate), int(file_rate))
        x = resample_poly(x, f.numerator, f.denominator)
    return x


def level_db(samples: np.ndarray, rate: int, fps: float, window_s: float = 2.0 / 30.0,
             floor_db: float = FLOOR_DB, n_frames: int | None = None) -> np.ndarray:
    """RMS level in dBFS of a Hann window centred on each frame time i / fps.

    Parameters
    ----------
    samples : ndarray of shape (n,), float, in [-1, 1]
    rate : int, Hz
    fps : float, animation frames per second
    n_frames : int or None, default floor(duration * fps)

    Returns
    -------
    level_db : ndarray of shape (n_frames,), float64, dBFS, >= floor_db
    """
    samples = np.asarray(samples, np.float64)
    if samples.ndim != 1:
        raise ValueError(f"samples: expected shape (n,), got {samples.shape}")
    if not np.isfinite(samples).all():
        raise ValueError("samples: expected finite values, found NaN or infinity")
    n = int(math.floor(len(samples) / rate * fps)) if n_frames is None else int(n_frames)
    half = max(1, int(round(window_s * rate / 2)))
    win = np.hanning(2 * half + 1)
    win /= win.sum()
    padded = np.pad(samples ** 2, half)
    centres = np.round(np.arange(n) * rate / fps).astype(np.int64)
    power = np.convolve(padded, win[::-1], mode="valid")  # power[c] = Σ w x²[c-half .. c+half]
    p = power[np.clip(centres, 0, len(power) - 1)]
    return np.maximum(10.0 * np.log10(np.maximum(p, 1e-30)), floor_db)  # dBFS of the RMS


def noise_gate(level: np.ndarray, floor_db: float = FLOOR_DB) -> float:
    """Noise gate in dBFS from the speaker's level distribution (see the module docstring)."""
    level = np.asarray(level, np.float64)
    noise = float(np.percentile(level, GATE_PERCENTILE))
    gate = min(noise + GATE_MARGIN_DB, float(np.percentile(level, 90.0)) - GATE_BELOW_PEAKS_DB)
    return max(gate, floor_db + 1.0)


def speaker_stats(level: np.ndarray, floor_db: float = FLOOR_DB) -> tuple[float, float, float]:
    """(mean, std, gate) in dB: the noise gate and the statistics of the voiced frames (above the gate).

    All silent (fewer than 2 voiced frames): (floor, 1, floor + 1) and a RuntimeWarning.
    """
    level = np.asarray(level, np.float64)
    gate = noise_gate(level, floor_db) if len(level) else floor_db + 1.0
    voiced = level[level > gate]
    if len(voiced) < 2:
        warnings.warn("speech intensity: no voiced frames (all silence); intensity is the floor throughout",
                      RuntimeWarning, stacklevel=2)
        return float(floor_db), 1.0, floor_db + 1.0
    return float(voiced.mean()), float(max(voiced.std(), 1.0)), gate


def normalise(level: np.ndarray, mean_db: float, std_db: float, gate_db: float = FLOOR_DB + 1.0) -> np.ndarray:
    """Per-speaker z-score of dB levels; at or below the gate: SILENCE_Z."""
    z = np.maximum((level - mean_db) / std_db, SILENCE_Z)
    return np.where(level > gate_db, z, SILENCE_Z)


def speech_intensity(path: str | os.PathLike, fps: float = 30.0, rate: int = DEFAULT_RATE, stereo: str = "refuse",
                     n_frames: int | None = None) -> tuple[np.ndarray, np.ndarray, tuple[float, float, float]]:
    """WAV -> (level_db, intensity, (mean_db, std_db, gate_db)) at ``fps`` frames per second.

    Returns
    -------
    level_db : ndarray of shape (n_frames,), float64, dBFS
    intensity : ndarray of shape (n_frames,), float64, per-speaker z-score s(t)
    stats : (mean_db, std_db) of the voiced frames and the noise gate gate_db, dBFS
    """
    x = read_speech(path, rate=rate, stereo=stereo)
    level = level_db(x, rate, fps, n_frames=n_frames)
    stats = speaker_stats(level)
    return level, normalise(level, *stats), stats
