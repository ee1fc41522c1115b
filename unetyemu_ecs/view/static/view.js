// The unetyemu web view: the city, the vehicles, LiDAR points and camera images, from one WebSocket.
//
// Plain ES module (no framework, no bundler); three.js and its addons are vendored under vendor/
// and resolved by the import map in index.html. The wire protocol is described in
// unetyemu_ecs/view/wire.py. The world is ENU (x east, y north, z up): the scene keeps those axes
// and sets z as "up" for the camera and the orbit controls. Frames are drawn on demand (a new state,
// a camera move), not continuously, so an idle page costs little.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { CSS2DObject, CSS2DRenderer } from 'three/addons/renderers/CSS2DRenderer.js';

THREE.Object3D.DEFAULT_UP.set(0, 0, 1);

const SKY = new THREE.Color().setRGB(0.62, 0.76, 0.92, THREE.SRGBColorSpace);
const SUN_DIR = new THREE.Vector3(0.35, -0.45, 0.82).normalize();
const DRONE_SCALE = 4;               // drones are drawn this much larger unless "true scale" is ticked
const LIDAR_Z_RANGE_M = [0, 60];     // point colours run from blue (low) to yellow (high) over this height

const $ = (id) => document.getElementById(id);

// -- what the page knows (window.unetyemuView.state() returns a copy) ---------------------------
const view = {
  connected: false, mode: null, world: null, sceneLoaded: false, meshTriangles: 0,
  messages: 0, states: 0, lidarFrames: 0, lidarPoints: 0, images: 0, imageVehicle: null, renders: 0, renderMs: null,
  simTime: null, rtf: null, replay: null, selected: null, follow: false, badMessages: 0, glRenderer: null,
};
const vehicles = new Map();          // name -> {look, group, label, card, stalk, state}
const clouds = new Map();            // vehicle name -> THREE.Points

// -- three.js scene ---------------------------------------------------------------------------
const viewport = $('viewport');
// A software rasteriser (SwiftShader: no GPU, a VM, a headless browser) draws every pixel on the CPU
// the simulation needs: then no multisampling and at most one pixel per CSS pixel.
const software = /swiftshader|llvmpipe|software/i.test(glRendererName());
const renderer = new THREE.WebGLRenderer({ antialias: !software });
view.glRenderer = software ? 'software' : 'gpu';
renderer.setPixelRatio(software ? 1 : Math.min(window.devicePixelRatio || 1, 2));
viewport.appendChild(renderer.domElement);
const labelRenderer = new CSS2DRenderer();
labelRenderer.domElement.className = 'labels';
viewport.appendChild(labelRenderer.domElement);

const scene = new THREE.Scene();
scene.background = SKY;
scene.add(new THREE.HemisphereLight(0xffffff, 0x6b705c, 1.8));
const sun = new THREE.DirectionalLight(0xffffff, 1.6);
sun.position.copy(SUN_DIR).multiplyScalar(1000);
scene.add(sun);

const camera = new THREE.PerspectiveCamera(50, 1, 0.3, 8000);
const controls = new OrbitControls(camera, renderer.domElement);
controls.enableDamping = false;
controls.addEventListener('change', requestRender);

const world = new THREE.Group();     // the city and the ground, replaced on every scene message
scene.add(world);
let bounds = [[-100, -100, 0], [100, 100, 10]];

