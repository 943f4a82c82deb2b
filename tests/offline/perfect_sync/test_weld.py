"""Seams: glTF splits a surface into copies of a vertex where its UVs or normals change; the face is found and
cloned on the welded surface, and a seam's copies move as one vertex."""

import numpy as np
import pytest

from facepuppet.runtime.demo.head import build_demo_character
from facepuppet.runtime.model.character_parts import Layout

from facepuppet.offline.elastic.clone import mesh_character
from facepuppet.offline.elastic.laplacian import components
from facepuppet.offline.perfect_sync.face import FaceError, find_face, weld_map


def _split_at_seam(c, x_seam=0.3):
    """The demo head's mesh with every triangle whose centre lies beyond x = ``x_seam`` on copies of its vertices
    (a UV seam as glTF stores it): (vertices, triangles, indices of the copies' originals)."""
    v = c.vertices
    t = c.triangles.astype(np.int64)
    beyond = v[t].mean(1)[:, 0] > x_seam
    used = np.unique(t[beyond])
    copy_of = np.full(len(v), -1)
    copy_of[used] = len(v) + np.arange(len(used))
    t2 = t.copy()
    t2[beyond] = copy_of[t[beyond]]
    return np.concatenate([v, v[used]]), t2.astype(np.uint32), used


def _with_layout(character):
    return character.with_parts(layout=Layout(mesh_names=("head",), primitives=np.array(
        [[0, character.n_vertices, 0, len(character.triangles), 0, 0]], np.int64)))


def test_a_face_split_at_a_seam_is_found_as_one_skin():
    c = build_demo_character()
    whole = find_face(_with_layout(mesh_character(c.vertices, c.triangles, "whole")))
    v, t, used = _split_at_seam(c)
    split = mesh_character(v, t, "seamed")
    assert components(len(v), t)[0] > components(c.n_vertices, c.triangles)[0]  # the seam cuts the index graph
    with pytest.raises(FaceError, match="several disconnected pieces"):
        find_face(split)  # no layout: coincident vertices are distinct pieces (as an OBJ's would be)
    seamed = _with_layout(split)
    weld = weld_map(seamed)
    np.testing.assert_array_equal(weld[c.n_vertices:], weld[used])  # each copy onto its original's first copy
    assert (weld[c.n_vertices:] < c.n_vertices).all()
    face = find_face(seamed)
    np.testing.assert_array_equal(np.sort(face.skin), np.sort(whole.skin))  # one vertex per position
    np.testing.assert_array_equal(face.mesh, np.union1d(np.unique(t), weld[np.unique(t)]))  # copies and firsts
    assert face.nose_tip == whole.nose_tip
    np.testing.assert_allclose(face.frame, whole.frame, atol=1e-9)


def test_coincident_vertices_of_different_primitives_are_not_welded():
    c = build_demo_character()
    v, t, used = _split_at_seam(c)
    n = c.n_vertices
    first = np.isin(t, np.arange(n)).all(1)
    order = np.concatenate([np.flatnonzero(first), np.flatnonzero(~first)])
    two = mesh_character(v, t[order], "two").with_parts(layout=Layout(mesh_names=("a", "b"), primitives=np.array(
        [[0, n, 0, int(first.sum()), 0, 0], [n, len(v) - n, int(first.sum()), int((~first).sum()), 1, 0]],
        np.int64)))
    weld = weld_map(two)
    assert (weld[n:] >= n).all() and (weld[:n] < n).all()  # welded within each primitive only
    assert (weld_map(_with_layout(mesh_character(v, t, "one")))[n:] < n).all()  # one primitive: welded
