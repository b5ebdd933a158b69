// Checks of the viewer's JavaScript receiver (viewer/artx.js) against artex itself, run by
// scripts/viewer_test under node's test runner:
//   ARTEX_BIN=build/experiments/artex ARTEX_STREAM=x.artx ARTEX_PLAYED=play/poses.csv \
//     ARTEX_TRACKED=run/tracked.glb node --test viewer/test/artx_test.mjs
// - the container and pose decoder reproduce `artex stream play`'s decoded poses;
// - a damaged record is reported and skipped, as stream/container.cc does;
// - the skinning reproduces `artex template pose` (models/skinning.cc) on a pose with strong
//   twists, where glTF's plain LBS (what three.js's SkinnedMesh computes) is millimetres off;
// - the stream's last rest shape (shape estimation) skins as the run's tracked template.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { spawnSync } from 'node:child_process';
import {
  parseHeader, indexRecords, PoseDecoder, parseTemplateGlb, Skinning, expSO3, applyCoverage,
  applyRestShape,
} from '../artx.js';

const { ARTEX_BIN, ARTEX_STREAM, ARTEX_PLAYED, ARTEX_TRACKED } = process.env;
const skip = !ARTEX_BIN || !ARTEX_STREAM ? 'ARTEX_BIN and ARTEX_STREAM not set' : false;
const bytes = skip ? null : new Uint8Array(fs.readFileSync(ARTEX_STREAM));

test('poses decode as artex stream play decodes them', { skip: skip || (!ARTEX_PLAYED && 'ARTEX_PLAYED not set') }, async () => {
  const header = parseHeader(bytes);
  const { records, issues } = indexRecords(bytes, header);
  assert.equal(issues.length, 0);
  const rows = fs.readFileSync(ARTEX_PLAYED, 'utf8').trim().split('\n').slice(1).map((l) => l.split(',').map(Number));
  assert.equal(records.length, rows.length);
  const decoder = new PoseDecoder(header);
  const bits = new Uint8Array(Math.ceil(header.numTriangles / 8));
  let worst = 0, textured = 0;
  records.forEach((r, i) => {
    const v = decoder.decode(r.pose, r.keyframe);
    assert.equal(r.frame, rows[i][0]);
    // poses.csv holds rotation vectors (LogSO3 of the decoded rotation): compare as rotations.
    worst = Math.max(worst, Math.abs(v[0] - rows[i][1]));
    for (let k = 1; k < 4; ++k) worst = Math.max(worst, Math.abs(v[k] - rows[i][k + 1]));
    for (let k = 4; k < v.length; k += 3) {
      const a = expSO3(v[k], v[k + 1], v[k + 2]), b = expSO3(rows[i][k + 1], rows[i][k + 2], rows[i][k + 3]);
      for (let e = 0; e < 9; ++e) worst = Math.max(worst, Math.abs(a[e] - b[e]));
    }
  });
  for (const r of records) if (r.hasMask) textured = await applyCoverage(r.mask, r.keyframe, bits);
  assert.ok(worst < 1e-6, `largest difference ${worst}`);
  assert.ok(textured > 0 && textured <= header.numTriangles, `${textured} textured triangles`);
});

test('a damaged record is reported and the reader resynchronises', { skip }, () => {
  const header = parseHeader(bytes);
  const { records } = indexRecords(bytes, header);
  assert.ok(records.length >= 3);
  const damaged = bytes.slice();
  damaged[records[1].offset + 30] ^= 0xff;  // inside record 1's payload
  const again = indexRecords(damaged, header);
  assert.equal(again.issues.length, 1);
  assert.match(again.issues[0].what, /CRC mismatch .*resynchronised at byte \d+ \(frame \d+\)/);
  assert.equal(again.issues[0].offset, records[1].offset);
  assert.equal(again.records.length, records.length - 1);
  assert.throws(() => parseHeader(bytes.subarray(0, 100)), /stream header \(byte 0\): header size/);
});

