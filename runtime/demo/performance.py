"""A deterministic synthetic performance for the demo: someone talking, blinking, smiling.

Phrases of syllables at about 4.5 Hz, separated by pauses, drive the jaw and
the audio level together; stressed syllables raise the brows and nod the
head; blinks come every 2-5 s (one of them a wink), smiles build and fade,
the eyes jump between gaze targets and the head sways slowly. Everything is
drawn from ``numpy.random.default_rng(seed)``, so a seed gives the same
frames bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.model.geometry import euler_to_quat

DEMO_CHANNELS: tuple[str, ...] = (
    "jawOpen", "mouthFunnel", "mouthPucker", "mouthClose",
    "mouthSmileLeft", "mouthSmileRight", "cheekSquintLeft", "cheekSquintRight",
    "eyeBlinkLeft", "eyeBlinkRight", "eyeWideLeft", "eyeWideRight",
    "eyeLookUpLeft", "eyeLookUpRight", "eyeLookDownLeft", "eyeLookDownRight",
    "eyeLookInLeft", "eyeLookInRight", "eyeLookOutLeft", "eyeLookOutRight",
    "browInnerUp", "browOuterUpLeft", "browOuterUpRight", "browDownLeft", "browDownRight",
)
SILENCE_DB = -60.0  # audio level between phrases, dBFS
LOUDEST_DB = -12.0  # audio level of the loudest syllable, dBFS


@dataclass(frozen=True)
class DemoCurves:
    """The performance as arrays, one row per frame.

    Attributes
    ----------
    t : ndarray of shape (n_frames,), float64, seconds from 0 in steps of 1 / rate
    weights : ndarray of shape (n_frames, len(DEMO_CHANNELS)), float32, 0..1
    head_rotation : ndarray of shape (n_frames, 4), float32, quaternion (x, y, z, w)
    head_translation : ndarray of shape (n_frames, 3), float32, cm
    audio_level : ndarray of shape (n_frames,), float64, dBFS
    """

    t: np.ndarray
    weights: np.ndarray
    head_rotation: np.ndarray
    head_translation: np.ndarray
    audio_level: np.ndarray


def _pulse(t: np.ndarray, start: float, attack: float, hold: float, release: float) -> np.ndarray:
    """0 → 1 → 0 envelope with raised-cosine ramps, (n,) float64."""
    up = np.clip((t - start) / attack, 0.0, 1.0)
    down = np.clip((t - start - attack - hold) / release, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * up) - (0.5 - 0.5 * np.cos(np.pi * down))


def _speech(t, duration, rng):
    """Syllable envelope (n,), rounded-lip envelope (n,) and the times of stressed syllables."""
    env = np.zeros_like(t)
    round_lips = np.zeros_like(t)
    stresses = []
    start = 0.4 + rng.uniform(0.0, 0.4)
    while start < duration - 0.5:
        length = rng.uniform(1.2, 3.0)
        n_syll = max(2, int(length * rng.uniform(4.0, 5.0)))
        onsets = start + np.cumsum(rng.uniform(0.18, 0.26, n_syll)) - 0.2
        amps = rng.uniform(0.25, 0.75, n_syll)
        stressed = rng.choice(n_syll, size=min(2, n_syll), replace=False)
        amps[stressed] = rng.uniform(0.85, 1.0, len(stressed))
        rounded = rng.uniform(size=n_syll) < 0.2
        for onset, amp, is_round in zip(onsets, amps, rounded):
            bump = amp * _pulse(t, onset, 0.07, 0.03, 0.1)
            env = np.maximum(env, bump)
            if is_round:
                round_lips = np.maximum(round_lips, bump)
        stresses.extend(onsets[stressed].tolist())
        start = onsets[-1] + 0.25 + rng.uniform(0.4, 1.2)  # pause between phrases
    return env, round_lips, sorted(stresses)


def demo_curves(duration: float = 12.0, rate: float = 60.0, seed: int = 0) -> DemoCurves:
    """The synthetic performance as arrays; see :class:`DemoCurves`.

    Parameters
    ----------
    duration : float, seconds, > 0
    rate : float, frames per second, > 0
    seed : int, seeds ``numpy.random.default_rng``; the only source of randomness
    """
    if not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration > 0):
        raise UsageError(f"demo performance: duration must be a finite number of seconds > 0, got {duration!r}")
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0):
        raise ValueError(f"demo performance: rate must be a finite number of frames per second > 0, got {rate!r}")
    rng = np.random.default_rng(seed)
    n = max(1, int(round(duration * rate)))
    t = np.arange(n) / float(rate)
    ch = {name: np.zeros(n) for name in DEMO_CHANNELS}

    env, round_lips, stresses = _speech(t, duration, rng)
    ch["jawOpen"] = 0.62 * env * (1 - 0.5 * round_lips / np.maximum(env, 1e-9))
    ch["mouthFunnel"] = 0.6 * round_lips
    ch["mouthPucker"] = 0.35 * round_lips
    ch["mouthClose"] = 0.15 * env * (env < 0.4)
    noise = rng.normal(0.0, 0.8, n)
    level = 20.0 * np.log10(1e-3 + 0.25 * env) + noise * (env > 0.02)
    level = np.clip(level, SILENCE_DB, LOUDEST_DB)

    # blinks every 2-5 s, ~150 ms; the third is a slow wink of the left eye
    blink_l, blink_r = np.zeros(n), np.zeros(n)
    moment, count = rng.uniform(0.8, 1.5), 0
    while moment < duration - 0.2:
        if count == 2:
            wink = _pulse(t, moment, 0.12, 0.25, 0.2)
            blink_l = np.maximum(blink_l, wink)
            ch["mouthSmileLeft"] = np.maximum(ch["mouthSmileLeft"], 0.5 * wink)
            ch["cheekSquintLeft"] = np.maximum(ch["cheekSquintLeft"], 0.6 * wink)
        else:
            blink = _pulse(t, moment, 0.055, 0.02, 0.085)
            blink_l, blink_r = np.maximum(blink_l, blink), np.maximum(blink_r, blink)
        count += 1
        moment += rng.uniform(2.0, 4.5)

    # smiles that build and fade, a little lopsided
    for start in np.sort(rng.uniform(0.0, max(duration - 2.0, 0.1), 2 + int(duration // 8))):
        amount = rng.uniform(0.45, 0.9)
        smile = amount * _pulse(t, start, rng.uniform(0.4, 0.8), rng.uniform(0.8, 2.0), rng.uniform(0.6, 1.0))
        tilt = rng.uniform(-0.15, 0.15)
        ch["mouthSmileLeft"] = np.maximum(ch["mouthSmileLeft"], smile * (1 + tilt))
        ch["mouthSmileRight"] = np.maximum(ch["mouthSmileRight"], smile * (1 - tilt))
        for side in ("Left", "Right"):
            ch["cheekSquint" + side] = np.maximum(ch["cheekSquint" + side], 0.5 * smile)

    # stresses raise the brows and nod the head
    raise_ = np.zeros(n)
    for moment in stresses:
        raise_ = np.maximum(raise_, rng.uniform(0.5, 0.9) * _pulse(t, moment - 0.05, 0.12, 0.15, 0.35))
    ch["browInnerUp"] = raise_
    ch["browOuterUpLeft"] = ch["browOuterUpRight"] = 0.7 * raise_
    ch["eyeWideLeft"] = ch["eyeWideRight"] = 0.35 * raise_
    frown = rng.uniform(0.3, 0.6) * _pulse(t, rng.uniform(0.3, 0.7) * duration, 0.3, 0.8, 0.5)
    ch["browDownLeft"] = ch["browDownRight"] = frown * (1 - raise_)

    # gaze: jumps between targets (saccades), held, eased over ~40 ms
    gaze = np.zeros((n, 2))  # yaw (+ towards the character's left), pitch (+ up), rad
    moment, target = 0.0, np.zeros(2)
    while moment < duration:
        end = moment + rng.uniform(0.6, 2.2)
        previous, target = target, rng.uniform([-0.35, -0.25], [0.35, 0.25]) * (rng.uniform() < 0.7)
        ease = np.clip((t - moment) / 0.04, 0, 1)[:, None]
        span = ((t >= moment) & (t < end))[:, None]
        gaze = np.where(span, previous + (target - previous) * ease, gaze)
        moment = end
    yaw_g, pitch_g = gaze[:, 0] / 0.5, gaze[:, 1] / 0.4
    ch["eyeLookUpLeft"] = ch["eyeLookUpRight"] = np.clip(pitch_g, 0, 1)
    ch["eyeLookDownLeft"] = ch["eyeLookDownRight"] = np.clip(-pitch_g, 0, 1)
    ch["eyeLookOutLeft"] = ch["eyeLookInRight"] = np.clip(yaw_g, 0, 1)  # both eyes to +x
    ch["eyeLookInLeft"] = ch["eyeLookOutRight"] = np.clip(-yaw_g, 0, 1)
    ch["eyeBlinkLeft"] = np.maximum(blink_l, 0.25 * ch["eyeLookDownLeft"])
    ch["eyeBlinkRight"] = np.maximum(blink_r, 0.25 * ch["eyeLookDownRight"])

    # head: slow sway plus a nod on each stress, following the gaze a little
    phase = rng.uniform(0, 2 * np.pi, 6)
    nod = np.zeros(n)
    for moment in stresses:
        nod += 0.07 * _pulse(t, moment - 0.08, 0.15, 0.05, 0.3)
    yaw = (0.12 * np.sin(2 * np.pi * 0.11 * t + phase[0]) + 0.04 * np.sin(2 * np.pi * 0.31 * t + phase[1])
           + 0.3 * gaze[:, 0])
    pitch = 0.05 * np.sin(2 * np.pi * 0.17 * t + phase[2]) + nod - 0.1 * gaze[:, 1]
    roll = 0.04 * np.sin(2 * np.pi * 0.13 * t + phase[3])
    rotation = np.array([euler_to_quat(a, b, c) for a, b, c in zip(yaw, pitch, roll)], dtype=np.float32)
    translation = np.stack([
        0.6 * np.sin(2 * np.pi * 0.09 * t + phase[4]),
        0.3 * np.sin(2 * np.pi * 0.23 * t + phase[5]) - 2.0 * nod,
        0.4 * np.sin(2 * np.pi * 0.07 * t + phase[0]),
    ], -1).astype(np.float32)

    weights = np.clip(np.stack([ch[name] for name in DEMO_CHANNELS], -1), 0.0, 1.0).astype(np.float32)
    return DemoCurves(t, weights, rotation, translation, level)


def demo_frames(duration: float = 12.0, rate: float = 60.0, seed: int = 0) -> list[Frame]:
    """The synthetic performance as frames for the frame loop.

    Parameters
    ----------
    duration : float, seconds, > 0
    rate : float, frames per second, > 0
    seed : int, seeds ``numpy.random.default_rng``

    Returns
    -------
    list of Frame
        ``t`` from 0 in steps of 1 / rate, ``source`` "demo", ``number`` the
        frame index, weights under :data:`DEMO_CHANNELS`, head pose (cm) and
        audio level (dBFS, -60 in silence). Same arguments, same frames bit for bit.
    """
    c = demo_curves(duration, rate, seed)
    return [
        Frame(
            t=float(c.t[i]),
            source="demo",
            channels=DEMO_CHANNELS,
            weights=c.weights[i],
            head_rotation=c.head_rotation[i],
            head_translation=c.head_translation[i],
            audio_level=float(c.audio_level[i]),
            number=i,
        )
        for i in range(len(c.t))
    ]
