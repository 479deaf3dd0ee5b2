// vistream's browser client (docs/browser.md): opens a walkthrough Session over a
// WebSocket to the server that served this page, reports its pose, and draws with three.js what
// the server streamed, by the native client's frame rule (client/frame_loop.cpp): the ε-mask of
// the neighbourhood the eye is in once all its objects are here (a masked frame), else the
// viewcell's PVS once complete, else what is held (a hole frame). A frame inside a viewcell that
// is not complete is a stall.
//
// The URL says what to open: /?scene=london&walk=cross-town&speed=30 (km/h); also seconds= (stop
// the walk after), memory_mb= (the client's memory budget), masks=off, token= is NOT read from
// the URL (tokens never travel in URLs): the page asks for one when the server refuses without.
//
// For tests and benchmarks the page exposes window.vistream: summary() (frames, stalls, hole
// frames, masked frames, bytes, frame times, state) and idPass() (the objects the current
// frame shows, with their pixel counts).

import * as THREE from 'three';
import { MeshoptDecoder } from 'meshoptimizer/decoder';
import {
  ViewcellGrid, MaskHoldings, PoseCadence, CreditWindow, chargedBytes, helloMessage, poseMessage, creditMessage,
  encode, decode,
} from './protocol.js';

const params = new URLSearchParams(location.search);
const options = {
  scene: params.get('scene') || '',
  walk: params.get('walk') || '',
  speedKmh: Number(params.get('speed') || 5),
  seconds: Number(params.get('seconds') || 0),
  memoryBudgetBytes: Math.round(Number(params.get('memory_mb') || 0) * 1048576),
  masks: params.get('masks') !== 'off',
  maxFps: Number(params.get('max_fps') || 0),  // 0: every animation frame
  width: Number(params.get('width') || 0),
  height: Number(params.get('height') || 0),
};
const EYE_HEIGHT_M = 1.7;  // scenes/catalog.h WalkPath::eye_height_m

// The address's numbers, checked as vistream-client checks its options (its --speed range):
// the first that is not a number in its range, named with what it takes; '' when all are.
function badAddressNumber() {
  const rules = [
    ['speed', 0.01, 10000, 'km/h'],
    ['seconds', 0, 1e7, 'seconds of the walk (0: all of it)'],
    ['memory_mb', 0, 1e6, 'MiB (0: no budget)'],
    ['max_fps', 0, 1000, 'frames per second (0: every animation frame)'],
    ['width', 0, 16384, 'pixels'],
    ['height', 0, 16384, 'pixels'],
  ];
  for (const [name, lo, hi, what] of rules) {
    const text = params.get(name);
    if (text === null) continue;
    const v = Number(text);
    if (text.trim() === '' || !Number.isFinite(v) || v < lo || v > hi) {
      return `The address's ${name}=${text} is not a number from ${lo} to ${hi} (${what}).`;
    }
  }
  return '';
}

const $ = (id) => document.getElementById(id);
function say(text, kind = 'info') {
  const el = $('message');
  el.textContent = text;
  el.className = text ? kind : '';
}

// ---- state ----

const summary = {
  state: 'starting',  // starting, connecting, walking, reconnecting, done, error
  error: '',
  scene: '',
  walk: '',
  frames: 0,
  stalls: 0,
  hole_frames: 0,
  masked_frames: 0,
  bytes_received: 0,     // WebSocket payload bytes (serialized ServerMessages)
  charged_bytes: 0,      // what the credit counts (geometry and mask bytes)
  messages: 0,
  objects_held: 0,
  objects_received: 0,
  objects_received_twice: 0,
  masks_received: 0,
  sessions: 0,
  first_frame_ms: null,  // from navigation start to the first frame with scene geometry drawn
  startup_s: null,       // from the session's start until its first viewcell (and the next on the walk) was complete
  frame_ms: [],
  walk_s: 0,
  walk_done: false,
  reversed_depth: false,  // whether the GPU offered reversed depth (EXT_clip_control)
};
window.vistream = {
  summary: () => ({ ...summary, frame_ms: summary.frame_ms.slice() }),
  idPass: () => idPass(),
  options,
};