function glRendererName() {
  const gl = document.createElement('canvas').getContext('webgl2');
  if (!gl) return '';
  const info = gl.getExtension('WEBGL_debug_renderer_info');
  const name = String(gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
  const lose = gl.getExtension('WEBGL_lose_context');
  if (lose) lose.loseContext();
  return name;
}

const MIN_FRAME_MS = software ? 100 : 0;     // a software rasteriser draws at most 10 frames a second
const PANEL_MS = 200;                          // the side panel's text changes at most 5 times a second
let renderPending = false;
let lastRenderMs = -Infinity;
function requestRender() {
  if (renderPending) return;
  renderPending = true;
  const wait = lastRenderMs + MIN_FRAME_MS - performance.now();
  if (wait > 0) setTimeout(() => requestAnimationFrame(render), wait);
  else requestAnimationFrame(render);
}

function render() {
  renderPending = false;
  lastRenderMs = performance.now();
  followSelected();
  // near plane by distance: close-ups of a drone, and no depth flicker when the whole city is in view
  const near = THREE.MathUtils.clamp(camera.position.distanceTo(controls.target) * 0.005, 0.05, 5);
  if (Math.abs(near - camera.near) > 1e-3) { camera.near = near; camera.updateProjectionMatrix(); }
  const t0 = performance.now();
  renderer.render(scene, camera);
  labelRenderer.render(scene, camera);
  view.renderMs = performance.now() - t0;
  view.renders += 1;
}

function resize() {
  const w = viewport.clientWidth || 1, h = viewport.clientHeight || 1;
  renderer.setSize(w, h);
  labelRenderer.setSize(w, h);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
  requestRender();
}
new ResizeObserver(resize).observe(viewport);

function homeCamera() {
  const [lo, hi] = bounds;
  const cx = (lo[0] + hi[0]) / 2, cy = (lo[1] + hi[1]) / 2;
  const size = Math.max(hi[0] - lo[0], hi[1] - lo[1], 50);
  controls.target.set(cx, cy, 0);
  camera.position.set(cx - 0.35 * size, cy - 0.85 * size, 0.65 * size);
  controls.update();
  requestRender();
}

// sRGB byte -> linear float (vertex colours are given in sRGB, three.js lights in linear)
const SRGB_TO_LINEAR = new Float32Array(256);
for (let i = 0; i < 256; i++) {
  const c = i / 255;
  SRGB_TO_LINEAR[i] = c <= 0.04045 ? c / 12.92 : Math.pow((c + 0.055) / 1.055, 2.4);
}

function disposeTree(obj) {
  obj.traverse((o) => {
    if (o.geometry) o.geometry.dispose();
    if (o.material) o.material.dispose();
  });
}

// -- messages ---------------------------------------------------------------------------------
function onScene(msg) {
  for (const v of vehicles.values()) removeVehicle(v);
  vehicles.clear();
  for (const c of clouds.values()) { scene.remove(c); disposeTree(c); }
  clouds.clear();
  for (const child of [...world.children]) { world.remove(child); disposeTree(child); }
  $('vehicles').replaceChildren();
  view.mode = msg.mode;
  view.world = msg.world;
  view.sceneLoaded = false;
  bounds = msg.bounds_m;
  $('world').textContent = msg.world;
  $('mode').textContent = msg.mode;
  $('mode').className = `badge ${msg.mode}`;
  $('player').hidden = msg.mode !== 'replay';
  $('note').hidden = !msg.note;
  $('note').textContent = msg.note || '';
  addGround(msg.ground_rgb);
  for (const look of msg.vehicles) addVehicle(look);
  if (view.selected === null || !vehicles.has(view.selected)) {
    const withSensor = msg.vehicles.find((v) => v.sensors.length) || msg.vehicles[0];
    select(withSensor ? withSensor.name : null);
  } else {
    select(view.selected);
  }
  sendLidarMode();
  homeCamera();
}

function addGround(rgb) {
  const [lo, hi] = bounds;
  const size = 3 * Math.max(hi[0] - lo[0], hi[1] - lo[1], 100);
  const ground = new THREE.Mesh(new THREE.PlaneGeometry(size, size),
    new THREE.MeshLambertMaterial({ color: new THREE.Color().setRGB(...rgb, THREE.SRGBColorSpace) }));
  ground.position.set((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, -0.05);
  world.add(ground);
}

function onMesh(header, buf, offset) {
  const nv = header.vertices, nt = header.triangles;
  const verts = new Float32Array(buf, offset, nv * 3);
  const idx = new Uint32Array(buf, offset + nv * 12, nt * 3);
  const rgb = new Uint8Array(buf, offset + nv * 12 + nt * 12, nt * 3);
  // flat shading: one vertex per triangle corner, the triangle's colour at each
  const pos = new Float32Array(nt * 9), col = new Float32Array(nt * 9);
  for (let t = 0; t < nt; t++) {
    const r = SRGB_TO_LINEAR[rgb[3 * t]], g = SRGB_TO_LINEAR[rgb[3 * t + 1]], b = SRGB_TO_LINEAR[rgb[3 * t + 2]];
    for (let k = 0; k < 3; k++) {
      const v = idx[3 * t + k] * 3, o = 9 * t + 3 * k;
      pos[o] = verts[v]; pos[o + 1] = verts[v + 1]; pos[o + 2] = verts[v + 2];
      col[o] = r; col[o + 1] = g; col[o + 2] = b;
    }
  }
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(pos, 3));
  geometry.setAttribute('color', new THREE.BufferAttribute(col, 3));
  geometry.computeVertexNormals();
  const city = new THREE.Mesh(geometry, new THREE.MeshLambertMaterial({ vertexColors: true }));
  city.name = 'city';
  world.add(city);
  view.meshTriangles = nt;
  view.sceneLoaded = true;
  requestRender();
}

let lastPanelMs = -Infinity;
function onState(msg) {
  view.states += 1;
  view.simTime = msg.t;
  view.rtf = msg.rtf;
  view.replay = msg.replay || null;
  $('simtime').textContent = msg.t === null ? 't –' : `t ${msg.t.toFixed(2)} s`;
  $('rtf').textContent = msg.rtf === null ? 'RTF –' : `RTF ${msg.rtf.toFixed(2)}×`;
  for (const s of msg.vehicles) {
    let v = vehicles.get(s.name);
    if (!v) v = addVehicle({ name: s.name, kind: 'vehicle', rgb: [0.8, 0.8, 0.8], half_extents_m: [0.5, 0.5, 0.5], sensors: [] });
    v.state = s;
    if (s.p.every((x) => x !== null)) v.group.position.set(s.p[0], s.p[1], s.p[2]);
    if (s.q.every((x) => x !== null)) v.group.quaternion.set(s.q[0], s.q[1], s.q[2], s.q[3]);
    if (v.stalk) {
      const a = v.stalk.geometry.attributes.position;
      a.setXYZ(0, v.group.position.x, v.group.position.y, v.group.position.z);
      a.setXYZ(1, v.group.position.x, v.group.position.y, 0);
      a.needsUpdate = true;
      v.stalk.geometry.computeBoundingSphere();
    }
  }
  const now = performance.now();
  if (now - lastPanelMs < PANEL_MS) {
    requestRender();
    return;
  }
  lastPanelMs = now;
  for (const v of vehicles.values()) if (v.state) updateCard(v);
  const events = $('events');
  const items = msg.events.map(([t, who, text]) => {
    const li = document.createElement('li');
    li.textContent = `${t === null ? '' : t.toFixed(1)} s ${who ? who + ': ' : ''}${text}`;
    return li;
  });
  events.replaceChildren(...items.reverse());
  if (msg.replay) updatePlayer(msg.replay, msg.t);
  requestRender();
}

function onLidar(header, buf, offset) {
  view.lidarFrames += 1;
  view.lidarPoints = header.points;
  const pts = new Float32Array(buf, offset, header.points * 3);
  let cloud = clouds.get(header.vehicle);
  if (!cloud || cloud.userData.capacity < header.points) {
    if (cloud) { scene.remove(cloud); disposeTree(cloud); }
    const capacity = Math.max(1024, Math.ceil(header.points * 1.25));
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(capacity * 3), 3).setUsage(THREE.DynamicDrawUsage));
    geometry.setAttribute('color', new THREE.BufferAttribute(new Float32Array(capacity * 3), 3).setUsage(THREE.DynamicDrawUsage));
    cloud = new THREE.Points(geometry, new THREE.PointsMaterial({ size: 2, sizeAttenuation: false, vertexColors: true }));
    cloud.frustumCulled = false;
    cloud.userData.capacity = capacity;
    clouds.set(header.vehicle, cloud);
    scene.add(cloud);
  }
  const pos = cloud.geometry.attributes.position, col = cloud.geometry.attributes.color;
  pos.array.set(pts);
  const [z0, z1] = LIDAR_Z_RANGE_M;
  for (let i = 0; i < header.points; i++) {
    const f = Math.min(1, Math.max(0, (pts[3 * i + 2] - z0) / (z1 - z0)));
    col.array[3 * i] = 0.1 + 0.9 * f;
    col.array[3 * i + 1] = 0.3 + 0.6 * f;
    col.array[3 * i + 2] = 1.0 - 0.9 * f;
  }
  pos.needsUpdate = true;
  col.needsUpdate = true;
  cloud.geometry.setDrawRange(0, header.points);
  updateCloudVisibility();
  requestRender();
}

