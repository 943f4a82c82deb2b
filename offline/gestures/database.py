"""Build the gesture reference database (Ju & Lee 2008, §4-§5) and export it as ``gesture_db`` tables.

What each reference gives (the data have no take with audio *and* whole-face gestures, so the
database is assembled from three kinds of take, each contributing the groups it really has):

=====================  =========================================  ====================================
take                   groups it provides                         speech intensity s(t)
=====================  =========================================  ====================================
speech + mouth curves  lips P(t) (FACEGOOD controls -> ARKit by   measured from its WAV
(FACEGOOD, 30 fps)     the mapping sheet, ``max`` combinations)
Live Link Face CSV     mood c(t) (§4.1) and residuals D_j(t) of   *proxy*: the take's own jawOpen,
                       brows, eyes, the rest (§4.2)               quantile-mapped onto the speech
                                                                  take's intensity distribution
marker take (C3D)      head track (rigid motion of forehead +     *proxy*: the Chin-NoseTop distance,
                       nose markers)                              quantile-mapped the same way
=====================  =========================================  ====================================

So only the lips have a measured speech-to-motion relation; the speech link of
blinks, brows and head is through the mouth activity of their own takes, an
assumption (people move more while they talk), not a measurement.

Every take is brought to ``fps`` (linear interpolation on its time stamps).
"""

from __future__ import annotations

import csv
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from facepuppet.runtime.errors import InputFileError, UsageError
from facepuppet.runtime.files.tables import hash_inputs, save_tables
from facepuppet.runtime.gestures.tables import GROUPS, HEAD_FEATURES
from facepuppet.runtime.mapping.channels import canonical, gesture_group
from facepuppet.runtime.recording.livelinkface_csv import read_llf_csv

from facepuppet.offline.gestures.blend_weights import BlendWeights, choose_basis
from facepuppet.offline.gestures.regional_features import head_track
from facepuppet.offline.gestures.speech_intensity import speech_intensity


@dataclass
class Take:
    """One reference take at the animation rate: features by name, intensity, and the groups it has."""

    name: str
    intensity: np.ndarray                      # (n,) float64, z-score s(t)
    columns: dict[str, np.ndarray]             # channel name -> (n,) float64
    groups: tuple[str, ...]
    source: str = ""
    n_frames: int = field(init=False)

    def __post_init__(self) -> None:
        self.n_frames = len(self.intensity)


