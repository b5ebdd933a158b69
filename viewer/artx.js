// The receiver side of artex's .artx tele-presence stream in JavaScript (no DOM, no WebGL: runs
// in the page and under node): the container (header, records, CRC-32, resynchronisation),
// the pose decoder (quantised, predicted, adaptive Rice), the coverage bits, the template from
// the header's glb and artex's skinning (LBS of the swing + cylindrical SLERP of the twist,
// eq. 1-2 of the paper) -- the same arithmetic as stream/*.cc and models/skinning.cc, in
// float64. The layout is specified in docs/streaming.md and docs/formats-template.md.

const CRC_TABLE = (() => {
  const t = new Uint32Array(256);
  for (let n = 0; n < 256; ++n) {
    let c = n;
    for (let k = 0; k < 8; ++k) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
    t[n] = c >>> 0;
  }
  return t;
})();

// zlib's crc32 of bytes[from, to).
export function crc32(bytes, from = 0, to = bytes.length) {
  let c = 0xffffffff;
  for (let i = from; i < to; ++i) c = CRC_TABLE[(c ^ bytes[i]) & 0xff] ^ (c >>> 8);
  return (c ^ 0xffffffff) >>> 0;
}

export const CODEC_NAMES = ['none', 'vp9', 'h264', 'av1'];
const RECORD_FRAMING = 24;
const MAX_PAYLOAD = 64 << 20;

function isMagic(b, at, s) {
  for (let i = 0; i < 4; ++i) if (b[at + i] !== s.charCodeAt(i)) return false;
  return true;
}

// The header of a stream (bytes: Uint8Array from the start). Throws an Error naming the field
// for a damaged or truncated header.
export function parseHeader(bytes) {
  const fail = (what) => { throw new Error(`stream header (byte 0): ${what}`); };
  if (bytes.length < 12 || !isMagic(bytes, 0, 'ARTX'))
    fail('expected the magic ARTX, found another file or fewer than 12 bytes');
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const version = dv.getUint16(4, true);
  if (version < 1 || version > 2) fail(`expected version 1 to 2, found ${version}`);
  const size = dv.getUint32(8, true);
  if (size < 24 || size > bytes.length)
    fail(`header size ${size} beyond the ${bytes.length} bytes of the stream (truncated)`);
  if (dv.getUint32(size - 4, true) !== crc32(bytes, 0, size - 4)) fail('CRC mismatch (damaged header)');
  let at = 12;
  const u8 = () => dv.getUint8(at++);
  const u16 = () => { const v = dv.getUint16(at, true); at += 2; return v; };
  const u32 = () => { const v = dv.getUint32(at, true); at += 4; return v; };
  const f64 = () => { const v = dv.getFloat64(at, true); at += 8; return v; };
  const h = { version, headerSize: size };
  h.frameRateNum = u32(); h.frameRateDen = u32();
  h.codec = u8(); h.posePrediction = u8(); h.numJoints = u16();
  h.atlasWidth = u16(); h.atlasHeight = u16(); h.numTriangles = u32();
  h.scaleStep = f64(); h.translationStep = f64(); h.rotationStep = f64();
  h.keyframeInterval = u32(); h.targetKbps = u32();
  const cam = { width: u16(), height: u16() };
  cam.fx = f64(); cam.fy = f64(); cam.cx = f64(); cam.cy = f64();
  cam.worldToCamera = [];  // 3 x 4 row-major
  for (let i = 0; i < 12; ++i) cam.worldToCamera.push(f64());
  h.camera = cam;
  const glbSize = u32();
  if (at + glbSize + 4 !== size) fail('fields do not fit the header size (malformed)');
  h.glb = bytes.subarray(at, at + glbSize);
  if (!h.frameRateNum || !h.frameRateDen) fail('frame rate 0');
  if (h.codec > 3) fail(`unknown codec ${h.codec}`);
  h.frameRate = h.frameRateNum / h.frameRateDen;
  h.codecName = CODEC_NAMES[h.codec];
  return h;
}