let sceneInfo = null;
let grid = null;
const objects = new Map();     // id -> { mesh, triangles, rawBytes, indices }
const lists = new Map();       // cell -> [object ids]
const masks = new MaskHoldings();
const received = new Set();    // every object id ever received (nothing sent twice)
let socket = null;
let credit = new CreditWindow();
const cadence = new PoseCadence();
let sessionStart = 0;
let ended = null;              // SessionEnd of a session that must not be resumed
let messageChain = Promise.resolve();

// ---- drawing ----

const canvas = $('view');
const gl = canvas.getContext('webgl2', { antialias: false, preserveDrawingBuffer: true });
if (!gl) {
  summary.state = 'error';
  summary.error = 'no WebGL 2';
  say('This browser has no WebGL 2: vistream draws with WebGL 2 (any current Chrome, Firefox or Safari has it).', 'error');
  throw new Error('no WebGL 2');
}
// Reversed depth where the GPU offers it (EXT_clip_control; three.js's reversedDepthBuffer):
// with the id pass's float depth, buildings a hand apart kilometres away stay apart, as in the
// native client's id buffer (gl/id_renderer.h).
const renderer = new THREE.WebGLRenderer({ canvas, context: gl, reversedDepthBuffer: true });
summary.reversed_depth = renderer.capabilities.reversedDepthBuffer === true;
const scene3 = new THREE.Scene();
scene3.background = new THREE.Color(0xb8d0e8);
scene3.add(new THREE.HemisphereLight(0xffffff, 0x606060, 2.2));
const sun = new THREE.DirectionalLight(0xffffff, 1.2);
sun.position.set(0.4, 0.3, 1.0);
scene3.add(sun);
// The ground: a plane at z = 0 under everything (no object of the scene: the id pass leaves it out).
const ground = new THREE.Mesh(new THREE.PlaneGeometry(200000, 200000), new THREE.MeshLambertMaterial({ color: 0x8a9078 }));
ground.position.z = -0.05;
scene3.add(ground);
const camera = new THREE.PerspectiveCamera(60, 16 / 9, 0.5, 20000);
camera.up.set(0, 0, 1);
// Both sides of every face, as the native client draws (client/renderer.cpp: no culling): an
// open shell of a city model shows its inside.
const material = new THREE.MeshLambertMaterial({ color: 0xd8d2c4, side: THREE.DoubleSide });

function resize() {
  const w = options.width || window.innerWidth;
  const h = options.height || window.innerHeight;
  renderer.setPixelRatio(1);
  renderer.setSize(w, h, false);
  canvas.style.width = `${w}px`;
  canvas.style.height = `${h}px`;
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
}
window.addEventListener('resize', resize);
resize();

// An object's mesh from ObjectGeometry: meshoptimizer's vertex codec (24-byte vertices:
// position, normal) and index sequence codec (scenes/geometry_codec.h).
function decodeObject(g) {
  if (g.level !== 0) throw new Error(`object ${g.object_id}: a level of detail came, but none was asked for`);
  const vertices = new Uint8Array(g.vertex_count * 24);
  MeshoptDecoder.decodeVertexBuffer(vertices, g.vertex_count, 24, g.vertices);
  const indices = new Uint32Array(g.index_count);
  MeshoptDecoder.decodeIndexSequence(new Uint8Array(indices.buffer), g.index_count, 4, g.indices);
  for (const i of indices) if (i >= g.vertex_count) throw new Error(`object ${g.object_id}: an index out of range`);
  const floats = new Float32Array(vertices.buffer);
  const interleaved = new THREE.InterleavedBuffer(floats, 6);
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.InterleavedBufferAttribute(interleaved, 3, 0));
  geometry.setAttribute('normal', new THREE.InterleavedBufferAttribute(interleaved, 3, 3));
  geometry.setIndex(new THREE.BufferAttribute(indices, 1));
  geometry.computeBoundingSphere();
  const mesh = new THREE.Mesh(geometry, material);
  mesh.matrixAutoUpdate = false;
  mesh.visible = false;
  mesh.userData.id = g.object_id;
  return { mesh, geometry, indices, triangles: g.index_count / 3, rawBytes: g.vertex_count * 24 + g.index_count * 4,
    masked: new Map() };
}