// glTF's skin (docs/formats-template.md): w_l A_k x + (1 - w_l) A_parent(k) x.
function plainLbs(tmpl, pose) {
  const J = tmpl.joints.length, A = [];
  const s0 = pose[0], r0 = expSO3(pose[4], pose[5], pose[6]);
  const mulm = (a, b) => Array.from({ length: 9 }, (_, e) => a[3 * Math.floor(e / 3)] * b[e % 3] + a[3 * Math.floor(e / 3) + 1] * b[3 + (e % 3)] + a[3 * Math.floor(e / 3) + 2] * b[6 + (e % 3)]);
  const app = (m, x) => [0, 1, 2].map((i) => m[3 * i] * x[0] + m[3 * i + 1] * x[1] + m[3 * i + 2] * x[2]);
  const global = { L: [1, 0, 0, 0, 1, 0, 0, 0, 1], o: [0, 0, 0] };
  for (let j = 0; j < J; ++j) {
    const { parent, center: t } = tmpl.joints[j];
    const p = parent >= 0 ? A[parent] : global;
    const r = expSO3(pose[7 + 3 * j], pose[8 + 3 * j], pose[9 + 3 * j]);
    const rt = app(r, t), pd = app(p.L, [t[0] - rt[0], t[1] - rt[1], t[2] - rt[2]]);
    A.push({ L: mulm(p.L, r), o: [0, 1, 2].map((i) => pd[i] + p.o[i]), parent: p });
  }
  const world = (T, x) => { const y = app(T.L, x); return app(r0, [y[0] + T.o[0], y[1] + T.o[1], y[2] + T.o[2]]).map((v, i) => s0 * v + pose[1 + i]); };
  const out = new Float64Array(tmpl.positions.length);
  for (let v = 0; v < tmpl.vertexJoint.length; ++v) {
    const x = [tmpl.positions[3 * v], tmpl.positions[3 * v + 1], tmpl.positions[3 * v + 2]];
    const T = A[tmpl.vertexJoint[v]], w = tmpl.lbsWeight[v];
    const a = world(T, x), b = world(T.parent, x);
    for (let i = 0; i < 3; ++i) out[3 * v + i] = w * a[i] + (1 - w) * b[i];
  }
  return out;
}

// A pose with strong twists about the limbs and the neck, and swings (degrees, as `artex
// template pose --joint` takes them), for a template's joints.
const TWISTS = { l_elbow: [0, 80, 40], neck: [10, 60, 0], r_wrist: [70, 20, 10], l_knee: [50, 30, 0], r_shoulder: [-30, 50, 40] };
function twistedPose(tmpl) {
  const pose = new Float64Array(7 + 3 * tmpl.joints.length);
  pose.set([1.03, 0.1, -0.05, 0.2, 0.1, 0.4, -0.05]);
  const names = tmpl.joints.map((j) => j.name);
  for (const [name, deg] of Object.entries(TWISTS)) {
    const j = names.indexOf(name);
    assert.ok(j >= 0, `joint ${name}`);
    for (let i = 0; i < 3; ++i) pose[7 + 3 * j + i] = (deg[i] * Math.PI) / 180;
  }
  return pose;
}

// `artex template pose` of the glb at `glbPath` in twistedPose: positions per template vertex
// (x y z nx ny nz rows of its PLY).
function artexPosed(glbPath, pose, joints) {
  const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'artex-viewer-'));
  const ply = path.join(dir, 'posed.ply');
  const run = spawnSync(ARTEX_BIN, ['template', 'pose', glbPath, '--pose', Array.from(pose.slice(0, 7)).concat(Array(3 * joints).fill(0)).join(' '),
    ...Object.entries(TWISTS).map(([n, d]) => ['--joint', `${n}=${d.join(',')}`]).flat(), '-o', ply], { encoding: 'utf8' });
  assert.equal(run.status, 0, run.stderr);
  const data = fs.readFileSync(ply);
  fs.rmSync(dir, { recursive: true });
  const end = data.indexOf('end_header\n') + 'end_header\n'.length;
  const V = +/element vertex (\d+)/.exec(data.subarray(0, end).toString())[1];
  return { V, rows: new Float32Array(data.buffer.slice(data.byteOffset + end, data.byteOffset + end + V * 24)) };
}

