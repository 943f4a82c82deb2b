"""How much larger the character's face is than the actor's: one ratio from many landmark distances.

Marker displacements reach the character multiplied by this ratio, so it sets how far every shape is driven.
A single distance (the inner eye corners) decides it from two markers: a marker stuck a few millimetres off
its landmark, or a face whose eyes sit closer together than the character's, scales the whole face by its
error (on the AnimFace kit takes onto the ICT head, 1.29 from the inner eye corners where most of the 36
landmark-marker distances say 0.94, and the character's weights ran into 1.0 for it). Here every distance
between two landmark markers gives a ratio (character distance / actor distance) and the median is the
scale: one misplaced marker moves a minority of them.

One ratio cannot be right for two faces of different proportions (a wider mouth, closer eyes): their
landmark distances then disagree with each other, not only with the scale. The middle half of the ratios
measures that disagreement; when it is wide the scale is reported as uncertain, with the landmarks whose
distances disagree most, and the user can choose the ratio (``retarget-actor --face-scale``).

Each face's FAPU (:func:`face_units`, the inner-eye-corner distance, else the marker cloud's size) stays the
unit of lengths on one face (the character's sets how near a marker must be to a shape's region), and gives
the ratio when fewer than three markers sit on landmarks.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.model.character import Character

#: the middle half of the ratios spans more than this fraction of the median: the scale is uncertain (one
#: ratio then misstates a quarter of the face's distances by more than about half this, each way). On nine
#: AnimFace landmarks of a 10 cm face, 1 mm of placement error per coordinate gives a spread of about 0.04,
#: 3 mm about 0.12; a face 1.5 times wider than the other (same height) 0.19; the kit's takes onto ICT 0.3.
UNCERTAIN_SPREAD = 0.15
FAPU_MARKERS = ("Leye_Inside", "Reye_Inside")       # actor FAPU: inner-eye-corner distance
FAPU_LANDMARKS = (39, 42)                           # character FAPU: the same, Multi-PIE 0-based
MIN_DISTANCE = 1e-6  # distances shorter than this (either face, its units) give no ratio


class FaceScale(NamedTuple):
    """The character-per-actor length ratio and how far the landmark distances agree with it.

    ratio : the median of the distance ratios (character length per actor length)
    n : the number of distances
    low, high : the ratios' lower and upper quartiles; least, most : their extremes
    by_landmark : {landmark marker name: the median ratio of the distances through it}, smallest first
    """

    ratio: float
    n: int
    low: float
    high: float
    least: float
    most: float
    by_landmark: dict[str, float]

    @property
    def spread(self) -> float:
        """The middle half's width as a fraction of the ratio."""
        return (self.high - self.low) / self.ratio

    @property
    def uncertain(self) -> bool:
        """The faces' proportions differ: one ratio misstates many of their distances."""
        return self.spread > UNCERTAIN_SPREAD

    def summary(self) -> str:
        """One line for a person: the ratio, where the distances lie, and whether it can be trusted."""
        line = (f"face-size ratio {self.ratio:.3f} (median of {self.n} landmark-distance ratios; middle half "
                f"{self.low:.2f}-{self.high:.2f}, all {self.least:.2f}-{self.most:.2f})")
        if not self.uncertain:
            return line
        names = list(self.by_landmark)
        ends = [n for n in (names[0], names[-1])]
        return (f"{line}\n  warning: the scale is uncertain: the faces' proportions differ (the middle half spans "
                f"{self.spread:.0%} of the ratio); distances through {ends[0]} say {self.by_landmark[ends[0]]:.2f}, "
                f"through {ends[1]} {self.by_landmark[ends[1]]:.2f}. Parts of the face will move more or less than "
                f"the actor's; check the replay (or --evaluate, --pictures) and choose with --face-scale RATIO")

    def as_dict(self) -> dict:
        """The metrics a pair table keeps (:meth:`from_dict` reads them back)."""
        return {"ratio": self.ratio, "n": self.n, "quartiles": [self.low, self.high],
                "range": [self.least, self.most], "spread": self.spread, "uncertain": self.uncertain,
                "by_landmark": self.by_landmark}

    @classmethod
    def from_dict(cls, d: dict) -> FaceScale:
        """The :meth:`as_dict` of a pair table's metrics."""
        return cls(float(d["ratio"]), int(d["n"]), float(d["quartiles"][0]), float(d["quartiles"][1]),
                   float(d["range"][0]), float(d["range"][1]), dict(d["by_landmark"]))