function dropObject(id) {
  const o = objects.get(id);
  if (!o) return;
  scene3.remove(o.mesh);
  o.geometry.dispose();
  for (const m of o.masked.values()) {
    scene3.remove(m.mesh);
    m.mesh.geometry.dispose();
  }
  objects.delete(id);
}

// The triangles of object `o` a mask's bits keep, as a mesh sharing the object's vertices
// (cached per mask key).
function maskedMesh(o, mask) {
  let entry = o.masked.get(mask.key);
  if (entry) return entry.mesh;
  const bits = mask.objects.get(o.mesh.userData.id);
  const keep = [];
  for (let t = 0; t < o.triangles; ++t) {
    if ((t >> 3) < bits.length && (bits[t >> 3] >> (t & 7)) & 1) keep.push(o.indices[3 * t], o.indices[3 * t + 1], o.indices[3 * t + 2]);
  }
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', o.geometry.getAttribute('position'));
  geometry.setAttribute('normal', o.geometry.getAttribute('normal'));
  geometry.setIndex(new THREE.BufferAttribute(new Uint32Array(keep), 1));
  geometry.boundingSphere = o.geometry.boundingSphere;
  const mesh = new THREE.Mesh(geometry, material);
  mesh.matrixAutoUpdate = false;
  mesh.userData.id = o.mesh.userData.id;
  mesh.visible = false;
  scene3.add(mesh);
  entry = { mesh, mask: mask.key };
  o.masked.set(mask.key, entry);
  return mesh;
}

// ---- the walk and the eye ----

const eye = { position: [0, 0, EYE_HEIGHT_M], yaw: 0, pitch: 0, velocity: [0, 0, 0] };
let walk = null;  // { name, points: [[x, y]...], cumulative: [m...], length }
let walkClock = 0;
let paused = false;
const keys = new Set();

function makeWalk(path) {
  const points = [];
  for (let k = 0; k + 1 < path.xy.length; k += 2) points.push([path.xy[k], path.xy[k + 1]]);
  const cumulative = [0];
  for (let k = 1; k < points.length; ++k) {
    cumulative.push(cumulative[k - 1] + Math.hypot(points[k][0] - points[k - 1][0], points[k][1] - points[k - 1][1]));
  }
  return { name: path.name, points, cumulative, length: cumulative[cumulative.length - 1] };
}

// Position and heading `s` metres along the walk.
function along(w, s) {
  s = Math.max(0, Math.min(w.length, s));
  let k = 1;
  while (k < w.cumulative.length - 1 && w.cumulative[k] < s) ++k;
  const a = w.points[k - 1];
  const b = w.points[k];
  const seg = w.cumulative[k] - w.cumulative[k - 1];
  const f = seg > 0 ? (s - w.cumulative[k - 1]) / seg : 0;
  return { x: a[0] + f * (b[0] - a[0]), y: a[1] + f * (b[1] - a[1]), yaw: Math.atan2(b[1] - a[1], b[0] - a[0]) };
}

// Start-up (client/walkthrough_startup.cpp): the walk's clock starts once the cell it starts in
// and the first cell it enters are complete; frames until then are not counted.
let started = false;

// client/cell_completion.h's rule: a viewcell is complete once its PVS list is held and every
// object on it (null: outside the grid, never complete).
function cellComplete(cell) {
  const list = cell !== null ? lists.get(cell) : undefined;
  return list !== undefined && list.every((id) => objects.has(id));
}

