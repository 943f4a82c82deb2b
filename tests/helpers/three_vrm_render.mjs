// Renders a VRM with three.js + @pixiv/three-vrm (the reference VRM implementation) in headless
// Chromium at a camera given by the caller, with and without its MToon outlines.
// Input (stdin, JSON): {vrm, width, height, view[16], projection[16] (column-major), background[3]
// (display sRGB), key_dir[3], env_radiance, out_prefix, args[]}. Writes OUT_on.png and OUT_off.png.
import { chromium } from 'playwright-core';
import { readFileSync, writeFileSync } from 'node:fs';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const root = resolve(here, '..', '..');
const config = JSON.parse(readFileSync(0, 'utf8'));

const page_html = `<!doctype html><html><body style="margin:0">
<canvas id="c" width="${config.width}" height="${config.height}"></canvas>
<script type="importmap">{"imports": {"three": "/node_modules/three/build/three.module.js",
  "three/addons/": "/node_modules/three/examples/jsm/",
  "@pixiv/three-vrm": "/node_modules/@pixiv/three-vrm/lib/three-vrm.module.js"}}</script>
<script type="module">
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { VRMLoaderPlugin, VRMUtils } from '@pixiv/three-vrm';
window.renderVRM = async (cfg) => {
  const canvas = document.getElementById('c');
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setSize(cfg.width, cfg.height, false);
  renderer.setClearColor(new THREE.Color().setRGB(...cfg.background, THREE.SRGBColorSpace), 1);
  const loader = new GLTFLoader();
  loader.register((parser) => new VRMLoaderPlugin(parser));
  const gltf = await loader.loadAsync('/vrm/model.vrm');
  const vrm = gltf.userData.vrm;
  if (vrm.meta.metaVersion === '0') VRMUtils.rotateVRM0(vrm);
  const scene = new THREE.Scene();
  scene.add(vrm.scene);
  const light = new THREE.DirectionalLight(0xffffff, Math.PI);   // radiance 1, as facepuppet's key light
  light.position.set(...cfg.key_dir);
  scene.add(light);
  scene.add(light.target);
  const envScene = new THREE.Scene();
  envScene.background = new THREE.Color(cfg.env_radiance, cfg.env_radiance, cfg.env_radiance);
  const pmrem = new THREE.PMREMGenerator(renderer);
  scene.environment = pmrem.fromScene(envScene).texture;
  const camera = new THREE.PerspectiveCamera();
  camera.matrixAutoUpdate = false;
  const view = new THREE.Matrix4().fromArray(cfg.view);
  camera.matrix.copy(view).invert();
  camera.matrixWorld.copy(camera.matrix);
  camera.matrixWorldInverse.copy(view);
  camera.projectionMatrix.fromArray(cfg.projection);
  camera.projectionMatrixInverse.copy(camera.projectionMatrix).invert();
  vrm.scene.traverse((o) => { o.frustumCulled = false; });
  const shots = {};
  for (const outlines of [true, false]) {
    vrm.scene.traverse((o) => {
      if (Array.isArray(o.material)) o.material.forEach((m) => { if (m.isOutline) m.visible = outlines; });
    });
    renderer.render(scene, camera);
    shots[outlines ? 'on' : 'off'] = canvas.toDataURL('image/png');
  }
  return shots;
};
window.ready = true;
</script></body></html>`;

const browser = await chromium.launch({ executablePath: config.chromium, args: config.args });
try {
  const page = await browser.newPage();
  const errors = [];
  page.on('pageerror', (e) => errors.push(String(e)));
  page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
  await page.route('http://facepuppet.test/**', async (route) => {
    const path = new URL(route.request().url()).pathname;
    if (path === '/index.html') return route.fulfill({ body: page_html, contentType: 'text/html' });
    if (path === '/vrm/model.vrm') return route.fulfill({ path: config.vrm, contentType: 'model/gltf-binary' });
    if (path.startsWith('/node_modules/')) {
      return route.fulfill({ path: join(root, path), contentType: 'text/javascript' });
    }
    return route.fulfill({ status: 404, body: 'not found' });
  });
  await page.goto('http://facepuppet.test/index.html');
  await page.waitForFunction(() => window.ready === true, null, { timeout: 60000 });
  const shots = await page.evaluate((cfg) => window.renderVRM(cfg), config);
  for (const [k, url] of Object.entries(shots)) {
    writeFileSync(`${config.out_prefix}_${k}.png`, Buffer.from(url.split(',')[1], 'base64'));
  }
  if (errors.length) console.error(errors.join('\n'));
} finally {
  await browser.close();
}