function onImage(header, buf, offset) {
  if (header.vehicle !== view.selected) return;
  view.images += 1;
  view.imageVehicle = header.vehicle;
  const canvas = $('camera');
  const w = header.width, h = header.height;
  if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
  canvas.hidden = false;
  const rgb = new Uint8Array(buf, offset, w * h * 3);
  const img = new ImageData(w, h);
  const px = img.data;
  for (let i = 0, j = 0; i < w * h; i++, j += 3) {
    px[4 * i] = rgb[j]; px[4 * i + 1] = rgb[j + 1]; px[4 * i + 2] = rgb[j + 2]; px[4 * i + 3] = 255;
  }
  canvas.getContext('2d').putImageData(img, 0, 0);
  $('camera-name').textContent = `${header.vehicle} (${header.sensor.replace('_', ' ')}, t ${header.t.toFixed(1)} s)`;
  $('camera-note').hidden = true;
}

function onText(data) {
  let msg;
  try { msg = JSON.parse(data); } catch { view.badMessages += 1; return; }
  if (msg.type === 'scene') onScene(msg);
  else if (msg.type === 'state') onState(msg);
  else view.badMessages += 1;
}

function onBinary(buf) {
  const n = new DataView(buf).getUint32(0, true);
  let header;
  try { header = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, n))); } catch { view.badMessages += 1; return; }
  const offset = 4 + n;
  if (header.type === 'mesh') onMesh(header, buf, offset);
  else if (header.type === 'lidar') onLidar(header, buf, offset);
  else if (header.type === 'image') onImage(header, buf, offset);
  else view.badMessages += 1;
}