function startupDone() {
  const here = grid.cellOf(eye.position[0], eye.position[1]);
  if (here === null || !cellComplete(here)) return false;
  if (!walk) return true;
  for (let s = 0; s <= walk.length; s += grid.size / 4) {
    const p = along(walk, s);
    const c = grid.cellOf(p.x, p.y);
    if (c !== null && c !== here) return cellComplete(c);
  }
  return true;
}

function moveEye(dt) {
  const before = eye.position.slice();
  if (!started) {
    // The velocity the walk will start at, so that the server ranks the cells ahead first.
    if (walk) {
      const p = along(walk, 0);
      const v = options.speedKmh / 3.6;
      eye.velocity = [v * Math.cos(p.yaw), v * Math.sin(p.yaw), 0];
    }
    return;
  }
  if (walk && !paused) {
    walkClock += dt;
    const speed = options.speedKmh / 3.6;
    let s = walkClock * speed;
    if (options.seconds > 0 && walkClock >= options.seconds) s = options.seconds * speed;
    if (s >= walk.length || (options.seconds > 0 && walkClock >= options.seconds)) summary.walk_done = true;
    const p = along(walk, s);
    eye.position = [p.x, p.y, EYE_HEIGHT_M];
    eye.yaw = p.yaw;
  } else if (!walk) {
    const speed = (keys.has('Shift') ? 15 : 4) * dt;
    const f = [Math.cos(eye.yaw), Math.sin(eye.yaw)];
    const move = (dx, dy) => { eye.position[0] += dx; eye.position[1] += dy; };
    if (keys.has('w') || keys.has('ArrowUp')) move(f[0] * speed, f[1] * speed);
    if (keys.has('s') || keys.has('ArrowDown')) move(-f[0] * speed, -f[1] * speed);
    if (keys.has('a')) move(-f[1] * speed, f[0] * speed);
    if (keys.has('d')) move(f[1] * speed, -f[0] * speed);
    if (keys.has('ArrowLeft')) eye.yaw += 1.2 * dt;
    if (keys.has('ArrowRight')) eye.yaw -= 1.2 * dt;
  }
  eye.velocity = dt > 0 ? [0, 1, 2].map((k) => (eye.position[k] - before[k]) / dt) : [0, 0, 0];
  summary.walk_s = walkClock;
}

window.addEventListener('keydown', (e) => {
  keys.add(e.key);
  if (e.key === ' ') paused = !paused;
  if (e.key === 'Escape' && walk) walk = null;  // take the keys
});
window.addEventListener('keyup', (e) => keys.delete(e.key));
canvas.addEventListener('mousemove', (e) => {
  if (e.buttons & 1) {
    eye.yaw -= e.movementX * 0.004;
    eye.pitch = Math.max(-1.2, Math.min(1.2, eye.pitch - e.movementY * 0.004));
  }
});

// ---- the session ----

function send(message) {
  if (socket && socket.readyState === WebSocket.OPEN) socket.send(encode(message));
}

let token = sessionStorage.getItem('vistream-token') || '';
let reconnectDelay = 0.5;

function connect() {
  summary.state = summary.sessions === 0 ? 'connecting' : 'reconnecting';
  const url = `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/session`;
  const ws = new WebSocket(url);
  ws.binaryType = 'arraybuffer';
  socket = ws;
  ws.onopen = () => {
    ++summary.sessions;
    sessionStart = performance.now() / 1000;
    masks.newSession();
    credit = new CreditWindow();
    cadence.restart(0);
    send(helloMessage({
      scene: options.scene, memoryBudgetBytes: options.memoryBudgetBytes, epsilonMasks: options.masks,
      heldObjects: [...objects.keys()], token,
    }));
    send(creditMessage(credit.open()));
    if (summary.sessions > 1) say(`Reconnected: resumed holding ${objects.size} objects.`);
    reconnectDelay = 0.5;
  };
  ws.onmessage = (e) => {
    const bytes = new Uint8Array(e.data);
    summary.bytes_received += bytes.length;
    ++summary.messages;
    // One at a time, in order (mask inflation is asynchronous).
    messageChain = messageChain.then(() => onMessage(decode(bytes))).catch((err) => fail(`bad message: ${err.message}`));
  };
  ws.onclose = () => {
    if (socket !== ws) return;
    socket = null;
    if (ended) return;
    summary.state = 'reconnecting';
    say(`Lost the server: reconnecting (holding ${objects.size} objects)...`, 'warn');
    setTimeout(connect, reconnectDelay * 1000);
    reconnectDelay = Math.min(2, reconnectDelay * 2);
  };
}

