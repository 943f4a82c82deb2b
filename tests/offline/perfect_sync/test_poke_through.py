"""The skin showing through a drawn piece between its corners (Godette): her cloned outer brow raises cut a notch
of forehead across her brows (the picture shows the outer end standing apart like a hook) while every check said
the shapes were fine. The measure is calibrated on her artist's own shapes, which never do it, and must name the
clone that does; with the clearance kept over the pieces' triangles, no cloned shape does it."""

import numpy as np
import pytest

from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.perfect_sync.commands import perfect_sync
from facepuppet.offline.perfect_sync.face import find_face
from facepuppet.offline.perfect_sync.own_expressions import (
    HIDDEN,
    POKED,
    VANISHED,
    Drawn,
    defects,
    expression_deltas,
    prefer_own,
)
from facepuppet.offline.perfect_sync.pieces import find_pieces
from facepuppet.offline.perfect_sync.poke_through import PokeThrough
from facepuppet.offline.perfect_sync.proposal import skin_triangles
from facepuppet.offline.perfect_sync.skin_clearance import keep_clearance
from facepuppet.offline.perfect_sync.source import fit_kit_source
from facepuppet.offline.perfect_sync.triangles import skin_front_depth
from tests.conftest import need_shared

pytestmark = pytest.mark.data


@pytest.fixture(scope="module")
def godette():
    g = read_gltf(need_shared("gltf", "Godette_vrm_v4.vrm"))
    face = find_face(g)
    pieces = find_pieces(g.vertices, face, skin_triangles(face))
    return g, face, pieces, Drawn(g, face, pieces, 0.1 * float(np.ptp(g.vertices[face.skin, 0])))


def test_her_own_shapes_never_let_the_skin_through_a_drawn_piece(godette):
    """Every shape of her artist's (blinks, vowels, looks, angled brows) and every VRM expression she has (Joy,
    Angry, Sorrow, Fun, ...): the skin comes through no drawn piece between its corners (measured 0 on all), so
    none is reported; her blinks and "ee" hide pieces by moving them behind the skin, corners and all."""
    g, _, _, drawn = godette
    dense = g.dense_deltas().astype(np.float64)
    shapes = {name: dense[s] for s, name in enumerate(g.shape_names)}
    for preset in ("Blink", "Blink_L", "Blink_R", "A", "I", "U", "E", "O", "Joy", "Angry", "Sorrow", "Fun"):
        own = expression_deltas(g, preset)
        if own is not None:
            shapes[preset] = own
    assert len(shapes) > 20
    for name, d in shapes.items():
        assert max(drawn.poking(d).values(), default=0.0) <= 0.01, name
        assert not [w for w in defects(drawn, d) if "shows through" in w], name


def _brows(g, face, pieces):
    """Her brows' pieces whole (every vertex of each piece with a vertex above her eyes)."""
    local = face.to_frame(g.vertices.astype(np.float64))
    above = pieces.on_skin[local[pieces.on_skin, 1] > local[pieces.eyes["L"][0], 1].max()]
    return local, np.flatnonzero(np.isin(pieces.labels, np.unique(pieces.labels[above])))


def test_a_notch_of_skin_through_her_brows_is_named_defective(godette):
    """Her brows pushed back by half their height over her skin: every corner stays in front, her forehead's
    crease comes through the middle (measured 51 % of a band of each brow). The four points a triangle of the
    hiding check see 12 %, under its limit; this measure names both brows."""
    g, face, pieces, drawn = godette
    local, brows = _brows(g, face, pieces)
    skin_t = skin_triangles(face)
    height = local[brows, 2] - skin_front_depth(local[brows, :2], local, skin_t)
    assert np.isfinite(height).all() and (height > 0).all()
    d = np.zeros((1, g.n_vertices, 3), np.float32)
    d[0, brows] = -(0.5 * height)[:, None] * face.frame[2]
    assert max(drawn.vanishing(d[0].astype(np.float64)).values()) < VANISHED
    poked = drawn.poking(d[0].astype(np.float64))
    assert len(poked) == 2 and min(poked.values()) > POKED, poked
    _, defective = prefer_own(g, face, pieces, ("browOuterUpLeft",), d, drawn.es)
    assert [w for w in defective["browOuterUpLeft"] if "shows through" in w], defective
    assert not [w for w in defective["browOuterUpLeft"] if "goes behind" in w], defective