// The intact record at `offset` ({frame, keyframe, hasMask, pose, mask, video, shape, offset,
// size}; shape: the rest-shape payload, empty when the record has none), or {error} saying
// what is wrong there. version: the stream's (rest shapes from version 2).
export function recordAt(bytes, offset, version = 2) {
  if (offset + RECORD_FRAMING > bytes.length)
    return { error: `truncated record (${bytes.length - offset} bytes left)` };
  if (!isMagic(bytes, offset, 'ARXF')) return { error: 'no record sync word' };
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const frame = dv.getUint32(offset + 4, true);
  const flags = dv.getUint8(offset + 8);
  const p = dv.getUint16(offset + 10, true);
  const m = dv.getUint32(offset + 12, true);
  const v = dv.getUint32(offset + 16, true);
  const hasShape = (flags & 4) !== 0 && version >= 2;
  const s = hasShape ? dv.getUint32(offset + 20, true) : 0;
  if (m > MAX_PAYLOAD || v > MAX_PAYLOAD || s > MAX_PAYLOAD) return { error: 'implausible payload sizes' };
  const head = hasShape ? 24 : 20;
  const size = RECORD_FRAMING + (head - 20) + p + m + v + s;
  if (offset + size > bytes.length)
    return { error: `truncated record (needs ${size} bytes, ${bytes.length - offset} left)` };
  if (dv.getUint32(offset + size - 4, true) !== crc32(bytes, offset, offset + size - 4))
    return { error: 'CRC mismatch (damaged record)' };
  const b = offset + head;
  return {
    frame, keyframe: (flags & 1) !== 0, hasMask: (flags & 2) !== 0, offset, size,
    pose: bytes.subarray(b, b + p), mask: bytes.subarray(b + p, b + p + m),
    video: bytes.subarray(b + p + m, b + p + m + v),
    shape: bytes.subarray(b + p + m + v, b + p + m + v + s),
  };
}

// Every intact record of a whole stream after its header, with the damage found (offset,
// frame expected there, what) -- the reader of stream/container.cc.
export function indexRecords(bytes, header) {
  const records = [], issues = [];
  let at = header.headerSize, last = -1;
  while (at < bytes.length) {
    let r = recordAt(bytes, at, header.version);
    if (r.error) {
      const issue = { offset: at, frame: last + 1, what: r.error };
      let next = at + 1;
      for (; next + 4 <= bytes.length; ++next) {
        if (!isMagic(bytes, next, 'ARXF')) continue;
        r = recordAt(bytes, next, header.version);
        if (!r.error) break;
      }
      if (r.error) { issue.what += '; no intact record after it'; issues.push(issue); break; }
      issue.what += `; resynchronised at byte ${next} (frame ${r.frame})`;
      issues.push(issue);
      at = next;
    }
    records.push(r);
    at += r.size;
    last = r.frame;
  }
  return { records, issues };
}

// ---- Pose payload (stream/bit_io.cc, stream/pose_codec.cc) ----

class BitReader {
  constructor(data) { this.data = data; this.pos = 0; }
  get(count) {  // null when the input ends
    if (count === 0) return 0;
    if (this.pos + count > 8 * this.data.length) { this.pos = 8 * this.data.length; return null; }
    let v = 0;
    for (let i = 0; i < count; ++i, ++this.pos)
      v = v * 2 + ((this.data[this.pos >> 3] >> (7 - (this.pos & 7))) & 1);
    return v;  // exact up to 2^53
  }
  unary(maxOnes) {
    let ones = 0;
    for (;;) {
      const bit = this.get(1);
      if (bit === null) return null;
      if (!bit) return ones;
      if (++ones > maxOnes) return null;
    }
  }
  expGolomb(k) {
    let zeros = 0;
    for (;;) {
      const bit = this.get(1);
      if (bit === null) return null;
      if (bit) break;
      if (++zeros > 32) return null;
    }
    const rest = this.get(zeros);
    if (rest === null) return null;
    const high = 2 ** zeros + rest - 1;
    const low = this.get(k);
    if (low === null) return null;
    const v = high * 2 ** k + low;
    return v > 0xffffffff ? null : v;
  }
}

