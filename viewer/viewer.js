// The page of the artex viewer (docs/viewer.md): plays an .artx stream from a file
// (/stream.artx or ?stream=URL) or live (?live=1, the server's WebSocket /live). The template
// comes from the stream's header, poses are skinned on the CPU with artex's skinning
// (artx.js: LBS of the swing + SLERP of the twist; never three.js's SkinnedMesh), the atlas
// video is decoded by WebCodecs' VideoDecoder and shown unlit, as artex's own renders.
// URL parameters: stream, live, frame (seek there and pause), yaw / height (viewpoint: the
// sender's camera turned about the model, as `artex stream play --views`), autoplay (0/1),
// bench (render that many frames as fast as possible and report the frame rate).
// window.artex exposes the state and measurements to tests (scripts/viewer_test.mjs).
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import {
  parseHeader, indexRecords, recordAt, PoseDecoder, applyCoverage, parseTemplateGlb, Skinning,
  applyRestShape,
  heldOutEye, meanOf,
} from './artx.js';

const params = new URLSearchParams(location.search);
const $ = (id) => document.getElementById(id);
const state = {
  ready: false, error: null, mode: null, frame: -1, frames: 0, playing: params.get('autoplay') !== '0',
  shown: 0, skipped: 0, decoded: 0, playFrames: 0, playSeconds: 0, dropped: 0, bytes: 0, textured: 0, numTriangles: 0,
  decodeMs: [], poseMs: [], latencyMs: [], receiveMs: [], decodedMs: [], encodeMs: [], pageMs: [], composeMs: [], fromAtlasMs: [], renderMs: [], fps: 0, benchFps: null, liveDone: false,
  codec: null,
};
window.artex = state;

function fail(e) {
  state.error = String(e && e.message ? e.message : e);
  $('error').textContent = state.error;
  console.error(e);
}
const median = (a) => { if (!a.length) return NaN; const s = [...a].sort((x, y) => x - y); return s[s.length >> 1]; };
const fmt = (x, d = 1) => (Number.isFinite(x) ? x.toFixed(d) : '–');

// ---- Scene ----
const canvas = $('view');
const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
renderer.outputColorSpace = THREE.LinearSRGBColorSpace;  // bytes as decoded, as artex renders
renderer.setPixelRatio(1);
renderer.setClearColor(0x000000, 1);
const scene = new THREE.Scene();
const camera = new THREE.PerspectiveCamera();
// tmpl: the header's template; skinning: of it with the latest rest shape read (docs/streaming.md).
let controls, mesh, geometry, skinning, tmpl, header, texture, posed, yuv;
// ?upload=frame: the VideoFrame itself as the texture (the browser converts it to RGB);
// default: its I420 planes, converted in the shader (the same matrix as artex's decoder).
const uploadYuv = params.get('upload') !== 'frame';
let homeEye, homeTarget;

// Projection of artex's pinhole camera (pixel centres at integers, OpenCV frame) in GL clip
// space; near / far planes 0.05 / 100 m.
function pinholeProjection(cam, near = 0.05, far = 100) {
  const { width: W, height: H, fx, fy, cx, cy } = cam;
  const m = new THREE.Matrix4();
  m.set(2 * fx / W, 0, 1 - 2 * (cx + 0.5) / W, 0,
    0, 2 * fy / H, 2 * (cy + 0.5) / H - 1, 0,
    0, 0, -(far + near) / (far - near), -2 * far * near / (far - near),
    0, 0, -1, 0);
  return m;
}