def test_the_clearance_is_kept_across_the_triangles_not_only_at_their_corners(godette):
    """Her brows raised by half an inner-eye distance slide over her box head's crease: with the clearance kept at
    the corners only, the crease comes through them (measured 13 % of a band); kept across the triangles, not at
    all, and the brows move only toward the viewer for it (their rise is untouched)."""
    g, face, pieces, drawn = godette
    _, brows = _brows(g, face, pieces)
    skin_t = skin_triangles(face)
    up = np.zeros((1, g.n_vertices, 3), np.float32)
    up[0, brows] = 0.5 * drawn.es * face.frame[1]
    corners, across = up.copy(), up.copy()
    keep_clearance(corners, g.vertices, face, brows, skin_t)
    keep_clearance(across, g.vertices, face, brows, skin_t, face.triangles[np.isin(face.triangles, brows).all(axis=1)])
    assert max(drawn.poking(corners[0].astype(np.float64)).values()) > 0.1
    assert drawn.poking(across[0].astype(np.float64)) == {}
    np.testing.assert_allclose(across[0] @ face.frame[:2].T, up[0] @ face.frame[:2].T, atol=1e-7)


@pytest.mark.slow
def test_the_true_shapes_of_ict_never_let_its_skin_through_its_lashes_and_films(ict_character):
    """The other head with known good shapes: ICT's own expressions, on the 54 pieces lying on its skin (lashes,
    tear films, eye occlusion). Measured over all 53 of its shapes: at most 0.023 (eyeLookUp_R); a few of them
    here, the eye's and brow's."""
    ict = ict_character
    face = find_face(ict)
    pieces = find_pieces(ict.vertices, face, skin_triangles(face))
    mine = np.zeros(ict.n_vertices, bool)
    mine[pieces.on_skin] = True
    tris = face.triangles[mine[face.triangles].all(axis=1)]
    everything = np.asarray(ict.triangles, np.int64)
    es = 0.1 * float(np.ptp(ict.vertices[face.skin, 0]))
    poke = PokeThrough(face, ict.vertices, tris, pieces.labels[tris[:, 0]], everything[~mine[everything].any(axis=1)],
                       es, HIDDEN * es)
    assert len(poke.parts) > 40
    dense = ict.dense_deltas()
    for name in ("eyeBlink_L", "eyeLookUp_R", "eyeWide_R", "browOuterUp_L", "cheekSquint_R"):
        d = dense[ict.shape_names.index(name)].astype(np.float64)
        assert max(poke(d).values(), default=0.0) < 0.05, name


@pytest.mark.slow
def test_her_cloned_brows_keep_the_skin_behind_them(godette):
    """Her clone, as the command makes it: no shape lets the skin through a drawn piece (with the clearance kept
    at the corners only: browOuterUpLeft and browOuterUpRight 0.81 of a band of the brow), and none is
    reported for it; the brows still rise (their highest point by at least a quarter of an inner-eye distance)."""
    g, face, pieces, drawn = godette
    out, report, _ = perfect_sync(g, fit_kit_source(need_shared("ict-facekit")), prefer_own=True)
    dense = out.dense_deltas().astype(np.float64)
    poked = {key: max(drawn.poking(dense[out.shape_names.index(key)]).values(), default=0.0)
             for key in report["added"]}
    assert max(poked.values()) < POKED, {k: round(v, 2) for k, v in poked.items() if v > 0.01}
    assert not [d for d in report["defective_shapes"] if "shows through" in d["why"]], report["defective_shapes"]
    local, _ = _brows(g, face, pieces)
    for key, sign in (("browOuterUpLeft", 1.0), ("browOuterUpRight", -1.0)):
        brow = pieces.on_skin[(local[pieces.on_skin, 1] > local[pieces.eyes["L"][0], 1].max())
                              & (sign * local[pieces.on_skin, 0] > 0)]
        rise = (dense[out.shape_names.index(key), brow] @ face.frame[1]).max()
        assert rise > 0.25 * drawn.es, (key, rise / drawn.es)
