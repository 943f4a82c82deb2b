"""Spring bones and look-at read from VRM files into the character table: VRM 1.0 written here
(tests/helpers/vrm_rigs.py), VRM 0.x from the data kit (Godette), malformed fields refused by JSON path."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from facepuppet.runtime.model.character import Character
from facepuppet.runtime.model.look_at import look_at_of
from facepuppet.runtime.model.springs import springs_of

from conftest import need_shared
from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.io.gltf_container import GltfError
from helpers.vrm_rigs import look_at_vrm


def test_vrm1_spring_chain_colliders_and_bone_look_at_survive_the_table(tmp_path):
    c = read_gltf(look_at_vrm(tmp_path / "eyes.vrm"))
    c.save(tmp_path / "eyes.npz")
    c = Character.load(tmp_path / "eyes.npz")
    rig = springs_of(c)
    names = c.skeleton.names
    assert [names[n] for n in rig.node] == ["hair0", "hair1"]  # hair2 is the last joint: only a tail
    assert [names[n] for n in rig.tail_node] == ["hair1", "hair2"]
    np.testing.assert_allclose(rig.tail, [[0, 0, -0.1]] * 2, atol=1e-7)
    np.testing.assert_allclose(rig.stiffness, [1.5, 1.0])
    np.testing.assert_allclose(rig.drag, [0.3, 0.5])  # the schema's default drag on the second joint
    np.testing.assert_allclose(rig.gravity_power, [0.2, 0.0])
    assert rig.hit_radius.tolist() == [0.01, 0.0]
    assert rig.collider_shape.tolist() == [0, 1] and rig.hits.all()
    np.testing.assert_allclose(rig.collider_tail[1], [0.1, 0.0, -0.1])
    look = look_at_of(c.metadata["settings"], c.skeleton.n_nodes)
    assert look.kind == "bone" and names[look.left_eye] == "leftEye" and names[look.right_eye] == "rightEye"
    assert look.horizontal_outer(30.0) == pytest.approx(30.0)


@pytest.mark.data
def test_godette_vrm0_bone_groups_give_16_joints_with_virtual_tails():
    c = read_gltf(need_shared("gltf", "Godette_vrm_v4.vrm"))
    rig = springs_of(c)
    assert rig.n_joints == 16 and len(rig.chain_names) == 8 and rig.n_colliders == 4
    leaves = rig.tail_node < 0
    assert leaves.sum() == 8
    np.testing.assert_allclose(np.linalg.norm(rig.tail[leaves], axis=1), 0.07, atol=1e-9)
    hair = [c.skeleton.names.index("FrontHair_Center_L")]
    j = int(np.flatnonzero(rig.node == hair[0])[0])
    assert rig.stiffness[j] == 2.5 and rig.drag[j] == 0.4 and rig.hit_radius[j] == 0.02  # "stiffiness"
    # collider offsets are Unity's: z negated (three-vrm: "z is opposite in VRM0.0")
    np.testing.assert_allclose(rig.collider_offset[0], [0, 0.06, 0.04], atol=1e-6)
    look = c.metadata["settings"]["look_at"]
    assert look["type"] == "expression" and len(look["horizontal_outer"]["curve"]) == 3


@pytest.mark.parametrize("springs,field", [
    ({"specVersion": "1.0", "springs": [{"joints": [{"node": 4, "dragForce": 2}, {"node": 5}]}]},
     "extensions.VRMC_springBone.springs[0].joints[0].dragForce"),
    ({"specVersion": "1.0", "springs": [{"joints": [{"node": 40}, {"node": 5}]}]},
     "extensions.VRMC_springBone.springs[0].joints[0].node"),
    ({"specVersion": "1.0", "springs": [{"joints": [{"node": 5}, {"node": 4}]}]},
     "extensions.VRMC_springBone.springs[0].joints[1].node"),
    ({"specVersion": "1.0", "colliders": [{"node": 1, "shape": {"sphere": {"radius": -1}}}]},
     "extensions.VRMC_springBone.colliders[0].shape.sphere.radius"),
    ({"specVersion": "1.0", "springs": [{"joints": [{"node": 4, "gravityDir": [0, "down", 0]}, {"node": 5}]}]},
     "extensions.VRMC_springBone.springs[0].joints[0].gravityDir[1]"),
    ({"specVersion": "1.0", "springs": [{"joints": [{"node": 4}] * 5000}]},
     "extensions.VRMC_springBone.springs[0].joints"),
])
def test_bad_spring_fields_are_refused_by_their_json_path(tmp_path, springs, field):
    path = look_at_vrm(tmp_path / "bad.vrm", springs=springs)
    with pytest.raises(GltfError, match=field.replace("[", r"\[").replace("]", r"\]")):
        read_gltf(path)


def test_import_rig_prints_the_chains_and_refuses_a_bad_look_at_with_exit_2(tmp_path):
    good = look_at_vrm(tmp_path / "eyes.vrm")
    done = subprocess.run([sys.executable, "-m", "facepuppet", "import-rig", str(good), "-o",
                           str(tmp_path / "eyes.npz")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "spring bones: 1 chains, 2 joints, 2 colliders" in done.stdout
    assert "spring hair: 2 joints hair0 → hair1" in done.stdout and "capsule r 0.02 on head" in done.stdout
    assert "look-at: bone (eye bones: left_eye, right_eye)" in done.stdout
    bad = look_at_vrm(tmp_path / "bad.vrm", look_at={"type": "bone", "rangeMapVerticalUp": {"inputMaxValue": 0}})
    done = subprocess.run([sys.executable, "-m", "facepuppet", "import-rig", str(bad), "-o",
                           str(tmp_path / "bad.npz")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert "bad.vrm" in done.stderr and "extensions.VRMC_vrm.lookAt.rangeMapVerticalUp.inputMaxValue" in done.stderr
