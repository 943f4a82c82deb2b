// three-vrm's spring bones (VRMSpringBoneManager, @pixiv/three-vrm) on a node hierarchy given as JSON, in node,
// no browser: the reference the Python simulation is compared with (tests/runtime/render/test_springs_three_vrm.py).
//
// Input (argv[2], JSON): nodes [{parent, matrix (16, column-major local rest)}], colliders [{node, shape, offset,
// tail, radius}], joints [{node, tail_node (-1: virtual tail), stiffness, drag, gravity_power, gravity_dir,
// hit_radius, center (-1: none), colliders [index]}], frames [{node index: local matrix (16)}] (the posed locals
// of the nodes a frame moves), dt (seconds per frame).
// Output (stdout, JSON): {"tails": [frame][joint][x, y, z], "heads": [frame][joint][x, y, z]}, the joints' tails
// and their bones' own positions in world space after each frame.
import { readFileSync } from "node:fs";
import * as THREE from "three";
import {
  VRMSpringBoneCollider,
  VRMSpringBoneColliderShapeCapsule,
  VRMSpringBoneColliderShapeSphere,
  VRMSpringBoneJoint,
  VRMSpringBoneManager,
} from "@pixiv/three-vrm";

const input = JSON.parse(readFileSync(process.argv[2], "utf8"));
const scene = new THREE.Scene();
const nodes = input.nodes.map((n) => {
  const o = new THREE.Object3D();
  new THREE.Matrix4().fromArray(n.matrix).decompose(o.position, o.quaternion, o.scale);
  return o;
});
input.nodes.forEach((n, i) => (n.parent >= 0 ? nodes[n.parent] : scene).add(nodes[i]));
scene.updateMatrixWorld(true);

const colliders = input.colliders.map((c) => {
  const offset = new THREE.Vector3().fromArray(c.offset);
  const shape = c.shape === "capsule"
    ? new VRMSpringBoneColliderShapeCapsule({ offset, tail: new THREE.Vector3().fromArray(c.tail), radius: c.radius })
    : new VRMSpringBoneColliderShapeSphere({ offset, radius: c.radius });
  const collider = new VRMSpringBoneCollider(shape);
  nodes[c.node].add(collider);
  return collider;
});
scene.updateMatrixWorld(true);

const manager = new VRMSpringBoneManager();
const joints = input.joints.map((j) => {
  const groups = j.colliders.length ? [{ colliders: j.colliders.map((k) => colliders[k]) }] : [];
  const joint = new VRMSpringBoneJoint(nodes[j.node], j.tail_node >= 0 ? nodes[j.tail_node] : null, {
    stiffness: j.stiffness,
    dragForce: j.drag,
    gravityPower: j.gravity_power,
    gravityDir: new THREE.Vector3().fromArray(j.gravity_dir),
    hitRadius: j.hit_radius,
  }, groups);
  if (j.center >= 0) joint.center = nodes[j.center];
  manager.addJoint(joint);
  return joint;
});
manager.setInitState();

const tails = [];
const heads = [];
const world = new THREE.Vector3();
for (const frame of input.frames) {
  for (const [index, matrix] of Object.entries(frame)) {
    const o = nodes[Number(index)];
    new THREE.Matrix4().fromArray(matrix).decompose(o.position, o.quaternion, o.scale);
  }
  scene.updateMatrixWorld(true);
  manager.update(input.dt);
  tails.push(joints.map((j) => {
    world.copy(j._currentTail);
    if (j.center) world.applyMatrix4(j.center.matrixWorld);
    return [world.x, world.y, world.z];
  }));
  heads.push(joints.map((j) => {
    world.setFromMatrixPosition(j.bone.matrixWorld);
    return [world.x, world.y, world.z];
  }));
}
process.stdout.write(JSON.stringify({ tails, heads }));
