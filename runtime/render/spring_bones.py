"""Spring bone simulation: hair, ribbons and skirts that swing behind the head, as VRM avatar apps do.

The algorithm is the one of the VRMC_springBone-1.0 specification
("Spring bone algorithm"; three-vrm's ``VRMSpringBoneJoint.update`` is the
same), per joint, parents first:

1. inertia: ``next = current + (current - previous) · (1 - dragForce)``, in the
   chain's center space (the center node's frame, or the character's), so a
   center that jumps carries its chains without lag;
2. stiffness toward the rest direction: ``+ axis_world · stiffness · Δt``,
   where ``axis_world`` is the bone's rest axis carried by its parent's
   current pose;
3. gravity: ``+ gravityDir · gravityPower · Δt``;
4. length: ``next = head + normalize(next - head) · boneLength``;
5. collisions: a sphere (or capsule: the segment's closest point) of radius
   r pushes the tail out to ``r + hitRadius`` from it, then the length is
   restored;
6. the joint turns so its rest axis points at the new tail.

Symbols: ``current``/``previous`` tails (``_cur``, ``_prev``), ``Δt`` the fixed
step :data:`STEP_S`.

**Frame-rate independence.** The simulation steps on a fixed grid of
:data:`STEP_S` seconds of the frames' time, whatever the frame rate; between
two frames the driving pose (the head, the colliders' and centers' nodes) is
interpolated linearly, so 30, 60 and 144 frames/s drive the same steps with
nearly the same poses. The frames' time is the loop's tick time (recorded time
on replay), so a replay gives the same motion every time. A jump back in
time, or a gap over :data:`MAX_GAP_S`, restarts the simulation at rest in the
current pose.

**Vectorised.** Joints are processed by *level* (depth below the nearest
joint above them): all joints of one level at once, in NumPy, levels in order;
each level's collisions are computed against every collider together and the
pushes of the colliders a tail is inside are added (the specification applies
them one after the other; the two differ only for a tail inside two colliders
at once). Bones are assumed uniformly scaled (turns are taken from the
transposed rest frame).
"""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.model.character_parts import Skeleton
from facepuppet.runtime.model.springs import SpringRig

#: The fixed internal step, seconds. The specification's update is tuned per step (the drag takes its share
#: of the velocity once a step), and avatars are authored in apps stepping at 60 frames/s (UniVRM, three-vrm
#: driven by a 60 Hz display): 60 steps a second move them as their authors saw them.
STEP_S = 1.0 / 60.0
#: A gap between frames longer than this (or time going back) restarts the simulation at rest.
MAX_GAP_S = 0.5


def _norm(v: np.ndarray) -> np.ndarray:
    """Row lengths (n,) of ``v`` (n, 3) (np.linalg.norm's axis handling costs more than the sum on 3 columns)."""
    return np.sqrt(np.einsum("ij,ij->i", v, v))


