"""Audio level (dBFS) from the microphone or a WAV file, for the gesture layer and the stats.

The level of a block of samples is its RMS in dB relative to full scale
(``20 log10(rms)``; a full-scale sine reads -3.01 dBFS), floored at
``floor_db``, then smoothed with separate attack and release time constants
in the dB domain: a rising level follows with time constant ``attack_s``, a
falling one with ``release_s`` (``level += (1 - exp(-block_s / tau)) * (new - level)``).

* :class:`MicLevel` opens an input stream with sounddevice; its callback
  (PortAudio's thread) writes the smoothed level into a preallocated slot and
  never allocates a Python object per block beyond NumPy scalars, never blocks.
  A block too far behind the capture clock is dropped unread and counted
  (:mod:`~facepuppet.runtime.inputs.capture_lag` says how far, and why). The
  stream opens with PortAudio's low latency, and a run starts it only when its
  loop is about to tick (samples captured while the chain and the window are set
  up would only be queued, stale, ahead of the first tick's).
* :class:`WavLevel` stands in for the microphone (``--audio-file``): the level
  at tick time ``t`` is computed from the samples between the previous tick and
  ``t``, so it plays on the frame clock and a replay gives the same levels.

A missing device or PortAudio raises :class:`AudioUnavailable` with a message
that says what to do; the live run logs it and goes on without audio.
"""

from __future__ import annotations

import logging
import math
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.errors import FacepuppetError, InputFileError
from facepuppet.runtime.files.input_files import regular_file
from facepuppet.runtime.inputs.capture_lag import MAX_LAG_S, CaptureLag

if TYPE_CHECKING:
    import os

logger = logging.getLogger(__name__)


class AudioUnavailable(FacepuppetError, RuntimeError):
    """No audio input could be opened; the message says why."""


class LevelMeter:
    """RMS dBFS of sample blocks with a noise floor and attack/release smoothing.

    Parameters
    ----------
    sample_rate : float, Hz
    attack_s : float, seconds, time constant of a rising level (> 0)
    release_s : float, seconds, time constant of a falling level (> 0)
    floor_db : float, dBFS, the level of silence (and the start value)
    """

    def __init__(self, sample_rate: float, attack_s: float = 0.01, release_s: float = 0.3,
                 floor_db: float = -60.0) -> None:
        for name, v in (("sample_rate", sample_rate), ("attack_s", attack_s), ("release_s", release_s)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"LevelMeter {name}: expected a positive number, got {v!r}")
        self.sample_rate = float(sample_rate)
        self.attack_s = float(attack_s)
        self.release_s = float(release_s)
        self.floor_db = float(floor_db)
        self.level_db = self.floor_db

    def block_db(self, samples: np.ndarray) -> float:
        """Unsmoothed level of one block: RMS in dBFS, at least ``floor_db``.

        samples : ndarray of shape (n,) or (n, channels), float in [-1, 1]; channels are averaged
        """
        x = np.asarray(samples, dtype=np.float64)
        if x.ndim == 2:
            x = x.mean(axis=1)
        if x.size == 0:
            return self.floor_db
        with np.errstate(all="ignore"):
            ms = float(np.dot(x, x)) / x.size
        if not (ms > 0 and math.isfinite(ms)):
            return self.floor_db
        # 20 log10(rms), within [floor, 0 dBFS]: samples beyond full scale are clipping, not louder speech
        return min(max(10.0 * math.log10(ms), self.floor_db), 0.0)

    def process(self, samples: np.ndarray) -> float:
        """Smoothed level (dBFS) after one more block; a block of 0 samples leaves it as it is."""
        n = len(samples)
        if n == 0:
            return self.level_db
        new = self.block_db(samples)
        tau = self.attack_s if new > self.level_db else self.release_s
        self.level_db += (1.0 - math.exp(-n / self.sample_rate / tau)) * (new - self.level_db)
        return self.level_db


