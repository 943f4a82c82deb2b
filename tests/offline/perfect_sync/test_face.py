"""Finding the face: the demo head's face and frame; a cube and a face cut in two refused."""

import re

import numpy as np
import pytest

from facepuppet.runtime.demo.head import build_demo_character

from facepuppet.offline.elastic.clone import mesh_character
from facepuppet.offline.perfect_sync.face import FaceError, find_face
from helpers.decal_heads import closed_box


def _box(n: int = 12) -> tuple[np.ndarray, np.ndarray]:
    v, t = closed_box(n)
    return v.astype(np.float32), t.astype(np.uint32)


def test_demo_head_face_is_found_with_its_frame():
    c = build_demo_character()
    face = find_face(c)
    assert face.evidence == "shapes"
    np.testing.assert_allclose(face.frame, np.eye(3), atol=0.02)  # stored +Y up, facing +Z
    assert abs(face.plane_offset) < 0.01 * face.width
    assert face.symmetry_error < 0.01
    assert c.vertices[face.nose_tip, 2] > np.percentile(c.vertices[face.skin, 2], 95)


@pytest.mark.parametrize("axis, degrees", [("-z", 180.0), ("+x", 90.0), ("-x", -90.0)])
def test_a_face_looking_another_way_is_refused_saying_how_to_import_it(axis, degrees):
    """The demo head turned to look along -Z, +X or -X (as OBJ exports of other tools do): its back or side
    must not be taken for a face (the back of a round head has a bump that passes the nose test)."""
    c = build_demo_character()
    a = np.radians(degrees)
    r = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]], np.float32)
    turned = c.with_parts(vertices=c.vertices @ r.T, delta_positions=c.delta_positions @ r.T, normals=None)
    assert np.allclose(np.asarray([0, 0, 1.0]) @ r.T, {"-z": [0, 0, -1], "+x": [1, 0, 0], "-x": [-1, 0, 0]}[axis],
                       atol=1e-6)
    with pytest.raises(FaceError, match=re.escape(f"looks along {axis}, not +Z: import the OBJ again with "
                                                  f"import-rig --forward={axis}")):
        find_face(turned)


@pytest.mark.parametrize("n", [1, 12])
def test_a_cube_has_no_face(n):
    v, t = _box(n)
    with pytest.raises(FaceError, match="cube.*no recognisable face"):
        find_face(mesh_character(v, t, "cube"))


def test_a_face_cut_in_two_pieces_is_refused():
    c = build_demo_character()
    face = find_face(c)
    v = c.vertices
    t = c.triangles.astype(np.int64)
    # cut every triangle crossing x = 0.3 (just off the plane): the skin falls into two unequal pieces
    side = v[:, 0] > 0.3
    keep = (side[t].all(1)) | (~side[t]).all(1)
    cut = mesh_character(v, t[keep].astype(np.uint32), "split")
    assert len(face.skin) > 1000
    with pytest.raises(FaceError, match="split: the face is in several disconnected pieces"):
        find_face(cut)


@pytest.mark.data
def test_the_ict_head_turned_round_is_refused_by_where_its_shapes_move(ict_character):
    """The back of the ICT head passes the nose test (a bump at the neck); its shapes tell the front."""
    c = ict_character
    turned = c.with_parts(vertices=c.vertices * np.float32((-1, 1, -1)),
                          delta_positions=c.delta_positions * np.float32((-1, 1, -1)), normals=None)
    with pytest.raises(FaceError, match=re.escape("looks along -z, not +Z: import the OBJ again with "
                                                  "import-rig --forward=-z")):
        find_face(turned)
    assert find_face(c).evidence == "shapes"


def test_a_mesh_too_small_for_a_face_is_refused_without_a_turn_hint():
    """SimpleMorph-like: a triangle whose shape leans sideways is not a face looking along +X; and a glTF
    character (it has a layout) is never told to use the OBJ import's --forward."""
    from helpers.gltf_characters import parts_character

    c = build_demo_character()
    tiny = mesh_character(c.vertices[:3], np.array([[0, 1, 2]], np.uint32), "tiny")
    tiny = tiny.with_parts(shape_names=("side",), delta_offsets=np.array([0, 3]),
                           delta_indices=np.arange(3, dtype=np.uint32),
                           delta_positions=np.array([[5, 0, 0]] * 3, np.float32),
                           delta_normals=np.zeros((3, 3), np.float32))
    for character in (tiny, parts_character()):
        with pytest.raises(FaceError) as caught:
            find_face(character)
        assert "no recognisable face" in str(caught.value) and "--forward" not in str(caught.value)


def _static(c, turn=(1, 1, 1)):
    """``c`` without its shapes (a static head, as ``import-rig head.obj`` makes), optionally mirrored."""
    return c.with_parts(vertices=c.vertices * np.float32(turn), normals=None, shape_names=(),
                        delta_offsets=np.zeros(1, np.int64), delta_indices=np.zeros(0, np.uint32),
                        delta_positions=np.zeros((0, 3), np.float32), delta_normals=np.zeros((0, 3), np.float32),
                        expressions=None)


def test_a_static_head_turned_round_is_refused_by_where_its_detail_is():
    """Without shapes the back of the demo head passes the nose test; its front has 1.6 times the vertices."""
    c = build_demo_character()
    assert find_face(_static(c)).nose_tip == find_face(c).nose_tip  # facing +Z: found as before
    with pytest.raises(FaceError, match=re.escape("looks along -z, not +Z")):
        find_face(_static(c, (-1, 1, -1)))


@pytest.mark.data
def test_the_static_ict_head_turned_round_is_refused(ict_character):
    find_face(_static(ict_character))
    with pytest.raises(FaceError, match=re.escape("import-rig --forward=-z")):
        find_face(_static(ict_character, (-1, 1, -1)))
