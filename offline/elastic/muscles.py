"""Muscles that move control points, Yano & Harada (2009) §6 (after Waters' muscle model).

A muscle registers the control points inside its zone of influence with a
fall-off weight; a contraction c moves each registered point, and the elastic
basis carries the motion to the skin. With the geometry fixed at the neutral,
the motion is linear in c, so each muscle is stored as the control
displacements of a unit contraction (``muscle_params`` of the elastic table).

Symbols → code names (equation numbers as this project maps §6):

    a, i (linear: attachment on bone, insertion in skin)   points[0], points[1]
    D = |p - a|, θ = ∠(p - a, i - a)                     dist, theta
    Rs, Rf (radial start / finish), Ω (angular zone)      ranges[0], ranges[1], ranges[2]
    k (strength, units per unit contraction)              ranges[3] (linear), ranges[2] (sphincter)
    eq. 8   Δp = c k A(θ) R(D) (a - p)/|a - p|               linear displacement
    eq. 9   A(θ) = cos(θ/Ω · π/2), θ ≤ Ω                     angular fall-off
    eq. 10  R(D) = cos((1 - D/Rs) π/2), D < Rs; cos((D - Rs)/(Rf - Rs) π/2), Rs ≤ D ≤ Rf
    o, lx, ly (sphincter centre and semi-axes)            points[0], ranges[0], ranges[1]
    eq. 11  Δp = c k F(ρ) (o - p)_xy                          sphincter displacement (in the face plane)
    eq. 12  F(ρ) = cos(ρ π/2), ρ = sqrt((dx/lx)² + (dy/ly)²) ≤ 1
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from facepuppet.runtime.elastic.model import MUSCLE_KINDS

from facepuppet.offline.elastic.control_points import ControlPoints


@dataclass(frozen=True)
class Muscle:
    """One muscle. ``points`` (2, 3) and ``ranges`` (4,) as in the elastic table (see the module docstring)."""

    name: str
    kind: str
    points: np.ndarray
    ranges: np.ndarray

    def __post_init__(self) -> None:
        if self.kind not in MUSCLE_KINDS:
            raise ValueError(f"muscle {self.name!r}: kind must be one of {tuple(MUSCLE_KINDS)}, got {self.kind!r}")
        object.__setattr__(self, "points", np.asarray(self.points, np.float64).reshape(2, 3))
        object.__setattr__(self, "ranges", np.asarray(self.ranges, np.float64).reshape(4))


def linear_displacements(muscle: Muscle, positions: np.ndarray) -> np.ndarray:
    """Control displacements of a unit contraction of a linear muscle, (n_c, 3) float64."""
    a, i = muscle.points
    rs, rf, omega, strength = muscle.ranges
    toward = a - positions
    dist = np.linalg.norm(toward, axis=1)
    axis = (i - a) / np.linalg.norm(i - a)
    cos_theta = np.clip(((positions - a) @ axis) / np.maximum(dist, 1e-12), -1, 1)
    theta = np.arccos(cos_theta)
    angular = np.where(theta <= omega, np.cos(theta / omega * np.pi / 2), 0.0)  # Yano & Harada eq. 9
    radial = np.where(
        dist < rs,
        np.cos((1 - dist / rs) * np.pi / 2),
        np.where(dist <= rf, np.cos((dist - rs) / (rf - rs) * np.pi / 2), 0.0),
    )  # Yano & Harada eq. 10
    unit = toward / np.maximum(dist, 1e-12)[:, None]
    return strength * (angular * radial)[:, None] * unit  # Yano & Harada eq. 8 (c = 1)


def sphincter_displacements(muscle: Muscle, positions: np.ndarray) -> np.ndarray:
    """Control displacements of a unit contraction of a sphincter, (n_c, 3) float64."""
    o = muscle.points[0]
    lx, ly, strength = muscle.ranges[:3]
    d = positions - o
    rho = np.sqrt((d[:, 0] / lx) ** 2 + (d[:, 1] / ly) ** 2)
    fall = np.where(rho <= 1, np.cos(rho * np.pi / 2), 0.0)  # Yano & Harada eq. 12
    inward = -d * np.array([1.0, 1.0, 0.0])
    return strength * fall[:, None] * inward  # Yano & Harada eq. 11 (c = 1)


def muscle_displacements(muscles: Sequence[Muscle], positions: np.ndarray) -> np.ndarray:
    """(n_muscles, n_c, 3) float32: each muscle's control displacements per unit contraction."""
    p = np.asarray(positions, np.float64)
    out = [linear_displacements(m, p) if m.kind == "linear" else sphincter_displacements(m, p) for m in muscles]
    return np.asarray(out, np.float32).reshape(len(out), len(p), 3)


