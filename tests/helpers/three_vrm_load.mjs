// Loads each VRM named on the command line with three.js's GLTFLoader and @pixiv/three-vrm's VRMLoaderPlugin
// (the reference VRM implementation) in node, and prints one JSON line per file with what three-vrm found:
// spring-bone joints and colliders, the look-at type and range maps, the first-person annotations, the MToon
// materials with their outline and rim, the expressions' material binds, the meta, and each MToon material's
// colour and texture offset with the "sad" expression at full weight.
// Node has no DOM: a GLTFLoader plugin hands three-vrm an empty texture for every glTF texture (no image is
// decoded; nothing here looks at texels), which is all that needs a browser.
import fs from "node:fs";
import path from "node:path";
import * as THREE from "three";
import { GLTFLoader } from "three/examples/jsm/loaders/GLTFLoader.js";
import { VRMLoaderPlugin, VRMUtils } from "@pixiv/three-vrm";

class NoImages {
  constructor(parser) { this.parser = parser; this.name = "facepuppet_tests_no_images"; }
  loadTexture() { return Promise.resolve(new THREE.Texture()); }
}

const round = (v) => Math.round(v * 1e6) / 1e6;

// The spring joints' world rotations after one scripted head motion: the avatar turned to face +Z
// (VRMUtils.rotateVRM0 for a VRM 0.x), the head yawed 0.6 rad and back over 0.5 s at 60 frames/s, then 0.25 s
// of hold; each joint bone's world quaternion (x, y, z, w) by bone name, at rest and after the motion.
function swing(vrm) {
  if (!vrm.springBoneManager || !vrm.humanoid) return null;
  if (vrm.meta && vrm.meta.metaVersion === "0") VRMUtils.rotateVRM0(vrm);
  vrm.scene.updateMatrixWorld(true);
  vrm.springBoneManager.setInitState();
  const head = vrm.humanoid.getNormalizedBoneNode("head");
  const q = new THREE.Quaternion();
  const pose = () => {
    const out = {};
    for (const j of vrm.springBoneManager.joints) {
      j.bone.getWorldQuaternion(q);
      out[j.bone.name] = [round(q.x), round(q.y), round(q.z), round(q.w)];
    }
    return out;
  };
  vrm.update(1 / 60);
  const rest = pose();
  for (let f = 0; f < 45; f++) {
    const t = f / 60;
    head.rotation.set(0, t < 0.5 ? 0.6 * Math.sin(Math.PI * t / 0.5) : 0, 0);
    head.position.set(0, 0, 0);
    vrm.update(1 / 60);
  }
  return { rest, moved: pose() };
}
const vec = (v) => [round(v.x), round(v.y), round(v.z)];

for (const file of process.argv.slice(2)) {
  const bytes = fs.readFileSync(file);
  const buffer = bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
  const loader = new GLTFLoader();
  loader.register((parser) => new NoImages(parser));
  loader.register((parser) => new VRMLoaderPlugin(parser));
  const warnings = [];
  const warn = console.warn;
  console.warn = (...a) => warnings.push(a.map(String).join(" "));
  const gltf = await new Promise((resolve, reject) => loader.parse(buffer, path.dirname(file) + "/", resolve, reject));
  console.warn = warn;
  const vrm = gltf.userData.vrm;
  const out = { file, warnings, vrm: vrm != null };
  if (vrm) {
    const sb = vrm.springBoneManager;
    out.joints = sb ? [...sb.joints].map((j) => ({ bone: j.bone.name, child: j.child ? j.child.name : null,
                                                     stiffness: round(j.settings.stiffness),
                                                     dragForce: round(j.settings.dragForce),
                                                     hitRadius: round(j.settings.hitRadius),
                                                     gravityPower: round(j.settings.gravityPower),
                                                     gravityDir: vec(j.settings.gravityDir),
                                                     colliderGroups: j.colliderGroups.length })) : [];
    out.colliders = sb ? [...sb.colliders].map((c) => ({ node: c.parent ? c.parent.name : null,
                                                         type: c.shape.type, radius: round(c.shape.radius),
                                                         offset: vec(c.shape.offset) })) : [];
    const la = vrm.lookAt;
    out.lookAt = la ? { applier: la.applier.constructor.type ?? la.applier.type ?? null,
                        offsetFromHeadBone: vec(la.offsetFromHeadBone),
                        ranges: ["rangeMapHorizontalInner", "rangeMapHorizontalOuter", "rangeMapVerticalDown",
                                 "rangeMapVerticalUp"].map((k) => la.applier[k]
                                   ? [round(la.applier[k].inputMaxValue), round(la.applier[k].outputScale)] : null) }
                    : null;
    out.firstPerson = vrm.firstPerson ? vrm.firstPerson.meshAnnotations.map((a) => a.type) : null;
    const mtoon = new Map();
    gltf.scene.traverse((o) => {
      const mats = o.material ? (Array.isArray(o.material) ? o.material : [o.material]) : [];
      for (const m of mats) {
        if (m.isMToonMaterial && !m.isOutline) {
          mtoon.set(m.name, { outlineWidthMode: m.outlineWidthMode, outlineWidthFactor: round(m.outlineWidthFactor),
                              outlineLightingMixFactor: round(m.outlineLightingMixFactor),
                              outlineColorFactor: [round(m.outlineColorFactor.r), round(m.outlineColorFactor.g),
                                                   round(m.outlineColorFactor.b)],
                              parametricRimFresnelPowerFactor: round(m.parametricRimFresnelPowerFactor),
                              rimLightingMixFactor: round(m.rimLightingMixFactor),
                              giEqualizationFactor: round(m.giEqualizationFactor) });
        }
      }
    });
    out.mtoon = Object.fromEntries(mtoon);
    out.expressionMaterialBinds = {};
    for (const e of vrm.expressionManager ? vrm.expressionManager.expressions : []) {
      const kinds = e.binds.map((b) => b.constructor.name).filter((n) => n !== "VRMExpressionMorphTargetBind");
      if (kinds.length) out.expressionMaterialBinds[e.expressionName] = kinds;
    }
    out.meta = vrm.meta;
    out.swing = swing(vrm);
    // what three-vrm draws with "sad" at full weight: each MToon material's colour and base texture offset
    out.sad = null;
    if (vrm.expressionManager && vrm.expressionManager.getExpression("sad")) {
      vrm.expressionManager.setValue("sad", 1.0);
      vrm.update(1 / 60);
      out.sad = {};
      gltf.scene.traverse((o) => {
        const mats = o.material ? (Array.isArray(o.material) ? o.material : [o.material]) : [];
        for (const m of mats) {
          if (m.isMToonMaterial && !m.isOutline && m.color) {
            out.sad[m.name] = { color: [round(m.color.r), round(m.color.g), round(m.color.b)],
                                mapOffset: m.map ? [round(m.map.offset.x), round(m.map.offset.y)] : null };
          }
        }
      });
    }
  }
  console.log(JSON.stringify(out));
}
