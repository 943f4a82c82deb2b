"""The unit of input: one immutable, timestamped frame from a source.

Missing data is explicit: a weight the tracker did not send is NaN, a head
pose or audio level that was not measured is None / NaN; never 0 by accident.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def _frozen(a, dtype, shape_tail: tuple[int, ...], field_name: str) -> np.ndarray | None:
    if a is None:
        return None
    arr = np.array(a, dtype=dtype, copy=True)
    if arr.shape[arr.ndim - len(shape_tail):] != shape_tail if shape_tail else False:
        raise ValueError(f"Frame.{field_name}: expected shape (..., {shape_tail}), got {arr.shape}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Frame:
    """One frame of tracking input.

    Attributes
    ----------
    t : float, seconds; receive time on the monotonic clock (live) or recorded time (replay)
    source : str, id of the source ("livelinkface", "vmc", "demo", ...)
    channels : tuple of n_channels str or None, names of ``weights``
    weights : ndarray of shape (n_channels,), float32, NaN where not sent; or None
    head_rotation : ndarray of shape (4,), float32, quaternion (x, y, z, w); or None
    head_translation : ndarray of shape (3,), float32, source units; or None
    audio_level : float, dBFS, NaN when not measured
    markers : ndarray of shape (n_markers, 3), float32, NaN where occluded; or None
    marker_names : tuple of n_markers str or None
    t_sender : float, seconds, the sender's own clock where known, else NaN
    number : int, the sender's frame number where known, else -1
    """

    t: float
    source: str = ""
    channels: tuple[str, ...] | None = None
    weights: np.ndarray | None = None
    head_rotation: np.ndarray | None = None
    head_translation: np.ndarray | None = None
    audio_level: float = math.nan
    markers: np.ndarray | None = None
    marker_names: tuple[str, ...] | None = None
    t_sender: float = math.nan
    number: int = -1

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "t", float(self.t))
        set_(self, "weights", _frozen(self.weights, np.float32, (), "weights"))
        if self.weights is not None:
            if self.weights.ndim != 1:
                raise ValueError(f"Frame.weights: expected shape (n_channels,), got {self.weights.shape}")
            if self.channels is None or len(self.channels) != len(self.weights):
                raise ValueError(
                    f"Frame.channels: {0 if self.channels is None else len(self.channels)} names "
                    f"for {len(self.weights)} weights"
                )
            set_(self, "channels", tuple(self.channels))
        set_(self, "head_rotation", _frozen(self.head_rotation, np.float32, (4,), "head_rotation"))
        set_(self, "head_translation", _frozen(self.head_translation, np.float32, (3,), "head_translation"))
        set_(self, "markers", _frozen(self.markers, np.float32, (3,), "markers"))
        if self.markers is not None and self.markers.ndim != 2:
            raise ValueError(f"Frame.markers: expected shape (n_markers, 3), got {self.markers.shape}")
        set_(self, "audio_level", float(self.audio_level))

    def is_finite(self) -> bool:
        """False when a value that is present is infinite, or a pose has NaN.

        NaN weights and markers mean "missing" and are allowed.
        """
        for arr in (self.weights, self.markers):
            if arr is not None and np.isinf(arr).any():
                return False
        for arr in (self.head_rotation, self.head_translation):
            if arr is not None and not np.isfinite(arr).all():
                return False
        return not math.isinf(self.audio_level)
