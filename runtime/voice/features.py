"""Causal log-mel features of a voice, computed block by block without allocating.

The mouth follows the sound it makes, so what a short window of the spectrum says about the
mouth's shape (open vowels, rounded vowels, closures) is read from mel bands of the last few
tens of milliseconds, with their history (a mouth closing before a /p/ shows in the sound of
the frames before). Every ``hop_s`` the extractor takes the last ``window_s`` of samples
(Hann window), its power spectrum by two fixed matrix products (a DFT written as cos / sin
matrices, so ``np.dot(..., out=...)`` writes into buffers made once: the audio thread never
allocates per block), its mel band energies in dB relative to full scale, floored at
``floor_db``, and keeps the last ``history`` hops in a ring.

The feature vector at a time is the mel frames of the hops ``0, step, 2 step, ...`` back
from the newest (``n_taps`` of them), each ``n_mels`` long, newest first, then the window's
level (dBFS): ``n_features = n_taps * n_mels + 1``. Nothing after the newest hop is used,
so the features are causal; a table fitted with a look-ahead is evaluated ``lookahead``
hops late (:mod:`facepuppet.runtime.voice.table`).

With ``level_ref_s`` > 0 every value of the vector is in dB relative to the speaker's running
level instead of full scale, and floored ``REL_FLOOR_DB`` under it: a microphone 10 dB quieter
than the training speech's gives the same vector once the running level has followed it. The
running level follows the loud part of speech: it starts at ``REF_START_DB``, rises toward a
louder hop with a time constant of ``ATTACK_S``, falls toward a quieter one within
``VOICED_SPAN_DB`` of it with ``level_ref_s``, and ignores hops further under it (pauses, a
room's noise) or under -80 dBFS. So a pause does not drag it down to the noise floor, and a
microphone of another gain is followed within a second or so when louder, a few ``level_ref_s``
when quieter.

The same class computes the training features offline (the whole WAV pushed through it), so
the features a table was fitted on and those it meets at run time are the same numbers.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

FLOOR_DB = -100.0
REL_FLOOR_DB = -60.0  # with a running level: values this far under it are all the same "nothing"
VOICED_SPAN_DB = 20.0
REF_START_DB = -30.0
ATTACK_S = 1.0


@dataclass(frozen=True)
class FeatureSpec:
    """The features a voice table was fitted on (stored in the table, so run time computes the same).

    sample_rate : float, Hz, of the samples the extractor is fed
    window_s, hop_s : float, seconds, analysis window and hop
    n_mels : int, mel bands between fmin and fmax (Hz)
    n_taps, step : int, how many past mel frames, every ``step`` hops
    level_ref_s : float, seconds, time constant of the running level the features are relative to (0: dBFS)
    """

    sample_rate: float = 16000.0
    window_s: float = 0.032
    hop_s: float = 0.010
    n_mels: int = 20
    fmin: float = 80.0
    fmax: float = 7000.0
    n_taps: int = 6
    step: int = 3
    level_ref_s: float = 0.0

    def __post_init__(self) -> None:
        for name in ("sample_rate", "window_s", "hop_s", "fmin", "fmax"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"FeatureSpec {name}: expected a positive number, got {v!r}")
        for name in ("n_mels", "n_taps", "step"):
            v = getattr(self, name)
            if not (isinstance(v, int) and 1 <= v <= 256):
                raise ValueError(f"FeatureSpec {name}: expected an int in 1..256, got {v!r}")
        if not self.fmin < self.fmax:
            raise ValueError(f"FeatureSpec: fmin {self.fmin} must be below fmax {self.fmax}")
        if not 0.002 <= self.window_s <= 0.2 or not 0.001 <= self.hop_s <= self.window_s:
            raise ValueError(f"FeatureSpec: window_s {self.window_s} must be within 2..200 ms and hop_s "
                             f"{self.hop_s} within 1 ms..window_s")
        ref = self.level_ref_s
        if not (isinstance(ref, (int, float)) and math.isfinite(ref) and (ref == 0 or 0.1 <= ref <= 600)):
            raise ValueError(f"FeatureSpec level_ref_s: expected 0 or 0.1..600 s, got {ref!r}")
        if self.sample_rate < 2 * self.fmax:
            raise ValueError(f"FeatureSpec: sample rate {self.sample_rate:g} Hz cannot carry fmax {self.fmax:g} Hz")

    @property
    def n_features(self) -> int:
        return self.n_taps * self.n_mels + 1

    @property
    def history(self) -> int:
        """Hops kept in the ring: enough for the oldest tap."""
        return (self.n_taps - 1) * self.step + 1

    def at_rate(self, sample_rate: float) -> FeatureSpec:
        """The same features for another sample rate (a microphone at 48 kHz): windows in seconds, bands in Hz."""
        return FeatureSpec(float(sample_rate), self.window_s, self.hop_s, self.n_mels, self.fmin,
                           min(self.fmax, 0.5 * float(sample_rate)), self.n_taps, self.step, self.level_ref_s)


def mel_filters(n_mels: int, n_fft: int, sample_rate: float, fmin: float, fmax: float) -> np.ndarray:
    """Triangular mel filters (HTK mel scale), shape (n_mels, n_fft // 2 + 1), float64, each summing to 1."""
    def mel(f):
        return 2595.0 * np.log10(1.0 + np.asarray(f, np.float64) / 700.0)

    edges_mel = np.linspace(mel(fmin), mel(fmax), n_mels + 2)
    edges = 700.0 * (10.0 ** (edges_mel / 2595.0) - 1.0)
    freqs = np.arange(n_fft // 2 + 1) * sample_rate / n_fft
    fb = np.zeros((n_mels, len(freqs)))
    for m in range(n_mels):
        lo, mid, hi = edges[m], edges[m + 1], edges[m + 2]
        up = (freqs - lo) / max(mid - lo, 1e-9)
        down = (hi - freqs) / max(hi - mid, 1e-9)
        fb[m] = np.maximum(0.0, np.minimum(up, down))
        if fb[m].sum() == 0.0:  # a band narrower than one bin: the nearest bin
            fb[m, int(np.argmin(np.abs(freqs - mid)))] = 1.0
        fb[m] /= fb[m].sum()
    return fb


class VoiceFeatures:
    """Streaming causal log-mel features (see the module docstring).

    ``push(samples)`` takes any number of samples (mono float in [-1, 1]) and returns how many
    hops completed; ``vector()`` is the feature vector after the newest hop, a view of a buffer
    the next call overwrites. ``on_hop`` (optional) is called after each hop, in the caller's
    thread, with this extractor: a voice source predicts there.
    """

    def __init__(self, spec: FeatureSpec, on_hop: Callable[[VoiceFeatures], None] | None = None) -> None:
        self.spec = spec
        rate = spec.sample_rate
        self.window_n = max(8, int(round(spec.window_s * rate)))
        self.hop_n = max(1, int(round(spec.hop_s * rate)))
        n = self.window_n
        n_bins = n // 2 + 1
        t = np.arange(n)
        hann = 0.5 - 0.5 * np.cos(2 * np.pi * (t + 0.5) / n)
        k = np.arange(n_bins)[:, None]
        # the DFT as two matrices with the window folded in: re = C x, im = S x
        self._cos = np.ascontiguousarray(np.cos(2 * np.pi * k * t / n) * hann)
        self._sin = np.ascontiguousarray(np.sin(2 * np.pi * k * t / n) * hann)
        # power -> band energies as a fraction of a full-scale sine's, so dB are relative to full scale
        full_scale = (hann.sum() / 2.0) ** 2
        self._mel = np.ascontiguousarray(mel_filters(spec.n_mels, n, rate, spec.fmin, spec.fmax) / full_scale)
        self._ring = np.zeros(2 * n)  # samples, written twice so the last window is always contiguous
        self._pos = 0  # write position in [0, n)
        self._since_hop = 0
        self._re = np.zeros(n_bins)
        self._im = np.zeros(n_bins)
        self._bands = np.zeros(spec.n_mels)
        self._frames = np.full((spec.history, spec.n_mels), FLOOR_DB)  # ring of mel frames in dB
        self._newest = spec.history - 1
        self._taps = np.zeros(spec.n_taps, np.intp)
        self._vector = np.full(spec.n_features, FLOOR_DB)
        self.level_db = FLOOR_DB
        self.ref_db = REF_START_DB
        self._ref_rate = spec.hop_s / spec.level_ref_s if spec.level_ref_s > 0 else 0.0
        self._attack = min(1.0, spec.hop_s / ATTACK_S)
        self.hops = 0
        self.on_hop = on_hop

    def reset(self) -> None:
        self._ring[:] = 0.0
        self._pos = self._since_hop = 0
        self._frames[:] = FLOOR_DB
        self._vector[:] = FLOOR_DB
        self.level_db = FLOOR_DB
        self.ref_db = REF_START_DB
        self.hops = 0

    def push(self, samples: np.ndarray) -> int:
        """Feed samples (shape (k,), float); returns the number of hops completed."""
        n, done, i, k = self.window_n, 0, 0, len(samples)
        while i < k:
            take = min(k - i, self.hop_n - self._since_hop, n - self._pos)
            chunk = samples[i:i + take]
            self._ring[self._pos:self._pos + take] = chunk
            self._ring[self._pos + n:self._pos + n + take] = chunk
            self._pos = (self._pos + take) % n
            self._since_hop += take
            i += take
            if self._since_hop == self.hop_n:
                self._since_hop = 0
                self._hop()
                done += 1
        return done

    def _hop(self) -> None:
        n = self.window_n
        x = self._ring[self._pos:self._pos + n]  # the last n samples, oldest first (a view)
        np.dot(self._cos, x, out=self._re)
        np.dot(self._sin, x, out=self._im)
        np.multiply(self._re, self._re, out=self._re)
        np.multiply(self._im, self._im, out=self._im)
        np.add(self._re, self._im, out=self._re)
        np.dot(self._mel, self._re, out=self._bands)
        self._newest = (self._newest + 1) % self.spec.history
        row = self._frames[self._newest]
        np.maximum(self._bands, 1e-30, out=row)
        np.log10(row, out=row)
        np.multiply(row, 10.0, out=row)
        np.maximum(row, FLOOR_DB, out=row)
        ms = float(np.dot(x, x)) / n
        self.level_db = max(10.0 * math.log10(ms), FLOOR_DB) if ms > 0.0 else FLOOR_DB
        if self._ref_rate > 0.0:
            level = self.level_db
            if level > self.ref_db:
                self.ref_db += self._attack * (level - self.ref_db)
            elif level > max(self.ref_db - VOICED_SPAN_DB, -80.0):
                self.ref_db += self._ref_rate * (level - self.ref_db)
        self.hops += 1
        if self.on_hop is not None:
            self.on_hop(self)

    def vector(self) -> np.ndarray:
        """Features after the newest hop, shape (n_features,), float64 (a view overwritten by the next call)."""
        spec = self.spec
        np.subtract(self._newest, np.arange(0, spec.n_taps * spec.step, spec.step, dtype=np.intp), out=self._taps)
        np.remainder(self._taps, spec.history, out=self._taps)
        m = spec.n_mels
        for j in range(spec.n_taps):
            self._vector[j * m:(j + 1) * m] = self._frames[self._taps[j]]
        self._vector[-1] = self.level_db
        if self._ref_rate > 0.0:  # relative to the running level, floored under it
            np.subtract(self._vector, self.ref_db, out=self._vector)
            np.maximum(self._vector, REL_FLOOR_DB, out=self._vector)
        return self._vector


def features_of(samples: np.ndarray, spec: FeatureSpec, times: np.ndarray) -> np.ndarray:
    """The feature vectors at ``times`` (s) of a whole recording, each from the samples before it.

    samples : ndarray of shape (n,), float, at ``spec.sample_rate``
    times : ndarray of shape (k,), float, seconds, increasing
    Returns ndarray of shape (k, n_features), float64.
    """
    ex = VoiceFeatures(spec)
    out = np.empty((len(times), spec.n_features))
    pos = 0
    for i, t in enumerate(times):
        end = min(max(int(round(t * spec.sample_rate)), pos), len(samples))
        ex.push(samples[pos:end])
        pos = end
        out[i] = ex.vector()
    return out
