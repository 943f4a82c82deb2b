"""``--llf-out HOST:PORT``: the character's face and head sent as Live Link Face packets (PROTOCOLS.md §5).

Every tick sends one UDP datagram laid out as the phone's version-6 packet,
byte for byte what :mod:`facepuppet.runtime.inputs.livelinkface` decodes (and
Unreal's Live Link Face source reads): little-endian version 6, the 37-byte
device id (``$`` and a UUID), the big-endian name length and the subject name,
the frame time (frame number, sub-frame, fps, denominator; big-endian int32,
float32, int32, int32), the count 61 (uint8), and 61 big-endian float32:

* the 52 ARKit weights in Apple's order (the UDP order; the CSV order differs),
  the rig's channels folded into them by
  :func:`facepuppet.runtime.mapping.vrm_names.fold_to_arkit` (the same fold as
  ``--vmc-out``: split ``browInnerUp_L/_R`` by their max; a shape the rig lacks
  is 0), clipped to [0, 1], NaN sent as 0. A shape the rig lacks is sent as the tick's input frame (after
  the stages) gives it, folded the same way, when the frame has it: a character that cannot answer for a
  channel (a VRM avatar without ARKit morphs lacks them all) passes the face it was given on, rather than
  a still face; only a channel neither has is 0;
* head yaw, pitch, roll in radians, the inverse of the decoder's
  :func:`~facepuppet.runtime.model.geometry.euler_to_quat` (R = Ry(yaw) Rx(pitch) Rz(roll),
  :func:`~facepuppet.runtime.model.geometry.quat_to_euler`), so what we send decodes
  to the rotation we drew;
* left-eye then right-eye yaw, pitch, roll in radians. A frame carries no eye
  rotation, so they are made from the eyeLook weights the packet carries
  (facepuppet's choice, not the phone's fact): yaw = ``EYE_YAW_MAX`` ×
  (look to the eye's own left − look to its own right), i.e. for the left eye
  ``eyeLookOutLeft − eyeLookInLeft`` and for the right eye
  ``eyeLookInRight − eyeLookOutRight`` (positive yaw turns about +y, towards the
  character's left, as the head's); pitch = ``EYE_PITCH_MAX`` × (down − up)
  (positive pitch turns about +x, downwards); roll 0.

**Frame time.** Tick time ``t`` on a 60 fps timecode: frame number
``floor(t · 60)``, sub-frame the fraction left, fps 60, denominator 1, so the
decoder's sender time ``(frame + sub-frame) · denominator / fps`` is ``t``.

**Socket.** Connected to the destination at start (the kernel binds it to the
local address routing there, the loopback for 127.0.0.1); it sends only to
the address the user named. The packet is built once and only the changing
bytes are patched per tick (one ``struct.pack_into`` for the 61 values).
"""

from __future__ import annotations

import math
import socket
import struct
import uuid
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.inputs.livelinkface import N_VALUES, encode_llf_packet
from facepuppet.runtime.mapping.channels import ARKIT_NAMES
from facepuppet.runtime.mapping.vrm_names import fold_to_arkit
from facepuppet.runtime.model.geometry import quat_to_euler

if TYPE_CHECKING:
    from facepuppet.runtime.frames import Frame
    from facepuppet.runtime.live.loop import TickInfo

TIMECODE_FPS = 60
MAX_INPUT_FOLDS = 8  # input channel layouts whose fold is kept (a run's inputs have one or two)
EYE_YAW_MAX = math.radians(30.0)    # eyeLookOut/In = 1 sent as a 30° eye turn (facepuppet's choice)
EYE_PITCH_MAX = math.radians(25.0)  # eyeLookUp/Down = 1 sent as a 25° eye turn
SUBJECT = "facepuppet"
_TIMING = struct.Struct(">ifii")
_VALUES = struct.Struct(f">{N_VALUES}f")
_ARKIT = {name: i for i, name in enumerate(ARKIT_NAMES)}


def device_id(name: str = SUBJECT) -> str:
    """The 37-character device id: ``$`` and a UUID made from ``name`` (the same every run)."""
    return "$" + str(uuid.uuid5(uuid.NAMESPACE_URL, f"facepuppet:{name}")).upper()


def eye_angles(arkit: np.ndarray) -> tuple[float, ...]:
    """Left then right eye (yaw, pitch, roll), radians, from ARKit weights ``arkit`` (52,) (see the module doc)."""
    a = arkit

    def w(name: str) -> float:
        return float(a[_ARKIT[name]])

    left_yaw = EYE_YAW_MAX * (w("eyeLookOutLeft") - w("eyeLookInLeft"))
    right_yaw = EYE_YAW_MAX * (w("eyeLookInRight") - w("eyeLookOutRight"))
    left_pitch = EYE_PITCH_MAX * (w("eyeLookDownLeft") - w("eyeLookUpLeft"))
    right_pitch = EYE_PITCH_MAX * (w("eyeLookDownRight") - w("eyeLookUpRight"))
    return (left_yaw, left_pitch, 0.0, right_yaw, right_pitch, 0.0)


