// The client's side of the walkthrough protocol for the browser (client/client_model.h restated
// for JavaScript; the same rules: Hello, pose cadence, byte credit, what each message costs), the
// ε-mask wire form (visibility/mask_codec.h) and the held masks (client/mask_holdings.h), the
// viewcell grid (proto/scene_info.h) and a cell's completeness (client/cell_completion.h).
// Messages are proto/walkthrough.proto's, read at run time by protobufjs.

import protobuf from 'protobufjs';
import protoText from '../../proto/walkthrough.proto';

const root = protobuf.parse(protoText, { keepCase: true }).root;
export const ClientMessage = root.lookupType('vistream.v1.ClientMessage');
export const ServerMessage = root.lookupType('vistream.v1.ServerMessage');

export const PROTOCOL_VERSION_CURRENT = 1;
export const POSE_RATE_HZ = 10;                 // client_model.h kPoseRateHz
export const CREDIT_WINDOW_BYTES = 8 * 1048576; // CreditWindow::kDefaultBytes
export const MAX_MASKS = 64;                    // MaskHoldings::kMaxMasks

export function encode(message) {
  return ClientMessage.encode(ClientMessage.fromObject(message)).finish();
}

export function decode(bytes) {
  return ServerMessage.decode(bytes);
}

// Hello as client_model.h MakeHello writes it (no levels of detail: every object at full detail).
export function helloMessage({ scene, memoryBudgetBytes = 0, triangleBudget = 0, epsilonMasks = true, heldObjects = [], token = '' }) {
  return {
    hello: {
      scene,
      protocol_version: PROTOCOL_VERSION_CURRENT,
      memory_budget_bytes: memoryBudgetBytes,
      triangle_budget: triangleBudget,
      epsilon_masks: epsilonMasks,
      deflated_masks: epsilonMasks,
      held_objects: heldObjects,
      token,
    },
  };
}

export function poseMessage(position, velocity, yaw, pitch, clientTimeS) {
  return {
    pose: {
      client_time_s: clientTimeS,
      position: { x: position[0], y: position[1], z: position[2] },
      velocity: { x: velocity[0], y: velocity[1], z: velocity[2] },
      yaw_rad: yaw,
      pitch_rad: pitch,
    },
  };
}

export function creditMessage(bytes) {
  return { credit: { bytes } };
}

// client_model.h PoseCadence: one pose every 1 / rate seconds, never a burst to catch up.
export class PoseCadence {
  constructor(rateHz = POSE_RATE_HZ) {
    this.period = 1 / Math.max(0.1, rateHz);
    this.next = 0;
  }
  restart(now) { this.next = now; }
  due(now) { return now >= this.next; }
  sent(now) {
    this.next += this.period;
    if (this.next < now) this.next = now;
  }
}

// client_model.h CreditWindow.
export class CreditWindow {
  constructor(windowBytes = CREDIT_WINDOW_BYTES) {
    this.windowBytes = windowBytes;
    this.consumed = 0;
  }
  open() {
    this.consumed = 0;
    return this.windowBytes;
  }
  consume(bytes) { this.consumed += bytes; }
  grantDue() { return this.consumed >= this.windowBytes / 2; }
  takeGrant() {
    const g = this.consumed;
    this.consumed = 0;
    return g;
  }
}

// client_model.h ChargedBytes.
export function chargedBytes(m) {
  if (m.geometry) return m.geometry.vertices.length + m.geometry.indices.length;
  if (m.cluster) return m.cluster.vertices.length + m.cluster.indices.length;
  if (m.epsilon_mask) return m.epsilon_mask.triangles.length;
  return 0;
}

// ---- the viewcell grid (SceneInfo.grid; visibility::ViewcellGrid) ----

export class ViewcellGrid {
  constructor(g) {
    this.size = g.cell_size_m;
    this.x0 = g.x0_m;
    this.y0 = g.y0_m;
    this.nx = g.nx;
    this.ny = g.ny;
  }
  cellCount() { return this.nx * this.ny; }
  // The cell holding scene-local (x, y), or null outside the grid.
  cellOf(x, y) {
    const i = Math.floor((x - this.x0) / this.size);
    const j = Math.floor((y - this.y0) / this.size);
    if (i < 0 || j < 0 || i >= this.nx || j >= this.ny) return null;
    return j * this.nx + i;
  }
  coord(cell) { return [cell % this.nx, Math.floor(cell / this.nx)]; }
  near(a, b) {
    const [ai, aj] = this.coord(a);
    const [bi, bj] = this.coord(b);
    return Math.abs(ai - bi) <= 1 && Math.abs(aj - bj) <= 1;
  }
}

// ---- ε-masks (visibility/mask_codec.h) ----

class Reader {
  constructor(bytes) {
    this.bytes = bytes;
    this.at = 0;
  }
  done() { return this.at >= this.bytes.length; }
  varint() {
    let v = 0;
    let scale = 1;
    for (let k = 0; k < 5; ++k) {
      if (this.at >= this.bytes.length) throw new Error(`truncated varint at byte ${this.at}`);
      const b = this.bytes[this.at++];
      v += (b & 0x7f) * scale;
      if ((b & 0x80) === 0) return v;
      scale *= 128;
    }
    throw new Error(`over-long varint at byte ${this.at}`);
  }
}