// -- vehicles ---------------------------------------------------------------------------------
function box(sx, sy, sz, material, x = 0, y = 0, z = 0) {
  const m = new THREE.Mesh(new THREE.BoxGeometry(sx, sy, sz), material);
  m.position.set(x, y, z);
  return m;
}

function vehicleModel(look) {
  const model = new THREE.Group();
  const colour = new THREE.Color().setRGB(...look.rgb, THREE.SRGBColorSpace);
  const body = new THREE.MeshLambertMaterial({ color: colour });
  const dark = new THREE.MeshLambertMaterial({ color: 0x222222 });
  const [hx, hy, hz] = look.half_extents_m;
  if (look.kind === 'quadrotor') {
    const arm = Math.hypot(hx, hy) * 0.9;
    model.add(box(hx * 0.7, hy * 0.7, hz * 1.6, body));
    for (const a of [Math.PI / 4, -Math.PI / 4]) {
      const bar = box(2 * arm, hz * 0.35, hz * 0.35, body);
      bar.rotation.z = a;
      model.add(bar);
    }
    for (const [sx, sy] of [[1, 1], [1, -1], [-1, 1], [-1, -1]]) {
      const rotor = new THREE.Mesh(new THREE.CylinderGeometry(arm * 0.45, arm * 0.45, hz * 0.15, 16), dark);
      rotor.rotation.x = Math.PI / 2;            // cylinder axis (y) -> z
      rotor.position.set(sx * arm / Math.SQRT2, sy * arm / Math.SQRT2, hz * 0.4);
      model.add(rotor);
    }
    model.add(box(hx * 0.25, hy * 0.12, hz * 0.5, new THREE.MeshLambertMaterial({ color: 0xff5722 }), hx * 0.45, 0, 0));  // nose
  } else if (look.kind === 'car') {
    model.add(box(2 * hx, 2 * hy, 1.2 * hz, body, 0, 0, -0.2 * hz));
    model.add(box(1.1 * hx, 1.8 * hy, 0.7 * hz, body, -0.15 * hx, 0, 0.75 * hz));
    const r = Math.min(hz * 0.55, 0.5);
    for (const [sx, sy] of [[1, 1], [1, -1], [-1, 1], [-1, -1]]) {
      const wheel = new THREE.Mesh(new THREE.CylinderGeometry(r, r, 0.3, 16), dark);   // axis along y
      wheel.position.set(sx * hx * 0.65, sy * hy * 0.95, -hz * 0.8);
      model.add(wheel);
    }
  } else {
    model.add(box(2 * hx, 2 * hy, 2 * hz, body));
  }
  return model;
}

