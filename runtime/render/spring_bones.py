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

**Few calls.** For the few dozen joints of an avatar the arithmetic is nothing
and each NumPy call's dispatch (about a microsecond, twice that when drawing
the frame has left the caches cold) is the cost, so a step is arranged in as
few calls as the algorithm allows: batched products (``matmul``) for the
rotations, dot products and Rodrigues' formula, buffers turned round rather
than copied, and the pose reusing the last step's joint frames when that step
was at the frame's own drivers (a frame on the step grid).

**Preallocated.** Every array a step or a frame writes (tails, frames, turns,
collision distances, the skinning matrices) is allocated once, in the
constructor; the arithmetic writes into them (``out=``, in place), the level
runs are slices (:mod:`facepuppet.runtime.render.spring_layout`). What a frame
still allocates is NumPy's own: array views, and the internal buffer of a few
strided or broadcast operations (freed by the operation); a chain with a center
also inverts its center's matrix each step (``np.linalg.inv``).
"""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.model.character_parts import Skeleton
from facepuppet.runtime.model.springs import SpringRig
from facepuppet.runtime.render.spring_layout import MODEL_ROW, WORLD_ROW, spring_layout

#: The fixed internal step, seconds. The specification's update is tuned per step (the drag takes its share
#: of the velocity once a step), and avatars are authored in apps stepping at 60 frames/s (UniVRM, three-vrm
#: driven by a 60 Hz display): 60 steps a second move them as their authors saw them.
STEP_S = 1.0 / 60.0
#: A gap between frames longer than this (or time going back) restarts the simulation at rest.
MAX_GAP_S = 0.5


#: ``(v, c) @ _SKEW_EYE`` is ``[v]x + c I`` flattened row-major (9,): the cross-product matrix of ``v`` (rows 0-2,
#: ``v @ _SKEW_EYE[:3]`` alone) plus ``c`` on the diagonal (row 3).
_SKEW_EYE = np.zeros((4, 9))
_SKEW_EYE[[2, 1, 2, 0, 1, 0], [1, 2, 3, 5, 6, 7]] = (-1, 1, 1, -1, -1, 1)
_SKEW_EYE[3, ::4] = 1.0


def _turn_rows(m: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
    """``out[i] = m[i] @ v[i]`` for (n, 3, 3) ``m`` and (n, 3) ``v``: one batched product (a ufunc, where einsum's
    Python dispatch costs more than the arithmetic of a few joints)."""
    np.matmul(m, v[:, :, None], out=out[:, :, None])


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

    Attributes
    ----------
    moved_nodes : ndarray (n_nodes,) bool, the nodes the springs move (joints and the nodes below them)
    steps : int, the steps taken since the start
    """

    def __init__(self, rig: SpringRig, skeleton: Skeleton, step_s: float = STEP_S) -> None:
        if not step_s > 0:
            raise ValueError(f"step_s: expected a positive step, got {step_s}")
        self.rig, self.step_s = rig, float(step_s)
        lay = self._lay = spring_layout(rig, skeleton, self.step_s)
        n, nd, c = rig.n_joints, len(lay.driver_nodes), rig.n_colliders
        self.moved_nodes = lay.moved_nodes
        self._nj0 = 2 + nd  # W's first joint row
        self._w = np.tile(np.eye(4), (lay.n_rows, 1, 1))
        self._wd_prev = np.tile(np.eye(4), (nd + 2, 1, 1))
        self._wd_cur = np.tile(np.eye(4), (nd + 2, 1, 1))
        self._wd_tmp = np.zeros((nd + 2, 4, 4))
        self._drv32 = np.zeros((nd, 4, 4), np.float32)
        self._drv, self._drv_rest = np.zeros((nd, 4, 4)), np.zeros((nd, 4, 4))
        self._cur, self._prev, self._new = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
        self._a3, self._b3, self._sq = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
        self._len = np.zeros(n)
        self._k = np.zeros(n)
        self._skew9, self._vc = np.zeros((n, 9)), np.zeros((n, 4))
        self._frame = np.zeros((n, 4, 4))  # each joint's unturned frame this step
        self._anchors = np.zeros((n, 4, 4))
        self._turn = np.tile(np.eye(3), (n, 1, 1))  # each joint's turn from its rest, in its rest frame
        self._turn4 = np.tile(np.eye(4), (n, 1, 1))
        self._centers = np.zeros((n, 4, 4))
        self._skin = np.zeros((n, 4, 4))
        self._skin2 = np.zeros((n, 4, 4))
        self._skin32 = np.zeros((n, 4, 4), np.float32)
        self._follow = np.zeros((len(lay.follow_nodes), 4, 4), np.float32)
        self._inv_model = np.eye(4)
        self._identity = np.eye(4)
        self._has_center = bool((lay.center_row != WORLD_ROW).any())
        self._any_capsule = bool((rig.collider_shape == 1).any())
        self._capsule = (rig.collider_shape == 1).astype(np.float64)
        self._cw = np.zeros((c, 4, 4))
        self._c_local = np.ones((c, 4, 2))
        self._c_local[:, :3, 0], self._c_local[:, :3, 1] = rig.collider_offset, rig.collider_tail
        self._c_world = np.zeros((c, 4, 2))
        self._c_start, self._c_end = self._c_world[:, :3, 0], self._c_world[:, :3, 1]  # views
        self._seg = np.zeros((c, 3))
        self._seg_sq = np.zeros(c)
        self._rel = np.zeros((n, c, 3))
        self._rel2 = np.zeros((n, c, 3))
        self._nc = np.zeros((n, c))
        self._depth = np.zeros((n, c))
        self._level_hits = [bool(lay.hits[a:b].any()) for a, b in lay.levels]
        self._t_sim = self._t_last = None
        self._at_frame = False  # the last step's drivers were this frame's (its joint rows of W are the pose's)
        self.steps = 0
        self._reach = np.where(lay.hits, lay.reach, -np.inf)  # a pair that does not collide is never inside

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
        self._driver_worlds(skinning, model)
        t = float(t)
        if self._t_last is None or t < self._t_last or t - self._t_last > MAX_GAP_S:
            self._start(t)
        else:
            self._at_frame = False
            span = t - self._t_last
            while self._t_sim + self.step_s <= t + 1e-9:
                alpha = 1.0 if span <= 0 else (self._t_sim + self.step_s - self._t_last) / span
                self._wd_lerp(min(max(alpha, 0.0), 1.0))
                self._step()
                self._t_sim += self.step_s
                self.steps += 1
            self._t_last = t
        self._wd_prev, self._wd_cur = self._wd_cur, self._wd_prev  # row 0 (the world) is the identity in both
        self._pose(skinning)
        return skinning

    def tails(self) -> np.ndarray:
        """The tails' positions (n_joints, 3) float64, world (the model matrix applied), after the last step,
        in the rig's joint order."""
        out = np.empty((self.rig.n_joints, 3))
        out[self._lay.order] = self._from_center(self._cur, np.empty_like(self._cur))
        return out

    # -- the parts of a frame ---------------------------------------------------------------------------------
    def _driver_worlds(self, skinning: np.ndarray, model: np.ndarray | None) -> None:
        """This frame's world transforms of the drivers (rows 1 .. of ``W``): model · skinning · rest."""
        cur = self._wd_cur
        cur[MODEL_ROW] = self._identity if model is None else model
        if len(self._drv):
            skinning.take(self._lay.driver_nodes, axis=0, out=self._drv32, mode="clip")
            self._drv[:] = self._drv32
            np.matmul(self._drv, self._lay.g_drivers, out=self._drv_rest)  # (in place would copy its input)
            np.matmul(cur[MODEL_ROW], self._drv_rest, out=cur[2:])
        m = cur[MODEL_ROW]  # rigid: the inverse is the transpose and the turned translation
        inv = self._inv_model
        inv[:3, :3] = m[:3, :3].T
        np.matmul(inv[:3, :3], m[:3, 3], out=inv[:3, 3])
        inv[:3, 3] *= -1.0

    def _wd_lerp(self, alpha: float) -> None:
        """The drivers at ``alpha`` between the last frame's and this frame's (``W``'s rows before the joints)."""
        w = self._w[:self._nj0]
        self._at_frame = alpha == 1.0  # a frame on the step grid: the step's joint frames are the frame's own
        if self._at_frame:
            w[:] = self._wd_cur
            return
        np.multiply(self._wd_prev, 1.0 - alpha, out=w)
        np.multiply(self._wd_cur, alpha, out=self._wd_tmp)
        w += self._wd_tmp

    def _start(self, t: float) -> None:
        """At rest in the current pose: tails where the pose puts them, no velocity."""
        self._at_frame = False
        self._w[:self._nj0] = self._wd_cur
        self._turn[:] = np.eye(3)
        self._turn4[:, :3, :3] = self._turn
        self._pose_frames()
        lay = self._lay
        joints = self._w[self._nj0:]
        tails = np.einsum("nij,nj->ni", joints[:, :3, :3], lay.axis * lay.length[:, None]) + joints[:, :3, 3]
        self._to_center(tails, self._cur)
        self._prev[:] = self._cur
        self._t_sim = self._t_last = t

    def _to_center(self, points: np.ndarray, out: np.ndarray) -> np.ndarray:
        if not self._has_center:
            out[:] = points
            return out
        self._w.take(self._lay.center_row, axis=0, out=self._centers, mode="clip")
        inv = np.linalg.inv(self._centers)
        _turn_rows(inv[:, :3, :3], points, out)
        out += inv[:, :3, 3]
        return out

    def _from_center(self, points: np.ndarray, out: np.ndarray) -> np.ndarray:
        if not self._has_center:
            out[:] = points
            return out
        self._w.take(self._lay.center_row, axis=0, out=self._centers, mode="clip")
        _turn_rows(self._centers[:, :3, :3], points, out)
        out += self._centers[:, :3, 3]
        return out

    @staticmethod
    def _dot(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Row dot products (n,) of ``a``, ``b`` (n, 3) into ``out``: one (1, 3) · (3, 1) product per row."""
        np.matmul(a[:, None, :], b[:, :, None], out=out[:, None, None])
        return out

    def _normalise_to(self, v: np.ndarray, length: np.ndarray | float, lens: np.ndarray) -> np.ndarray:
        """``v`` (n, 3) scaled in place to ``length``."""
        self._dot(v, v, lens)
        np.sqrt(lens, out=lens)
        np.maximum(lens, 1e-12, out=lens)
        np.divide(length, lens, out=lens)
        v *= lens[:, None]
        return v

    def _step(self) -> None:
        """One step of :data:`STEP_S` for every joint, level by level (the numbered steps of the module doc)."""
        lay, w, j0 = self._lay, self._w, self._nj0
        new, a3, b3 = self._new, self._a3, self._b3
        if self._has_center:
            self._from_center(self._cur, new)
            self._from_center(self._prev, a3)
            np.subtract(new, a3, out=a3)
            a3 *= lay.inertia
            new += a3  # 1: inertia
        else:
            np.subtract(self._cur, self._prev, out=a3)
            a3 *= lay.inertia
            np.add(self._cur, a3, out=new)  # 1: inertia
        if self.rig.n_colliders:
            w.take(lay.collider_row, axis=0, out=self._cw, mode="clip")
            np.matmul(self._cw, self._c_local, out=self._c_world)  # offset and tail as homogeneous columns
        for (s, e), hits in zip(lay.levels, self._level_hits):
            frame = self._frame[s:e]
            w.take(lay.anchor[s:e], axis=0, out=self._anchors[s:e], mode="clip")
            np.matmul(self._anchors[s:e], lay.rel_local[s:e], out=frame)  # the joint's frame, unturned
            head, rot = frame[:, :3, 3], frame[:, :3, :3]
            axis, nxt, d, lens = a3[s:e], new[s:e], b3[s:e], self._len[s:e]
            _turn_rows(rot, lay.axis[s:e], axis)
            self._normalise_to(axis, lay.push[s:e, 0], lens)  # (an interpolated frame is not rigid)
            nxt += axis  # 2: stiffness
            nxt += lay.gravity[s:e]  # 3: gravity
            np.subtract(nxt, head, out=d)
            np.add(head, self._normalise_to(d, lay.length[s:e], lens), out=nxt)  # 4: length
            if hits:
                self._collide(s, e, head)  # 5: collisions
            # 6: the turn taking the rest axis onto the new tail, in the joint's rest frame (``d``: the tail from the
            # head after 4 and 5)
            _turn_rows(rot.transpose(0, 2, 1), d, axis)
            self._normalise_to(axis, 1.0, lens)
            self._rotation_between(lay.axis[s:e], axis, self._turn[s:e])
            np.matmul(rot, self._turn[s:e], out=w[j0 + s:j0 + e, :3, :3])
            w[j0 + s:j0 + e, :3, 3] = head  # the bottom row stays (0, 0, 0, 1)
        if self._has_center:
            self._prev[:] = self._cur
            self._to_center(new, self._cur)
        else:  # the buffers turned round: previous <- current <- new, the old previous is the next new
            self._prev, self._cur, self._new = self._cur, self._new, self._prev

    def _collide(self, s: int, e: int, head: np.ndarray) -> None:
        """The level's tails pushed out of the colliders they hit, then put back at bone length."""
        lay, nxt = self._lay, self._new[s:e]
        rel, nc, depth = self._rel[s:e], self._nc[s:e], self._depth[s:e]
        np.subtract(nxt[:, None, :], self._c_start[None], out=rel)
        if self._any_capsule:  # from the closest point of a capsule's segment (a sphere: its centre)
            np.subtract(self._c_end, self._c_start, out=self._seg)
            self._dot(self._seg, self._seg, self._seg_sq)
            np.maximum(self._seg_sq, 1e-12, out=self._seg_sq)
            np.matmul(rel[:, :, None, :], self._seg[None, :, :, None], out=nc[:, :, None, None])
            nc /= self._seg_sq
            np.clip(nc, 0.0, 1.0, out=nc)
            nc *= self._capsule
            np.multiply(nc[:, :, None], self._seg[None], out=self._rel2[s:e])
            rel -= self._rel2[s:e]
        np.matmul(rel[:, :, None, :], rel[:, :, :, None], out=nc[:, :, None, None])
        np.sqrt(nc, out=nc)  # distances
        np.subtract(self._reach[s:e], nc, out=depth)
        np.maximum(depth, 0.0, out=depth)  # how far inside (0: outside, or a pair that does not collide)
        if not depth.any():
            return
        np.maximum(nc, 1e-12, out=nc)
        np.divide(depth, nc, out=depth)
        push = self._a3[s:e]
        np.matmul(depth[:, None, :], rel, out=push[:, None, :])
        nxt += push
        d = self._b3[s:e]
        np.subtract(nxt, head, out=d)
        np.add(head, self._normalise_to(d, lay.length[s:e], self._len[s:e]), out=nxt)

    def _rotation_between(self, a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
        """``out`` (n, 3, 3), contiguous: the rotations turning unit vectors ``a`` onto ``b`` (n, 3), Rodrigues'
        formula for unit vectors ``R = [v]x + c I + v vᵀ / (1 + c)`` with v = a × b, c = a · b.

        The cross product is ``[a]x`` times ``b``, and ``[v]x + c I`` flattened is ``(v, c)`` times the
        constant :data:`_SKEW_EYE` (4, 9): each term is one batched product, a dozen whole-array operations
        whatever the number of joints (a broadcast product would be buffered)."""
        n = len(a)
        skew, vc, k, vk = self._skew9[:n], self._vc[:n], self._k[:n], self._sq[:n]
        v, c = vc[:, :3], vc[:, 3]
        np.matmul(a, _SKEW_EYE[:3], out=skew)
        np.matmul(skew.reshape(n, 3, 3), b[:, :, None], out=v[:, :, None])  # v = a × b
        self._dot(a, b, c)
        np.add(c, 1.0, out=k)
        np.maximum(k, 1e-9, out=k)
        np.divide(1.0, k, out=k)
        np.matmul(k[:, None, None], v[:, None, :], out=vk[:, None, :])
        np.matmul(v[:, :, None], vk[:, None, :], out=out)  # v vᵀ / (1 + c)
        np.matmul(vc, _SKEW_EYE, out=skew)
        out.reshape(n, 9)[:] += skew  # + [v]x + c I

    def _pose_frames(self) -> None:
        """The joints' world frames at the frame's pose with the last step's turns (``W``'s joint rows)."""
        lay, w, j0 = self._lay, self._w, self._nj0
        for s, e in lay.levels:
            w.take(lay.anchor[s:e], axis=0, out=self._anchors[s:e], mode="clip")
            np.matmul(self._anchors[s:e], lay.rel_local[s:e], out=self._frame[s:e])
            np.matmul(self._frame[s:e], self._turn4[s:e], out=w[j0 + s:j0 + e])

    def _pose(self, skinning: np.ndarray) -> None:
        """The joints' skinning matrices at the frame's pose with the last step's turns: the roots of the chains
        stay on the head as it is now (the steps may be up to one step behind)."""
        lay = self._lay
        if not self._at_frame:
            self._w[:self._nj0] = self._wd_prev  # this frame's drivers (advance turned the buffers round)
            self._turn4[:, :3, :3] = self._turn
            self._pose_frames()
        np.matmul(self._w[self._nj0:], lay.g_inv, out=self._skin)
        np.matmul(self._inv_model, self._skin, out=self._skin2)
        self._skin32[:] = self._skin2
        skinning[lay.node] = self._skin32
        if len(lay.follow_nodes):
            skinning.take(lay.node[lay.follow_joint], axis=0, out=self._follow, mode="clip")
            skinning[lay.follow_nodes] = self._follow