function fail(text) {
  summary.state = 'error';
  summary.error = text;
  say(text, 'error');
}

async function onMessage(m) {
  if (m.end) {
    const { code, message } = m.end;
    if (code === 16) {  // UNAUTHENTICATED
      ended = m.end;
      fail(`The server refused the token: ${message}.`);
      askToken();
    } else if (code === 5) {  // NOT_FOUND: an unknown scene
      ended = m.end;
      fail(`The server has no such scene: ${message}`);
    } else if (code === 14) {  // UNAVAILABLE: draining; reconnect (perhaps to another replica)
      say(`The server is going away (${message}): reconnecting...`, 'warn');
    } else if (code !== 0) {
      ended = m.end;
      fail(`The session ended: ${message} (code ${code}).`);
    }
    return;
  }
  const charged = chargedBytes(m);
  summary.charged_bytes += charged;
  credit.consume(charged);
  if (credit.grantDue()) send(creditMessage(credit.takeGrant()));
  if (m.scene_info) {
    sceneInfo = m.scene_info;
    grid = new ViewcellGrid(sceneInfo.grid);
    summary.scene = sceneInfo.name;
    if (!walk && summary.sessions === 1) startWalk();
    summary.state = 'walking';
  } else if (m.geometry) {
    const id = m.geometry.object_id;
    if (received.has(id)) ++summary.objects_received_twice;
    received.add(id);
    ++summary.objects_received;
    dropObject(id);
    const o = decodeObject(m.geometry);
    objects.set(id, o);
    scene3.add(o.mesh);
  } else if (m.pvs) {
    if (m.pvs.delta) throw new Error('a PVS list came as a difference, but none was asked for');
    lists.set(m.pvs.cell_id, m.pvs.object_ids.slice());
  } else if (m.evict) {
    for (const id of m.evict.object_ids) dropObject(id);
  } else if (m.epsilon_mask) {
    ++summary.masks_received;
    await masks.add(m.epsilon_mask, sceneInfo.object_count, Number(sceneInfo.triangle_count));
  }
  summary.objects_held = objects.size;
}

function startWalk() {
  const paths = sceneInfo.paths || [];
  let path = null;
  if (options.walk) {
    path = paths.find((p) => p.name === options.walk);
    if (!path) {
      say(`No walk '${options.walk}' in ${sceneInfo.name} (known: ${paths.map((p) => p.name).join(', ')}); walk with the keys.`, 'warn');
    }
  }
  if (!path && !options.walk && paths.length > 0) path = null;  // no walk asked: the keys walk
  if (path) {
    walk = makeWalk(path);
    summary.walk = walk.name;
    const p = along(walk, 0);
    eye.position = [p.x, p.y, EYE_HEIGHT_M];
    eye.yaw = p.yaw;
  } else if (paths.length > 0) {
    // Stand at the start of the scene's first walk.
    const first = makeWalk(paths[0]);
    const p = along(first, 0);
    eye.position = [p.x, p.y, EYE_HEIGHT_M];
    eye.yaw = p.yaw;
  }
}