function addVehicle(look) {
  const group = new THREE.Group();
  const model = vehicleModel(look);
  group.add(model);
  const div = document.createElement('div');
  div.className = 'label';
  div.textContent = look.name;
  div.addEventListener('click', () => select(look.name));
  const label = new CSS2DObject(div);
  label.center.set(0.5, 1.4);
  group.add(label);
  scene.add(group);
  let stalk = null;
  if (look.kind === 'quadrotor') {         // a thin line down to the ground shows the altitude
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(6), 3));
    stalk = new THREE.Line(geometry, new THREE.LineBasicMaterial({ color: 0x333333, transparent: true, opacity: 0.5 }));
    scene.add(stalk);
  }
  const v = { look, group, model, label, stalk, state: null, card: addCard(look) };
  vehicles.set(look.name, v);
  applyScale(v);
  return v;
}

function removeVehicle(v) {
  scene.remove(v.group);
  v.label.element.remove();
  disposeTree(v.group);
  if (v.stalk) { scene.remove(v.stalk); disposeTree(v.stalk); }
}

function applyScale(v) {
  const s = v.look.kind === 'quadrotor' && !$('truescale').checked ? DRONE_SCALE : 1;
  v.model.scale.setScalar(s);
  v.label.position.set(0, 0, (v.look.half_extents_m[2] + 0.3) * s);
}

function addCard(look) {
  const card = document.createElement('div');
  card.className = 'card';
  card.dataset.name = look.name;
  const [r, g, b] = look.rgb.map((c) => Math.round(c * 255));
  card.innerHTML = `<div class="head"><span class="swatch" style="background: rgb(${r}, ${g}, ${b})"></span>`
    + `<span class="name"></span><small></small></div><dl>`
    + '<dt>mode</dt><dd class="mode">–</dd><dt>speed</dt><dd class="speed">–</dd>'
    + '<dt>altitude</dt><dd class="alt">–</dd><dt>battery</dt><dd class="battery">–</dd>'
    + '<dt>mission</dt><dd class="mission">–</dd></dl>';
  card.querySelector('.name').textContent = look.name;
  card.querySelector('small').textContent = `${look.kind}${look.sensors.length ? ' · ' + look.sensors.join(', ').replace('_', ' ') : ''}`;
  card.addEventListener('click', () => select(look.name));
  $('vehicles').appendChild(card);
  return card;
}

function updateCard(v) {
  const s = v.state, c = v.card;
  c.querySelector('.mode').textContent = s.mode || '–';
  c.querySelector('.speed').textContent = s.speed === null ? '–' : `${s.speed.toFixed(1)} m/s`;
  c.querySelector('.alt').textContent = s.alt === null ? '–' : `${s.alt.toFixed(1)} m`;
  const bat = c.querySelector('.battery');
  if (s.battery === null || s.battery === undefined) bat.textContent = '–';
  else {
    const pct = Math.max(0, Math.min(100, 100 * s.battery));
    bat.innerHTML = `<span class="bar"><i style="width: ${pct.toFixed(0)}%"></i></span>`;
    bat.append(`${pct.toFixed(1)} %`);
  }
  c.querySelector('.mission').textContent = s.mission || '–';
  c.querySelector('.mission').title = s.mission || '';
}

// -- selection, follow camera, LiDAR mode -------------------------------------------------------
function select(name) {
  view.selected = name;
  for (const [n, v] of vehicles) {
    v.card.classList.toggle('selected', n === name);
    v.label.element.classList.toggle('selected', n === name);
  }
  const v = name === null ? null : vehicles.get(name);
  const hasCamera = v && v.look.sensors.some((s) => s === 'camera' || s === 'depth_camera');
  if (view.imageVehicle !== name) {
    const canvas = $('camera');
    canvas.getContext('2d').clearRect(0, 0, canvas.width, canvas.height);
    canvas.hidden = true;
    $('camera-name').textContent = '';
    $('camera-note').hidden = false;
    $('camera-note').textContent = hasCamera ? `waiting for ${name}'s camera…` : `${name || 'no vehicle'} has no camera`;
    view.imageVehicle = null;
  }
  send({ type: 'select', vehicle: name });
  if (view.follow && v) followStart(v);
  updateCloudVisibility();
  requestRender();
}