function setupScene() {
  const cam = header.camera;
  canvas.width = cam.width;
  canvas.height = cam.height;
  renderer.setSize(cam.width, cam.height, false);
  camera.projectionMatrix.copy(pinholeProjection(cam));
  camera.projectionMatrixInverse.copy(camera.projectionMatrix).invert();
  camera.updateProjectionMatrix = () => {};  // keep the pinhole projection (OrbitControls)
  geometry = new THREE.BufferGeometry();
  posed = new Float32Array(tmpl.positions.length);
  geometry.setAttribute('position', new THREE.BufferAttribute(posed, 3).setUsage(THREE.DynamicDrawUsage));
  geometry.setAttribute('uv', new THREE.BufferAttribute(tmpl.uvs, 2));
  geometry.setIndex(new THREE.BufferAttribute(tmpl.indices, 1));
  let material = new THREE.MeshBasicMaterial({ color: 0x404040, side: THREE.DoubleSide });
  if (header.codec !== 0 && uploadYuv) {
    // The decoded I420 planes as three one-channel textures, converted to RGB in the fragment
    // shader with the BT.601 studio-range matrix that artex's decoder (OpenCV) uses.
    const W = header.atlasWidth, H = header.atlasHeight;
    const plane = (w, h) => {
      const t = new THREE.DataTexture(new Uint8Array(w * h), w, h, THREE.RedFormat, THREE.UnsignedByteType);
      t.flipY = false;  // artex's UV v runs downwards: image row = v * height
      t.colorSpace = THREE.NoColorSpace;
      t.generateMipmaps = false;
      t.minFilter = t.magFilter = THREE.LinearFilter;
      t.unpackAlignment = 1;
      return t;
    };
    yuv = { y: plane(W, H), u: plane(W / 2, H / 2), v: plane(W / 2, H / 2), W, H };
    material = new THREE.ShaderMaterial({
      side: THREE.DoubleSide,
      uniforms: { yTex: { value: yuv.y }, uTex: { value: yuv.u }, vTex: { value: yuv.v }, lit: { value: 0 } },
      vertexShader: 'varying vec2 vUv; void main() { vUv = uv; gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0); }',
      fragmentShader: `precision highp float;
        uniform sampler2D yTex, uTex, vTex; uniform float lit; varying vec2 vUv;
        void main() {
          float y = 1.164 * (255.0 * texture2D(yTex, vUv).r - 16.0);
          float u = 255.0 * texture2D(uTex, vUv).r - 128.0, v = 255.0 * texture2D(vTex, vUv).r - 128.0;
          vec3 rgb = vec3(y + 1.596 * v, y - 0.813 * v - 0.391 * u, y + 2.018 * u) / 255.0;
          gl_FragColor = vec4(lit > 0.5 ? clamp(rgb, 0.0, 1.0) : vec3(0.25), 1.0);
        }`,
    });
  } else if (header.codec !== 0) {
    texture = new THREE.VideoFrameTexture();
    texture.flipY = false;  // artex's UV v runs downwards: image row = v * height
    texture.colorSpace = THREE.NoColorSpace;
    texture.generateMipmaps = false;
    texture.minFilter = THREE.LinearFilter;
    texture.magFilter = THREE.LinearFilter;
    material.map = texture;
  }
  mesh = new THREE.Mesh(geometry, material);
  mesh.frustumCulled = false;
  scene.add(mesh);
  controls = new OrbitControls(camera, canvas);
  controls.enableDamping = false;
  state.numTriangles = header.numTriangles;
}

// The viewpoint of `artex stream play --views YAW --view-height H` for the current pose.
function placeCamera(yaw, height) {
  const target = meanOf(posed, tmpl.uniqueVertices);
  const eye = heldOutEye(header.camera.worldToCamera, target, yaw, height);
  camera.position.set(...eye);
  camera.up.set(0, 1, 0);
  camera.lookAt(...target);
  controls.target.set(...target);
  controls.update();
  homeEye = eye;
  homeTarget = target;
}

// ---- Decoding ----
let poseDecoder, videoDecoder, coverageBits, pendingFrames = new Map(), lastVideoFrame = null;
let latestPose = null, latestPoseFrame = -1, textureFrame = -1, dirty = true;

function codecString(firstKeyVideo) {
  if (header.codec === 1) return 'vp09.00.31.08';
  if (header.codec === 3) return 'av01.0.08M.08';
  // H.264: profile, constraints and level from the SPS of the first keyframe (Annex B).
  const v = firstKeyVideo;
  for (let i = 0; i + 4 < v.length; ++i) {
    if (v[i] === 0 && v[i + 1] === 0 && v[i + 2] === 1 && (v[i + 3] & 0x1f) === 7) {
      const h = (x) => x.toString(16).padStart(2, '0');
      return `avc1.${h(v[i + 4])}${h(v[i + 5])}${h(v[i + 6])}`;
    }
  }
  return 'avc1.640028';
}