function askToken() {
  const form = $('token');
  form.hidden = false;
  form.onsubmit = (e) => {
    e.preventDefault();
    token = $('token-value').value.trim();
    sessionStorage.setItem('vistream-token', token);
    form.hidden = true;
    ended = null;
    say('');
    connect();
  };
}

// ---- frames ----

let lastFrame = performance.now() / 1000;
const frameState = { mask: null, cell: null, complete: false, hole: false, drawn: 0 };

function frame() {
  const now = performance.now() / 1000;
  if (options.maxFps > 0 && now - lastFrame < 1 / options.maxFps - 0.002) {
    requestAnimationFrame(frame);
    return;
  }
  const dt = Math.min(0.25, now - lastFrame);
  lastFrame = now;
  if (grid && !started && startupDone()) {
    started = true;
    summary.startup_s = now - sessionStart;
  }
  if (grid) moveEye(dt);
  // The pose, at the protocol's cadence.
  const clientTime = now - sessionStart;
  if (grid && cadence.due(clientTime)) {
    send(poseMessage(eye.position, eye.velocity, eye.yaw, eye.pitch, clientTime));
    cadence.sent(clientTime);
  }
  if (grid) draw(now);
  requestAnimationFrame(frame);
}

function draw(now) {
  const start = performance.now();
  const cell = grid.cellOf(eye.position[0], eye.position[1]);
  masks.keepNear(cell, grid);
  const complete = cellComplete(cell);
  const list = complete ? lists.get(cell) : undefined;
  const choice = options.masks ? masks.choose(eye.position, (id) => objects.has(id)) : { mask: null };
  const mask = choice.mask;
  const hole = mask === null && !complete;
  for (const o of objects.values()) {
    o.mesh.visible = false;
    for (const m of o.masked.values()) m.mesh.visible = false;
  }
  let drawn = 0;
  if (mask !== null) {
    for (const id of mask.objectIds) {
      maskedMesh(objects.get(id), mask).visible = true;
      ++drawn;
    }
  } else if (complete) {
    for (const id of list) {
      objects.get(id).mesh.visible = true;
      ++drawn;
    }
  } else {
    for (const o of objects.values()) {
      o.mesh.visible = true;
      ++drawn;
    }
  }
  const [x, y, z] = eye.position;
  camera.position.set(x, y, z);
  const c = Math.cos(eye.pitch);
  camera.lookAt(x + c * Math.cos(eye.yaw), y + c * Math.sin(eye.yaw), z + Math.sin(eye.pitch));
  renderer.render(scene3, camera);
  if (summary.first_frame_ms === null && drawn > 0) summary.first_frame_ms = performance.now();
  Object.assign(frameState, { mask, cell, complete, hole, drawn });
  overlay(now);
  if (!started) return;
  ++summary.frames;
  if (mask !== null) ++summary.masked_frames;
  if (hole) ++summary.hole_frames;
  if (cell !== null && !complete) ++summary.stalls;
  summary.frame_ms.push(performance.now() - start);
}

// ---- the overlay and the minimap ----

let lastOverlay = 0;
function overlay(now) {
  if (now - lastOverlay < 0.25) return;
  lastOverlay = now;
  const n = summary.frame_ms.length;
  const recent = summary.frame_ms.slice(Math.max(0, n - 60));
  const ms = recent.reduce((a, b) => a + b, 0) / Math.max(1, recent.length);
  const mode = frameState.mask ? 'masked' : frameState.hole ? 'HOLE' : 'PVS';
  const cell = frameState.cell === null ? 'outside the grid' : grid.coord(frameState.cell).join(',');
  $('stats').textContent = [
    `${summary.scene}${walk ? ` · ${walk.name} at ${options.speedKmh} km/h` : ' · keys: W A S D, drag to look'}`,
    `cell ${cell} · ${mode} · ${frameState.drawn} objects drawn`,
    `held ${objects.size} objects · ${(summary.bytes_received / 1e6).toFixed(1)} MB received`,
    `frames ${summary.frames} · masked ${summary.masked_frames} · stalls ${summary.stalls} · holes ${summary.hole_frames}`,
    `draw ${ms.toFixed(1)} ms · session ${summary.sessions} · ${summary.state}`,
  ].join('\n');
  minimap();
}