const unZigZag = (u) => (u % 2 ? -(u + 1) / 2 : u / 2);
const RICE_ESCAPE = 20, RICE_RESET = 32, KEYFRAME_ORDER = 12;

class AdaptiveRice {
  constructor() { this.reset(); }
  reset() { this.sum = 2; this.count = 1; }
  parameter() {
    let k = 0;
    while (k < 24 && this.count * 2 ** k < this.sum) ++k;
    return k;
  }
  update(magnitude) {
    this.sum += magnitude;
    if (++this.count >= RICE_RESET) { this.sum = Math.floor((this.sum + 1) / 2); this.count = Math.floor(this.count / 2); }
  }
  decode(reader) {
    const k = this.parameter();
    const q = reader.unary(RICE_ESCAPE);
    if (q === null) return null;
    let u;
    if (q === RICE_ESCAPE) {
      u = reader.get(32);
      if (u === null) return null;
    } else {
      const low = reader.get(k);
      if (low === null) return null;
      u = q * 2 ** k + low;
    }
    this.update(Math.floor(u / 2));
    return unZigZag(u);
  }
}

// Decodes pose payloads into pose vectors (Float64Array: scale, translation, global rotation
// vector, one rotation vector per joint -- Pose::ToVector of the sender, quantised).
export class PoseDecoder {
  constructor(header) {
    this.n = 7 + 3 * header.numJoints;
    this.steps = new Float64Array(this.n);
    for (let i = 0; i < this.n; ++i)
      this.steps[i] = i === 0 ? header.scaleStep : i < 4 ? header.translationStep : header.rotationStep;
    this.velocity = header.posePrediction === 1;
    this.previous = new Float64Array(this.n);
    this.before = new Float64Array(this.n);
    this.codes = Array.from({ length: this.n }, () => new AdaptiveRice());
    this.history = 0;
  }
  reset() { this.history = 0; }
  predict(i) {
    if (this.history === 0) return 0;
    if (this.history === 1 || !this.velocity) return this.previous[i];
    return Math.max(-2147483648, Math.min(2147483647, 2 * this.previous[i] - this.before[i]));
  }
  // Throws an Error for a malformed payload or a delta without a preceding keyframe (the
  // decoder then needs a keyframe again).
  decode(payload, keyframe) {
    if (!keyframe && this.history === 0) throw new Error('pose delta frame without a preceding keyframe');
    const reader = new BitReader(payload);
    const q = new Float64Array(this.n);
    const fail = (what) => { this.history = 0; throw new Error(what); };
    if (keyframe) {
      for (const c of this.codes) c.reset();
      for (let i = 0; i < this.n; ++i) {
        const u = reader.expGolomb(KEYFRAME_ORDER);
        if (u === null) fail(`pose keyframe payload ends early (parameter ${i})`);
        q[i] = unZigZag(u);
      }
    } else {
      for (let i = 0; i < this.n; ++i) {
        const r = this.codes[i].decode(reader);
        if (r === null) fail(`pose payload ends early (parameter ${i})`);
        q[i] = (this.predict(i) + r) | 0;  // int32 wrap-around as in the sender
      }
    }
    if (reader.pos + 8 <= 8 * payload.length) fail('pose payload longer than its parameters');
    const v = new Float64Array(this.n);
    for (let i = 0; i < this.n; ++i) v[i] = q[i] * this.steps[i];
    if (!(v[0] > 0)) fail(`decoded pose: expected a positive scale, found ${v[0]}`);
    this.before = this.previous;
    this.previous = q;
    this.history = keyframe ? 1 : Math.min(2, this.history + 1);
    return v;
  }
}