function updateCloudVisibility() {
  const mode = $('lidarmode').value;
  for (const [name, cloud] of clouds) cloud.visible = mode === 'all' || (mode === 'selected' && name === view.selected);
}

function sendLidarMode() {
  send({ type: 'lidar', mode: $('lidarmode').value });
  updateCloudVisibility();
  requestRender();
}

let followLast = null;
function followStart(v) {
  // come close if the camera is far away, then keep the same offset as the vehicle moves
  const p = v.group.position;
  if (camera.position.distanceTo(p) > 150) {
    controls.target.copy(p);
    camera.position.set(p.x - 25, p.y - 35, p.z + 25);
    controls.update();
  }
  followLast = p.clone();
}

function followSelected() {
  if (!view.follow || view.selected === null) return;
  const v = vehicles.get(view.selected);
  if (!v) return;
  const p = v.group.position;
  if (followLast === null) followLast = p.clone();
  const delta = p.clone().sub(followLast);
  camera.position.add(delta);
  controls.target.add(delta);
  followLast.copy(p);
  controls.update();
}

// -- replay player ----------------------------------------------------------------------------
let seeking = false;
let lastSeekSent = 0;
function updatePlayer(r, t) {
  const seek = $('seek');
  seek.min = r.start; seek.max = r.end;
  if (!seeking) seek.value = t;
  $('play').textContent = r.playing ? 'pause' : 'play';
  $('playtime').textContent = `${(t - r.start).toFixed(1)} / ${(r.end - r.start).toFixed(1)} s`;
  if (document.activeElement !== $('speed')) $('speed').value = String(r.speed);
}

$('play').addEventListener('click', () => send({ type: view.replay && view.replay.playing ? 'pause' : 'play' }));
$('seek').addEventListener('input', () => {
  seeking = true;
  const now = performance.now();
  if (now - lastSeekSent > 100) { lastSeekSent = now; send({ type: 'seek', t: Number($('seek').value) }); }
});
$('seek').addEventListener('change', () => { seeking = false; send({ type: 'seek', t: Number($('seek').value) }); });
$('speed').addEventListener('change', () => send({ type: 'speed', x: Number($('speed').value) }));

// -- controls ---------------------------------------------------------------------------------
$('follow').addEventListener('change', () => {
  view.follow = $('follow').checked;
  const v = vehicles.get(view.selected);
  if (view.follow && v) followStart(v);
  requestRender();
});
$('truescale').addEventListener('change', () => { for (const v of vehicles.values()) applyScale(v); requestRender(); });
$('lidarmode').addEventListener('change', sendLidarMode);
$('home').addEventListener('click', homeCamera);

// -- connection -------------------------------------------------------------------------------
let socket = null;
function send(msg) {
  if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(msg));
}

function connect() {
  socket = new WebSocket(`ws://${location.host}/ws`);
  socket.binaryType = 'arraybuffer';
  socket.addEventListener('open', () => {
    view.connected = true;
    $('conn').textContent = 'connected';
    $('conn').className = 'on';
  });
  socket.addEventListener('message', (ev) => {
    view.messages += 1;
    if (typeof ev.data === 'string') onText(ev.data);
    else onBinary(ev.data);
  });
  socket.addEventListener('close', () => {
    view.connected = false;
    $('conn').textContent = 'disconnected: retrying…';
    $('conn').className = 'off';
    setTimeout(connect, 2000);                 // the run ended, or restarts on the same port
  });
}

// -- what tests (and the devtools console) can read ------------------------------------------------
window.unetyemuView = Object.freeze({
  state() {
    const out = { ...view, vehicles: {} };
    for (const [name, v] of vehicles) {
      const p = v.group.position;
      out.vehicles[name] = { kind: v.look.kind, p: [p.x, p.y, p.z], ...(v.state ? {
        speed: v.state.speed, alt: v.state.alt, battery: v.state.battery, mode: v.state.mode, mission: v.state.mission,
      } : {}) };
    }
    if (out.replay) out.replay = { ...out.replay };
    return out;
  },
  select,
  setFollow(on) { $('follow').checked = !!on; $('follow').dispatchEvent(new Event('change')); },
});

resize();
homeCamera();
connect();
