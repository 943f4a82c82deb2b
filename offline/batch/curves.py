"""A job's ARKit curves as a Live Link Face CSV: what an engine's importer (and ``facepuppet replay``) reads.

Each tick's drawn weights are folded onto ARKit's 52 shapes the way ``--llf-out`` sends them
(:func:`~facepuppet.runtime.mapping.vrm_names.fold_to_arkit`: a channel by its ARKit name in any spelling, an
unsided ARKit shape from the larger of a rig's two sides; NaN as 0, clipped to [0, 1]; a shape the rig lacks
is 0). The timecode counts Live Link Face's 60 frames per second from 00:00:00:00 at the first tick, with the
sub-frame in the fraction, so the tick times read back exactly as written to a microsecond.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from facepuppet.runtime.files.outputs import write_atomic
from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.mapping.vrm_names import fold_to_arkit
from facepuppet.runtime.recording.livelinkface_csv import TIMECODE_FPS


def arkit_curves(weights: np.ndarray, names: Sequence[str]) -> np.ndarray:
    """ARKit's 52 curves of a rig's weights.

    Parameters
    ----------
    weights : ndarray of shape (n_ticks, n_shapes), float
    names : sequence of n_shapes str, the rig's channel names

    Returns
    -------
    ndarray of shape (n_ticks, 52), float32, in :data:`ARKIT_NAMES` order
    """
    weights = np.asarray(weights, dtype=np.float64).reshape(len(weights), len(names))
    first, second, _ = fold_to_arkit(names)
    padded = np.zeros((len(weights), len(names) + 1))
    padded[:, :-1] = np.clip(np.nan_to_num(weights, nan=0.0), 0.0, 1.0)
    return np.maximum(padded[:, first], padded[:, second]).astype(np.float32)


def timecode(t: float) -> str:
    """``HH:MM:SS:FF.ffffff`` of ``t`` seconds at Live Link Face's 60 frames per second."""
    frames = max(t, 0.0) * TIMECODE_FPS
    seconds, sub = divmod(frames, TIMECODE_FPS)
    h, rest = divmod(int(seconds), 3600)
    m, s = divmod(rest, 60)
    return f"{h:02d}:{m:02d}:{s:02d}:{sub:09.6f}"


def write_curves(path: Path, times: np.ndarray, weights: np.ndarray, names: Sequence[str]) -> Path:
    """Write ``path`` (atomically): ``Timecode``, ``BlendShapeCount`` and the 52 curves, one row per tick."""
    curves = arkit_curves(weights, names)
    text = io.StringIO(newline="")
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(["Timecode", "BlendShapeCount", *(n[0].upper() + n[1:] for n in ARKIT_NAMES)])
    t0 = float(times[0]) if len(times) else 0.0
    for t, row in zip(times, curves):
        writer.writerow([timecode(float(t) - t0), len(ARKIT_NAMES), *(f"{v:.6g}" for v in row)])
    data = text.getvalue()
    return write_atomic(path, lambda temp: temp.write_text(data, encoding="ascii"))
