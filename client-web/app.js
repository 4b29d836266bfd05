// isoray browser client: shows streamed frames, sends camera, isovalue and size changes.
import { parseFrameHeader, FRAME_HEADER_LEN, CODECS } from './protocol.js';

const $ = (id) => document.getElementById(id);
const canvas = $('view');
const ctx = canvas.getContext('2d');
const statusEl = $('status');
const statsEl = $('stats');
const sceneSelect = $('scene');
const isoSlider = $('isovalue');
const isoOut = $('isovalue-out');

const params = new URLSearchParams(location.search);
const state = {
  scene: params.get('scene'),
  orbit: null,          // { target: [x,y,z], yaw, pitch, distance, fov }
  isovalue: params.has('iso') ? Number(params.get('iso')) : null,
  // Pinned scene time in seconds, or null to follow the live animation.
  time: params.has('t') && Number.isFinite(Number(params.get('t'))) ? Number(params.get('t')) : null,
  info: null,
  socket: null,
  nextInputId: 1,
  pendingInputs: new Map(), // input_id -> performance.now() when sent
  reconnectDelayMs: 250,
  cameraDirty: false,
};

// Statistics over a sliding one-second window; exposed for tests as window.isorayStats.
const stats = { frames: [], bytes: [], latencies: [], last: null, framesTotal: 0 };
window.isorayStats = stats;

function setStatus(text) {
  statusEl.textContent = text || '';
  statusEl.hidden = !text;
}

function showError(message) {
  const el = document.createElement('div');
  el.className = 'error';
  el.textContent = message;
  el.title = 'Click to dismiss';
  el.addEventListener('click', () => el.remove());
  $('errors').append(el);
  setTimeout(() => el.remove(), 8000);
}

function send(message) {
  if (!state.socket || state.socket.readyState !== WebSocket.OPEN) return;
  const inputId = state.nextInputId++;
  state.pendingInputs.set(inputId, performance.now());
  state.socket.send(JSON.stringify({ ...message, input_id: inputId }));
}

// --- camera -----------------------------------------------------------------------------
function orbitFromPose(pose) {
  const [ex, ey, ez] = pose.eye, [tx, ty, tz] = pose.target;
  const dx = ex - tx, dy = ey - ty, dz = ez - tz;
  const distance = Math.hypot(dx, dy, dz);
  return { target: [...pose.target], yaw: Math.atan2(dx, dz), pitch: Math.asin(dy / distance), distance, fov: pose.fov_y_deg };
}

function poseFromOrbit(o) {
  const cp = Math.cos(o.pitch);
  const eye = [
    o.target[0] + o.distance * cp * Math.sin(o.yaw),
    o.target[1] + o.distance * Math.sin(o.pitch),
    o.target[2] + o.distance * cp * Math.cos(o.yaw),
  ];
  return { eye, target: o.target, up: [0, 1, 0], fov_y_deg: o.fov };
}

function scheduleCamera() {
  if (state.cameraDirty) return;
  state.cameraDirty = true;
  requestAnimationFrame(() => {
    state.cameraDirty = false;
    if (!state.orbit) return;
    send({ type: 'camera', ...poseFromOrbit(state.orbit) });
    saveUrl();
  });
}

function saveUrl() {
  const p = new URLSearchParams();
  if (state.scene) p.set('scene', state.scene);
  if (state.orbit) {
    const o = state.orbit;
    p.set('cam', [o.yaw, o.pitch, o.distance, ...o.target].map((v) => +v.toFixed(5)).join(','));
  }
  if (state.isovalue !== null) p.set('iso', String(state.isovalue));
  if (state.time !== null) p.set('t', String(state.time));
  history.replaceState(null, '', `?${p}`);
}

function orbitFromUrl() {
  const cam = params.get('cam');
  if (!cam || !state.info) return null;
  const v = cam.split(',').map(Number);
  if (v.length !== 6 || v.some((x) => !Number.isFinite(x)) || v[2] <= 0) return null;
  return { yaw: v[0], pitch: v[1], distance: v[2], target: v.slice(3), fov: state.info.camera.fov_y_deg };
}

