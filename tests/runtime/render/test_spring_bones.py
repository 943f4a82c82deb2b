"""Spring bones against the properties the VRMC_springBone-1.0 specification's algorithm has (small chains built
in tests/helpers/spring_rigs.py; no GL)."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.files.tables import TablesError
from facepuppet.runtime.model.springs import spring_rig
from facepuppet.runtime.render.spring_bones import STEP_S, SpringBones

from helpers.spring_rigs import chain_skeleton, chain_springs, head_skinning, rig_of, yaw_quat


def heads_and_tails(sb: SpringBones, sk, skinning):
    """World positions of each joint's node (from the skinning it wrote) and of its tail (the simulation's)."""
    g = sk.global_transforms()
    nodes = sb.rig.node
    heads = np.einsum("nij,nj->ni", skinning[nodes].astype(np.float64) @ g[nodes], np.tile([0, 0, 0, 1.0],
                                                                                            (len(nodes), 1)))[:, :3]
    return heads, sb.tails()


def swing(t: float) -> float:
    """A head turn: 0.6 rad of yaw swinging at 0.8 Hz for 1.5 s, then still."""
    return 0.6 * np.sin(2 * np.pi * 0.8 * min(t, 1.5))


def run(sb, sk, fps: float, seconds: float, motion=swing, model_of=lambda t: None, sample=()):
    """Advance ``sb`` at ``fps`` for ``seconds``; the tails at each time of ``sample`` (s), and the last ones."""
    out = {}
    n = int(round(seconds * fps))
    for k in range(n + 1):
        t = k / fps
        skin = head_skinning(sk, yaw_quat(motion(t)))
        sb.advance(t, skin, model_of(t))
        for s in sample:
            if abs(s - t) < 1e-9:
                out[s] = sb.tails()
    return out, sb.tails()


def test_at_rest_nothing_moves():
    sk = chain_skeleton(4)
    sb = SpringBones(rig_of(sk, chain_springs(sk, stiffness=0.5, drag=0.2)), sk)
    first = None
    for k in range(180):
        skin = head_skinning(sk, None)
        sb.advance(k / 60, skin)
        first = sb.tails() if first is None else first
        np.testing.assert_allclose(skin, np.tile(np.eye(4), (sk.n_nodes, 1, 1)), atol=1e-6)
    np.testing.assert_allclose(sb.tails(), first, atol=1e-12)


def test_every_tail_stays_at_its_bone_length_through_a_swing():
    sk = chain_skeleton(4, step=(0.08, -0.03, 0.02))
    rig = rig_of(sk, chain_springs(sk, stiffness=1.0, drag=0.3, gravity_power=0.5))
    sb = SpringBones(rig, sk)
    lengths = np.linalg.norm(rig.tail, axis=1)
    for k in range(121):
        skin = head_skinning(sk, yaw_quat(swing(k / 60)))
        sb.advance(k / 60, skin)
        heads, tails = heads_and_tails(sb, sk, skin)
        np.testing.assert_allclose(np.linalg.norm(tails - heads, axis=1), lengths, rtol=1e-6)  # float32 skinning
    assert sb.steps == 120


def test_gravity_alone_hangs_the_chain_straight_down():
    sk = chain_skeleton(3, step=(0.1, 0.0, 0.0))  # sticking out sideways
    sb = SpringBones(rig_of(sk, chain_springs(sk, stiffness=0.0, drag=0.5, gravity_power=1.0)), sk)
    run(sb, sk, 60, 6.0, motion=lambda t: 0.0)
    skin = head_skinning(sk, None)
    sb.advance(6.0 + 1 / 60, skin)
    heads, tails = heads_and_tails(sb, sk, skin)
    directions = (tails - heads) / np.linalg.norm(tails - heads, axis=1)[:, None]
    np.testing.assert_allclose(directions, [[0, -1, 0]] * len(directions), atol=1e-6)


def test_a_sphere_collider_pushes_a_tail_out_to_radius_plus_hit_radius():
    # one joint at the first link (0.1, 1.5, 0) with a 0.1 m bone along +x; the sphere's centre c lies on the
    # line through the rest tail P1 and a point X also at bone length, with |X - c| = R: the push moves P1
    # along that line to X, which is already at bone length, so the result is exactly R from c
    sk = chain_skeleton(2, step=(0.1, 0.0, 0.0))
    g = sk.global_transforms()  # the skeleton's float32 rest, exactly
    head, p1 = g[2][:3, 3], g[3][:3, 3]
    length = float(np.linalg.norm(p1 - head))
    x = head + length * np.array([np.cos(0.7), np.sin(0.7), 0.0])
    c = p1 + 0.3 * (p1 - x)  # beyond P1, on the line from X through P1
    big_r, hit = float(np.linalg.norm(x - c)), 0.01
    collider = {"node": 0, "shape": "sphere", "offset": c.tolist(), "tail": [0, 0, 0], "radius": big_r - hit}
    sb = SpringBones(rig_of(sk, chain_springs(sk, stiffness=0.0, drag=1.0, hit_radius=hit,
                                              colliders=[collider])), sk)
    sb.advance(0.0, head_skinning(sk, None))
    assert np.linalg.norm(sb.tails()[0] - c) < big_r  # starts inside
    sb.advance(STEP_S, head_skinning(sk, None))
    tail = sb.tails()[0]
    assert np.linalg.norm(tail - c) == pytest.approx(big_r, abs=1e-12)
    assert np.linalg.norm(tail - head) == pytest.approx(length, abs=1e-12)
    np.testing.assert_allclose(tail, x, atol=1e-12)


def test_a_capsule_collider_keeps_the_tail_out_of_its_segment():
    sk = chain_skeleton(2, step=(0.0, -0.1, 0.0))
    capsule = {"node": 0, "shape": "capsule", "offset": [-0.2, 1.33, 0.02], "tail": [0.2, 1.33, 0.02],
               "radius": 0.04}
    sb = SpringBones(rig_of(sk, chain_springs(sk, stiffness=0.2, gravity_power=0.3, hit_radius=0.01,
                                              colliders=[capsule])), sk)
    _, tails = run(sb, sk, 60, 2.0)
    dist = np.hypot(tails[:, 1] - 1.33, tails[:, 2] - 0.02)  # distance to the segment along x
    # at rest 3.6 cm from it; held at r + hit radius, less what each step's stiffness and gravity bring in
    # before the push (the length constraint after the push moves the tail back toward the joint)
    assert dist[0] == pytest.approx(0.05, abs=2e-3)


def test_moving_the_center_carries_the_chain_without_lag():
    sk = chain_skeleton(3, step=(0.0, -0.1, 0.05))

    def jump(t):  # root motion: the whole character jumps 2 m at t = 0.5 s
        m = np.eye(4)
        m[0, 3] = 2.0 if t >= 0.5 else 0.0
        return m

    tails = {}
    for center in (-1, 0):
        for model_of in (lambda t: None, jump):
            sb = SpringBones(rig_of(sk, chain_springs(sk, drag=0.2, center=center)), sk)
            tails[center, model_of is jump] = run(sb, sk, 60, 1.0, model_of=model_of, sample=(0.5, 0.7))[0]
    for s in (0.5, 0.7):
        np.testing.assert_allclose(tails[0, True][s], tails[0, False][s] + [2.0, 0, 0], atol=1e-9)
    # in the character's space (no center) the same jump leaves the tails behind for a while
    assert np.abs(tails[-1, True][0.5] - tails[-1, False][0.5] - [2.0, 0, 0]).max() > 0.01


def test_30_60_and_144_frames_per_second_give_the_same_tails():
    """Tolerance: 1 mm on a 30 cm chain. The steps are the same (a fixed 1/60 s grid); what differs is the
    driving pose between frames, interpolated linearly from 30 or 144 samples a second of a 0.8 Hz swing."""
    sk = chain_skeleton(3, step=(0.0, -0.1, 0.02))
    times = (0.5, 1.0, 1.5, 2.0, 3.0)
    got = {}
    for fps in (30, 60, 144):
        sb = SpringBones(rig_of(sk, chain_springs(sk, stiffness=1.0, drag=0.4, gravity_power=0.5)), sk)
        got[fps] = run(sb, sk, fps, 3.0, sample=times)[0]
    moved = max(np.abs(got[60][t] - got[60][3.0]).max() for t in times)
    assert moved > 0.02  # the swing moves the tails by centimetres
    for fps in (30, 144):
        for t in times:
            np.testing.assert_allclose(got[fps][t], got[60][t], atol=1e-3, err_msg=f"{fps} fps at {t} s")


def test_replay_on_the_same_times_gives_the_same_motion():
    sk = chain_skeleton(3, step=(0.0, -0.1, 0.02))
    runs = []
    for _ in range(2):
        sb = SpringBones(rig_of(sk, chain_springs(sk)), sk)
        runs.append(run(sb, sk, 50, 2.0, sample=(0.4, 1.2))[0])
    for t in (0.4, 1.2):
        np.testing.assert_array_equal(runs[0][t], runs[1][t])


def test_time_going_back_restarts_at_rest():
    sk = chain_skeleton(2, step=(0.0, -0.1, 0.02))
    sb = SpringBones(rig_of(sk, chain_springs(sk)), sk)
    run(sb, sk, 60, 1.0)
    skin = head_skinning(sk, yaw_quat(0.3))
    sb.advance(0.0, skin)
    heads, tails = heads_and_tails(sb, sk, skin)
    rest = sk.pose_matrices({1: yaw_quat(0.3)}).astype(np.float64) @ sk.global_transforms()
    np.testing.assert_allclose(tails, [rest[j + 1][:3, 3] for j in sb.rig.node], atol=1e-6)


@pytest.mark.parametrize("change,field", [
    (lambda s: s["chains"][0]["joints"][0].update(drag=1.5), "settings.springs.chains[0].joints[0].drag"),
    (lambda s: s["chains"][0]["joints"][0].update(node=99), "settings.springs.chains[0].joints[0].node"),
    (lambda s: s["chains"][0]["joints"][0].update(tail=[0, 0, "x"]), "settings.springs.chains[0].joints[0].tail"),
    (lambda s: s["chains"][0].update(colliders=[3]), "settings.springs.chains[0].colliders[0]"),
    (lambda s: s.update(chains=[s["chains"][0]] * 2000), "settings.springs.chains"),
])
def test_bad_spring_tables_are_refused_naming_the_field(change, field):
    sk = chain_skeleton(2)
    springs = chain_springs(sk)
    change(springs)
    with pytest.raises(TablesError, match=field.replace("[", r"\[").replace("]", r"\]")):
        spring_rig(springs, sk.parent)


def test_a_joint_on_a_zero_scaled_node_is_refused_not_crashed():
    sk = chain_skeleton(2)
    springs = chain_springs(sk)
    world = sk.global_transforms()
    world[2, :3, :3] = 0.0
    with pytest.raises(TablesError, match=r"settings.springs.chains\[0\].joints\[0\].node: node 2 has a singular"):
        spring_rig(springs, sk.parent, world)


def test_a_frame_allocates_no_arrays_of_its_own():
    """300 chains of 2 joints with a capsule: one (600, 4, 4) float64 temporary would be 77 kB, and the
    simulation written with temporaries peaked at 161 kB a frame. What a frame still allocates is Python's small
    objects (array views) and NumPy's internal buffering of a few strided or broadcast operations (18 kB at
    the peak here, freed by the operation itself); nothing is kept (no growth)."""
    import tracemalloc

    from facepuppet.runtime.model.character_parts import Skeleton

    n_chains = 300
    names, parent, local = ["root", "head"], [-1, 0], [np.eye(4), np.eye(4)]
    local[1][:3, 3] = (0, 1.5, 0)
    joints = []
    for k in range(n_chains):
        angle = 2 * np.pi * k / n_chains
        for depth in range(3):
            m = np.eye(4)
            m[:3, 3] = (0.1 * np.cos(angle), 0.0, 0.1 * np.sin(angle)) if depth == 0 else (0.0, -0.05, 0.0)
            parent.append(1 if depth == 0 else len(names) - 1)
            names.append(f"c{k}_{depth}")
            local.append(m)
            if depth < 2:
                joints.append({"node": len(names) - 1, "tail_node": len(names), "tail": [0.0, -0.05, 0.0],
                               "stiffness": 1.0, "drag": 0.4, "gravity_power": 0.2, "gravity_dir": [0, -1, 0],
                               "hit_radius": 0.01})
    sk = Skeleton(tuple(names), np.array(parent, np.int32), np.array(local, np.float32), np.zeros((1, 4), np.uint16),
                  np.array([[1.0, 0, 0, 0]], np.float32), {"head": 1})
    collider = {"node": 1, "shape": "capsule", "offset": [-0.2, 0.0, 0.0], "tail": [0.2, 0.0, 0.0], "radius": 0.05}
    springs = {"chains": [{"name": "ring", "center": -1, "colliders": [0], "joints": joints}],
               "colliders": [collider]}
    sb = SpringBones(rig_of(sk, springs), sk)
    skins = [head_skinning(sk, yaw_quat(swing(k / 60))) for k in range(40)]
    for k in range(20):
        sb.advance(k / 60, skins[k])
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        for k in range(20, 40):
            sb.advance(k / 60, skins[k])
        current, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert sb.steps == 39
    assert peak - base < 24_000, f"a frame allocated up to {peak - base} bytes at once"
    assert current - base < 4_000


def test_a_frame_on_the_step_grid_poses_the_joints_as_a_frame_between_steps_does():
    """A frame whose last step was at its own pose reuses that step's joint frames; the same frame given again
    takes no step and poses the joints afresh from the drivers and the turns: the two must agree (float32
    skinning)."""
    sk = chain_skeleton(4, step=(0.08, -0.03, 0.02))
    sb = SpringBones(rig_of(sk, chain_springs(sk, stiffness=1.0, drag=0.3, gravity_power=0.5)), sk)
    model = np.eye(4)
    for k in range(90):
        t = k * STEP_S
        model[0, 3] = 0.1 * np.sin(t)
        on_grid = sb.advance(t, head_skinning(sk, yaw_quat(swing(t))), model)
        steps = sb.steps
        again = sb.advance(t, head_skinning(sk, yaw_quat(swing(t))), model)
        assert sb.steps == steps  # no step the second time
        np.testing.assert_allclose(again, on_grid, atol=1e-6, err_msg=f"frame {k}")