def face_scale(actor_points: np.ndarray, character_points: np.ndarray,
               names: Sequence[str]) -> FaceScale | None:
    """The face-size ratio from corresponding landmarks on both faces; None with fewer than three usable distances.

    Parameters
    ----------
    actor_points : ndarray of shape (n, 3), float, the landmark markers on the actor's neutral (actor units)
    character_points : ndarray of shape (n, 3), float, their landmark vertices on the character (its units)
    names : the n landmark markers' names
    """
    a = np.asarray(actor_points, np.float64)
    c = np.asarray(character_points, np.float64)
    if a.shape != c.shape or a.ndim != 2 or a.shape[1] != 3 or len(names) != len(a):
        raise ValueError(f"face_scale: expected two (n, 3) arrays and n names, got {a.shape}, {c.shape}, "
                         f"{len(names)} names")
    ratios, through = [], {name: [] for name in names}
    for i, j in itertools.combinations(range(len(a)), 2):
        da, dc = float(np.linalg.norm(a[i] - a[j])), float(np.linalg.norm(c[i] - c[j]))
        if da > MIN_DISTANCE and dc > MIN_DISTANCE:
            ratios.append(dc / da)
            through[names[i]].append(dc / da)
            through[names[j]].append(dc / da)
    if len(ratios) < 3:
        return None
    r = np.asarray(ratios)
    low, median, high = (float(q) for q in np.quantile(r, [0.25, 0.5, 0.75]))
    by_landmark = {name: round(float(np.median(v)), 4) for name, v in through.items() if v}
    by_landmark = dict(sorted(by_landmark.items(), key=lambda item: item[1]))
    return FaceScale(median, len(r), low, high, float(r.min()), float(r.max()), by_landmark)


def landmark_scale(actor: Actor, character: Character, landmarks: np.ndarray | None,
                   pairs: dict[int, int]) -> FaceScale | None:
    """The face-size ratio from the landmark markers (``pairs``: marker index -> landmark), or None."""
    if landmarks is None or len(pairs) < 3:
        return None
    idx = sorted(pairs)
    return face_scale(actor.neutral[idx], character.vertices[landmarks[[pairs[i] for i in idx]]],
                      [actor.names[i] for i in idx])


def face_units(actor: Actor, character: Character, vertices: np.ndarray,
               landmarks: np.ndarray | None) -> tuple[float, float, str]:
    """FAPU on each face: (actor units, character units, kind).

    The inner-eye-corner distance (markers :data:`FAPU_MARKERS`, landmarks :data:`FAPU_LANDMARKS`)
    when both faces have them; otherwise the RMS radius of the marker cloud / its mapped vertices.
    """
    src = actor.neutral.astype(np.float64)
    if all(n in actor.names for n in FAPU_MARKERS) and landmarks is not None and max(FAPU_LANDMARKS) < len(landmarks):
        a, b = (src[actor.names.index(n)] for n in FAPU_MARKERS)
        p, q = (character.vertices[landmarks[i]].astype(np.float64) for i in FAPU_LANDMARKS)
        return float(np.linalg.norm(a - b)), float(np.linalg.norm(p - q)), "inner eye corners"
    mapped = character.vertices[vertices].astype(np.float64)
    radius = lambda p: float(np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1))))  # noqa: E731
    return radius(src), radius(mapped), "marker cloud RMS radius"