def read_wav(path: str | os.PathLike, stereo: str = "mix", finite: bool = False) -> tuple[np.ndarray, int]:
    """Samples of a WAV file as float64 in [-1, 1], shape (n,), and the rate (Hz).

    int16, int32, uint8 and float32/64 files are read (scipy.io.wavfile); integer
    samples are divided by the type's magnitude (uint8 centred on 128).

    Parameters
    ----------
    path : str or Path, a WAV file
    stereo : "mix" (average the channels) or "refuse" (ValueError for more than one channel)
    finite : bool, refuse NaN or infinite samples (InputFileError) instead of reading them as silence

    Without ``finite``, NaN or infinite samples read as 0 and float samples beyond
    full scale are clipped to +-1; one warning, naming the file, says how many.

    Raises
    ------
    InputFileError (a ValueError)
        naming the file when it is not a WAV file scipy can read, has an unsupported sample
        type, has several channels with ``stereo="refuse"``, or non-finite samples with ``finite``.
    """
    from scipy.io import wavfile

    if stereo not in ("mix", "refuse"):
        raise ValueError(f"read_wav stereo: expected 'mix' or 'refuse', got {stereo!r}")
    path = regular_file(path, "WAV file")
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            rate, data = wavfile.read(path)
    except (FileNotFoundError, IsADirectoryError, PermissionError):
        raise
    except Exception as exc:  # scipy raises ValueError, struct.error, EOFError, ... on damaged files
        raise InputFileError(f"{path}: not a readable WAV file ({type(exc).__name__}: {exc})") from None
    if caught:  # scipy's own warnings (e.g. a short data chunk) do not name the file: say it once, with it
        warnings.warn(f"{path}: {caught[0].message}", UserWarning, stacklevel=2)
    if not (isinstance(rate, int) and rate > 0):
        raise InputFileError(f"{path}: WAV sample rate must be a positive integer, found {rate!r}")
    with np.errstate(all="ignore"):  # garbled float data: counted below, not warned about per sample
        if data.dtype.kind == "f":
            x = data.astype(np.float64)
        elif data.dtype == np.uint8:
            x = (data.astype(np.float64) - 128.0) / 128.0
        elif data.dtype.kind == "i":
            x = data.astype(np.float64) / float(-np.iinfo(data.dtype).min)
        else:
            raise InputFileError(f"{path}: WAV sample type {data.dtype} is not supported "
                                 f"(expected int16/int32/uint8/float)")
        if x.ndim == 2:
            if stereo == "refuse" and x.shape[1] > 1:
                raise InputFileError(f"{path}: expected a mono WAV, found {x.shape[1]} channels "
                                     f"(convert it to mono, or pass stereo='mix' / --stereo mix to average them)")
            x = x.mean(axis=1)
    bad = ~np.isfinite(x)
    n_bad = int(np.count_nonzero(bad))
    if finite and n_bad:
        raise InputFileError(f"{path}: {n_bad} samples are NaN or infinite; expected finite audio")
    if n_bad:
        x[bad] = 0.0
    n_over = int(np.count_nonzero(np.abs(x) > 1.0))
    if n_bad or n_over:
        np.clip(x, -1.0, 1.0, out=x)
        warnings.warn(f"{path}: {n_bad} samples NaN or infinite (read as silence), {n_over} beyond full scale "
                      f"(clipped to +-1); the level is measured on the cleaned samples", UserWarning, stacklevel=2)
    return x, int(rate)


class WavLevel:
    """The level of a WAV file played on the frame clock.

    Parameters
    ----------
    path : str or Path, a WAV file (mono or stereo, int or float samples)
    attack_s, release_s, floor_db : see :class:`LevelMeter`
    loop : bool, start again at the end (default False: silence after the end)

    ``level(t)`` gives the level after the samples in ``[t_prev, t)``, where
    ``t_prev`` is the time of the previous call (tick times, seconds from 0).
    """

    def __init__(self, path: str | os.PathLike, attack_s: float = 0.01, release_s: float = 0.3,
                 floor_db: float = -60.0, loop: bool = False) -> None:
        self.path = Path(path)
        self.samples, self.sample_rate = read_wav(self.path)
        self.meter = LevelMeter(self.sample_rate, attack_s, release_s, floor_db)
        self.loop = loop
        self._pos = 0

    @property
    def duration(self) -> float:
        return len(self.samples) / self.sample_rate

    def level(self, t: float) -> float:
        """Smoothed level (dBFS) at tick time ``t`` (s); times must not go back."""
        end = int(round(t * self.sample_rate))
        if end <= self._pos:
            return self.meter.level_db
        n = len(self.samples)
        if self.loop and n:
            block = self.samples[np.arange(self._pos, end) % n]
        else:
            block = self.samples[min(self._pos, n):min(end, n)]
            if end - self._pos > len(block):  # past the end: silence
                block = np.concatenate([block, np.zeros(end - self._pos - len(block))])
        self._pos = end
        return self.meter.process(block)

    def close(self) -> None:
        pass