// ---- Coverage payload: zlib-deflated bits (XOR with the previous bits on delta frames) ----

export async function inflate(bytes) {
  const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream('deflate'));
  return new Uint8Array(await new Response(stream).arrayBuffer());
}

// Updates `bits` (Uint8Array of ceil(F / 8)) in place; returns the number of textured triangles.
export async function applyCoverage(payload, keyframe, bits) {
  const raw = await inflate(payload);
  if (raw.length !== bits.length)
    throw new Error(`coverage payload: expected ${bits.length} bytes of bits, found ${raw.length}`);
  for (let i = 0; i < bits.length; ++i) bits[i] = keyframe ? raw[i] : bits[i] ^ raw[i];
  return countBits(bits);
}

export function countBits(bits) {
  let n = 0;
  for (const b of bits) { let x = b; while (x) { n += x & 1; x >>= 1; } }
  return n;
}

// ---- Template (the header's glb, docs/formats-template.md) ----

// {positions (Float32Array 3N, rest, per glTF vertex), uvs (Float32Array 2N), indices
// (Uint32Array 3F), vertexJoint, lbsWeight, slerpTau (per glTF vertex), joints: [{name,
// parent, center, axis}]}. glTF vertices are the template's vertices split at UV seams; every
// copy carries its vertex's skinning constants, so skinning them gives the template's surface.
export function parseTemplateGlb(glb) {
  const dv = new DataView(glb.buffer, glb.byteOffset, glb.byteLength);
  if (glb.length < 20 || dv.getUint32(0, true) !== 0x46546c67) throw new Error('template: not a glTF binary (magic glTF)');
  const jsonLength = dv.getUint32(12, true);
  if (dv.getUint32(16, true) !== 0x4e4f534a) throw new Error('template: first glb chunk is not JSON');
  const gltf = JSON.parse(new TextDecoder().decode(glb.subarray(20, 20 + jsonLength)));
  const binAt = 20 + jsonLength;
  const binLength = dv.getUint32(binAt, true);
  const bin = glb.subarray(binAt + 8, binAt + 8 + binLength);
  const COMPONENTS = { SCALAR: 1, VEC2: 2, VEC3: 3, VEC4: 4 };
  const accessor = (index, what) => {
    const a = gltf.accessors[index];
    if (!a) throw new Error(`template: missing accessor for ${what}`);
    const view = gltf.bufferViews[a.bufferView];
    const n = a.count * COMPONENTS[a.type];
    const at = bin.byteOffset + (view.byteOffset || 0) + (a.byteOffset || 0);
    const copy = (T, size) => new T(bin.buffer.slice(at, at + n * size));
    switch (a.componentType) {
      case 5126: return copy(Float32Array, 4);
      case 5125: return copy(Uint32Array, 4);
      case 5123: return copy(Uint16Array, 2);
      default: throw new Error(`template: ${what}: unsupported component type ${a.componentType}`);
    }
  };
  const prim = gltf.meshes[0].primitives[0];
  const attr = prim.attributes;
  for (const name of ['POSITION', 'TEXCOORD_0', '_ARTEX_JOINT', '_ARTEX_LBS_WEIGHT', '_ARTEX_SLERP_TAU'])
    if (attr[name] === undefined) throw new Error(`template: the mesh has no ${name} attribute (not an artex template with an atlas)`);
  const skin = gltf.skins[0];
  const nodeToJoint = new Map();
  skin.joints.slice(1).forEach((node, j) => nodeToJoint.set(node, j));
  const parentOf = new Map();
  gltf.nodes.forEach((node, i) => (node.children || []).forEach((c) => parentOf.set(c, i)));
  const joints = skin.joints.slice(1).map((node, j) => {
    const n = gltf.nodes[node];
    const parentNode = parentOf.get(node);
    const center = n.extras && n.extras.artex_center, axis = n.extras && n.extras.artex_twist_axis;
    if (!center || !axis) throw new Error(`template: joint ${j} (${n.name}) lacks artex_center / artex_twist_axis`);
    const parent = nodeToJoint.has(parentNode) ? nodeToJoint.get(parentNode) : -1;
    if (parent >= j) throw new Error(`template: joint ${j} (${n.name}) has parent ${parent} after it`);
    return { name: n.name, parent, center, axis };
  });
  const vertexJoint = Int32Array.from(accessor(attr._ARTEX_JOINT, 'joints'), Math.round);
  // One glTF vertex per template vertex (the first copy; copies are sorted by template vertex).
  // templateVertex: the template vertex of each glTF vertex (the rest shapes' order).
  const uniqueVertices = [];
  let templateVertex;
  if (attr._ARTEX_VERTEX !== undefined) {
    templateVertex = Int32Array.from(accessor(attr._ARTEX_VERTEX, 'template vertex indices'), Math.round);
    let last = -1;
    templateVertex.forEach((tv, i) => {
      if (tv !== last) uniqueVertices.push(i);
      last = tv;
    });
  } else {
    templateVertex = Int32Array.from(vertexJoint, (_, i) => i);
    for (let i = 0; i < vertexJoint.length; ++i) uniqueVertices.push(i);
  }
  const t = {
    positions: accessor(attr.POSITION, 'positions'),
    uvs: accessor(attr.TEXCOORD_0, 'UVs'),
    indices: Uint32Array.from(accessor(prim.indices, 'indices')),
    vertexJoint,
    uniqueVertices,
    templateVertex,
    lbsWeight: accessor(attr._ARTEX_LBS_WEIGHT, 'LBS weights'),
    slerpTau: accessor(attr._ARTEX_SLERP_TAU, 'SLERP tau'),
    joints,
  };
  for (const k of vertexJoint)
    if (k < 0 || k >= joints.length) throw new Error(`template: vertex joint ${k} outside 0..${joints.length - 1}`);
  return t;
}

