"""Which of the character's shapes the actor's markers can drive, and what to say when none is left.

A shape whose moving skin has no marker near it, or that moves what markers on the skin cannot see (gaze,
pupils), would be fitted to nothing: the least squares would give it whatever weight costs least, and the
replay would show it moving at random. Such shapes are left out (weight 0) with the reason; the user brings
any back by name.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Sequence

import numpy as np
from scipy.spatial import cKDTree

from facepuppet.runtime.model.character import MATERIAL_KINDS, Character
from facepuppet.runtime.model.geometry import vertex_normals

UNOBSERVABLE = ("eyeLook*", "PupilDilate*")         # markers on the skin cannot see gaze or pupils
REGION_RADIUS = 0.3                                 # of the character's FAPU: a shape's region must have a
                                                    # marker vertex this close


#: a character without expression shapes: what is wrong and what to do (the command adds the file's name)
NO_SHAPES = ("character '{name}' has no expression shapes (0 blendshapes or morph targets), so an actor has "
             "nothing to drive on it (imported from a neutral mesh alone, or a glTF/VRM without morph targets). "
             "Import it with its shapes: "
             "`facepuppet import-rig NEUTRAL.obj SHAPES_FOLDER -o CHARACTER.npz` (a folder of OBJs with the "
             "neutral's vertex order, e.g. the ICT-FaceKit folder itself), or a glTF/VRM that has morph targets")


def every_shape_left_out(name: str, left_out: dict[str, str]) -> str:
    """Why no shape is left to fit, counted by reason, and the options that bring shapes back."""
    reasons: dict[str, int] = {}
    for why in left_out.values():
        reasons[why] = reasons.get(why, 0) + 1
    counted = "; ".join(f"{n} {why}" for why, n in sorted(reasons.items(), key=lambda item: -item[1]))
    return (f"retarget_actor: every shape of '{name}' was left out ({len(left_out)} shapes: {counted}); "
            "bring shapes back with --include-shapes PATTERN or a larger --region-radius, or check that the "
            "actor's markers land on the character's face (--markers-to-mesh)")


def front_skin(character: Character) -> np.ndarray:
    """Indices of the skin vertices that face the viewer (+z); all vertices if there are too few."""
    kinds = character.material_params[:, 2].astype(int)
    skin_tri = kinds[character.triangle_material] == MATERIAL_KINDS["skin"]
    skin = np.unique(character.triangles[skin_tri])
    normals = vertex_normals(character.vertices, character.triangles)
    front = skin[normals[skin, 2] > 0.3] if len(skin) else np.arange(character.n_vertices)
    return front if len(front) >= 3 else np.arange(character.n_vertices)


def observable_shapes(character: Character, marker_vertices: np.ndarray, radius: float,
                      exclude: Sequence[str] = UNOBSERVABLE, include: Sequence[str] = ()) -> dict[str, str]:
    """Shapes the markers cannot observe, with the reason: {shape name: why}.

    A shape is left out when its name matches an ``exclude`` pattern (fnmatch), or when its moving
    skin region (front skin vertices with |delta| >= half the largest) has no marker vertex within
    ``radius`` (character units). Names matching an ``include`` pattern are never left out.
    """
    front = front_skin(character)
    dense = character.dense_deltas().astype(np.float64)
    marks = cKDTree(character.vertices[np.asarray(marker_vertices)].astype(np.float64))
    out = {}
    for j, name in enumerate(character.shape_names):
        if any(fnmatch.fnmatchcase(name, p) for p in include):
            continue
        if any(fnmatch.fnmatchcase(name, p) for p in exclude):
            out[name] = "excluded by name"
            continue
        length = np.linalg.norm(dense[j, front], axis=1)
        if length.max(initial=0.0) <= 1e-6:
            out[name] = "moves no front skin"
            continue
        region = character.vertices[front[length >= 0.5 * length.max()]].astype(np.float64)
        dist, _ = marks.query(region)
        if dist.min() > radius:
            out[name] = f"no marker within {radius:.2f} {character.units} of its region"
    return out