class LlfSender:
    """Send a character's weights and head rotation as Live Link Face version-6 packets (see the module doc).

    Parameters
    ----------
    host, port : where to send (UDP); only there
    names : sequence of n str, the character's (or the retargeted) channel names, any spelling
    subject : str, the subject name Unreal lists (default ``facepuppet``)

    Attributes
    ----------
    packet : bytearray, the datagram of the last tick
    counters : dict: ``packets_sent``, ``send_errors``
    missing : tuple of str, the ARKit names the rig has no channel for (sent from the input frame, else 0)
    """

    def __init__(self, host: str, port: int, names: Sequence[str], subject: str = SUBJECT) -> None:
        self.address = (host, int(port))
        names = tuple(names)
        raw = subject.encode("utf-8")
        if not raw or len(raw) > 256:
            raise ValueError(f"--llf-out: the subject name must be 1 to 256 bytes of UTF-8, got {subject!r}")
        self.subject = subject
        self._n = len(names)
        self._first, self._second, _extras = fold_to_arkit(names)
        self.missing = tuple(name for name, i in zip(_ARKIT, self._first) if i == self._n)
        self._lacking = np.flatnonzero(self._first == self._n)
        self._padded = np.zeros(self._n + 1)
        self._input_folds: dict[tuple[str, ...], tuple[np.ndarray, np.ndarray]] = {}
        self.packet = bytearray(encode_llf_packet([0.0] * 52, name=subject, device_id=device_id(subject),
                                                  fps=TIMECODE_FPS))
        self._timing_at = 45 + len(raw)
        self._values_at = self._timing_at + _TIMING.size + 1
        self.counters = {"packets_sent": 0, "send_errors": 0}
        self._sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.connect(self.address)
        except OSError as exc:
            self._sock.close()
            raise OSError(f"--llf-out {host}:{port}: cannot send there: {exc.strerror or exc}") from exc

    def arkit(self, weights: np.ndarray) -> np.ndarray:
        """ARKit's 52 values of the rig's ``weights`` (n,) float: folded, NaN as 0, clipped to [0, 1]; (52,) float64."""
        padded = self._padded
        padded[:-1] = weights
        np.nan_to_num(padded, copy=False, nan=0.0)
        np.clip(padded, 0.0, 1.0, out=padded)
        return np.maximum(padded[self._first], padded[self._second])

    def from_input(self, arkit: np.ndarray, frame: Frame | None) -> None:
        """Fill the ARKit channels the rig lacks in ``arkit`` (52,) from ``frame``'s weights where it has them
        (folded as the rig's are, clipped to [0, 1]; NaN, "not sent", stays 0)."""
        if not self._lacking.size or frame is None or frame.weights is None:
            return
        folds = self._input_folds.get(frame.channels)
        if folds is None:
            if len(self._input_folds) >= MAX_INPUT_FOLDS:
                self._input_folds.clear()
            first, second, _ = fold_to_arkit(frame.channels)
            folds = self._input_folds[frame.channels] = (first, second)
        first, second = folds
        values = np.zeros(len(frame.weights) + 1)
        values[:-1] = frame.weights
        np.nan_to_num(values, copy=False, nan=0.0)
        np.clip(values, 0.0, 1.0, out=values)
        lacking = self._lacking
        arkit[lacking] = np.maximum(values[first[lacking]], values[second[lacking]])

    def encode(self, weights: np.ndarray, rotation: np.ndarray | None = None, t: float = 0.0,
               frame: Frame | None = None) -> bytearray:
        """The packet of one tick: rig ``weights`` (n,), head ``rotation`` (x, y, z, w) or None (identity),
        tick time ``t`` seconds (>= 0), the tick's input ``frame`` (after the stages; it answers for the
        shapes the rig lacks) or None. Returns :attr:`packet`, patched in place."""
        arkit = self.arkit(weights)
        self.from_input(arkit, frame)
        head = (0.0, 0.0, 0.0) if rotation is None else quat_to_euler(rotation)
        frames = max(t, 0.0) * TIMECODE_FPS
        number = int(frames)
        _TIMING.pack_into(self.packet, self._timing_at, number, frames - number, TIMECODE_FPS, 1)
        _VALUES.pack_into(self.packet, self._values_at, *arkit.tolist(), *head, *eye_angles(arkit))
        return self.packet

    def send(self, weights: np.ndarray, rotation: np.ndarray | None = None, t: float = 0.0,
             frame: Frame | None = None) -> None:
        """Send one tick (see :meth:`encode`); a send error is counted, never raised."""
        packet = self.encode(weights, rotation, t, frame)
        try:
            self._sock.send(packet)
            self.counters["packets_sent"] += 1
        except OSError:
            self.counters["send_errors"] += 1

    def on_tick(self, info: TickInfo) -> None:
        """FrameLoop ``on_tick`` hook: send what this tick drew."""
        self.send(info.weights, info.rotation, info.t, info.frame)

    def describe(self) -> str:
        """One line for the start of a run: where, what, what the rig cannot drive."""
        line = (f"llf-out: {self.address[0]}:{self.address[1]}, Live Link Face v6 packets, subject "
                f"{self.subject!r}: 52 ARKit weights, head and eye yaw/pitch/roll, one packet a tick")
        if self.missing:
            shown = ", ".join(self.missing[:6]) + (" …" if len(self.missing) > 6 else "")
            n = len(self.missing)
            line += (f"; {n} ARKit shape{'s' if n > 1 else ''} the character lacks sent as the input gives them "
                     f"(0 where it lacks them too): {shown}")
        return line

    def close(self) -> None:
        self._sock.close()
