"""The per-channel response of the ``filter`` stage: mirror, gain, range and curve, clamp, blink linking.

:class:`Response` turns one config and one channel layout into flat arrays once (when the layout or the
config changes), so the per-frame work is a handful of vectorised numpy operations, no Python loop over
channels. For a calibrated value ``x`` (the filtered value minus the neutral) of channel ``i``:

1. **mirror** (``[face] mirror``): the value of the channel's other side (``eyeBlinkLeft`` <- ``eyeBlinkRight``,
   ``jawLeft`` <- ``jawRight``); the settings that follow are those of the channel the value lands on;
2. ``v = gain * x``;
3. a shaped channel (an input or output range, or a curve other than linear):
   ``u = clip((v - in_low) / (in_high - in_low), 0, 1)``; ``ease``: ``u = 3u² - 2u³``; ``threshold``:
   ``u = 0`` where ``v < threshold``; then ``v = out_from + u * (out_to - out_from)`` (the input and output
   ranges default to [0, 1]); an unshaped channel keeps ``v``;
4. ``clip(v, clamp_low, clamp_high)``;
5. **blink linking** (``[face] link_blinks``): both ``eyeBlink`` channels take the larger of the two
   (one not sent: the other's).

A NaN (channel not sent) stays NaN through every step. The head's mirror: rotation (x, y, z, w) ->
(x, -y, -z, w), i.e. the reflection in the x = 0 plane (yaw and roll change sign, pitch is kept), and
translation x -> -x.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from facepuppet.runtime.live.config import LiveConfig
from facepuppet.runtime.mapping.channels import canonical, split_side

_MIRROR_ROT = np.array([1.0, -1.0, -1.0, 1.0])
_MIRROR_TRANS = np.array([-1.0, 1.0, 1.0])
_OTHER_SIDE = {"Left": "Right", "Right": "Left"}


def mirror_permutation(channels: Sequence[str]) -> np.ndarray | None:
    """Index of each channel's other side in ``channels`` (itself when it has none); None when nothing swaps."""
    keys = [canonical(c) for c in channels]
    at = {k: i for i, k in enumerate(keys)}
    perm = np.arange(len(keys))
    for i, k in enumerate(keys):
        base, side = split_side(k)
        if side is None and k.endswith(("Left", "Right")):  # directional: jawLeft, mouthRight, ...
            side = "Left" if k.endswith("Left") else "Right"
            base = k[: -len(side)]
        if side is not None:
            perm[i] = at.get(base + _OTHER_SIDE[side], i)
    return None if np.array_equal(perm, np.arange(len(keys))) else perm


def mirror_rotation(q: np.ndarray) -> np.ndarray:
    """The head rotation (x, y, z, w) seen in a mirror (the x = 0 plane): yaw and roll negated."""
    return q * _MIRROR_ROT


def mirror_translation(t: np.ndarray) -> np.ndarray:
    """The head translation seen in a mirror: x negated."""
    return t * _MIRROR_TRANS


class Response:
    """The precomputed response of one channel layout under one config (see the module docstring).

    Parameters
    ----------
    channels : sequence of str, the input's channel names, in frame order
    config : LiveConfig
    """

    def __init__(self, channels: Sequence[str], config: LiveConfig) -> None:
        n = len(channels)
        self.mirror = bool(config.mirror)
        self.perm = mirror_permutation(channels) if self.mirror else None
        per = [config.channel(c) for c in channels]
        self.gain = np.array([p.gain for p in per], dtype=np.float64).reshape(n)
        self.low = np.array([p.clamp[0] for p in per], dtype=np.float64).reshape(n)
        self.high = np.array([p.clamp[1] for p in per], dtype=np.float64).reshape(n)
        in_lo, in_hi, out_from, out_to, u_lo, u_hi = (np.zeros(n) for _ in range(6))
        thresholds = []
        for i, p in enumerate(per):
            if p.shaped:
                in_lo[i], in_hi[i] = p.input_range or (0.0, 1.0)
                out_from[i], out_to[i] = p.output_range or (0.0, 1.0)
                u_lo[i], u_hi[i] = 0.0, 1.0
            else:  # identity: v passes as it is
                in_lo[i], in_hi[i], out_from[i], out_to[i] = 0.0, 1.0, 0.0, 1.0
                u_lo[i], u_hi[i] = -np.inf, np.inf
            if p.curve == "threshold":
                thresholds.append((i, p.threshold))
        self.in_lo, self.inv_span = in_lo, 1.0 / (in_hi - in_lo)
        self.out_from, self.out_span = out_from, out_to - out_from
        self.u_lo, self.u_hi = u_lo, u_hi
        self.ease = np.array([i for i, p in enumerate(per) if p.curve == "ease"], dtype=np.intp)
        self.thr = np.array([i for i, _ in thresholds], dtype=np.intp)
        self.thr_v = np.array([t for _, t in thresholds], dtype=np.float64)
        self.any_shaped = any(p.shaped for p in per)
        keys = [canonical(c) for c in channels]
        self.blinks = None
        if config.link_blinks and "eyeBlinkLeft" in keys and "eyeBlinkRight" in keys:
            self.blinks = (keys.index("eyeBlinkLeft"), keys.index("eyeBlinkRight"))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """The response to calibrated values ``x`` (n,) float64: a new array (n,) float64."""
        if self.perm is not None:
            x = x[self.perm]
        v = x * self.gain
        if self.any_shaped:
            u = (v - self.in_lo) * self.inv_span
            np.clip(u, self.u_lo, self.u_hi, out=u)
            if self.ease.size:
                e = u[self.ease]
                u[self.ease] = e * e * (3.0 - 2.0 * e)
            if self.thr.size:
                u[self.thr] = np.where(v[self.thr] < self.thr_v, 0.0, u[self.thr])
            # unshaped channels: u = v here (in [0, 1] -> out [0, 1], no clip), so this is v for them
            v = self.out_from + u * self.out_span
        np.clip(v, self.low, self.high, out=v)
        if self.blinks is not None:
            left, right = self.blinks
            v[left] = v[right] = np.fmax(v[left], v[right])
        return v

    def rotation(self, q: np.ndarray) -> np.ndarray:
        """The head rotation after the response (mirrored when asked)."""
        return mirror_rotation(q) if self.mirror else q

    def translation(self, t: np.ndarray) -> np.ndarray:
        """The head translation after the response (mirrored when asked)."""
        return mirror_translation(t) if self.mirror else t