function newVideoDecoder(firstKeyVideo) {
  if (videoDecoder && videoDecoder.state !== 'closed') videoDecoder.close();
  pendingFrames.clear();
  state.codec = codecString(firstKeyVideo);
  videoDecoder = new VideoDecoder({
    output: (frame) => {
      const f = Math.round(frame.timestamp);
      const p = pendingFrames.get(f);
      pendingFrames.delete(f);
      if (p) state.decodeMs.push(performance.now() - p.t);
      const show = () => {
        textureFrame = f;
        if (p && p.onShown) p.onShown(p.pose);
        dirty = true;
      };
      if (yuv) {
        if (frame.format !== 'I420') { fail(`atlas video: expected I420 pictures, found ${frame.format}`); frame.close(); return; }
        const { W, H } = yuv, buffer = new Uint8Array((W * H * 3) / 2);
        frame.copyTo(buffer, { layout: [{ offset: 0, stride: W }, { offset: W * H, stride: W / 2 },
          { offset: (W * H * 5) / 4, stride: W / 2 }] }).then(() => {
          frame.close();
          yuv.y.image.data.set(buffer.subarray(0, W * H));
          yuv.u.image.data.set(buffer.subarray(W * H, (W * H * 5) / 4));
          yuv.v.image.data.set(buffer.subarray((W * H * 5) / 4));
          yuv.y.needsUpdate = yuv.u.needsUpdate = yuv.v.needsUpdate = true;
          mesh.material.uniforms.lit.value = 1;
          show();
        }).catch(fail);
        return;
      }
      if (lastVideoFrame) lastVideoFrame.close();
      lastVideoFrame = frame;
      texture.setFrame(frame);
      mesh.material.color.setRGB(1, 1, 1);
      show();
    },
    error: fail,
  });
  videoDecoder.configure({
    codec: state.codec, codedWidth: header.atlasWidth, codedHeight: header.atlasHeight,
    optimizeForLatency: true,
  });
}

// Decodes one record: pose now, coverage asynchronously, the picture by the VideoDecoder.
// onShown (live) is called when the record's picture (or pose, without one) is current.
function decodeRecord(r, onShown) {
  state.bytes += r.size;
  if (r.keyframe) {
    poseDecoder.reset();
    if (header.codec !== 0 && (!videoDecoder || videoDecoder.state === 'closed' || state.needVideoReset)) {
      newVideoDecoder(r.video);
      state.needVideoReset = false;
    }
  }
  if (r.shape.length && !applyShape(r)) return false;
  const t = performance.now();
  try {
    latestPose = poseDecoder.decode(r.pose, r.keyframe);
    latestPose.skinning = skinning;  // the body this pose was fitted with
  } catch (e) {
    ++state.dropped;
    console.warn(`frame ${r.frame}: ${e.message}`);
    return false;
  }
  state.poseMs.push(performance.now() - t);
  latestPoseFrame = r.frame;
  ++state.decoded;
  if (r.hasMask && r.mask.length) {
    applyCoverage(r.mask, r.keyframe, coverageBits).then((n) => { state.textured = n; }).catch(fail);
  }
  if (header.codec !== 0 && r.video.length && videoDecoder && videoDecoder.state === 'configured') {
    pendingFrames.set(r.frame, { t: performance.now(), onShown, pose: latestPose });
    videoDecoder.decode(new EncodedVideoChunk({
      type: r.keyframe ? 'key' : 'delta', timestamp: r.frame, data: r.video,
    }));
  } else if (onShown) {
    onShown(latestPose);
  }
  dirty = true;
  return true;
}

// A record's rest shape: the body its pose and the later ones are skinned with.
function applyShape(r) {
  try {
    skinning = new Skinning(applyRestShape(tmpl, r.shape));
    return true;
  } catch (e) {
    ++state.dropped;
    console.warn(`frame ${r.frame}: ${e.message}`);
    return false;
  }
}