// Largest distance (m) between glTF-vertex positions and artex's rows (per template vertex).
function worstAgainst(tmpl, positions, ref) {
  let worst = 0;
  for (let g = 0; g < tmpl.templateVertex.length; ++g) {
    const t = tmpl.templateVertex[g];
    let d = 0;
    for (let i = 0; i < 3; ++i) d += (positions[3 * g + i] - ref.rows[6 * t + i]) ** 2;
    worst = Math.max(worst, Math.sqrt(d));
  }
  return worst;
}

test('skinning reproduces artex template pose (LBS + SLERP), plain LBS does not', { skip }, () => {
  const header = parseHeader(bytes);
  const tmpl = parseTemplateGlb(header.glb);
  const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'artex-viewer-'));
  const glb = path.join(dir, 'template.glb');
  fs.writeFileSync(glb, header.glb);
  const pose = twistedPose(tmpl);
  const ref = artexPosed(glb, pose, tmpl.joints.length);
  fs.rmSync(dir, { recursive: true });
  assert.equal(tmpl.uniqueVertices.length, ref.V);
  const posed = new Skinning(tmpl).apply(pose, new Float64Array(tmpl.positions.length));
  const worst = worstAgainst(tmpl, posed, ref), worstLbs = worstAgainst(tmpl, plainLbs(tmpl, pose), ref);
  console.log(`skinning vs artex: ${(1000 * worst).toFixed(4)} mm max; plain glTF LBS: ${(1000 * worstLbs).toFixed(1)} mm max`);
  assert.ok(worst < 2e-5, `viewer skinning ${1000 * worst} mm from artex's`);
  assert.ok(worstLbs > 5e-3, `plain LBS only ${1000 * worstLbs} mm off: the pose does not test the twist`);
});

// With shape estimation the stream's records carry the subject's rest shapes (docs/streaming.md):
// the last one is the template the run's last frames were tracked with (its tracked.glb).
test('the last rest shape skins as the run\'s tracked template', { skip: skip || (!ARTEX_TRACKED && 'ARTEX_TRACKED not set') }, () => {
  const header = parseHeader(bytes);
  assert.equal(header.version, 2);
  const { records } = indexRecords(bytes, header);
  const shaped = records.filter((r) => r.shape.length);
  assert.ok(shaped.length >= 1, 'no record carries a rest shape');
  for (const r of shaped) assert.ok(r.keyframe, `frame ${r.frame}: a rest shape on a delta frame`);
  const base = parseTemplateGlb(header.glb);
  const tmpl = applyRestShape(base, shaped[shaped.length - 1].shape);
  const pose = twistedPose(tmpl);
  const ref = artexPosed(ARTEX_TRACKED, pose, tmpl.joints.length);
  const worst = worstAgainst(tmpl, new Skinning(tmpl).apply(pose, new Float64Array(tmpl.positions.length)), ref);
  const header_ = worstAgainst(base, new Skinning(base).apply(pose, new Float64Array(base.positions.length)), ref);
  console.log(`rest shapes: ${shaped.length}; the last one's skinning vs artex's tracked template: ${(1000 * worst).toFixed(3)} mm max (the header's template: ${(1000 * header_).toFixed(1)} mm)`);
  assert.ok(worst < 1.5e-4, `${1000 * worst} mm from the tracked template (0.1 mm steps)`);
  assert.ok(header_ > 2e-3, `the shape moved the body by only ${1000 * header_} mm`);
  assert.throws(() => applyRestShape(base, shaped[0].shape.subarray(0, 100)), /rest shape: 100 bytes/);
});