// ---- Rest shape of a record (stream/rest_shape.cc) ----

// The header's template `base` with a record's rest shape: the payload's joint centres and
// vertices (base vertex + int16 q * step, per template vertex), the rig, mesh and weights
// unchanged. Throws an Error for a damaged payload or one of another template.
export function applyRestShape(base, payload) {
  const dv = new DataView(payload.buffer, payload.byteOffset, payload.byteLength);
  const J = base.joints.length, V = base.uniqueVertices.length;
  const expected = 14 + 24 * J + 6 * V;
  if (payload.length < 14) throw new Error(`rest shape: ${payload.length} bytes, expected ${expected}`);
  const joints = dv.getUint16(0, true), vertices = dv.getUint32(2, true), step = dv.getFloat64(6, true);
  if (joints !== J || vertices !== V)
    throw new Error(`rest shape: ${joints} joints and ${vertices} vertices, expected the header template's ${J} and ${V}`);
  if (payload.length !== expected || !(step > 0) || !Number.isFinite(step))
    throw new Error(`rest shape: ${payload.length} bytes with step ${step}, expected ${expected} bytes, step > 0`);
  let at = 14;
  const shapedJoints = base.joints.map((j) => {
    const center = [0, 1, 2].map((i) => dv.getFloat64(at + 8 * i, true));
    at += 24;
    if (!center.every(Number.isFinite)) throw new Error(`rest shape: joint ${j.name}'s centre is not finite`);
    return { ...j, center };
  });
  const positions = new Float64Array(base.positions.length);
  for (let g = 0; g < base.templateVertex.length; ++g) {
    const q = at + 6 * base.templateVertex[g];
    for (let i = 0; i < 3; ++i) positions[3 * g + i] = base.positions[3 * g + i] + dv.getInt16(q + 2 * i, true) * step;
  }
  return { ...base, positions, joints: shapedJoints };
}

// ---- Skinning (models/skinning.cc) ----

