"""The skeleton's pose each frame: the head pose, then the eyes' look-at, then the spring bones.

:class:`~facepuppet.runtime.render.renderer.FaceRenderer` draws a skinned
character with one array of skinning matrices per frame; this module makes
it, in the order in which each part needs the one before: the head pose turns
the neck and head (:class:`~facepuppet.runtime.render.parts_path.HeadPose`);
a bone-type look-at turns the eye bones inside the turned head
(:mod:`facepuppet.runtime.model.look_at`); the spring bones then swing behind
all of it, the root motion (the model matrix) included
(:mod:`facepuppet.runtime.render.spring_bones`). The frame's time and its
eye-look channels arrive through :meth:`SkeletonMotion.set_frame` (the frame
loop's tick time; a caller that gives none, a benchmark or a contact sheet,
advances :data:`DEFAULT_FRAME_S` per frame). The matrices are written into
one preallocated array.
"""

from __future__ import annotations

import time

import numpy as np

from facepuppet.runtime.frames import Frame
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.model.look_at import Gaze, LookAt, look_at_of
from facepuppet.runtime.model.springs import springs_of
from facepuppet.runtime.render.parts_path import HeadPose
from facepuppet.runtime.render.spring_bones import SpringBones

#: The time a frame advances when the caller gives no time (60 frames/s).
DEFAULT_FRAME_S = 1.0 / 60.0


def _euler_yp(yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """The rotation (3, 3) of a gaze: yaw about +Y (toward +X, the avatar's left), then pitch up (about -X)."""
    y, p = np.radians(yaw_deg), np.radians(pitch_deg)
    ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    rx = np.array([[1, 0, 0], [0, np.cos(p), np.sin(p)], [0, -np.sin(p), np.cos(p)]])
    return ry @ rx


class SkeletonMotion:
    """Head pose, eye look-at and spring bones as one array of skinning matrices per frame.

    Parameters
    ----------
    character : Character with a skeleton and a humanoid head bone
    head_pose : HeadPose of that character
    springs : bool, simulate the spring bones (``--no-springs``: False)

    Attributes
    ----------
    springs : SpringBones or None
    look_at : LookAt or None, a bone-type look-at with at least one eye bone
    moved_nodes : ndarray (n_nodes,) bool, every node this motion can move (the CPU skinner's rows)
    spring_ms : float, the last frame's spring simulation time, milliseconds (0 without springs)
    active : bool, there is something beyond the head pose
    """

    def __init__(self, character: Character, head_pose: HeadPose, springs: bool = True) -> None:
        sk = character.skeleton
        self.head_pose = head_pose
        self.n_nodes = sk.n_nodes
        settings = character.metadata.get("settings", {})
        rig = springs_of(character) if springs else None
        self.springs = SpringBones(rig, sk) if rig is not None and rig.n_joints else None
        look = look_at_of(settings, sk.n_nodes)
        self.look_at: LookAt | None = look if look is not None and look.kind == "bone" and (
            look.left_eye >= 0 or look.right_eye >= 0) else None
        self.moved_nodes = head_pose.moved_nodes.copy()
        self._eyes = []
        if self.look_at is not None:
            rest = sk.global_transforms()
            for node in (self.look_at.left_eye, self.look_at.right_eye):
                if node >= 0:
                    mask = sk.descendants(node)
                    self._eyes.append((node, mask, rest[node][:3, 3].copy()))
                    self.moved_nodes |= mask
                else:
                    self._eyes.append(None)
        if self.springs is not None:
            self.moved_nodes |= self.springs.moved_nodes
        self.active = self.springs is not None or self.look_at is not None
        self._out = np.tile(np.eye(4, dtype=np.float32), (max(self.n_nodes, 1), 1, 1))[:self.n_nodes]
        self._gaze = np.zeros(4)
        self._gazes: dict[tuple[str, ...], Gaze] = {}
        self._t: float | None = None
        self._given = False
        self.spring_ms = 0.0

    def set_frame(self, t: float, frame: Frame | None) -> None:
        """The next frame's time (seconds) and its eye-look channels (None: the gaze stays as it was)."""
        self._t, self._given = float(t), True
        if self.look_at is not None and frame is not None and frame.weights is not None:
            gaze = self._gazes.get(frame.channels)
            if gaze is None:
                gaze = self._gazes[frame.channels] = Gaze(frame.channels)
            if gaze.available:
                gaze.angles(frame.weights, out=self._gaze)

    def set_gaze(self, gaze: np.ndarray) -> None:
        """Set the gaze directly: (yaw left, pitch left, yaw right, pitch right) degrees."""
        self._gaze[:] = gaze

    def matrices(self, head_rotation: np.ndarray | None, model: np.ndarray) -> np.ndarray:
        """The frame's skinning matrices (n_nodes, 4, 4) float32 (the motion's buffer, rewritten next frame)."""
        out = self._out
        out[:] = self.head_pose.matrices(head_rotation)
        if self.look_at is not None:
            self._turn_eyes(out)
        if self.springs is not None:
            if not self._given:
                self._t = 0.0 if self._t is None else self._t + DEFAULT_FRAME_S
            self._given = False
            start = time.perf_counter()
            self.springs.advance(self._t, out, model)
            self.spring_ms = (time.perf_counter() - start) * 1e3
        return out

    def _turn_eyes(self, out: np.ndarray) -> None:
        turns = self.look_at.eye_turns(self._gaze)
        for eye, (yaw, pitch) in zip(self._eyes, turns):
            if eye is None:
                continue
            node, mask, pivot = eye
            turn = np.eye(4)
            r = _euler_yp(yaw, pitch)
            turn[:3, :3] = r
            turn[:3, 3] = pivot - r @ pivot
            carried = out[node].astype(np.float64)
            out[mask] = (carried @ turn @ np.linalg.inv(carried) @ out[mask].astype(np.float64)).astype(np.float32)


__all__ = ["DEFAULT_FRAME_S", "SkeletonMotion"]