function showPose(pose = latestPose, frame = latestPoseFrame) {
  if (!pose) return;
  const t = performance.now();
  (pose.skinning || skinning).apply(pose, posed);
  geometry.attributes.position.needsUpdate = true;
  state.poseMs.push(performance.now() - t);
  state.frame = frame;
}

// ---- File playback ----
let fileKbps = 0, records = [], next = 0, lastTick = 0, seeking = false;

async function seek(frame) {
  // Decode from the last keyframe at or before `frame` up to it.
  let k = records.findIndex((r) => r.frame >= frame);
  if (k < 0) k = records.length - 1;
  let key = k;
  while (key > 0 && !records[key].keyframe) --key;
  // The rest shape is state: the latest before the keyframe (decodeRecord applies later ones).
  skinning = new Skinning(tmpl);
  for (let i = key - 1; i >= 0; --i) if (records[i].shape.length) { applyShape(records[i]); break; }
  state.needVideoReset = true;
  seeking = true;  // no playback ticks until the picture of `frame` is decoded
  // (not VideoDecoder.flush(): after a flush the decoder wants a keyframe again)
  let shown;
  const picture = new Promise((resolve) => { shown = resolve; });
  for (let i = key; i <= k; ++i) decodeRecord(records[i], i === k ? shown : undefined);
  next = k + 1;
  try {
    await Promise.race([picture, new Promise((resolve) => setTimeout(resolve, 10000))]);
  } finally {
    seeking = false;
  }
  showPose();
  $('seek').value = String(k);
  dirty = true;
}

async function playFile(url) {
  const response = await fetch(url);
  if (!response.ok) throw new Error(`${url}: HTTP ${response.status}`);
  const bytes = new Uint8Array(await response.arrayBuffer());
  start(parseHeader(bytes));
  const index = indexRecords(bytes, header);
  for (const i of index.issues) console.warn(`byte ${i.offset}, frame ${i.frame}: ${i.what}`);
  records = index.records;
  fileKbps = records.length ? (8 * header.frameRate * records.reduce((a, r) => a + r.size, 0)) / records.length / 1000 : 0;
  state.frames = records.length;
  state.issues = index.issues;
  $('seek').max = String(Math.max(0, records.length - 1));
  $('seek').oninput = () => { state.playing = false; $('play').textContent = 'Play'; seek(records[+$('seek').value].frame); };
  const target = params.has('frame') ? +params.get('frame') : records.length ? records[0].frame : 0;
  if (params.has('frame')) state.playing = false;
  $('play').textContent = state.playing ? 'Pause' : 'Play';
  if (records.length) await seek(target);
  placeCamera(+(params.get('yaw') || 0), +(params.get('height') || 0));
  state.ready = true;
}

function tickFile(now) {
  if (!state.playing || !records.length || seeking) return;
  if (now - lastTick < 1000 / header.frameRate) return;
  lastTick = now;
  if (next >= records.length) { state.playing = false; $('play').textContent = 'Play'; return; }
  const r = records[next++];
  decodeRecord(r);
  showPose();
  $('seek').value = String(next - 1);
}

