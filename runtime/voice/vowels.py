"""Calibrated vowels (the uLipSync method): the user's own A, I, U, E, O as MFCC templates, matched per hop.

A vowel is a shape of the spectrum's envelope (its formants) far more than a loudness, so each hop's newest
log-mel frame is turned into MFCCs (a DCT-II of the mel bands in dB, coefficient 0 — the loudness — left
out) and compared with one template per vowel, the mean MFCC of the user saying it (``calibrate-voice``).
Each vowel's weight is a softmax of the negative distances over ``temperature``, a silence template (when
calibrated) competes like a vowel and shuts the mouth when it wins, and the mouth's openness comes from the
level: 0 at ``floor_db``, 1 at ``ceiling_db`` (linear in dB). The outputs are the VRM vowel expressions
(``aa ih ou ee oh``: a VRM avatar's presets by name) and the ARKit mouth shapes those vowels look like
(:data:`VOWEL_ARKIT`), each vowel weight times the openness, so any avatar with the five presets talks, and a
perfect-sync one too.

The profile is a TOML file a person can read; it is untrusted input: every field is checked and a refusal
(:class:`VoiceProfileError`, exit 2) names the file and the field.
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facepuppet.runtime.errors import InputFileError
from facepuppet.runtime.files.input_files import regular_file
from facepuppet.runtime.files.outputs import write_atomic
from facepuppet.runtime.voice.features import FeatureSpec, VoiceFeatures

FORMAT = "facepuppet-voice-profile"
VERSION = 1
VOWELS = ("A", "I", "U", "E", "O")
VRM1_VOWELS = ("aa", "ih", "ou", "ee", "oh")
N_MFCC = 12
MAX_PROFILE_BYTES = 64 << 10

#: What each vowel looks like in ARKit shapes at full openness (the mouth of a Japanese-style a/i/u/e/o).
VOWEL_ARKIT: dict[str, dict[str, float]] = {
    "A": {"jawOpen": 0.7, "mouthLowerDownLeft": 0.3, "mouthLowerDownRight": 0.3},
    "I": {"jawOpen": 0.2, "mouthStretchLeft": 0.6, "mouthStretchRight": 0.6},
    "U": {"jawOpen": 0.15, "mouthPucker": 0.8, "mouthFunnel": 0.3},
    "E": {"jawOpen": 0.35, "mouthStretchLeft": 0.4, "mouthStretchRight": 0.4, "mouthLowerDownLeft": 0.3,
          "mouthLowerDownRight": 0.3},
    "O": {"jawOpen": 0.45, "mouthFunnel": 0.7, "mouthPucker": 0.2},
}
ARKIT_OUTPUTS = tuple(dict.fromkeys(name for shapes in VOWEL_ARKIT.values() for name in shapes))
VOWEL_SPEC = FeatureSpec(n_mels=26, n_taps=1, step=1, window_s=0.032, hop_s=0.010, fmin=80.0, fmax=7000.0)


class VoiceProfileError(InputFileError):
    """A voice profile that cannot be used; the message names the file and the field."""


def dct_matrix(n_mels: int, n_mfcc: int = N_MFCC) -> np.ndarray:
    """DCT-II rows 1..n_mfcc (orthonormal) over n_mels bands, shape (n_mfcc, n_mels), float64."""
    k = np.arange(1, n_mfcc + 1)[:, None]
    m = np.arange(n_mels)[None, :]
    return np.sqrt(2.0 / n_mels) * np.cos(np.pi * k * (m + 0.5) / n_mels)


def mfcc_of_frames(mel_db: np.ndarray, n_mfcc: int = N_MFCC) -> np.ndarray:
    """MFCCs (coefficient 0 left out) of mel frames in dB, shape (k, n_mels) -> (k, n_mfcc)."""
    return mel_db @ dct_matrix(mel_db.shape[1], n_mfcc).T


@dataclass(frozen=True, eq=False)
class VowelProfile:
    """The templates and the level range of one user's calibration.

    templates : ndarray of shape (5, n_mfcc), float64, A I U E O
    silence : ndarray of shape (n_mfcc,) or None
    temperature : float, > 0, the softmax's scale of distances
    floor_db, ceiling_db : float, dBFS, openness 0 and 1
    spec : FeatureSpec, the features (one tap: the newest mel frame, and the level)
    """

    templates: np.ndarray
    silence: np.ndarray | None
    temperature: float
    floor_db: float
    ceiling_db: float
    spec: FeatureSpec = VOWEL_SPEC
    path: str = ""

    @property
    def outputs(self) -> tuple[str, ...]:
        return (*VRM1_VOWELS, *ARKIT_OUTPUTS)

    lookahead_s = 0.0

    def evaluator(self) -> VowelEvaluator:
        return VowelEvaluator(self)

    def predict(self, X: np.ndarray) -> np.ndarray:
        ev = self.evaluator()
        return np.array([ev(x).astype(np.float64) for x in X]).reshape(len(X), len(self.outputs))

    def classify(self, X: np.ndarray) -> np.ndarray:
        """The winning class of each feature row: 0..4 the vowels, 5 silence."""
        ev = self.evaluator()
        out = np.empty(len(X), np.intp)
        for i, x in enumerate(X):
            ev(x)
            out[i] = ev.winner
        return out

    # -- file --------------------------------------------------------------
    def to_toml(self) -> str:
        def row(v):
            return "[" + ", ".join(f"{float(x):.4f}" for x in v) + "]"
        s = self.spec
        lines = [f'format = "{FORMAT}"', f"version = {VERSION}", "", "[features]",
                 f"sample_rate = {s.sample_rate:g}", f"window_s = {s.window_s:g}", f"hop_s = {s.hop_s:g}",
                 f"n_mels = {s.n_mels}", f"fmin = {s.fmin:g}", f"fmax = {s.fmax:g}", f"n_mfcc = {N_MFCC}", "",
                 "[match]", f"temperature = {self.temperature:.4f}", f"floor_db = {self.floor_db:.2f}",
                 f"ceiling_db = {self.ceiling_db:.2f}", "", "[templates]"]
        lines += [f"{v} = {row(t)}" for v, t in zip(VOWELS, self.templates)]
        if self.silence is not None:
            lines.append(f"silence = {row(self.silence)}")
        return "\n".join(lines) + "\n"

    def save(self, path: str | os.PathLike) -> Path:
        return write_atomic(path, lambda temp: temp.write_text(self.to_toml()))

    @classmethod
    def load(cls, path: str | os.PathLike) -> VowelProfile:
        """Read and check a profile (VoiceProfileError naming the file and the field)."""
        path = regular_file(path, "voice profile")
        size = path.stat().st_size
        if size > MAX_PROFILE_BYTES:
            raise VoiceProfileError(f"{path}: {size} bytes; a voice profile is at most {MAX_PROFILE_BYTES}")
        try:
            doc = tomllib.loads(path.read_bytes().decode("utf-8"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError, RecursionError) as exc:
            raise VoiceProfileError(f"{path}: not a TOML voice profile ({exc})") from None

        def fail(field: str, problem: str):
            raise VoiceProfileError(f"{path}: {field}: {problem}")

        if doc.get("format") != FORMAT:
            fail("format", f"expected {FORMAT!r}, found {doc.get('format')!r}")
        if not isinstance(doc.get("version"), int) or doc["version"] > VERSION or doc["version"] < 1:
            fail("version", f"expected an integer 1..{VERSION} (a newer facepuppet wrote it?), found "
                            f"{doc.get('version')!r}")

        def table(name: str) -> dict:
            v = doc.get(name)
            if not isinstance(v, dict):
                fail(name, "expected a table")
            return v

        def number(section: dict, where: str, key: str, low: float, high: float) -> float:
            v = section.get(key)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not low <= v <= high:
                fail(f"{where}.{key}", f"expected a number in {low:g}..{high:g}, found {v!r}")
            return float(v)

        f, m, t = table("features"), table("match"), table("templates")
        n_mels = number(f, "features", "n_mels", 8, 128)
        n_mfcc = number(f, "features", "n_mfcc", N_MFCC, N_MFCC)
        if n_mels != int(n_mels):
            fail("features.n_mels", f"expected an integer, found {n_mels}")
        try:
            spec = FeatureSpec(number(f, "features", "sample_rate", 8000, 192000),
                               number(f, "features", "window_s", 0.002, 0.2), number(f, "features", "hop_s",
                                                                                     0.001, 0.2),
                               int(n_mels), number(f, "features", "fmin", 1, 96000),
                               number(f, "features", "fmax", 1, 96000), 1, 1)
        except ValueError as exc:
            fail("features", str(exc))

        def vector(name: str, required: bool = True) -> np.ndarray | None:
            v = t.get(name)
            if v is None and not required:
                return None
            if not (isinstance(v, list) and len(v) == int(n_mfcc)
                    and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                            and abs(x) < 1e4 for x in v)):
                fail(f"templates.{name}", f"expected {int(n_mfcc)} finite numbers")
            return np.array(v, np.float64)

        floor = number(m, "match", "floor_db", -120, 0)
        ceiling = number(m, "match", "ceiling_db", -120, 0)
        if ceiling <= floor:
            fail("match.ceiling_db", f"expected more than floor_db {floor:g}, found {ceiling:g}")
        return cls(np.stack([vector(v) for v in VOWELS]), vector("silence", required=False),
                   number(m, "match", "temperature", 1e-3, 1e4), floor, ceiling, spec, str(path))


class VowelEvaluator:
    """Per hop: vowel weights and openness into buffers made once; ``ev(x)`` returns a view it overwrites."""

    def __init__(self, profile: VowelProfile) -> None:
        self.profile = profile
        n = profile.spec.n_mels
        self._dct = np.ascontiguousarray(dct_matrix(n))
        self._templates = profile.templates if profile.silence is None else np.vstack(
            [profile.templates, profile.silence])
        self._mfcc = np.zeros(N_MFCC)
        self._diff = np.zeros_like(self._templates)
        self._d = np.zeros(len(self._templates))
        self._y = np.zeros(len(profile.outputs), np.float32)
        # the ARKit rows: per vowel, the shapes at full openness
        self._look = np.zeros((len(VOWELS), len(ARKIT_OUTPUTS)))
        for i, v in enumerate(VOWELS):
            for name, w in VOWEL_ARKIT[v].items():
                self._look[i, ARKIT_OUTPUTS.index(name)] = w
        self._w = np.zeros(len(VOWELS))
        self._arkit = np.zeros(len(ARKIT_OUTPUTS))
        self.winner = 5

    def __call__(self, x: np.ndarray) -> np.ndarray:
        p = self.profile
        n = p.spec.n_mels
        np.dot(self._dct, x[:n], out=self._mfcc)
        np.subtract(self._templates, self._mfcc, out=self._diff)
        np.multiply(self._diff, self._diff, out=self._diff)
        np.sum(self._diff, axis=1, out=self._d)
        np.sqrt(self._d, out=self._d)
        self.winner = int(np.argmin(self._d))
        # softmax of -d / T, shifted by the smallest distance (no overflow)
        np.subtract(self._d, self._d[self.winner], out=self._d)
        np.multiply(self._d, -1.0 / p.temperature, out=self._d)
        np.exp(self._d, out=self._d)
        np.multiply(self._d, 1.0 / float(self._d.sum()), out=self._d)
        level = float(x[-1])
        openness = min(max((level - p.floor_db) / (p.ceiling_db - p.floor_db), 0.0), 1.0)
        if len(self._d) > len(VOWELS):  # a silence template: it wins or shares out the weight
            openness *= 1.0 - float(self._d[len(VOWELS)])
            if self.winner == len(VOWELS):
                openness = 0.0
        if openness == 0.0:
            self.winner = 5 if level <= p.floor_db or self.winner == len(VOWELS) else self.winner
        np.multiply(self._d[:len(VOWELS)], openness, out=self._w)
        np.dot(self._w, self._look, out=self._arkit)
        y = self._y
        y[:len(VOWELS)] = self._w
        y[len(VOWELS):] = self._arkit
        np.clip(y, 0.0, 1.0, out=y)
        return y


def feature_rows(x: np.ndarray, spec: FeatureSpec) -> np.ndarray:
    """The feature vector after each whole hop of samples ``x``, shape (k, n_features) (newest mel frame, level)."""
    ex = VoiceFeatures(spec)
    hop = ex.hop_n
    rows = []
    for start in range(0, len(x) - hop + 1, hop):
        ex.push(x[start:start + hop])
        rows.append(ex.vector().copy())
    return np.array(rows).reshape(-1, spec.n_features)


def build_profile(takes: dict[str, np.ndarray], sample_rate: float, silence: np.ndarray | None = None) -> tuple[
        VowelProfile, dict]:
    """A profile from one recording per vowel (samples at ``sample_rate``), each a few seconds of the vowel held
    (:func:`profile_from_rows` over each take's hops)."""
    spec = VOWEL_SPEC.at_rate(sample_rate)
    missing = [v for v in VOWELS if v not in takes]
    if missing:
        raise ValueError(f"calibrate-voice: no recording of {', '.join(missing)}")
    rows = {v: feature_rows(np.asarray(takes[v], np.float64), spec) for v in VOWELS}
    if silence is not None and len(silence):
        rows["silence"] = feature_rows(np.asarray(silence, np.float64), spec)
    return profile_from_rows(rows, spec)


def profile_from_rows(rows: dict[str, np.ndarray], spec: FeatureSpec) -> tuple[VowelProfile, dict]:
    """A profile from the feature rows (k, n_features) of each vowel's take (and optionally ``"silence"``).

    The template is the mean MFCC over the voiced hops (within 20 dB of the take's loudest); the temperature is a
    quarter of the median distance between templates; openness runs from 10 dB over the silence's level (at
    least -60 dBFS; -50 dBFS without a silence take) to the vowels' median level. Returns (profile, report of
    per-vowel hops and levels). ValueError when a vowel's take is missing or silent.
    """
    n = spec.n_mels
    templates, voiced_levels, report = [], [], {}
    for v in VOWELS:
        X = rows.get(v)
        lv = X[:, -1] if X is not None else np.zeros(0)
        if len(lv) == 0 or lv.max() <= -90:
            raise ValueError(f"calibrate-voice: the recording of {v} is {'missing' if X is None else 'silent'}")
        keep = lv >= lv.max() - 20.0
        templates.append(mfcc_of_frames(X[keep, :n]).mean(axis=0))
        voiced_levels.extend(lv[keep].tolist())
        report[v] = {"hops": int(keep.sum()), "level_db": float(np.median(lv[keep]))}
    T = np.array(templates)
    d = np.sqrt(((T[:, None] - T[None]) ** 2).sum(-1))[np.triu_indices(len(VOWELS), 1)]
    sil = None
    floor = -50.0
    quiet = rows.get("silence")
    if quiet is not None and len(quiet):
        sil = mfcc_of_frames(quiet[:, :n]).mean(axis=0)
        floor = float(min(max(np.median(quiet[:, -1]) + 10.0, -60.0), np.median(voiced_levels) - 12.0))
        report["silence"] = {"hops": int(len(quiet)), "level_db": float(np.median(quiet[:, -1]))}
    ceiling = float(max(np.median(voiced_levels), floor + 6.0))
    profile = VowelProfile(T, sil, float(max(np.median(d) / 4.0, 1e-2)), floor, ceiling, spec)
    report["template_distance_median"] = float(np.median(d))
    return profile, report


def voiced_hops(profile: VowelProfile, x: np.ndarray, rate: float) -> np.ndarray:
    """Feature rows of the hops within 20 dB of the take's loudest (the vowel held), shape (k, n_features)."""
    X = feature_rows(x, profile.spec.at_rate(rate))
    return X[X[:, -1] >= X[:, -1].max() - 20.0] if len(X) else X