def _resample(t: np.ndarray, values: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Values (n, d) on times t resampled to k / fps, k = 0 .. floor((t[-1] - t[0]) fps)."""
    t = np.asarray(t, np.float64) - t[0]
    grid = np.arange(int(np.floor(t[-1] * fps + 1e-9)) + 1) / fps
    return grid, np.stack([np.interp(grid, t, v) for v in np.asarray(values, np.float64).T], 1)


def quantile_map(x: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Map ``x`` onto the distribution of ``reference`` by ranks (ties share the mean rank's value)."""
    ranks = (np.argsort(np.argsort(x, kind="stable"), kind="stable") + 0.5) / len(x)
    return np.quantile(reference, ranks)


def read_speech_take(wav: str | os.PathLike, curves_csv: str | os.PathLike, mapping_csv: str | os.PathLike,
                     fps: float = 30.0, frames: slice = slice(None)) -> Take:
    """FACEGOOD speech take: intensity from the WAV, lips P(t) mapped to ARKit (``valid`` rows only)."""
    try:
        with open(curves_csv, newline="") as handle:
            rows = list(csv.reader(handle))
        header, data = rows[0], np.array(rows[1:], np.float64)
    except (UnicodeDecodeError, csv.Error, IndexError, ValueError) as exc:  # ValueError: a cell not a number
        raise InputFileError(f"{curves_csv}: expected a header row, then rows of numbers ({exc})") from None
    if data.ndim != 2 or not len(data):
        raise InputFileError(f"{curves_csv}: expected a header row, then rows of numbers (found {len(rows) - 1} rows)")
    col = {n: i for i, n in enumerate(header)}
    lips: dict[str, np.ndarray] = {}
    try:
        with open(mapping_csv, newline="") as handle:
            mapping = list(csv.DictReader(handle))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise InputFileError(f"{mapping_csv}: not a readable CSV file ({exc})") from None
    for row in mapping:
        if row.get("status") != "valid":
            continue
        if not (isinstance(row.get("arkit"), str) and isinstance(row.get("sources"), str)):
            raise InputFileError(f"{mapping_csv}: expected the columns arkit and sources in every valid row")
        if gesture_group(row["arkit"]) != "lips":
            continue
        srcs = [s for s in row["sources"].split(";") if s in col]
        if not srcs:
            continue
        v = np.max(data[:, [col[s] for s in srcs]], axis=1)  # the sheet's "max" combination
        if v.std() > 1e-6:  # keep the channels the take animates
            lips[canonical(row["arkit"])] = v
    if not lips:
        raise InputFileError(f"{curves_csv}: no animated lip channel maps to ARKit through {mapping_csv}")
    n = len(data)
    if abs(fps - 30.0) > 1e-9:
        raise UsageError(f"{curves_csv}: the curves are at 30 fps; build the database at fps=30, got {fps}")
    level, z, stats = speech_intensity(wav, fps=fps, n_frames=n)
    take = Take(Path(curves_csv).stem, z[frames], {k: v[frames] for k, v in lips.items()}, ("lips",),
                source=f"{Path(wav).name} + {Path(curves_csv).name}")
    take.speaker_stats = stats
    return take


def read_llf_take(path: str | os.PathLike, speech_z: np.ndarray, fps: float = 30.0) -> Take:
    """Live Link Face take: all weight channels at ``fps``; proxy intensity from its jawOpen."""
    frames = [f for f in read_llf_csv(path) if f.weights is not None]
    if len(frames) < 2:
        raise InputFileError(f"{path}: expected at least 2 frames with weights, found {len(frames)}")
    names = [canonical(c) for c in frames[0].channels]
    _, w = _resample(np.array([f.t for f in frames]), np.stack([f.weights for f in frames]), fps)
    columns = {n: w[:, i] for i, n in enumerate(names)}
    if "jawOpen" not in columns:
        raise InputFileError(f"{path}: expected a JawOpen column for the proxy intensity")
    z = quantile_map(columns["jawOpen"], speech_z)  # proxy s(t): see the module docstring
    return Take(Path(path).stem, z, columns, ("mood", "brows", "eyes", "rest"), source=Path(path).name)


def read_marker_take(path: str | os.PathLike, speech_z: np.ndarray, fps: float = 30.0) -> Take:
    """Marker take (C3D): head track; proxy intensity from the chin's distance to the nose top."""
    import warnings

    import c3d

    try:
        with open(path, "rb") as handle, warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "No analog data found" is expected
            reader = c3d.Reader(handle)
            names = [s.strip() for s in reader.point_labels]
            rate = float(reader.point_rate)
            pts = np.stack([p[:, :3] for _, p, _ in reader.read_frames()]).astype(np.float64)
    except OSError:
        raise
    except Exception as exc:  # the c3d package raises assorted errors on damaged files; np.stack on no frames
        raise InputFileError(f"{path}: not a readable C3D file ({type(exc).__name__}: {exc})") from None
    for m in ("Chin", "NoseTop"):
        if m not in names:
            raise InputFileError(f"{path}: expected marker {m!r} for the proxy intensity")
    track = head_track(pts, names)
    jaw = np.linalg.norm(pts[:, names.index("Chin")] - pts[:, names.index("NoseTop")], axis=1)
    _, res = _resample(np.arange(len(pts)) / rate, np.column_stack([track, jaw]), fps)
    z = quantile_map(res[:, -1], speech_z)
    return Take(Path(path).stem, z, {n: res[:, i] for i, n in enumerate(HEAD_FEATURES)}, ("head",),
                source=Path(path).name)


def assemble(takes: list[Take], n_basis: int = 6, epsilon: float = 0.1, window: int = 41,
             method: str = "lsq", seed: int = 0) -> tuple[dict, dict, dict]:
    """Blend weights (§4.1) over the mood takes, regional residuals (§4.2), one frame table.

    Returns
    -------
    arrays : dict of the ``gesture_db`` sections
    channels : dict with ``features``, ``takes``, ``groups``
    metrics : dict, blend fit error per take
    """
    lips = sorted({n for t in takes if "lips" in t.groups for n in t.columns})
    mood_takes = [t for t in takes if "mood" in t.groups]
    stoch = sorted({n for t in mood_takes for n in t.columns if gesture_group(n) != "lips"},  # by region, then name:
                   key=lambda n: (("brows", "eyes", "rest").index(gesture_group(n)), n))  # not the set's hash order
    head = list(HEAD_FEATURES) if any("head" in t.groups for t in takes) else []
    n_b = n_basis if mood_takes else 0
    names = lips + [f"mood_{i}" for i in range(n_b)] + stoch + head
    group = ([GROUPS.index("lips")] * len(lips) + [GROUPS.index("mood")] * n_b
             + [GROUPS.index(gesture_group(n)) for n in stoch] + [GROUPS.index("head")] * len(head))
    N = sum(t.n_frames for t in takes)
    F = np.zeros((N, len(names)))
    avail = np.zeros((N, len(GROUPS)), bool)
    basis_full = np.zeros((n_b, len(names)))
    metrics = {}
    stoch_cols = [names.index(n) for n in stoch]
    if mood_takes:
        X = np.vstack([np.column_stack([t.columns.get(n, np.zeros(t.n_frames)) for n in stoch]) for t in mood_takes])
        basis = choose_basis(X, n_basis, window, seed)
        basis_full[:, stoch_cols] = basis
    start = 0
    for t in takes:
        rows = slice(start, start + t.n_frames)
        for g in t.groups:
            avail[rows, GROUPS.index(g)] = True
        for n in lips + head:
            if n in t.columns:
                F[rows, names.index(n)] = t.columns[n]
        if "mood" in t.groups:
            x = np.column_stack([t.columns.get(n, np.zeros(t.n_frames)) for n in stoch])
            fit = BlendWeights(basis, epsilon, window, method, seed=seed).fit(x)
            F[rows, len(lips):len(lips) + n_b] = fit.weights_      # c(t), §4.1
            F[rows, stoch_cols] = fit.residual_                    # D_j(t), §4.2
            metrics[f"blend_rms_{t.name}"] = fit.error_
        start += t.n_frames
    scale = np.array([F[avail[:, g], i].std() if avail[:, g].any() else 1.0 for i, g in enumerate(group)])
    arrays = {
        "intensity": np.concatenate([t.intensity for t in takes]).astype(np.float32),
        "features": F.astype(np.float32),
        "feature_group": np.array(group, np.int32),
        "feature_scale": np.maximum(scale, 1e-3).astype(np.float32),
        "blend_basis": basis_full.astype(np.float32),
        "frame_take": np.repeat(np.arange(len(takes)), [t.n_frames for t in takes]).astype(np.int32),
        "available": avail,
    }
    channels = {"features": names, "takes": [t.name for t in takes], "groups": list(GROUPS)}
    return arrays, channels, metrics


def build_gesture_db(out: str | os.PathLike, speech: tuple, llf: Sequence[str | os.PathLike] = (),
                     markers: Sequence[str | os.PathLike] = (), fps: float = 30.0, speech_frames: slice = slice(None),
                     n_basis: int = 6, epsilon: float = 0.1, window: int = 41, method: str = "lsq",
                     seed: int = 0, alpha: dict[str, float] | None = None) -> tuple[Path, list[Take]]:
    """Read the references, assemble and save the ``gesture_db`` tables at ``out``; returns (path, takes).

    Parameters
    ----------
    speech : (wav, curves_csv, mapping_csv) of the speech take
    llf : Live Link Face CSV paths; markers : C3D paths
    speech_frames : slice of the speech take to use (the rest can be held out)
    """
    sp = read_speech_take(*speech, fps=fps, frames=speech_frames)
    takes = [sp] + [read_llf_take(p, sp.intensity, fps) for p in llf] + [read_marker_take(p, sp.intensity, fps)
                                                                         for p in markers]
    arrays, channels, metrics = assemble(takes, n_basis, epsilon, window, method, seed)
    settings = {
        "fps": fps, "n_basis": n_basis, "epsilon": epsilon, "window": window, "blend_method": method,
        "speaker_mean_db": sp.speaker_stats[0], "speaker_std_db": sp.speaker_stats[1],
        "speaker_gate_db": sp.speaker_stats[2],
        "alpha": dict(alpha or {"lips": 0.9, "mood": 0.1, "brows": 0.1, "eyes": 0.1, "rest": 0.1, "head": 0.1}),
        "sources": {t.name: t.source for t in takes},
        "pairing": "lips: measured speech; mood/brows/eyes/rest: proxy intensity from the take's jawOpen; "
                   "head: proxy from the markers' chin-nose distance (quantile-mapped onto the speech take)",
    }
    paths = [p for p in (*speech, *llf, *markers)]
    path = save_tables(out, "gesture_db", arrays, units="cm" if markers else "", channels=channels,
                       settings=settings, input_hash=hash_inputs(*[str(p) for p in paths]), metrics=metrics)
    return path, takes