// ---- Live ----
let pendingShow = null, presenting = null;
const slowMs = +(params.get('slow') || 0);  // tests: a browser slower than the sender
function playLive() {
  const ws = new WebSocket(`ws://${location.host}/live`);
  ws.binaryType = 'arraybuffer';
  let placed = false, handled = 0;
  // Flow control: the number of records handled so far (the server sends a few ahead only).
  const ack = () => { if (ws.readyState === WebSocket.OPEN) ws.send(String(++handled)); };
  ws.onmessage = (event) => {
    const all = new Uint8Array(event.data);
    const dv = new DataView(event.data);
    // Wall-clock stamps (ms): frame handed to the sender, its atlas composed, record published.
    const stamp = dv.getFloat64(0, true), atlasReady = dv.getFloat64(8, true);
    const published = dv.getFloat64(16, true);
    const bytes = all.subarray(24);
    if (slowMs > 0) { const until = performance.now() + slowMs; while (performance.now() < until); }
    if (!header) {
      try { start(parseHeader(bytes)); } catch (e) { fail(e); ws.close(); }
      return;
    }
    const r = recordAt(bytes, 0, header.version);
    if (r.error) { ++state.dropped; console.warn(`live record: ${r.error}`); ack(); return; }
    ++state.frames;
    const received = Date.now();
    state.receiveMs.push(received - stamp);
    state.encodeMs.push(published - stamp);
    state.composeMs.push(atlasReady - stamp);
    // Drawn at the next animation frame once its picture is decoded (a newer picture replaces
    // it: skipped); timed at the animation frame after the one that drew it, when the browser
    // has composited it. Drawing only in animation frames keeps a software GPU from queueing.
    const ok = decodeRecord(r, (pose) => {
      ack();
      state.decodedMs.push(Date.now() - stamp);
      if (pendingShow) ++state.skipped;
      pendingShow = { pose, frame: r.frame, stamp, atlasReady, received };
    });
    if (!ok) { ack(); return; }
    if (!placed && r.keyframe) {
      showPose();
      placeCamera(+(params.get('yaw') || 0), +(params.get('height') || 0));
      placed = true;
      state.ready = true;
    }
  };
  ws.onclose = () => { state.liveDone = true; report(true); };
  ws.onerror = () => fail('live: the WebSocket to the server failed');
}

// ---- Reporting (POST /report: printed by the server) ----
function summary() {
  const lat = state.latencyMs;
  return {
    mode: state.mode, codec: state.codec, frames_received: state.frames, frames_decoded: state.decoded,
    frames_shown: state.shown, frames_skipped: state.skipped, dropped: state.dropped, textured_triangles: state.textured,
    decode_ms_median: median(state.decodeMs), pose_and_skinning_ms_median: median(state.poseMs),
    render_ms_median: median(state.renderMs), fps: state.fps,
    playback_fps: state.playFrames / Math.max(1e-9, state.playSeconds), bench_fps: state.benchFps,
    sender_ms_median: median(state.encodeMs), atlas_compose_ms_median: median(state.composeMs), receive_ms_median: median(state.receiveMs),
    page_ms_median: median(state.pageMs), decoded_ms_median: median(state.decodedMs), latency_ms_median: median(lat), latency_ms_max: lat.length ? Math.max(...lat) : NaN,
    within_100ms: lat.length ? lat.filter((x) => x <= 100).length / lat.length : NaN,
    // The same from the composed atlas picture (the sender's atlas composition excluded).
    from_atlas_ms_median: median(state.fromAtlasMs),
    from_atlas_within_100ms: state.fromAtlasMs.length ? state.fromAtlasMs.filter((x) => x <= 100).length / state.fromAtlasMs.length : NaN,
  };
}
state.summary = summary;
function report(done) {
  const body = JSON.stringify({ ...summary(), done });
  return fetch('/report', { method: 'POST', body, headers: { 'content-type': 'application/json' } }).catch(() => {});
}

// ---- Main loop ----
let fpsCount = 0, fpsSince = performance.now(), bitsSince = 0, kbps = 0;
function render() {
  const t = performance.now();
  renderer.render(scene, camera);
  state.renderMs.push(performance.now() - t);
  if (state.renderMs.length > 600) state.renderMs.splice(0, 300);
  ++fpsCount;
}

let lastLoop = 0;
function loop(now) {
  requestAnimationFrame(loop);
  const previousLoop = lastLoop;
  lastLoop = now;
  if (!header) return;
  if (state.mode === 'file') tickFile(now);
  if (state.mode === 'live' && latestPoseFrame !== state.frame && header.codec === 0) dirty = true;
  if (presenting) {
    const now = Date.now();
    state.latencyMs.push(now - presenting.stamp);
    state.fromAtlasMs.push(now - presenting.atlasReady);
    state.pageMs.push(now - presenting.received);
    ++state.shown;
    presenting = null;
  }
  if (pendingShow) {
    showPose(pendingShow.pose, pendingShow.frame);
    presenting = pendingShow;
    pendingShow = null;
    dirty = true;
  }
  if (dirty || (state.playing && state.mode === 'file')) {
    if (state.playing && state.mode === 'file' && previousLoop) {
      ++state.playFrames;
      state.playSeconds += (now - previousLoop) / 1000;
    }
    render();
    dirty = false;
    if (state.mode === 'file' && state.playing) ++state.shown;
  }
  if (now - fpsSince >= 1000) {
    state.fps = (1000 * fpsCount) / (now - fpsSince);
    kbps = (8 * (state.bytes - bitsSince)) / (now - fpsSince);
    bitsSince = state.bytes;
    fpsCount = 0;
    fpsSince = now;
    updatePanel();
    if (state.mode === 'live') report(false);
  }
}