// The minimap: 800 m around the eye, north up: viewcells held (green: complete, orange: not
// yet), the walk, the eye; a scale bar and a legend.
function minimap() {
  const mc = $('minimap');
  const ctx = mc.getContext('2d');
  const W = mc.width;
  const H = mc.height;
  const span = 800;  // metres across
  const scale = W / span;
  const [ex, ey] = eye.position;
  const px = (x) => W / 2 + (x - ex) * scale;
  const py = (y) => (H - 30) / 2 - (y - ey) * scale;
  ctx.fillStyle = 'rgba(255,255,255,0.9)';
  ctx.fillRect(0, 0, W, H);
  for (const cell of lists.keys()) {
    const [i, j] = grid.coord(cell);
    ctx.fillStyle = cellComplete(cell) ? 'rgba(60,170,80,0.45)' : 'rgba(240,150,40,0.6)';
    const x0 = grid.x0 + i * grid.size;
    const y1 = grid.y0 + (j + 1) * grid.size;
    ctx.fillRect(px(x0), py(y1), grid.size * scale, grid.size * scale);
  }
  if (walk) {
    ctx.strokeStyle = '#3060c0';
    ctx.lineWidth = 2;
    ctx.beginPath();
    walk.points.forEach((p, k) => (k ? ctx.lineTo(px(p[0]), py(p[1])) : ctx.moveTo(px(p[0]), py(p[1]))));
    ctx.stroke();
    ctx.lineWidth = 1;
  }
  ctx.fillStyle = '#d02020';
  ctx.beginPath();
  ctx.arc(px(ex), py(ey), 4, 0, 2 * Math.PI);
  ctx.fill();
  ctx.strokeStyle = '#d02020';
  ctx.beginPath();
  ctx.moveTo(px(ex), py(ey));
  ctx.lineTo(px(ex) + 14 * Math.cos(eye.yaw), py(ey) - 14 * Math.sin(eye.yaw));
  ctx.stroke();
  ctx.fillStyle = 'rgba(255,255,255,0.95)';
  ctx.fillRect(0, H - 30, W, 30);
  ctx.strokeStyle = '#000';
  ctx.beginPath();
  ctx.moveTo(6, H - 20);
  ctx.lineTo(6 + 100 * scale, H - 20);
  ctx.stroke();
  ctx.fillStyle = '#000';
  ctx.font = '10px sans-serif';
  ctx.fillText('100 m', 10 + 100 * scale, H - 17);
  ctx.fillText('north up · cells: green complete, orange not yet', 6, H - 5);
  ctx.fillText('blue: walk · red: you', 70 + 100 * scale, H - 17);
}

// ---- the object-id pass (tests: the objects the current frame shows) ----

// The id pass follows gl::IdRenderer::RenderView (gl/id_renderer.cpp) so that the two can be
// compared pixel for pixel: a float depth buffer (reversed where the GPU offers it), a near plane
// at 0.01 m, both sides drawn, a face turned away from the eye names no object (it hides what is
// behind it) and a face towards the eye wins a tie in depth with one turned away.
const idTarget = new THREE.WebGLRenderTarget(1, 1, { depthTexture: new THREE.DepthTexture(1, 1, THREE.FloatType) });
const kIdNear = 0.01;  // metres, as gl::IdRenderer's
const idMaterials = new Map();
function idMaterial(id) {
  let m = idMaterials.get(id);
  if (!m) {
    const v = id + 1;
    m = new THREE.ShaderMaterial({
      side: THREE.DoubleSide,
      uniforms: { idColor: { value: new THREE.Vector3(((v >> 16) & 255) / 255, ((v >> 8) & 255) / 255, (v & 255) / 255) } },
      vertexShader: 'void main() { gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0); }',
      fragmentShader: `uniform vec3 idColor;
void main() {
#ifdef USE_REVERSED_DEPTH_BUFFER
  gl_FragDepth = gl_FrontFacing ? gl_FragCoord.z * 1.000001 : gl_FragCoord.z;
#else
  gl_FragDepth = gl_FrontFacing ? gl_FragCoord.z * 0.999999 : gl_FragCoord.z;
#endif
  gl_FragColor = gl_FrontFacing ? vec4(idColor, 1.0) : vec4(0.0, 0.0, 0.0, 1.0);
}`,
    });
    idMaterials.set(id, m);
  }
  return m;
}