let drag = null;
canvas.addEventListener('pointerdown', (e) => {
  canvas.setPointerCapture(e.pointerId);
  drag = { x: e.clientX, y: e.clientY, pan: e.shiftKey || e.button === 2 };
  canvas.style.cursor = 'grabbing';
});
canvas.addEventListener('pointermove', (e) => {
  if (!drag || !state.orbit) return;
  const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
  drag.x = e.clientX; drag.y = e.clientY;
  const o = state.orbit;
  if (drag.pan) {
    const scale = o.distance * 0.0015;
    const right = [Math.cos(o.yaw), 0, -Math.sin(o.yaw)];
    o.target = o.target.map((t, i) => t - right[i] * dx * scale);
    o.target[1] += dy * scale;
  } else {
    o.yaw -= dx * 0.008;
    o.pitch = Math.max(-1.55, Math.min(1.55, o.pitch + dy * 0.008));
  }
  scheduleCamera();
});
const endDrag = () => { drag = null; canvas.style.cursor = 'grab'; };
canvas.addEventListener('pointerup', endDrag);
canvas.addEventListener('pointercancel', endDrag);
canvas.addEventListener('contextmenu', (e) => e.preventDefault());
canvas.addEventListener('wheel', (e) => {
  e.preventDefault();
  if (!state.orbit) return;
  state.orbit.distance = Math.max(0.1, Math.min(1e4, state.orbit.distance * Math.exp(e.deltaY * 0.001)));
  scheduleCamera();
}, { passive: false });
canvas.addEventListener('keydown', (e) => {
  if (!state.orbit) return;
  const step = { ArrowLeft: [0.05, 0], ArrowRight: [-0.05, 0], ArrowUp: [0, 0.05], ArrowDown: [0, -0.05] }[e.key];
  if (step) { state.orbit.yaw += step[0]; state.orbit.pitch = Math.max(-1.55, Math.min(1.55, state.orbit.pitch + step[1])); }
  else if (e.key === '+' || e.key === '=') state.orbit.distance *= 0.9;
  else if (e.key === '-') state.orbit.distance *= 1.1;
  else return;
  e.preventDefault();
  scheduleCamera();
});
$('reset').addEventListener('click', () => {
  if (!state.info) return;
  state.orbit = orbitFromPose(state.info.camera);
  scheduleCamera();
});
document.addEventListener('keydown', (e) => {
  if (e.key === 's' && e.target === document.body) statsEl.hidden = !statsEl.hidden;
});

isoSlider.addEventListener('input', () => {
  state.isovalue = Number(isoSlider.value);
  isoOut.textContent = state.isovalue.toFixed(3);
  send({ type: 'isovalue', value: state.isovalue });
  saveUrl();
});

// --- size -------------------------------------------------------------------------------
function renderSize() {
  const dpr = window.devicePixelRatio || 1;
  const rect = canvas.getBoundingClientRect();
  const max = state.info ? state.info.max_width : 4096;
  const maxH = state.info ? state.info.max_height : 4096;
  return [Math.max(1, Math.min(max, Math.round(rect.width * dpr))), Math.max(1, Math.min(maxH, Math.round(rect.height * dpr)))];
}
let lastSize = '';
function sendSize() {
  const [width, height] = renderSize();
  const key = `${width}x${height}`;
  if (key === lastSize || !state.socket || state.socket.readyState !== WebSocket.OPEN) return;
  lastSize = key;
  send({ type: 'resize', width, height });
}
new ResizeObserver(() => sendSize()).observe(canvas);

// --- frames -----------------------------------------------------------------------------
async function onFrame(socket, buffer) {
  const header = parseFrameHeader(buffer);
  try {
    await drawFrame(header, buffer);
  } finally {
    // Acknowledge once shown: the server sends only a small window of frames ahead of acks.
    if (socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify({ type: 'ack', sequence: header.sequence }));
  }
}

async function drawFrame(header, buffer) {
  const now = performance.now();
  const sentAt = state.pendingInputs.get(header.inputId);
  if (sentAt !== undefined) {
    stats.latencies.push([now, now - sentAt]);
    for (const id of state.pendingInputs.keys()) if (id <= header.inputId) state.pendingInputs.delete(id);
  }
  stats.frames.push(now);
  stats.bytes.push([now, buffer.byteLength]);
  stats.framesTotal += 1;
  stats.last = header;
  const blob = new Blob([new Uint8Array(buffer, FRAME_HEADER_LEN)], { type: CODECS[header.codec] || 'image/jpeg' });
  const bitmap = await createImageBitmap(blob);
  if (canvas.width !== header.width || canvas.height !== header.height) {
    canvas.width = header.width;
    canvas.height = header.height;
  }
  ctx.drawImage(bitmap, 0, 0);
  bitmap.close();
  setStatus('');
  canvas.dataset.frames = String(stats.framesTotal);
}