function updatePanel() {
  if (!header) return;
  const lat = state.latencyMs;
  const rows = [
    ['mode', `${state.mode} (${header.codecName} ${header.atlasWidth}², ${fmt(header.frameRate, 0)} Hz)`],
    ['frame', `${state.frame}${state.mode === 'file' ? ` / ${records.length ? records[records.length - 1].frame : 0}` : ''}`],
    [state.mode === 'file' ? 'frames / drawn' : 'received / shown', `${state.frames} / ${state.shown}${state.dropped ? `, ${state.dropped} dropped` : ''}`],
    state.mode === 'file'
      ? ['bitrate', `${fmt(fileKbps, 0)} kbit/s (the stream's mean; header ${fmt(header.headerSize / 1024, 0)} KiB)`]
      : ['bitrate', `${fmt(kbps, 0)} kbit/s (last second; ${fmt(state.bytes / 1024, 0)} KiB in all)`],
    ['page', `${fmt(state.fps, 0)} frames/s, render ${fmt(median(state.renderMs), 1)} ms`],
    ['decode', `picture ${fmt(median(state.decodeMs), 1)} ms, pose+skin ${fmt(median(state.poseMs), 2)} ms`],
    ['textured', `${state.textured} / ${state.numTriangles} triangles`],
  ];
  if (state.mode === 'live')
    rows.push(['latency', `${fmt(median(lat), 0)} ms median, ${fmt(100 * lat.filter((x) => x <= 100).length / Math.max(1, lat.length), 0)} % ≤ 100 ms`]);
  $('stats').innerHTML = rows.map(([k, v]) => `<tr><td>${k}</td><td>${v}</td></tr>`).join('');
}

function start(h) {
  header = h;
  tmpl = parseTemplateGlb(header.glb);
  skinning = new Skinning(tmpl);
  poseDecoder = new PoseDecoder(header);
  coverageBits = new Uint8Array(Math.ceil(header.numTriangles / 8));
  setupScene();
  $('play').onclick = () => {
    state.playing = !state.playing;
    $('play').textContent = state.playing ? 'Pause' : 'Play';
    if (state.playing && state.mode === 'file' && next >= records.length) seek(records[0].frame);
  };
  $('home').onclick = () => {
    camera.position.set(...homeEye);
    controls.target.set(...homeTarget);
    controls.update();
    dirty = true;
  };
  controls.addEventListener('change', () => { dirty = true; });
  $('play').textContent = state.playing ? 'Pause' : 'Play';
}

// Renders `n` frames back to back (skinning of the current pose + draw + a pixel read to wait
// for the GPU) and returns their rate: the page's frame rate without the display's pacing.
state.bench = async (n) => {
  const gl = renderer.getContext(), px = new Uint8Array(4);
  const t = performance.now();
  for (let i = 0; i < n; ++i) {
    showPose();
    renderer.render(scene, camera);
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
  }
  state.benchFps = (1000 * n) / (performance.now() - t);
  return state.benchFps;
};
state.render = () => { render(); return true; };

async function main() {
  if (typeof VideoDecoder === 'undefined') throw new Error('this browser has no WebCodecs VideoDecoder');
  let info = { file: true, live: false };
  try { info = await (await fetch('/info.json')).json(); } catch (e) { /* a plain file server */ }
  requestAnimationFrame(loop);
  if (params.get('live') === '1') {
    state.mode = 'live';
    state.playing = true;
    playLive();
  } else {
    state.mode = 'file';
    await playFile(params.get('stream') || '/stream.artx');
    if (params.has('bench')) await state.bench(+params.get('bench'));
  }
  updatePanel();
}
main().catch(fail);