// 3 x 3 matrices as row-major Float64Array(9).
function mul(a, b) {
  const r = new Float64Array(9);
  for (let i = 0; i < 3; ++i)
    for (let j = 0; j < 3; ++j) r[3 * i + j] = a[3 * i] * b[j] + a[3 * i + 1] * b[3 + j] + a[3 * i + 2] * b[6 + j];
  return r;
}
function apply(m, x, y, z) {
  return [m[0] * x + m[1] * y + m[2] * z, m[3] * x + m[4] * y + m[5] * z, m[6] * x + m[7] * y + m[8] * z];
}
const IDENTITY = Float64Array.of(1, 0, 0, 0, 1, 0, 0, 0, 1);

// Unit quaternion [w, x, y, z] of a rotation vector.
function quatOf(wx, wy, wz) {
  const theta = Math.hypot(wx, wy, wz);
  if (theta < 1e-12) {
    const q = [1, wx / 2, wy / 2, wz / 2], l = Math.hypot(...q);
    return q.map((v) => v / l);
  }
  const s = Math.sin(theta / 2) / theta;
  return [Math.cos(theta / 2), s * wx, s * wy, s * wz];
}
function quatMatrix([w, x, y, z]) {
  return Float64Array.of(
    1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
    2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
    2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y));
}
function quatMul([aw, ax, ay, az], [bw, bx, by, bz]) {
  return [aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
    aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw];
}
// Rodrigues: ExpSO3 of models/so3.cc.
export function expSO3(wx, wy, wz) {
  return quatMatrix(quatOf(wx, wy, wz));
}
// DecomposeSwingTwist of models/so3.cc: r = swing * twist, twist about the unit axis a.
function swingTwist(q, a) {
  const p = q[1] * a[0] + q[2] * a[1] + q[3] * a[2];
  const n = Math.sqrt(p * p + q[0] * q[0]);
  if (n < 1e-12) return { swing: quatMatrix(q), angle: 0 };
  let tw = [q[0] / n, a[0] * p / n, a[1] * p / n, a[2] * p / n];
  if (tw[0] < 0) tw = tw.map((v) => -v);
  const angle = 2 * Math.atan2(tw[1] * a[0] + tw[2] * a[1] + tw[3] * a[2], tw[0]);
  const swing = quatMatrix(quatMul(q, [tw[0], -tw[1], -tw[2], -tw[3]]));
  return { swing, angle };
}