function updateStats() {
  const now = performance.now();
  const cut = now - 1000;
  while (stats.frames.length && stats.frames[0] < cut) stats.frames.shift();
  while (stats.bytes.length && stats.bytes[0][0] < cut) stats.bytes.shift();
  while (stats.latencies.length && stats.latencies[0][0] < now - 5000) stats.latencies.shift();
  const fps = stats.frames.length;
  const kbps = stats.bytes.reduce((a, [, b]) => a + b, 0) * 8 / 1000;
  const lat = stats.latencies.length ? stats.latencies[stats.latencies.length - 1][1] : NaN;
  const h = stats.last;
  stats.fps = fps;
  statsEl.textContent = [
    `fps      ${fps}`,
    `latency  ${Number.isNaN(lat) ? '–' : lat.toFixed(0) + ' ms'}`,
    `bitrate  ${(kbps / 1000).toFixed(2)} Mbit/s`,
    h ? `size     ${h.width}×${h.height}` : '',
    h ? `update   ${(h.updateUs / 1000).toFixed(2)} ms` : '',
    h ? `build    ${(h.buildUs / 1000).toFixed(2)} ms` : '',
    h ? `trace    ${(h.traceUs / 1000).toFixed(2)} ms` : '',
    h ? `encode   ${(h.encodeUs / 1000).toFixed(2)} ms` : '',
  ].filter(Boolean).join('\n');
}
setInterval(updateStats, 250);

// --- connection -------------------------------------------------------------------------
function connect() {
  const proto = location.protocol === 'https:' ? 'wss' : 'ws';
  const socket = new WebSocket(`${proto}://${location.host}/api/v1/scenes/${encodeURIComponent(state.scene)}/stream`);
  socket.binaryType = 'arraybuffer';
  state.socket = socket;
  setStatus('Waiting for the first frame…');
  socket.addEventListener('open', () => { state.reconnectDelayMs = 250; });
  socket.addEventListener('message', (event) => {
    if (typeof event.data === 'string') return onText(JSON.parse(event.data));
    onFrame(socket, event.data).catch((err) => showError(`bad frame: ${err.message}`));
  });
  socket.addEventListener('close', (event) => {
    if (state.socket !== socket) return;
    state.socket = null;
    lastSize = '';
    const delay = state.reconnectDelayMs;
    state.reconnectDelayMs = Math.min(5000, delay * 2);
    setStatus(`Disconnected${event.reason ? ` (${event.reason})` : ''}; reconnecting…`);
    setTimeout(connect, delay);
  });
}

function onText(message) {
  if (message.type === 'info') {
    state.info = message;
    const [lo, hi] = message.isovalue_slider;
    isoSlider.min = String(lo);
    isoSlider.max = String(hi);
    isoSlider.step = String((hi - lo) / 1000);
    if (state.isovalue === null) state.isovalue = message.isovalue;
    isoSlider.value = String(state.isovalue);
    isoOut.textContent = state.isovalue.toFixed(3);
    state.orbit = state.orbit || orbitFromUrl() || orbitFromPose(message.camera);
    if (state.time !== null) send({ type: 'time', time: state.time });
    sendSize();
    send({ type: 'camera', ...poseFromOrbit(state.orbit) });
    if (state.isovalue !== message.isovalue) send({ type: 'isovalue', value: state.isovalue });
  } else if (message.type === 'error') {
    showError(`${message.code}: ${message.message}`);
  }
}

async function start() {
  try {
    const response = await fetch('/api/v1/scenes');
    const { scenes } = await response.json();
    for (const s of scenes) {
      const option = new Option(`${s.name} (${s.kind}, ${s.primitives})`, s.id);
      sceneSelect.append(option);
    }
    if (!scenes.some((s) => s.id === state.scene)) state.scene = scenes[0]?.id ?? null;
    sceneSelect.value = state.scene;
    sceneSelect.addEventListener('change', () => {
      state.scene = sceneSelect.value;
      state.orbit = null;
      state.isovalue = null;
      saveUrl();
      if (state.socket) state.socket.close();
    });
    if (state.scene) connect();
    else setStatus('The server has no scenes.');
  } catch (err) {
    setStatus('Cannot reach the server; retrying…');
    setTimeout(start, 1000);
  }
}
start();
