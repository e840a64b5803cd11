// The page: one or two exports (?a=DIR/&b=DIR/, side by side with their bytes and settings),
// shape, light, camera, display settings, frame time. `btfc view` serves it; the browser test
// (tests/viewer/browser_test.mjs) drives it through window.btfcViewer.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { loadExport, mipLevels, setMipLevel, uploadMips } from './export.js';
import { features, makeMaterial } from './material.js';
import { makeShape } from './shapes.js';

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const deg = Math.PI / 180;
// theta from +z, phi from +x towards +y (degrees), as btfc's --light / --view.
const dirOf = (th, ph) => new THREE.Vector3(Math.sin(th * deg) * Math.cos(ph * deg), Math.sin(th * deg) * Math.sin(ph * deg), Math.cos(th * deg));
const pair = (s, d) => (s ? s.split(',').map(Number) : d);

// Settings: the URL gives the start (so a test or a shared link reproduces a view), the controls
// change them.
const S = {
  mode: params.get('mode') || 'sphere',           // flat | rsphere (as btfc render) | plane | sphere | cloth
  tiles: Number(params.get('tiles') ?? 1),          // rsphere: btfc render's --tiles
  light: pair(params.get('light'), [45, 240]),     // theta, phi (degrees): in front, left of the camera
  view: pair(params.get('view'), [0, 0]),          // flat mode's view direction
  distance: Number(params.get('distance') ?? 0),   // 0: directional
  intensity: Number(params.get('intensity') ?? 1),
  exposure: Number(params.get('exposure') ?? 0),
  tonemap: params.get('tonemap') || 'reinhard',
  lightKind: params.get('lightkind') || 'light',   // light | env (lpca with --env)
  lod: Number(params.get('lod') ?? 0), autoLod: params.get('autolod') === '1',
  repeat: Number(params.get('repeat') ?? 3), bilinear: params.get('bilinear') === '1',  // bilinear: 4 x the cost
  zoom: Number(params.get('zoom') ?? 0),           // flat mode: CSS pixels per texel (0: fit)
  continuous: params.get('continuous') === '1',     // redraw every frame, not only on changes
  size: Number(params.get('size') ?? 512),         // mesh modes: canvas pixels (software GL: keep small)
};

const uniforms = {
  u_light: { value: new THREE.Vector3() }, u_distance: { value: 0 }, u_intensity: { value: 1 },
  u_exposure: { value: 0 }, u_tonemap: { value: 1 }, u_light_kind: { value: 0 }, u_lod: { value: 0 },
  u_auto_lod: { value: false }, u_view: { value: new THREE.Vector3(0, 0, 1) }, u_camera: { value: new THREE.Vector3() },
  u_size: { value: new THREE.Vector2(1, 1) }, u_bilinear: { value: true }, u_canvas: { value: 512 }, u_tiles: { value: 1 },
};

const camera = new THREE.PerspectiveCamera(35, 1, 0.01, 100);
camera.up.set(0, 0, 1);                  // z up: the sample's normal, as in btfc render
camera.position.set(0, -3.6, 2.6);
const panels = [];
let controls = null;

function errorPanel(el, msg) {
  el.querySelector('.error').textContent = msg;
  el.querySelector('.error').hidden = false;
  el.classList.add('failed');
}

