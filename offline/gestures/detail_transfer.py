"""Detail transfer onto a character mesh (Ju & Lee 2008, §5.2).

Marker-space detail features (the residual of a stabilised marker take after
the §4.1 blend-weight fit, per region) are carried onto a character by the
compact-support RBF of :mod:`.rbf_transfer` (cubic B-spline kernel, no linear
term), one interpolant per region, applied only to that region's vertices.

Steps
-----
1. :func:`place_markers`: the actor's neutral marker cloud is brought onto the
   character by a similarity (Umeyama) fitted on the markers that have a
   Multi-PIE 68 landmark (``MARKER_LANDMARKS``; ICT ``vertex_indices.json``
   ``idx_to_landmark_verts``), then every marker is snapped to its nearest
   front-facing skin vertex, its *surface point*.
2. :func:`marker_detail`: per take, the head motion is removed
   (:func:`facepuppet.offline.actuation.stabilise.stabilise` on the forehead + nose-top markers), the
   displacements from the take's first frame are fitted by blend weights
   (§4.1, :class:`.blend_weights.BlendWeights`) and the residual is split by
   region (``MARKER_REGIONS``); per region its principal directions
   (1 std each) are the detail features, their z-scored coefficients the tracks.
3. :class:`DetailTransfer`: per region r, f_r(x) = Σ_i w_i φ(|x - p_i| / r_r)
   over the region's surface points p_i, interpolating the marker
   displacements (f_r(p_i) = d_i), evaluated on the vertices whose nearest
   surface point belongs to region r (so brow markers move only brow vertices),
   faded to zero by a smoothstep of (distance to the nearest other-region
   surface point - distance to the nearest own one) over ``BORDER_BAND`` r_r,
   so the regions meet without a seam and f still interpolates at the markers.
   The support radius r_r is per region (default: ``RADIUS_FACTOR`` times the
   largest nearest-neighbour distance among the region's surface points).
4. :func:`detail_character`: the renderer takes only blendshape weights, so
   (rather than a per-vertex offset path through the shaders and the CPU
   deformer) each detail feature direction is transferred once into a
   per-vertex field and stored as an extra shape ``detail_<region>_<k>`` on a
   copy of the character; the tracks are the weights of those shapes.

Symbols: p_i -> ``surface`` positions, d_i -> marker ``displacements``,
r -> ``radius``, φ -> :func:`.rbf_transfer.cubic_bspline`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from facepuppet.runtime.errors import InputFileError, UsageError
from facepuppet.runtime.files.tables import Tables
from facepuppet.runtime.model.character import MATERIAL_KINDS, Character, sparse_deltas
from facepuppet.runtime.model.geometry import smoothstep, vertex_normals

from facepuppet.offline.actuation.stabilise import stabilise
from facepuppet.offline.actuation.transfer import umeyama
from facepuppet.offline.gestures.blend_weights import BlendWeights, choose_basis
from facepuppet.offline.gestures.rbf_transfer import RBFTransfer
from facepuppet.offline.gestures.regional_features import STABLE_MARKERS

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

DETAIL_REGIONS = ("brows", "eyes", "lips", "rest")
RADIUS_FACTOR = 1.5
BORDER_BAND = 0.5  # width of the fade at a region's border, as a fraction of its radius (at most the gap to
                   # the nearest marker of another region, so that the transfer still interpolates at its markers)

# AnimFace marker -> Multi-PIE 68 landmark (0-based; 17-21 the subject's right brow, 36-41 right eye,
# 48 right mouth corner). Markers without a clear landmark (forehead, eyelids, cheeks, chin sides) are
# placed by the similarity fitted on these.
MARKER_LANDMARKS = {
    "Reyebrow_Outside": 17, "Reyebrow_M": 19, "Reyebrow_Inside": 21,
    "Leyebrow_Inside": 22, "Leyebrow_M": 24, "Leyebrow_Outside": 26,
    "NoseTop": 27, "NoseHead": 30, "NoseHead_R": 31, "NoseHead_L": 35,
    "Reye_Outside": 36, "Reye_Inside": 39, "Leye_Inside": 42, "Leye_Outside": 45,
    "Mouth_Rend": 48, "Mouth_UpR1": 50, "Mouth_Up": 51, "Mouth_UpL1": 52, "Mouth_Lend": 54,
    "Mouth_DownL": 56, "Mouth_Down": 57, "Mouth_DownR": 58, "Chin": 8,
}


def marker_region(name: str) -> str:
    """Region of an AnimFace marker name: brows, eyes, lips (mouth and chin) or rest (forehead, nose, cheeks)."""
    key = name.lower()
    if "eyebrow" in key:
        return "brows"
    if key.startswith(("leye_", "reye_")):
        return "eyes"
    if key.startswith(("mouth", "chin")):
        return "lips"
    return "rest"


@dataclass(frozen=True)
class Placement:
    """Markers placed on a character.

    Attributes
    ----------
    names : tuple of str, marker names
    similarity : ndarray of shape (4, 4), float64, marker space -> character space (scale, rotation, shift)
    vertices : ndarray of shape (n_markers,), int64, each marker's surface vertex
    surface : ndarray of shape (n_markers, 3), float64, character units, those vertices' positions
    scale : float, character units per marker unit
    rms : float, character units, RMS distance of the landmark markers to their landmarks after the fit
    """

    names: tuple[str, ...]
    similarity: np.ndarray
    vertices: np.ndarray
    surface: np.ndarray
    scale: float
    rms: float


def _front_skin(character: Character) -> np.ndarray:
    kinds = character.material_params[:, 2].astype(int)
    skin = np.isin(kinds[character.triangle_material], [MATERIAL_KINDS["skin"], MATERIAL_KINDS["lips"]])
    idx = np.unique(character.triangles[skin])
    normals = vertex_normals(character.vertices, character.triangles)
    front = idx[normals[idx, 2] > 0.2]
    return front if len(front) >= 3 else np.arange(character.n_vertices)


def place_markers(neutral: np.ndarray, names: Sequence[str], character: Character,
                  landmarks: ArrayLike) -> Placement:
    """Similarity of the marker cloud onto the character's landmarks, then each marker's nearest front skin vertex.

    Parameters
    ----------
    neutral : ndarray of shape (n_markers, 3), float, marker units (head coordinates, neutral face)
    names : sequence of n_markers str (AnimFace names; at least 3 in ``MARKER_LANDMARKS``)
    character : Character
    landmarks : sequence of 68 int, vertex index of each Multi-PIE landmark (ICT ``idx_to_landmark_verts``)
    """
    neutral = np.asarray(neutral, np.float64)
    names = tuple(names)
    if neutral.shape != (len(names), 3) or not np.isfinite(neutral).all():
        raise ValueError(f"neutral: expected finite shape ({len(names)}, 3), got {neutral.shape}")
    landmarks = np.asarray(landmarks, np.int64)
    if landmarks.shape != (68,) or landmarks.min() < 0 or landmarks.max() >= character.n_vertices:
        raise InputFileError(f"landmarks: expected 68 vertex indices in 0..{character.n_vertices - 1}, "
                             f"got shape {landmarks.shape}")
    pairs = [(i, MARKER_LANDMARKS[n]) for i, n in enumerate(names) if n in MARKER_LANDMARKS]
    if len(pairs) < 3:
        raise InputFileError(f"names: expected at least 3 markers with a landmark ({sorted(MARKER_LANDMARKS)[:4]}...), "
                             f"found {len(pairs)}")
    src = neutral[[i for i, _ in pairs]]
    dst = character.vertices[landmarks[[j for _, j in pairs]]].astype(np.float64)
    m = umeyama(src, dst)
    moved = neutral @ m[:3, :3].T + m[:3, 3]
    rms = float(np.sqrt(np.mean(np.sum((moved[[i for i, _ in pairs]] - dst) ** 2, axis=1))))
    front = _front_skin(character)
    _, near = cKDTree(character.vertices[front]).query(moved)
    vertices = front[near].astype(np.int64)
    scale = float(np.cbrt(np.linalg.det(m[:3, :3])))
    return Placement(names, m, vertices, character.vertices[vertices].astype(np.float64), scale, rms)


class DetailTransfer:
    """Per-region compact-support RBF from marker surface points to the character's vertices (§5.2).

    Parameters
    ----------
    placement : Placement
    character : Character, the mesh whose vertices receive the detail
    radius : float or dict region -> float, support radius (character units); default per region
        ``RADIUS_FACTOR`` x the largest nearest-neighbour distance among its surface points
    """

    def __init__(self, placement: Placement, character: Character,
                 radius: float | dict[str, float] | None = None) -> None:
        self.placement = placement
        self.regions = np.array([marker_region(n) for n in placement.names])
        self._vertices = verts = character.vertices.astype(np.float64)
        front = _front_skin(character)
        _, nearest = cKDTree(placement.surface).query(verts[front])
        self.vertex_region = np.full(character.n_vertices, "", dtype=object)   # "" : no region (not skin)
        self.vertex_region[front] = self.regions[nearest]
        self.radius: dict[str, float] = {}
        self._parts = []  # (region, marker indices, vertex indices, Φ_vr (sparse), RBFTransfer for Φ_rr)
        for r in DETAIL_REGIONS:
            mk = np.flatnonzero(self.regions == r)
            if len(mk) == 0:
                continue
            p = placement.surface[mk]
            if isinstance(radius, dict):
                rad = float(radius[r])
            elif radius is not None:
                rad = float(radius)
            else:
                d, _ = cKDTree(p).query(p, k=2) if len(p) > 1 else (np.array([[0.0, 1.0]]), None)
                rad = RADIUS_FACTOR * float(d[:, 1].max())
            if not rad > 0:
                raise ValueError(f"radius[{r!r}]: expected a positive number, got {rad}")
            vx = np.flatnonzero(self.vertex_region == r)
            # fade to zero at the region's border (no seam): d_other - d_own goes from `band` inside to 0 at the
            # border; band <= the own markers' distance to other regions' markers, so the mask is 1 at them
            others = placement.surface[self.regions != r]
            d_own, _ = cKDTree(p).query(verts[vx])
            mask = np.ones(len(vx))
            if len(others):
                tree = cKDTree(others)
                band = min(BORDER_BAND * rad, float(tree.query(p)[0].min()))
                mask = smoothstep(0.0, max(band, 1e-12), tree.query(verts[vx])[0] - d_own)
            self.radius[r] = rad
            self._parts.append((r, mk, vx, RBFTransfer(rad), mask))

    def transfer(self, displacements: np.ndarray) -> np.ndarray:
        """Per-vertex offsets of marker displacements.

        Parameters
        ----------
        displacements : ndarray of shape (n_markers, 3) or (k, n_markers, 3), float, marker units
            (scaled to character units by the placement's similarity: rotation and scale)

        Returns
        -------
        offsets : ndarray of shape (n_vertices, 3) or (k, n_vertices, 3), float64, character units;
            zero outside each region and beyond the support of its markers
        """
        d = np.asarray(displacements, np.float64)
        single = d.ndim == 2
        d = d[None] if single else d
        n = len(self.placement.names)
        if d.ndim != 3 or d.shape[1:] != (n, 3) or not np.isfinite(d).all():
            raise ValueError(f"displacements: expected finite shape ({n}, 3) or (k, {n}, 3), got {d.shape}")
        d = d @ self.placement.similarity[:3, :3].T            # marker units/axes -> character's
        k = len(d)
        out = np.zeros((k, len(self.vertex_region), 3))
        verts = self._vertices
        for _, mk, vx, rbf, mask in self._parts:
            values = d[:, mk].transpose(1, 0, 2).reshape(len(mk), 3 * k)
            rbf.fit(self.placement.surface[mk], values)         # §5.2: Φ w = d, no linear term
            f = rbf.transform(verts[vx]).reshape(len(vx), k, 3).transpose(1, 0, 2)
            out[:, vx] = f * mask[None, :, None]                # faded to zero at the region's border
        return out[0] if single else out

@dataclass(frozen=True)
class MarkerDetail:
    """Detail features of marker takes (residual after the blend weights, per region).

    Attributes
    ----------
    names : tuple of str, markers
    neutral : ndarray of shape (n_markers, 3), float64, marker units, head coordinates (first take, frame 0)
    feature_names : tuple of str, ``detail_<region>_<k>``
    directions : ndarray of shape (n_features, n_markers, 3), float64, marker units: 1 std of each feature,
        zero outside its region's markers
    tracks : list of ndarray of shape (n_frames_take, n_features), float64, z-scored coefficients per take
    blend_rms : float, marker units, RMS error of the blend-weight fit
    """

    names: tuple[str, ...]
    neutral: np.ndarray
    feature_names: tuple[str, ...]
    directions: np.ndarray
    tracks: list
    blend_rms: float


def marker_detail(takes: Sequence[np.ndarray], names: Sequence[str], per_region: int = 2, n_basis: int = 6,
                  window: int = 41, step: int = 1, seed: int = 0) -> MarkerDetail:
    """Detail features of marker takes: stabilise, displacements, §4.1 blend fit, per-region PCA of the residual.

    Parameters
    ----------
    takes : sequence of ndarray of shape (n_frames, n_markers, 3), float, marker units (capture frame)
    names : sequence of n_markers str; must include ``STABLE_MARKERS``
    per_region : int, detail features kept per region
    n_basis, window : the blend basis size and temporal window (§4.1)
    step : int, use every ``step``-th frame for the fit (tracks are still for every frame)
    """
    names = tuple(names)
    disp, neutral = [], None
    for take in takes:
        st = stabilise(np.asarray(take, np.float64), names, head_markers=STABLE_MARKERS)
        m = st.markers.astype(np.float64)
        neutral = m[0] if neutral is None else neutral
        disp.append((m - m[0]).reshape(len(m), -1))
    X = np.vstack(disp)
    basis = choose_basis(X[::step], n_basis, window, seed)
    fits = [BlendWeights(basis, window=window).fit(x) for x in disp]
    residual = np.vstack([f.residual_ for f in fits])
    regions = np.array([marker_region(n) for n in names])
    directions, feature_names = [], []
    coef = []
    for r in DETAIL_REGIONS:
        cols = np.flatnonzero(np.repeat(regions == r, 3))
        if len(cols) == 0:
            continue
        x = residual[::step, cols]
        _, sv, vt = np.linalg.svd(x - x.mean(0), full_matrices=False)
        for j in range(min(per_region, len(sv))):
            std = sv[j] / np.sqrt(max(len(x) - 1, 1))
            d = np.zeros(len(names) * 3)
            d[cols] = vt[j] * std
            directions.append(d.reshape(len(names), 3))
            feature_names.append(f"detail_{r}_{j}")
            coef.append((cols, vt[j] / max(std, 1e-12)))
    tracks = []
    for f in fits:
        tracks.append(np.column_stack([f.residual_[:, cols] @ v for cols, v in coef]))
    rms = float(np.sqrt(np.mean([f.error_ ** 2 for f in fits])))
    return MarkerDetail(names, neutral, tuple(feature_names), np.array(directions), tracks, rms)


def detail_character(character: Character, transfer: DetailTransfer, detail: MarkerDetail,
                     tolerance: float = 1e-5) -> Character:
    """A copy of ``character`` with one extra shape per detail feature (its direction, RBF-transferred).

    The existing renderer then draws the detail from the weights ``detail.tracks`` (named
    ``detail.feature_names``). Shapes whose names already exist are refused (ValueError).
    """
    clash = set(detail.feature_names) & set(character.shape_names)
    if clash:
        raise InputFileError(f"character shape_names: already has {sorted(clash)}")
    fields = transfer.transfer(detail.directions)                    # (k, n_vertices, 3), character units
    verts = character.vertices.astype(np.float64)
    n0 = vertex_normals(verts, character.triangles)
    normals = np.stack([vertex_normals(verts + f, character.triangles) - n0 for f in fields])
    off, idx, pos = sparse_deltas(fields, tolerance)
    nrm = np.concatenate([normals[s, idx[off[s]:off[s + 1]]] for s in range(len(fields))]) if len(idx) else \
        np.zeros((0, 3))
    meta = dict(character.metadata)
    meta["detail_transfer"] = {"features": list(detail.feature_names), "radius": transfer.radius,
                               "placement_rms": transfer.placement.rms}
    return dataclasses.replace(
        character,
        shape_names=tuple(character.shape_names) + tuple(detail.feature_names),
        delta_offsets=np.concatenate([character.delta_offsets, character.delta_offsets[-1] + off[1:]]).astype(np.int64),
        delta_indices=np.concatenate([character.delta_indices, idx]).astype(np.uint32),
        delta_positions=np.concatenate([character.delta_positions, pos]).astype(np.float32),
        delta_normals=np.concatenate([character.delta_normals, nrm]).astype(np.float32),
        metadata=meta,
    )


def detail_table(db: Tables, detail: MarkerDetail, take_names: Sequence[str], rate: float = 60.0) -> np.ndarray:
    """Detail weights per reference frame of a ``gesture_db``, as the runtime's gesture layer reads them.

    See :class:`~facepuppet.runtime.gestures.layer.GestureLayer`.

    Parameters
    ----------
    db : Tables of kind ``gesture_db``
    detail : MarkerDetail of the marker takes, ``detail.tracks[i]`` for the take named ``take_names[i]``
    take_names : sequence of str, the database's take names of those marker takes (the files' stems)
    rate : float, Hz, frame rate of the marker takes

    Returns
    -------
    table : ndarray of shape (n_db_frames, n_features), float32; frame j of a marker take (time j / fps)
        holds its tracks linearly interpolated there, frames of other takes zero
    """
    takes = list(db.channels["takes"])
    fps = float(db.settings.get("fps", 30.0))
    frame_take = np.asarray(db["frame_take"])
    out = np.zeros((len(frame_take), len(detail.feature_names)), np.float32)
    if len(take_names) != len(detail.tracks):
        raise ValueError(f"take_names: expected {len(detail.tracks)} names (one per track), got {len(take_names)}")
    for name, track in zip(take_names, detail.tracks):
        if name not in takes:
            raise UsageError(f"take_names: {name!r} is not a take of the database ({takes})")
        rows = np.flatnonzero(frame_take == takes.index(name))
        t = np.arange(len(rows)) / fps
        src = np.arange(len(track)) / rate
        out[rows] = np.column_stack([np.interp(t, src, c) for c in track.T])
    return out
