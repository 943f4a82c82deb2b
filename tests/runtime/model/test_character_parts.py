"""The optional glTF/VRM parts of a character: saved and loaded whole, refused when half there, posed."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest

from facepuppet.runtime.files.tables import TablesError
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.model.character_parts import Skeleton

from helpers.small_characters import parts_character


def test_every_part_survives_save_and_load(tmp_path):
    c = parts_character()
    back = Character.load(c.save(tmp_path / "c.npz"))
    assert back.skeleton.names == ("root", "head") and back.skeleton.bones == {"head": 1}
    np.testing.assert_array_equal(back.skeleton.rest_local, c.skeleton.rest_local)
    np.testing.assert_array_equal(back.look.image(0), np.arange(16, dtype=np.uint8).reshape(2, 2, 4))
    assert back.expressions.names == ("Blink",) and back.expressions.presets == ("Blink",)
    np.testing.assert_array_equal(back.expressions.dense(1), [[0.5]])
    assert back.layout.mesh_names == ("m",) and back.credits == "Quad by Someone, CC BY 4.0"


def test_a_character_without_parts_has_none(tmp_path):
    c = parts_character(skeleton=None, look=None, expressions=None, layout=None)
    back = Character.load(c.save(tmp_path / "plain.npz"))
    assert (back.skeleton, back.look, back.expressions, back.layout) == (None, None, None, None)
    assert back.credits == "Quad by Someone, CC BY 4.0" and back.n_expressions == 0


def test_a_half_written_part_is_refused_naming_the_missing_section(tmp_path):
    path = parts_character().save(tmp_path / "c.npz")
    cut = tmp_path / "cut.npz"
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(cut, "w") as dst:
        for item in src.infolist():
            if item.filename != "vertex_weights.npy":
                dst.writestr(item, src.read(item.filename))
    with pytest.raises(TablesError, match=r"cut.npz: .*vertex_weights"):
        Character.load(cut)


@pytest.mark.parametrize("change, field", [
    (dict(vertex_weights=np.full((4, 4), 0.5, np.float32)), "vertex_weights"),
    (dict(parent=np.array([1, -1], np.int32)), "node_parent"),
    (dict(vertex_nodes=np.full((4, 4), 7, np.uint16)), "vertex_nodes"),
])
def test_a_bad_skeleton_is_refused(change, field):
    base = parts_character().skeleton
    fields = dict(names=base.names, parent=base.parent.copy(), rest_local=base.rest_local.copy(),
                  vertex_nodes=base.vertex_nodes.copy(), vertex_weights=base.vertex_weights.copy(), bones={})
    fields.update(change)
    with pytest.raises(TablesError, match=field):
        parts_character(skeleton=Skeleton(**fields))


def test_a_head_turn_moves_only_what_follows_the_head_about_the_head_node():
    sk = parts_character().skeleton
    quarter = np.array([0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)])  # 90 degrees about +z
    d = sk.pose_matrices({1: quarter})
    np.testing.assert_allclose(d[0], np.eye(4), atol=1e-6)
    # the vertex at (1, 1, 0) turns about the head node at (0.5, 1, 0): to (0.5, 1.5, 0)
    np.testing.assert_allclose((d[1] @ [1, 1, 0, 1])[:3], [0.5, 1.5, 0], atol=1e-6)
    np.testing.assert_allclose((d[1] @ [0.5, 1, 0, 1])[:3], [0.5, 1, 0], atol=1e-6)