function describe(exp) {
  const m = exp.manifest, b = m.bytes || {};
  const kb = (x) => (x === undefined ? '?' : `${(x / 1024).toFixed(1)} KiB`);
  const rows = [
    ['codec', m.codec], ['settings', m.spec], ['BTF', `${m.btf.width} x ${m.btf.height} texels, ${m.btf.lights.length} lights x ${m.btf.views.length} views`],
    ['texture bytes', `${kb(b.textures)} in ${m.textures.length} KTX2 files`], ['model payload', kb(b.model_payload)],
  ];
  const chains = Object.entries(exp.textures).filter(([, t]) => t.userData.levels > 1).map(([n, t]) => `${n}: ${t.userData.levels} mip levels`);
  if (chains.length) rows.push(['level of detail', chains.join(', ')]);
  if (m.warnings && m.warnings.length) rows.push(['warnings', m.warnings.join('; ')]);
  return rows.map(([k, v]) => `<tr><th>${k}</th><td>${String(v).replace(/[<&]/g, (c) => `&#${c.charCodeAt(0)};`)}</td></tr>`).join('');
}

async function openPanel(url, el) {
  const p = { url, el, exp: null, renderer: null, scene: null, mesh: null, mats: null, error: null };
  el.querySelector('.title').textContent = url;
  try {
    p.exp = await loadExport(url);
    el.querySelector('.info').innerHTML = describe(p.exp);
    const canvas = el.querySelector('canvas');
    p.renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
    p.renderer.setPixelRatio(1);  // flat mode: one canvas pixel per texel, whatever the screen
    p.renderer.setClearColor(0x303034);  // unlit parts of a mesh are black: keep them visible
    // A shader that does not compile is an export problem the user must see, not a blank canvas.
    p.renderer.debug.onShaderError = (gl, prog, vs, fs) => {
      const log = gl.getShaderInfoLog(fs) || gl.getShaderInfoLog(vs) || gl.getProgramInfoLog(prog);
      p.error = `btf.frag does not compile with the viewer's main(): ${log}`;
    };
    // Every mip level on the GPU; a codec whose chains cover its texel data (fmf) gets their
    // levels as its level of detail (lpyr has its own, in btf_eval_lod).
    p.levels = uploadMips(p.renderer, p.exp);
    p.mipLevels = features(p.exp.glsl).lod ? 1 : mipLevels(p.exp);
    p.exp.mipUv = { value: new THREE.Vector2(1, 1) };
    p.mats = { flat: makeMaterial(p.exp, 'flat', uniforms), rsphere: makeMaterial(p.exp, 'rsphere', uniforms),
      mesh: makeMaterial(p.exp, 'mesh', uniforms) };
    p.scene = new THREE.Scene();
    p.lightMarker = new THREE.Mesh(new THREE.SphereGeometry(0.04, 12, 8), new THREE.MeshBasicMaterial({ color: 0xffdd55 }));
    p.flatQuad = new THREE.Mesh(new THREE.PlaneGeometry(2, 2), p.mats.flat);
    p.flatQuad.frustumCulled = false;
    p.flatScene = new THREE.Scene().add(p.flatQuad);
    p.flatCamera = new THREE.OrthographicCamera(-1, 1, 1, -1, 0, 1);
    p.scene.add(p.lightMarker);
  } catch (e) {
    p.error = e.message;
  }
  if (p.error) errorPanel(el, p.error);
  panels.push(p);
  return p;
}

// Pushes S into the uniforms, meshes and canvas sizes.
function apply() {
  const live = panels.filter((p) => !p.error);
  uniforms.u_light.value.copy(dirOf(S.light[0], S.light[1]));
  uniforms.u_view.value.copy(dirOf(S.view[0], S.view[1]));
  uniforms.u_distance.value = S.distance;
  uniforms.u_intensity.value = S.intensity;
  uniforms.u_exposure.value = S.exposure;
  uniforms.u_tonemap.value = S.tonemap === 'reinhard' ? 1 : 0;
  uniforms.u_light_kind.value = S.lightKind === 'env' ? 1 : 0;
  uniforms.u_lod.value = S.lod;
  uniforms.u_auto_lod.value = S.autoLod;
  uniforms.u_bilinear.value = S.bilinear;
  uniforms.u_canvas.value = S.size;
  uniforms.u_tiles.value = S.tiles;
  const flat = S.mode === 'flat';
  for (const p of live) {
    p.flatQuad.material = S.mode === 'rsphere' ? p.mats.rsphere : p.mats.flat;
    const btf = p.exp.manifest.btf;
    const canvas = p.renderer.domElement;
    if (flat) {
      // The drawing buffer is the BTF's size; CSS scales it up without filtering.
      const z = S.zoom > 0 ? S.zoom : Math.max(1, Math.floor(512 / Math.max(btf.width, btf.height)));
      p.renderer.setSize(btf.width, btf.height, false);
      canvas.style.width = `${btf.width * z}px`;
      canvas.style.height = `${btf.height * z}px`;
    } else if (S.mode === 'rsphere') {
      p.renderer.setSize(S.size, S.size, false);
      canvas.style.width = canvas.style.height = `${S.size}px`;
    } else {
      p.renderer.setSize(S.size, S.size, false);
      canvas.style.width = canvas.style.height = `${S.size}px`;
      if (p.mesh?.userData.shape !== `${S.mode}:${S.repeat}`) {
        if (p.mesh) p.scene.remove(p.mesh), p.mesh.geometry.dispose();
        p.mesh = new THREE.Mesh(makeShape(S.mode, S.repeat), p.mats.mesh);
        p.mesh.userData.shape = `${S.mode}:${S.repeat}`;
        p.scene.add(p.mesh);
      }
    }
    if (p.mipLevels > 1) {
      p.mipLevel = Math.min(p.mipLevels - 1, Math.max(0, Math.round(S.lod)));
      p.exp.mipUv.value.set(...setMipLevel(p.exp, p.mipLevel));
    }
    const d = S.distance > 0 ? S.distance : 1.8;  // a directional light's marker: its direction
    p.lightMarker.position.copy(uniforms.u_light.value).multiplyScalar(d);
    p.lightMarker.visible = S.lightKind !== 'env';
  }
  camera.aspect = 1;
  camera.updateProjectionMatrix();
}

function renderPanel(p) {
  const btf = p.exp.manifest.btf;
  uniforms.u_size.value.set(btf.width, btf.height);
  if (S.mode === 'flat' || S.mode === 'rsphere') {
    p.renderer.render(p.flatScene, p.flatCamera);
  } else {
    uniforms.u_camera.value.copy(camera.position);
    p.renderer.render(p.scene, camera);
  }
}

function renderAll() {
  for (const p of panels) if (!p.error) renderPanel(p);
  for (const p of panels) if (p.error && !p.el.classList.contains('failed')) errorPanel(p.el, p.error);
}

// Frames are drawn when something changed (on software GL one frame can take seconds, and a
// loop drawing every frame would starve the controls), or every frame with "continuous".
// Frame time: each frame finished by a 1-pixel read-back, so it is the GPU's time, not the
// time to queue the commands; averaged over the last frames.
let dirty = true, avg = 0;
const invalidate = () => { dirty = true; };
function loop() {
  if (dirty || S.continuous) {
    dirty = false;
    const t0 = performance.now();
    renderAll();
    const px = new Uint8Array(4);
    for (const p of panels.filter((q) => !q.error)) {
      const gl = p.renderer.getContext();
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
    }
    const ms = performance.now() - t0;
    avg = avg ? 0.8 * avg + 0.2 * ms : ms;
    $('frametime').textContent = `${avg.toFixed(1)} ms / frame (${(1000 / avg).toFixed(0)} fps)`;
  }
  requestAnimationFrame(loop);
}

// Controls: every input is bound to one key of S.
function bindControls() {
  const bind = (id, key, conv = Number) => {
    const el = $(id);
    const get = () => (key.includes('.') ? S[key.split('.')[0]][Number(key.split('.')[1])] : S[key]);
    const v = get();
    if (el.type === 'checkbox') el.checked = Boolean(v); else el.value = v;
    el.addEventListener('input', () => {
      const val = el.type === 'checkbox' ? el.checked : conv(el.value);
      if (key.includes('.')) S[key.split('.')[0]][Number(key.split('.')[1])] = val; else S[key] = val;
      apply();
      invalidate();
    });
  };
  bind('mode', 'mode', String); bind('lighttheta', 'light.0'); bind('lightphi', 'light.1');
  bind('distance', 'distance'); bind('intensity', 'intensity'); bind('exposure', 'exposure');
  bind('tonemap', 'tonemap', String); bind('lightkind', 'lightKind', String); bind('lod', 'lod');
  bind('autolod', 'autoLod'); bind('repeat', 'repeat'); bind('bilinear', 'bilinear');
  bind('viewtheta', 'view.0'); bind('viewphi', 'view.1'); bind('continuous', 'continuous'); bind('tiles', 'tiles');
  const live = panels.filter((p) => !p.error);
  const f = live.map((p) => features(p.exp.glsl));
  $('lodrow').hidden = !f.some((x) => x.lod) && !live.some((p) => p.mipLevels > 1);
  // The slider spans the coarsest level any panel has (lpyr's manifest: evaluation.lmax; a mip
  // chain: its last level, shown at the nearest whole level).
  $('lod').max = Math.max(0, ...live.map((p) => Math.max(p.exp.manifest.evaluation?.lmax ?? 0, p.mipLevels - 1)));
  $('envopt').disabled = !f.some((x) => x.relit);
  // Dragging with Shift (or the right button) moves the light over the hemisphere instead of
  // orbiting: horizontal = phi, vertical = theta.
  const wrap = $('panels');
  let drag = null;
  wrap.addEventListener('pointerdown', (e) => {
    if (!(e.shiftKey || e.button === 2)) return;
    drag = { x: e.clientX, y: e.clientY, th: S.light[0], ph: S.light[1] };
    controls.enabled = false;
    wrap.setPointerCapture(e.pointerId);
    e.preventDefault();
  });
  wrap.addEventListener('pointermove', (e) => {
    if (!drag) return;
    S.light[1] = (((drag.ph - (e.clientX - drag.x) * 0.5) % 360) + 360) % 360;
    S.light[0] = Math.min(89, Math.max(0, drag.th + (e.clientY - drag.y) * 0.3));
    $('lighttheta').value = S.light[0].toFixed(0); $('lightphi').value = S.light[1].toFixed(0);
    apply();
    invalidate();
  });
  wrap.addEventListener('pointerup', () => { drag = null; controls.enabled = true; });
  wrap.addEventListener('contextmenu', (e) => e.preventDefault());
}

async function main() {
  document.body.dataset.state = 'loading';
  const urls = [params.get('a') || 'a/', params.get('b')].filter(Boolean);
  if (urls.length > 1) $('panel1').hidden = false;
  await Promise.all(urls.map((u, i) => openPanel(u, $(`panel${i}`))));
  panels.sort((x, y) => urls.indexOf(x.url) - urls.indexOf(y.url));
  controls = new OrbitControls(camera, $('panels'));
  controls.mouseButtons.RIGHT = null;  // the right button drags the light
  controls.addEventListener('change', invalidate);
  bindControls();
  apply();
  renderAll();  // compiles the shaders now, so a compile error is reported before "ready"
  const failed = panels.filter((p) => p.error);
  document.body.dataset.state = failed.length ? 'error' : 'ready';
  requestAnimationFrame(loop);
}

// Hooks for tests and scripts (tests/viewer/browser_test.mjs).
window.btfcViewer = {
  settings: S,
  set(changes) { Object.assign(S, changes); apply(); renderAll(); invalidate(); },
  errors: () => panels.filter((p) => p.error).map((p) => `${p.url}: ${p.error}`),
  // Per panel: the levels each texture holds on the GPU, the mip levels of detail, the one shown.
  levels: () => panels.filter((p) => !p.error).map((p) => ({ textures: p.levels, mipLevels: p.mipLevels, shown: p.mipLevel ?? 0 })),
  // Milliseconds per frame over n frames, each finished (a 1-pixel read-back waits for the GPU).
  measure(n = 20) {
    const px = new Uint8Array(4);
    const live = panels.filter((p) => !p.error);
    const t0 = performance.now();
    for (let i = 0; i < n; ++i)
      for (const p of live) {
        renderPanel(p);
        const gl = p.renderer.getContext();
        gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
      }
    return (performance.now() - t0) / n;
  },
};
main().catch((e) => {
  document.body.dataset.state = 'error';
  $('fatal').textContent = e.message;
  $('fatal').hidden = false;
});