def muscle_sections(muscles: Sequence[Muscle], positions: np.ndarray) -> dict:
    """The muscle sections of an elastic table."""
    return {
        "muscle_params": muscle_displacements(muscles, positions),
        "muscle_kinds": np.array([MUSCLE_KINDS[m.kind] for m in muscles], np.uint8),
        "muscle_points": np.array([m.points for m in muscles], np.float32).reshape(-1, 2, 3),
        "muscle_ranges": np.array([m.ranges for m in muscles], np.float32).reshape(-1, 4),
    }


def default_muscles(positions: np.ndarray, points: ControlPoints) -> list[Muscle]:
    """A default muscle set placed from named control points (any head facing +z, y up).

    Distances are in units of the inner-eye-corner distance e, so one set fits
    the ICT head, the demo head and cloned faces alike.
    """
    p = np.asarray(positions, np.float64)
    at = lambda name: p[points.index(name)]  # noqa: E731
    e = float(np.linalg.norm(at("eye_inner_L") - at("eye_inner_R")))
    muscles = []

    def linear(name, attachment, insertion, omega_deg, strength):
        length = float(np.linalg.norm(insertion - attachment))
        muscles.append(Muscle(name, "linear", [attachment, insertion],
                              [length, 1.6 * length, np.radians(omega_deg), strength * e]))

    for side, sx in (("L", 1.0), ("R", -1.0)):
        lift = np.array([sx * 0.55, 0.35, -0.6]) * e
        linear(f"zygomaticMajor_{side}", at(f"cheekbone_{side}") + lift, at(f"mouth_corner_{side}"), 22, 0.35)
        linear(f"frontalis_{side}", at(f"forehead_{side}") + np.array([0, 0.9, -0.4]) * e, at(f"brow_mid_{side}"),
               35, 0.25)
        linear(f"corrugator_{side}", at("nose_root") + np.array([sx * 0.15, 0.25, -0.2]) * e,
               at(f"brow_inner_{side}"), 40, 0.15)
        linear(f"depressorAnguli_{side}", at(f"jaw_chin_{side}") + np.array([sx * 0.3, -0.3, -0.3]) * e,
               at(f"mouth_corner_{side}"), 22, 0.3)
        linear(f"levatorLabii_{side}", at(f"cheekbone_{side}") + np.array([-sx * 0.2, 0.5, -0.3]) * e,
               at(f"lip_upper_{side}"), 20, 0.2)
        eye = (at(f"eye_inner_{side}") + at(f"eye_outer_{side}")) / 2
        width = float(np.linalg.norm(at(f"eye_outer_{side}") - at(f"eye_inner_{side}")))
        muscles.append(Muscle(f"orbicularisOculi_{side}", "sphincter", [eye, [0, 0, 0]],
                              [0.75 * width, 0.45 * width, 0.25, 0]))
    mouth = (at("mouth_corner_L") + at("mouth_corner_R")) / 2
    half = float(np.linalg.norm(at("mouth_corner_L") - at("mouth_corner_R"))) / 2
    muscles.append(Muscle("orbicularisOris", "sphincter", [mouth, [0, 0, 0]], [1.25 * half, 0.75 * half, 0.3, 0]))
    return muscles