// Renders the current frame's drawn set with each object's id as its colour; returns
// { width, height, objects: { id: pixels }, interior: { id: interior pixels }, eye, yaw, pitch }.
function idPass() {
  const size = renderer.getSize(new THREE.Vector2());
  idTarget.setSize(size.x, size.y);
  const swapped = [];
  const hidden = [];
  scene3.traverse((node) => {
    if (!node.isMesh || !node.visible) return;
    if (node.userData.id === undefined) {  // the ground: no object
      node.visible = false;
      hidden.push(node);
      return;
    }
    swapped.push([node, node.material]);
    node.material = idMaterial(node.userData.id);
  });
  const background = scene3.background;
  scene3.background = new THREE.Color(0, 0, 0);
  const colorSpace = renderer.outputColorSpace;
  renderer.outputColorSpace = THREE.LinearSRGBColorSpace;
  const near = camera.near;
  camera.near = kIdNear;
  camera.updateProjectionMatrix();
  renderer.setRenderTarget(idTarget);
  renderer.render(scene3, camera);
  camera.near = near;
  camera.updateProjectionMatrix();
  const pixels = new Uint8Array(size.x * size.y * 4);
  renderer.readRenderTargetPixels(idTarget, 0, 0, size.x, size.y, pixels);
  renderer.setRenderTarget(null);
  renderer.outputColorSpace = colorSpace;
  scene3.background = background;
  for (const [node, m] of swapped) node.material = m;
  for (const node of hidden) node.visible = true;
  const w = size.x, h = size.y;
  const ids = new Uint32Array(w * h);
  for (let i = 0, k = 0; i < ids.length; ++i, k += 4) ids[i] = (pixels[k] << 16) | (pixels[k + 1] << 8) | pixels[k + 2];
  // Per object its pixels, and its interior pixels: those whose eight neighbours show it too. An
  // object without one is a sliver under three pixels thick, which another rasterizer's
  // sub-pixel snapping can show or not (vistream bench web counts such differences apart).
  const counts = {};
  const interior = {};
  for (let y = 0; y < h; ++y) {
    for (let x = 0; x < w; ++x) {
      const v = ids[y * w + x];
      if (v === 0) continue;
      counts[v - 1] = (counts[v - 1] || 0) + 1;
      if (x === 0 || y === 0 || x === w - 1 || y === h - 1) continue;
      let inside = true;
      for (let dy = -1; dy <= 1 && inside; ++dy) {
        for (let dx = -1; dx <= 1; ++dx) {
          if (ids[(y + dy) * w + x + dx] !== v) { inside = false; break; }
        }
      }
      if (inside) interior[v - 1] = (interior[v - 1] || 0) + 1;
    }
  }
  return { width: w, height: h, objects: counts, interior, eye: eye.position.slice(), yaw: eye.yaw, pitch: eye.pitch };
}

// ---- start ----

if (badAddressNumber()) {
  fail(badAddressNumber());
} else if (!options.scene) {
  fail('Open a scene: add ?scene=NAME to the address (e.g. ?scene=default&walk=avenue-and-back-streets&speed=30; '
    + '`vistream scene walks NAME` lists a scene\'s walks).');
} else {
  MeshoptDecoder.ready.then(() => {
    connect();
    requestAnimationFrame(frame);
  });
}
