"""Godette's spring bones against three-vrm's (the reference VRM implementation), run in node on the same numbers.

tests/runtime/render/oracle/three_vrm_springs.mjs builds a three.js node hierarchy from Godette's stored
skeleton, three-vrm's ``VRMSpringBoneJoint``s and colliders from the same spring table, and steps its
``VRMSpringBoneManager`` at 60 frames/s through one scripted head motion (the head pose our renderer gives:
the neck and head turned). Our simulation steps on the same 1/60 s grid, so each of its steps sees the same
pose as three-vrm's.

Tolerance, 1e-5 m (10 µm, on bones of 7 to 30 cm): the algorithm is the same, step for step; what differs is
arithmetic: our skinning matrices are float32 (about 1e-7 m at Godette's 1.5 m height), and where a tail is
inside two colliders at once we add both pushes while three-vrm applies them one after the other.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from facepuppet.runtime.model.springs import springs_of
from facepuppet.runtime.render.parts_path import HeadPose
from facepuppet.runtime.render.spring_bones import SpringBones

from conftest import need_shared
from facepuppet.offline.io.gltf.read import read_gltf

ROOT = Path(__file__).resolve().parents[3]
ORACLE = Path(__file__).parent / "oracle" / "three_vrm_springs.mjs"
FPS = 60
N_FRAMES = 150


def motion(t: float) -> np.ndarray:
    """A head turn and nod for 1.5 s (0.7 rad of yaw at 0.9 Hz, 0.3 rad of pitch at 1.3 Hz), then still."""
    t = min(t, 1.5)
    yaw, pitch = 0.7 * np.sin(2 * np.pi * 0.9 * t), 0.3 * np.sin(2 * np.pi * 1.3 * t)
    qy = np.array([0, np.sin(yaw / 2), 0, np.cos(yaw / 2)])
    qx = np.array([np.sin(pitch / 2), 0, 0, np.cos(pitch / 2)])
    x1, y1, z1, w1 = qy
    x2, y2, z2, w2 = qx
    return np.array([w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                     w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2, w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2])


def column_major(m: np.ndarray) -> list[float]:
    return [float(x) for x in np.asarray(m, np.float64).T.reshape(-1)]


@pytest.mark.data
@pytest.mark.slow
def test_godette_tails_match_three_vrm(tmp_path):
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed: the three-vrm reference cannot run")
    if not (ROOT / "node_modules" / "@pixiv" / "three-vrm").is_dir():
        pytest.skip("node_modules/@pixiv/three-vrm is missing (make setup runs npm ci)")
    c = read_gltf(need_shared("gltf", "Godette_vrm_v4.vrm"))
    sk, rig = c.skeleton, springs_of(c)
    assert rig is not None and rig.n_joints == 16
    g = sk.global_transforms()
    pose = HeadPose(c)
    moved = [n for n in (pose.neck, pose.head) if n is not None]
    frames, skinning = [], []
    for k in range(N_FRAMES + 1):
        d = pose.matrices(motion(k / FPS))
        skinning.append(d)
        posed = d.astype(np.float64) @ g
        if k:  # three-vrm steps on every update; ours starts at rest on the first frame, then steps
            frames.append({str(n): column_major(np.linalg.solve(posed[sk.parent[n]], posed[n])) for n in moved})
    doc = {
        "nodes": [{"parent": int(p), "matrix": column_major(m)} for p, m in zip(sk.parent, sk.rest_local)],
        "colliders": [{"node": int(rig.collider_node[i]), "shape": ("sphere", "capsule")[int(rig.collider_shape[i])],
                       "offset": rig.collider_offset[i].tolist(), "tail": rig.collider_tail[i].tolist(),
                       "radius": float(rig.collider_radius[i])} for i in range(rig.n_colliders)],
        "joints": [{"node": int(rig.node[j]), "tail_node": int(rig.tail_node[j]),
                    "stiffness": float(rig.stiffness[j]), "drag": float(rig.drag[j]),
                    "gravity_power": float(rig.gravity_power[j]), "gravity_dir": rig.gravity_dir[j].tolist(),
                    "hit_radius": float(rig.hit_radius[j]), "center": int(rig.center[j]),
                    "colliders": np.flatnonzero(rig.hits[j]).tolist()} for j in range(rig.n_joints)],
        "frames": frames, "dt": 1.0 / FPS,
    }
    (tmp_path / "in.json").write_text(json.dumps(doc))
    done = subprocess.run([node, str(ORACLE), str(tmp_path / "in.json")], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    theirs = np.array(json.loads(done.stdout)["tails"])
    sb = SpringBones(rig, sk)
    ours = []
    for k in range(N_FRAMES + 1):
        sb.advance(k / FPS, skinning[k].copy())
        if k:
            ours.append(sb.tails())
    ours = np.array(ours)
    assert theirs.shape == ours.shape == (N_FRAMES, 16, 3)
    swing = np.abs(ours - ours[-1]).max()
    assert swing > 0.02  # the hair swings by centimetres
    print(f"max |ours - three-vrm| {np.abs(ours - theirs).max():.2e} m, swing {swing:.3f} m")
    np.testing.assert_allclose(ours, theirs, atol=1e-5)
