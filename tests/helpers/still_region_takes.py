"""Marker takes where one region of the face is held still and the head turns by a known motion.

The measure of the automatic head-marker choice: a region that does not move in a take is as rigid as
the skull, and the choice must still find the skull's motion. Built from a real take: its markers are
brought into head coordinates with the data README's rigid set (:data:`SKULL`), the ``still`` markers are
replaced by their rest positions there plus a slow residual of the size the skull markers show in the same
take (real markers never stand perfectly still), optionally the still region turns a little as one piece
(a jaw held closed still moves on its hinge), and a known smooth rigid head motion is added to every
marker. The truth is that head motion.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from facepuppet.runtime.model.geometry import euler_to_quat, quat_to_matrix

from facepuppet.offline.actuation.stabilise import stabilise
from facepuppet.offline.io.capture import Capture

#: the data README's rigid head set of the AnimFace layout
SKULL = ("ForeHead_M", "ForeHead_L", "ForeHead_R", "NoseTop")
#: the brows of the AnimFace layout
BROWS = ("Leyebrow_M", "Leyebrow_Inside", "Leyebrow_Outside", "Eyebrow_Center", "Reyebrow_M", "Reyebrow_Inside",
         "Reyebrow_Outside")
#: the jaw, cheeks and mouth of the AnimFace layout (everything that moves with the jaw)
JAW = ("Lcheek_Up", "Lcheek_Down", "Lcheek_Outside", "Rcheek_Up", "Rcheek_Down", "Rcheek_Outside", "Mouth_Up",
       "Mouth_Down", "Mouth_UpL1", "Mouth_Lend", "Mouth_UpR1", "Mouth_Rend", "Mouth_DownL", "Mouth_DownR", "Chin",
       "Chin_R1", "Chin_R2", "Chin_L1", "Chin_L2")


def rotations(yaw_deg: np.ndarray, pitch_deg: np.ndarray, roll_deg: np.ndarray) -> np.ndarray:
    """Rotation matrices of shape (n, 3, 3) from per-frame Euler angles in degrees."""
    return np.stack([quat_to_matrix(euler_to_quat(*np.radians([y, p, r]))).astype(np.float64)
                     for y, p, r in zip(yaw_deg, pitch_deg, roll_deg)])


def still_region_take(capture: Capture, still: tuple[str, ...], turn_deg: float = 4.0, hinge_deg: float = 0.0,
                      seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The take with ``still`` held still in the skull's frame and a known head motion added.

    Parameters
    ----------
    capture : a real take (the AnimFace layout: :data:`SKULL` must be in it)
    still : marker names held still
    turn_deg : float, the largest head rotation added (yaw; pitch and roll a little less), degrees; the head
        also moves by up to 1 cm
    hinge_deg : float, the still region turns as one piece by up to this much about the face's left-right
        axis through its centre (a held jaw on its hinge), degrees
    seed : int, the still markers' residual

    Returns
    -------
    markers : ndarray of shape (n_frames, n_markers, 3), float64, capture units
    rotation : ndarray of shape (n_frames, 3, 3), float64, the true rotation from each frame to frame 0
        (what stabilisation should remove)
    """
    m = capture.markers.astype(np.float64)
    names = list(capture.names)
    head = stabilise(m, names, head_markers=list(SKULL)).markers.astype(np.float64)
    skull = [names.index(n) for n in SKULL]
    idx = [names.index(n) for n in still]
    n, rate = len(m), capture.rate
    rng = np.random.default_rng(seed)
    # residual of the size the skull markers show here, as slow as skin slide (a quarter-second blur)
    level = float(np.std(head[:, skull] - head[:, skull].mean(axis=0)))
    wobble = gaussian_filter1d(rng.normal(size=(n, len(idx), 3)), sigma=0.25 * rate, axis=0)
    wobble *= level / wobble.std()
    rest = np.median(head[:, idx], axis=0)
    t = np.arange(n) / rate
    if hinge_deg:
        across = head[0, names.index("ForeHead_L")] - head[0, names.index("ForeHead_R")]
        across /= np.linalg.norm(across)
        angle = np.radians(hinge_deg) * np.sin(2 * np.pi * 0.17 * t + 0.5)
        k = np.array([[0, -across[2], across[1]], [across[2], 0, -across[0]], [-across[1], across[0], 0]])
        hinge = np.eye(3) + np.sin(angle)[:, None, None] * k + (1 - np.cos(angle))[:, None, None] * (k @ k)
        centre = rest.mean(axis=0)
        region = (rest - centre) @ np.swapaxes(hinge, 1, 2) + centre
    else:
        region = np.broadcast_to(rest, (n,) + rest.shape)
    head[:, idx] = region + wobble
    # the known head motion: smooth, about the face's centre, frame 0 at rest
    phase = 2 * np.pi * t
    turn = rotations(turn_deg * np.sin(0.15 * phase), 0.75 * turn_deg * np.sin(0.23 * phase),
                     0.5 * turn_deg * np.sin(0.11 * phase))
    shift = np.c_[np.sin(0.13 * phase), 0.5 * np.sin(0.19 * phase), 0.8 * np.sin(0.07 * phase)] * (1.0 / 1.0)
    shift *= {"mm": 10.0, "cm": 1.0, "m": 0.01}[capture.units]
    centre = head[0].mean(axis=0)
    moved = (head - centre) @ np.swapaxes(turn, 1, 2) + centre + shift[:, None, :]
    # frame f -> frame 0: undo turn[f] (turn[0] is the identity)
    return moved, np.swapaxes(turn, 1, 2)


def rotation_error_deg(removed: np.ndarray, true: np.ndarray) -> np.ndarray:
    """Per-frame angle between the rotation a stabilisation removed and the true one, degrees."""
    diff = removed @ np.swapaxes(true, 1, 2)
    return np.degrees(np.arccos(np.clip((np.trace(diff, axis1=1, axis2=2) - 1) / 2, -1, 1)))