export class Skinning {
  constructor(tmpl) {
    this.t = tmpl;
    const n = tmpl.vertexJoint.length;
    this.axes = tmpl.joints.map(({ axis }) => { const l = Math.hypot(...axis); return axis.map((v) => v / l); });
    this.offset = new Float64Array(3 * n);
    this.radial = new Float64Array(3 * n);
    this.cross = new Float64Array(3 * n);  // a x radial
    for (let v = 0; v < n; ++v) {
      const k = tmpl.vertexJoint[v], a = this.axes[k], c = tmpl.joints[k].center;
      const o = [0, 1, 2].map((i) => tmpl.positions[3 * v + i] - c[i]);
      const along = a[0] * o[0] + a[1] * o[1] + a[2] * o[2];
      const d = [0, 1, 2].map((i) => o[i] - a[i] * along);
      this.offset.set(o, 3 * v);
      this.radial.set(d, 3 * v);
      this.cross.set([a[1] * d[2] - a[2] * d[1], a[2] * d[0] - a[0] * d[2], a[0] * d[1] - a[1] * d[0]], 3 * v);
    }
  }
  // Posed positions (Float32Array 3N, or `out`) of a pose vector (parseable by PoseDecoder).
  apply(pose, out = new Float32Array(this.offset.length)) {
    const joints = this.t.joints;
    const s0 = pose[0], t0 = [pose[1], pose[2], pose[3]];
    const r0 = expSO3(pose[4], pose[5], pose[6]);
    const frames = [];
    for (let j = 0; j < joints.length; ++j) {
      const { parent, center: t } = joints[j];
      const b = 7 + 3 * j;
      const q = quatOf(pose[b], pose[b + 1], pose[b + 2]);
      const r = quatMatrix(q);
      const pl = parent >= 0 ? frames[parent].chainLinear : IDENTITY;
      const po = parent >= 0 ? frames[parent].chainOffset : [0, 0, 0];
      const rt = apply(r, ...t);
      const pd = apply(pl, t[0] - rt[0], t[1] - rt[1], t[2] - rt[2]);
      const chainLinear = mul(pl, r);
      const chainOffset = [pd[0] + po[0], pd[1] + po[1], pd[2] + po[2]];
      const parentWorld = mul(r0, pl);
      const scaledParent = parentWorld.map((v) => s0 * v);
      const pt = apply(pl, ...t);
      const cu = apply(r0, pt[0] + po[0], pt[1] + po[1], pt[2] + po[2]);
      const center = [s0 * cu[0] + t0[0], s0 * cu[1] + t0[1], s0 * cu[2] + t0[2]];
      const st = swingTwist(q, this.axes[j]);
      frames.push({ chainLinear, chainOffset, scaledParent, scaledSwing: mul(scaledParent, st.swing), center, angle: st.angle });
    }
    const { vertexJoint, lbsWeight, slerpTau } = this.t;
    const off = this.offset, rad = this.radial, cr = this.cross;
    for (let v = 0, i = 0; v < vertexJoint.length; ++v, i += 3) {
      const f = frames[vertexJoint[v]], w = lbsWeight[v];
      const angle = slerpTau[v] * f.angle, c = Math.cos(angle) - 1, s = Math.sin(angle);
      const ux = off[i] + c * rad[i] + s * cr[i];
      const uy = off[i + 1] + c * rad[i + 1] + s * cr[i + 1];
      const uz = off[i + 2] + c * rad[i + 2] + s * cr[i + 2];
      const A = f.scaledSwing, B = f.scaledParent, m = 1 - w;
      out[i] = w * (A[0] * ux + A[1] * uy + A[2] * uz) + m * (B[0] * ux + B[1] * uy + B[2] * uz) + f.center[0];
      out[i + 1] = w * (A[3] * ux + A[4] * uy + A[5] * uz) + m * (B[3] * ux + B[4] * uy + B[5] * uz) + f.center[1];
      out[i + 2] = w * (A[6] * ux + A[7] * uy + A[8] * uz) + m * (B[6] * ux + B[7] * uy + B[8] * uz) + f.center[2];
    }
    return out;
  }
}

// ---- Viewpoints (render/camera.cc, texture/texture_quality.cc) ----

// Camera centre of a 3 x 4 row-major world-to-camera [R | t]: -R^T t.
export function cameraCenter(m) {
  return [0, 1, 2].map((i) => -(m[i] * m[3] + m[4 + i] * m[7] + m[8 + i] * m[11]));
}

// The sender's camera turned by `yawDeg` about the world up axis (+Y) through `target` and
// raised by `height` (m): the eye of HeldOutCameras, which `artex stream play` renders from.
export function heldOutEye(worldToCamera, target, yawDeg, height) {
  const c = cameraCenter(worldToCamera);
  const a = (yawDeg * Math.PI) / 180, ca = Math.cos(a), sa = Math.sin(a);
  const d = [c[0] - target[0], c[1] - target[1], c[2] - target[2]];
  return [ca * d[0] + sa * d[2] + target[0], d[1] + target[1] + height, -sa * d[0] + ca * d[2] + target[2]];
}

// Mean of the posed positions of the template's vertices (`unique`: one glTF vertex per
// template vertex, Template.uniqueVertices): the target of the held-out views.
export function meanOf(positions, unique) {
  const m = [0, 0, 0];
  for (const v of unique) for (let i = 0; i < 3; ++i) m[i] += positions[3 * v + i];
  return m.map((x) => x / unique.length);
}