def _rotation_between(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3) turning unit vectors ``a`` onto ``b`` (n, 3) (Rodrigues' formula)."""
    ax, ay, az = a[:, 0], a[:, 1], a[:, 2]
    bx, by, bz = b[:, 0], b[:, 1], b[:, 2]
    x, y, z = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx  # v = a × b
    c = ax * bx + ay * by + az * bz
    k = 1.0 / np.maximum(1.0 + c, 1e-9)
    # R = I + [v]x + [v]x^2 / (1 + c)
    out[:, 0, 0] = 1.0 - (y * y + z * z) * k
    out[:, 1, 1] = 1.0 - (x * x + z * z) * k
    out[:, 2, 2] = 1.0 - (x * x + y * y) * k
    out[:, 0, 1] = -z + x * y * k
    out[:, 1, 0] = z + x * y * k
    out[:, 0, 2] = y + x * z * k
    out[:, 2, 0] = -y + x * z * k
    out[:, 1, 2] = -x + y * z * k
    out[:, 2, 1] = x + y * z * k
    return out


class SpringBones:
    """The spring bones of one character, stepped on its frames' time.

    Parameters
    ----------
    rig : SpringRig, the joints and colliders (:func:`~facepuppet.runtime.model.springs.spring_rig`)
    skeleton : Skeleton, the character's nodes in their rest pose
    step_s : float, the fixed internal step

    Use: :meth:`advance` once per frame with the frame's time, the skinning
    matrices the head pose gives (n_nodes, 4, 4) and the model matrix (root
    motion); it writes the spring joints' skinning matrices into those
    matrices. :meth:`tails` gives the tails' world positions.
    """

    def __init__(self, rig: SpringRig, skeleton: Skeleton, step_s: float = STEP_S) -> None:
        if not step_s > 0:
            raise ValueError(f"step_s: expected a positive step, got {step_s}")
        self.rig, self.step_s = rig, float(step_s)
        n, n_nodes = rig.n_joints, skeleton.n_nodes
        g = skeleton.global_transforms()
        self._g = g
        self._g_inv = np.linalg.inv(g[rig.node]) if n else np.zeros((0, 4, 4))
        parent = skeleton.parent.astype(np.int64)
        joint_of = np.full(n_nodes, -1, np.int64)
        joint_of[rig.node] = np.arange(n)
        # the nearest joint above each node (itself excluded), -1 when none
        above = np.full(n_nodes, -1, np.int64)
        for s in range(n_nodes):
            p = int(parent[s])
            if p >= 0:
                above[s] = p if joint_of[p] >= 0 else above[p]
        # drivers: the nodes whose pose comes from the head pose alone (row 0: the model matrix itself)
        drivers = [-1]
        anchor_is_joint = np.array([above[j] >= 0 for j in rig.node], bool)
        for j in range(n):
            if not anchor_is_joint[j]:
                drivers.append(int(parent[rig.node[j]]))
        drivers += [int(x) for x in rig.collider_node] + [int(x) for x in rig.center if x >= 0]
        self._drivers = np.array(list(dict.fromkeys(drivers)), np.int64)
        row = {int(d): i for i, d in enumerate(self._drivers)}
        nd = len(self._drivers)
        self._nd = nd
        # W: the world transforms of the drivers, then of the joints (this step's)
        self._w = np.tile(np.eye(4), (nd + n, 1, 1))
        self._wd_prev = np.tile(np.eye(4), (nd, 1, 1))
        self._wd_cur = np.tile(np.eye(4), (nd, 1, 1))
        anchor = np.empty(n, np.int64)
        rel = np.tile(np.eye(4), (n, 1, 1))
        local = np.empty((n, 4, 4))
        level = np.zeros(n, np.int64)
        for j in range(n):
            node, p = int(rig.node[j]), int(parent[rig.node[j]])
            g_parent = g[p] if p >= 0 else np.eye(4)
            local[j] = np.linalg.solve(g_parent, g[node])
            if anchor_is_joint[j]:
                a = int(joint_of[above[node]])
                anchor[j] = nd + a
                rel[j] = np.linalg.solve(g[above[node]], g_parent)
                level[j] = level[a] + 1  # parents first: a's level is known
            else:
                anchor[j] = row[p]
        self._anchor, self._rel, self._local = anchor, rel, local
        self._levels = [np.flatnonzero(level == v) for v in range(int(level.max()) + 1 if n else 0)]
        self._center = np.array([row[int(c)] if c >= 0 else 0 for c in rig.center], np.int64)
        self._has_center = bool((rig.center >= 0).any())
        self._collider_row = np.array([row[int(c)] for c in rig.collider_node], np.int64)
        self._capsule = rig.collider_shape == 1
        self._length = np.linalg.norm(rig.tail, axis=1)  # rest length in the node's frame
        scale = np.linalg.norm(g[rig.node][:, :3, 0], axis=1) if n else np.zeros(0)
        self._length_w = self._length * scale
        self._axis = rig.tail / np.maximum(self._length, 1e-12)[:, None]
        self._inertia = 1.0 - rig.drag
        self._push = rig.stiffness * self.step_s
        self._gravity = rig.gravity_dir * (rig.gravity_power * self.step_s)[:, None]
        self._cur = np.zeros((n, 3))
        self._prev = np.zeros((n, 3))
        self._turn = np.tile(np.eye(3), (n, 1, 1))  # each joint's turn from its rest, in its rest frame
        self._turn4 = np.tile(np.eye(4), (n, 1, 1))
        # nodes below a joint that are not joints follow their joint's skinning matrix
        follow = [(s, int(joint_of[above[s]])) for s in range(n_nodes) if joint_of[s] < 0 and above[s] >= 0]
        self._follow_nodes = np.array([f for f, _ in follow], np.int64)
        self._follow_joint = np.array([j for _, j in follow], np.int64)
        # what each level's step reads, gathered once
        rel_local = np.matmul(rel, local)
        reach = rig.collider_radius[None, :] + rig.hit_radius[:, None]  # (n, c)
        self._level_data = []
        for idx in self._levels:
            hits = rig.hits[idx]
            self._level_data.append((idx, anchor[idx], rel_local[idx], self._axis[idx], self._push[idx, None],
                                     self._gravity[idx], self._length_w[idx, None],
                                     hits if hits.any() else None, reach[idx]))
        self._any_capsule = bool(self._capsule.any())
        self._turn_buf = np.zeros((max(n, 1), 3, 3))
        self.moved_nodes = np.zeros(n_nodes, bool)
        self.moved_nodes[rig.node] = True
        self.moved_nodes[self._follow_nodes] = True
        self._t_sim = self._t_last = None
        self.steps = 0  # steps taken since the start (a measure for tests and benchmarks)

    # -- per frame ------------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the motion: the next :meth:`advance` starts at rest in its pose."""
        self._t_sim = self._t_last = None

    def advance(self, t: float, skinning: np.ndarray, model: np.ndarray | None = None) -> np.ndarray:
        """Step the simulation to time ``t`` and write the joints' skinning matrices.

        Parameters
        ----------
        t : float, seconds, the frame's time (the loop's tick time)
        skinning : ndarray (n_nodes, 4, 4) float32, the head pose's skinning matrices; the spring joints' and the
            nodes below them are overwritten (in place)
        model : ndarray (4, 4), the model matrix (root motion: head translation); None: identity

        Returns
        -------
        ``skinning``
        """
        if not self.rig.n_joints:
            return skinning
        model = np.eye(4) if model is None else np.asarray(model, np.float64)
        self._driver_worlds(skinning, model, self._wd_cur)
        t = float(t)
        if self._t_last is None or t < self._t_last or t - self._t_last > MAX_GAP_S:
            self._start(skinning, model, t)
        else:
            span = t - self._t_last
            while self._t_sim + self.step_s <= t + 1e-9:
                alpha = 1.0 if span <= 0 else (self._t_sim + self.step_s - self._t_last) / span
                self._wd_lerp(min(max(alpha, 0.0), 1.0))
                self._step()
                self._t_sim += self.step_s
                self.steps += 1
            self._t_last = t
        self._wd_prev[:] = self._wd_cur
        self._pose(skinning, model)
        return skinning

    def tails(self) -> np.ndarray:
        """The tails' positions (n_joints, 3) float64, world (the model matrix applied), after the last step."""
        if not self._has_center:
            return self._cur.copy()
        c = self._w[self._center]
        return np.einsum("nij,nj->ni", c[:, :3, :3], self._cur) + c[:, :3, 3]

    # -- the parts of a frame ---------------------------------------------------------------------------------
    def _driver_worlds(self, skinning: np.ndarray, model: np.ndarray, out: np.ndarray) -> None:
        d = self._drivers
        out[0] = model
        if len(d) > 1:
            np.matmul(model, np.matmul(skinning[d[1:]].astype(np.float64), self._g[d[1:]]), out=out[1:])

    def _wd_lerp(self, alpha: float) -> None:
        w = self._w[:self._nd]
        np.multiply(self._wd_prev, 1.0 - alpha, out=w)
        w += alpha * self._wd_cur

    def _start(self, skinning: np.ndarray, model: np.ndarray, t: float) -> None:
        """At rest in the current pose: tails where the pose puts them, no velocity."""
        self._w[:self._nd] = self._wd_cur
        self._turn[:] = np.eye(3)
        rig = self.rig
        world = model @ skinning[rig.node].astype(np.float64) @ self._g[rig.node]
        tails = np.einsum("nij,nj->ni", world[:, :3, :3], rig.tail) + world[:, :3, 3]
        self._cur[:] = self._to_center(tails)
        self._prev[:] = self._cur
        self._t_sim = self._t_last = t

    def _to_center(self, points: np.ndarray) -> np.ndarray:
        if not self._has_center:
            return points
        inv = np.linalg.inv(self._w[self._center])
        return np.einsum("nij,nj->ni", inv[:, :3, :3], points) + inv[:, :3, 3]

    def _from_center(self, points: np.ndarray) -> np.ndarray:
        if not self._has_center:
            return points
        c = self._w[self._center]
        return np.einsum("nij,nj->ni", c[:, :3, :3], points) + c[:, :3, 3]

    def _step(self) -> None:
        """One step of :data:`STEP_S` for every joint, level by level (the numbered steps of the module doc)."""
        w, nd = self._w, self._nd
        cur_w = self._from_center(self._cur)
        new_w = cur_w + (cur_w - self._from_center(self._prev)) * self._inertia[:, None]  # 1: inertia
        colliders = None
        if self.rig.n_colliders:
            cw = w[self._collider_row]
            colliders = (np.einsum("cij,cj->ci", cw[:, :3, :3], self.rig.collider_offset) + cw[:, :3, 3],
                         np.einsum("cij,cj->ci", cw[:, :3, :3], self.rig.collider_tail) + cw[:, :3, 3])
        for idx, anchor, rel_local, axis0, push, gravity, length, hits, reach in self._level_data:
            rest = np.matmul(w[anchor], rel_local)  # the joint's frame, unturned
            head = rest[:, :3, 3]
            axis = np.einsum("nij,nj->ni", rest[:, :3, :3], axis0)
            axis /= _norm(axis)[:, None]
            nxt = new_w[idx] + axis * push + gravity  # 2, 3: stiffness, gravity
            d = nxt - head
            nxt = head + d * (length / np.maximum(_norm(d), 1e-12)[:, None])  # 4: length
            if hits is not None:
                nxt = self._collide(nxt, head, length, colliders, hits, reach)  # 5
            new_w[idx] = nxt
            # 6: the turn taking the rest axis onto the new tail, in the joint's rest frame
            local_dir = np.einsum("nji,nj->ni", rest[:, :3, :3], nxt - head)
            local_dir /= np.maximum(_norm(local_dir), 1e-12)[:, None]
            turn = _rotation_between(axis0, local_dir, self._turn_buf[:len(idx)])
            self._turn[idx] = turn
            rest[:, :3, :3] = np.matmul(rest[:, :3, :3], turn)
            w[nd + idx] = rest
        self._prev[:] = self._cur
        self._cur[:] = self._to_center(new_w)

    def _collide(self, nxt: np.ndarray, head: np.ndarray, length: np.ndarray,
                 colliders: tuple[np.ndarray, np.ndarray], hits: np.ndarray, reach: np.ndarray) -> np.ndarray:
        """Tails (n, 3) pushed out of the colliders they hit (``hits`` (n, c), ``reach`` (n, c): radius plus hit
        radius), then put back at bone length."""
        start, end = colliders
        rel = nxt[:, None, :] - start[None]  # (n, c, 3)
        if self._any_capsule:  # from the closest point of a capsule's segment (a sphere: its centre)
            seg = end - start
            seg_sq = np.einsum("ci,ci->c", seg, seg)
            along = np.einsum("nci,ci->nc", rel, seg)
            frac = np.where(self._capsule & (seg_sq > 0), np.clip(along / np.maximum(seg_sq, 1e-12), 0.0, 1.0),
                            0.0)
            rel -= frac[:, :, None] * seg[None]
        dist = np.sqrt(np.einsum("nci,nci->nc", rel, rel))
        depth = reach - dist
        inside = hits & (depth > 0)
        if not inside.any():
            return nxt
        push = np.where(inside, depth / np.maximum(dist, 1e-12), 0.0)
        nxt = nxt + np.einsum("nc,nci->ni", push, rel)
        d = nxt - head
        return head + d * (length / np.maximum(_norm(d), 1e-12)[:, None])

    def _pose(self, skinning: np.ndarray, model: np.ndarray) -> None:
        """The joints' skinning matrices at the frame's pose with the last step's turns: the roots of the chains
        stay on the head as it is now (the steps may be up to one step behind)."""
        w, nd = self._w, self._nd
        w[:nd] = self._wd_cur
        t4 = self._turn4
        t4[:, :3, :3] = self._turn
        for idx, anchor, rel_local, *_ in self._level_data:
            w[nd + idx] = np.matmul(np.matmul(w[anchor], rel_local), t4[idx])
        joints = w[nd:]
        inv = np.eye(4)  # the model matrix is rigid (a head translation, root motion)
        inv[:3, :3] = model[:3, :3].T
        inv[:3, 3] = -inv[:3, :3] @ model[:3, 3]
        d = np.matmul(inv, np.matmul(joints, self._g_inv))
        skinning[self.rig.node] = d
        if len(self._follow_nodes):
            skinning[self._follow_nodes] = skinning[self.rig.node[self._follow_joint]]