// DecodeMaskRuns: Map object id -> Uint8Array of triangle bits (little-endian within bytes).
export function decodeMaskRuns(bytes, objectCount, maxTriangles) {
  const r = new Reader(bytes);
  const objects = new Map();
  let previous = -1;
  let total = 0;
  while (!r.done()) {
    const id = previous + 1 + r.varint();
    if (id >= objectCount) throw new Error(`object ${id} past the scene's ${objectCount} at byte ${r.at}`);
    previous = id;
    const pairs = r.varint();
    if (pairs < 1) throw new Error(`object ${id} without run pairs at byte ${r.at}`);
    const runs = [];
    let end = 0;
    for (let k = 0; k < pairs; ++k) {
      const hidden = r.varint();
      const visible = r.varint();
      if (visible < 1) throw new Error(`an empty visible run at byte ${r.at}`);
      runs.push(end + hidden, visible);
      end += hidden + visible;
      total += visible;
      if (end > maxTriangles) throw new Error(`runs past the scene's ${maxTriangles} triangles at byte ${r.at}`);
    }
    const bits = new Uint8Array((end + 7) >> 3);
    for (let k = 0; k < runs.length; k += 2) {
      for (let t = runs[k]; t < runs[k] + runs[k + 1]; ++t) bits[t >> 3] |= 1 << (t & 7);
    }
    objects.set(id, bits);
  }
  return objects;
}

function countBits(bits) {
  let n = 0;
  for (const b of bits) {
    let v = b;
    while (v) {
      v &= v - 1;
      ++n;
    }
  }
  return n;
}

// ApplyMaskDelta: the XOR per object; objects left without a set bit removed.
export function applyMaskDelta(base, delta) {
  const out = new Map(base);
  for (const [id, bits] of delta) {
    const old = out.get(id);
    const n = Math.max(old ? old.length : 0, bits.length);
    const x = new Uint8Array(n);
    for (let k = 0; k < n; ++k) x[k] = (old && k < old.length ? old[k] : 0) ^ (k < bits.length ? bits[k] : 0);
    if (countBits(x) === 0) out.delete(id);
    else out.set(id, x);
  }
  return new Map([...out.entries()].sort((a, b) => a[0] - b[0]));
}

async function inflate(bytes, maxBytes) {
  const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream('deflate'));
  const out = new Uint8Array(await new Response(stream).arrayBuffer());
  if (out.length > maxBytes) throw new Error(`more than ${maxBytes} bytes once inflated`);
  return out;
}

// client/mask_holdings.h MaskHoldings: masks decoded as they arrive (deltas against the latest
// mask of their cell), kept while their cell is the client's or a neighbour, at most MAX_MASKS.
export class MaskHoldings {
  constructor() {
    this.masks = new Map();  // mask id -> {id, key, cell, min, max, objects: Map, objectIds, triangles}
    this.bases = new Map();  // cell -> {maskId, objects}
    this.nextKey = 1;
  }
  newSession() { this.bases.clear(); }

  async add(m, objectCount, triangleCount) {
    let bytes = m.triangles;
    // MaxMaskRunBytes: a gap and a pair count per object, at most a pair per triangle, 5 bytes a varint.
    const maxBytes = 10 * objectCount + 10 * triangleCount;
    if (m.deflated) bytes = await inflate(bytes, maxBytes);
    let objects = decodeMaskRuns(bytes, objectCount, triangleCount);
    if (m.base_mask_id) {
      const base = this.bases.get(m.cell_id);
      if (!base || base.maskId !== m.base_mask_id) {
        throw new Error(`ε-mask ${m.mask_id}: its base ${m.base_mask_id} of cell ${m.cell_id} is not held`);
      }
      objects = applyMaskDelta(base.objects, objects);
    }
    this.bases.set(m.cell_id, { maskId: m.mask_id, objects });
    let triangles = 0;
    for (const bits of objects.values()) triangles += countBits(bits);
    const v = (p) => [p.x, p.y, p.z];
    this.masks.set(m.mask_id, {
      id: m.mask_id,
      key: this.nextKey++,
      cell: m.cell_id,
      min: v(m.neighbourhood_min),
      max: v(m.neighbourhood_max),
      objects,
      objectIds: [...objects.keys()],
      triangles,
    });
  }

  keepNear(cell, grid) {
    if (cell !== null) {
      for (const [id, m] of this.masks) {
        if (m.cell >= grid.cellCount() || !grid.near(m.cell, cell)) this.masks.delete(id);
      }
    }
    while (this.masks.size > MAX_MASKS) {
      let oldest = null;
      for (const m of this.masks.values()) if (oldest === null || m.key < oldest.key) oldest = m;
      this.masks.delete(oldest.id);
    }
  }

  // The mask a frame at `eye` may draw: among held masks whose box holds the eye and all of
  // whose objects are ready, the one with the fewest triangles (ties: the lower mask id).
  choose(eye, ready) {
    let chosen = null;
    let inBox = false;
    const ids = [...this.masks.keys()].sort((a, b) => a - b);
    for (const id of ids) {
      const m = this.masks.get(id);
      const inside = eye[0] >= m.min[0] && eye[0] <= m.max[0] && eye[1] >= m.min[1] && eye[1] <= m.max[1] &&
        eye[2] >= m.min[2] && eye[2] <= m.max[2];
      if (!inside) continue;
      inBox = true;
      if (chosen !== null && chosen.triangles <= m.triangles) continue;
      if (m.objectIds.every(ready)) chosen = m;
    }
    return { mask: chosen, inBox };
  }
}