class MicLevel:
    """The microphone's level, measured in sounddevice's callback.

    Parameters
    ----------
    device : int, str or None, sounddevice input device (None: the default)
    sample_rate : float or None, Hz (None: the device's default)
    block_s : float, seconds per callback block
    attack_s, release_s, floor_db : see :class:`LevelMeter`
    max_lag_s : float, seconds a block may lie behind the standing latency before it is dropped as stale
        (:class:`~facepuppet.runtime.inputs.capture_lag.CaptureLag`)
    start : bool, start the stream now (False: the caller calls :meth:`start` when it is ready to read)

    Attributes
    ----------
    lag : CaptureLag, the blocks' lag; ``lag.counters`` (also ``counters``): blocks read, dropped as stale, ...

    Raises
    ------
    AudioUnavailable
        when sounddevice or PortAudio is missing, the device does not exist,
        or the stream cannot be opened.
    """

    def __init__(self, device: int | str | None = None, sample_rate: float | None = None, block_s: float = 0.01,
                 attack_s: float = 0.01, release_s: float = 0.3, floor_db: float = -60.0,
                 max_lag_s: float = MAX_LAG_S, start: bool = True) -> None:
        try:
            import sounddevice as sd
        except (ImportError, OSError) as exc:  # OSError: the PortAudio library is missing
            raise AudioUnavailable(f"no audio: sounddevice/PortAudio is not available ({exc}); "
                                   "install PortAudio (apt-get install libportaudio2) or use --audio-file") from None
        self.device_name = "the default input device" if device is None else str(device)
        try:
            info = sd.query_devices(device, "input")
            rate = float(sample_rate or info["default_samplerate"])
            self.meter = LevelMeter(rate, attack_s, release_s, floor_db)
            self._slot = np.full(1, floor_db)  # written by the callback, read by the frame loop
            self.stream = sd.InputStream(device=device, channels=1, samplerate=rate, latency="low",
                                         blocksize=max(1, int(rate * block_s)), callback=self._callback)
            self.lag = CaptureLag(rate, max_lag_s, float(self.stream.latency), f"microphone {info.get('name', device)}")
            self.counters = self.lag.counters
            if start:
                self.stream.start()
        except (ValueError, sd.PortAudioError, OSError) as exc:
            name = "the default input device" if device is None else f"input device {device!r}"
            raise AudioUnavailable(f"no audio: could not open {name} ({exc}); "
                                   "list devices with `python -m sounddevice`, or use --audio-file") from None
        self.device_name = str(info.get("name", self.device_name))

    on_block = None  # callable taking each block's samples (n,) in the callback: the voice's features

    @property
    def status_errors(self) -> int:
        return self.counters["status_errors"]

    def start(self) -> None:
        """Start the stream (once; a started stream is left as it is)."""
        if not self.stream.active:
            self.stream.start()

    def _callback(self, indata, frames, time_info, status) -> None:
        if not self.lag.fresh(time_info, frames, status):
            return
        self._slot[0] = self.meter.process(indata[:, 0])
        if self.on_block is not None:
            self.on_block(indata[:, 0])

    def level(self, t: float | None = None) -> float:
        """The latest smoothed level (dBFS); ``t`` is ignored (the microphone is live)."""
        return float(self._slot[0])

    def close(self) -> None:
        self.stream.stop()
        self.stream.close()


def open_audio(device: int | str | None = None, wav: str | os.PathLike | None = None,
               log: Callable[[str], None] = logger.info, start: bool = True,
               **meter: float) -> WavLevel | MicLevel | None:
    """The audio level source the run asked for, or None (with a logged message) when none can be had.

    ``wav`` (a path) wins over ``device``; ``device`` may be "" / None for the default input. ``start=False``
    opens a microphone without starting it (the caller starts it when its loop is about to tick).
    """
    if wav is not None:
        return WavLevel(wav, **meter)
    try:
        if isinstance(device, str) and device.strip().isdigit():
            device = int(device)
        return MicLevel(device=device or None, start=start, **meter)
    except AudioUnavailable as exc:
        log(f"{exc}; the run goes on without audio")
        return None
