// isoray browser client: wires the modules together. The scene picker is fed by the REST API;
// the connection streams frames of the chosen scene; camera, isosurfaces, time and quality
// controls turn user input into protocol inputs; every setting lives in the URL.
import { $, setStatus, showError, fillSelect } from './ui.js';
import { parseSettings, serializeSettings, withBookmark } from './settings.js';
import { attachControls, orbitFromPose, poseFromOrbit } from './camera.js';
import { Connection } from './connection.js';
import { FrameView, download } from './frames.js';
import { Stats } from './stats.js';
import { Timeline } from './timeline.js';
import { Surfaces } from './surfaces.js';
import { Quality } from './quality.js';
import { EffectsPanel } from './effects.js';
import { apiFetch, describeFailure } from './api.js';
import { Reprojector } from './reproject.js';
import { supportedCodecs } from './decode.js';
import { Look } from './look.js';
import { Overlay } from './overlay.js';
import { Bookmarks } from './bookmarks.js';
import { Recorder } from './record.js';

const settings = parseSettings(location.search);
const canvas = $('view');
// Latency hiding (reproject.js): on by default, `?reproject=off` turns it off.
const reproject = new Reprojector({ enabled: new URLSearchParams(location.search).get('reproject') !== 'off' });
let lastCameraInput = 0; // input_id of the newest camera sent
const view = new FrameView(canvas, { onImage: reprojectFrame });
const stats = new Stats($('stats'), $('stats-text'), $('stats-plot'));
let info = null; // the server's `info` for the current session
let scenes = []; // GET /api/v1/scenes
let gotFrame = false;
let screenshotWanted = false;

// --- settings in the URL ---------------------------------------------------------------------
let saveTimer = null;
function saved() {
  if (saveTimer !== null) return;
  saveTimer = setTimeout(() => {
    saveTimer = null;
    history.replaceState(null, '', serializeSettings(settings));
  }, 100);
}
/** Writes the URL now (before copying it or leaving the page). */
function flushSettings() {
  clearTimeout(saveTimer);
  saveTimer = null;
  history.replaceState(null, '', serializeSettings(settings));
}

// --- connection ------------------------------------------------------------------------------
const connection = new Connection({
  state(name, detail) {
    document.body.dataset.connection = name;
    if (name === 'connecting') setStatus(detail.attempt > 1 ? `Reconnecting (attempt ${detail.attempt})…` : 'Connecting…');
    else if (name === 'open') setStatus('Waiting for the first frame…');
    else if (name === 'waiting') {
      gotFrame = false;
      const why = detail.reason ? ` (${detail.reason})` : '';
      setStatus(`Disconnected${why}. Reconnecting in ${(detail.delayMs / 1000).toFixed(1)} s…`);
      if (detail.code === 1013) showError(`The server refused the session${why}; retrying.`);
    }
  },
  info(message) {
    onInfo(message);
  },
  async frame(buffer) {
    const header = await view.show(buffer);
    onFrame(header, buffer.byteLength);
    return header.sequence;
  },
  serverError(message) {
    showError(`${message.message} (${message.code})`);
  },
});

function send(message) {
  return connection.send(message);
}

// --- camera ----------------------------------------------------------------------------------
/** Width over height of the frames asked for. */
function viewAspect() {
  const [width, height] = quality.size();
  return width > 0 && height > 0 ? width / height : 1;
}

/** The camera pose of the orbit for the frames asked for (a portrait view sees wider: viewFov). */
function currentPose() {
  return poseFromOrbit(settings.cam, settings.up, viewAspect());
}

let sentFov = null; // the field of view of the last camera message
let cameraQueued = false;
function cameraChanged() {
  saved();
  if (cameraQueued) return;
  cameraQueued = true;
  // At most one camera input per display frame, however fast the pointer moves.
  requestAnimationFrame(() => {
    cameraQueued = false;
    if (!settings.cam) return;
    const pose = currentPose();
    sentFov = pose.fov_y_deg;
    lastCameraInput = send({ type: 'camera', ...pose }) ?? lastCameraInput;
    overlay.update();
    // The last frame, reprojected to the new camera, in this display frame.
    const warped = reproject.render(pose, canvas.width, canvas.height);
    if (warped) view.draw(warped, canvas);
  });
}

/** Gives each frame to the reprojector; a frame older than the camera is shown reprojected. */
function reprojectFrame(frame) {
  reproject.setFrame(frame);
  if (frame.header.inputId < lastCameraInput && settings.cam && reproject.ready) {
    const warped = reproject.render(currentPose(), frame.header.width, frame.header.height);
    if (warped) view.draw(warped, frame.header);
  }
}

function sendStream() {
  send({ type: 'stream', ...quality.streamFields(), depth: reproject.enabled, visible: !document.hidden });
}
// What this browser decodes (H.264 once WebCodecs says so); the codec menu offers those.
supportedCodecs().then((found) => { quality.setDecodable(found); sendStream(); });
// A hidden page costs the server nothing: it renders no frames until the page shows again.
document.addEventListener('visibilitychange', () => send({ type: 'stream', visible: !document.hidden }));

function resetView() {
  if (!info) return;
  settings.cam = orbitFromPose(info.camera, settings.up);
  cameraChanged();
}

attachControls(canvas, {
  getOrbit: () => settings.cam,
  getUp: () => settings.up,
  getAspect: viewAspect,
  changed: cameraChanged,
  reset: resetView,
});
$('reset').addEventListener('click', resetView);
const upSelect = $('up');
upSelect.value = settings.up;
upSelect.addEventListener('change', () => {
  // Keep the eye where it is; only the axis the orbit turns around changes.
  const pose = settings.cam ? poseFromOrbit(settings.cam, settings.up) : null;
  settings.up = upSelect.value;
  if (pose) settings.cam = orbitFromPose(pose, settings.up);
  cameraChanged();
});

// --- isosurfaces, time, quality --------------------------------------------------------------
const surfaces = new Surfaces(settings, {
  changed(index, value) {
    if (index === 0) send({ type: 'isovalue', value });
    saved();
  },
});

const timeline = new Timeline(settings, {
  sendTime: (time) => {
    refreshHistogram();
    return send({ type: 'time', time });
  },
  saved,
  online: () => connection.isOpen,
});

// The field's histogram behind the isovalue slider, for the time on screen: fetched when the
// session starts, when the pinned time changes (at most every 300 ms while scrubbing), and
// every few seconds while following a live scene.
let histogramTimer = null;
function refreshHistogram(delayMs = 300) {
  clearTimeout(histogramTimer);
  histogramTimer = setTimeout(async () => {
    // Drawn behind the isovalue slider, which a surfel scene has none of.
    if (!info || !connection.isOpen || info.scalar_field === false) return;
    const scene = info.scene.id;
    const query = new URLSearchParams({ bins: '128' });
    if (settings.time !== null) query.set('time', String(settings.time));
    try {
      const response = await apiFetch(`/api/v1/scenes/${encodeURIComponent(scene)}/histogram?${query}`);
      if (!response.ok) throw new Error(describeFailure(response));
      const histogram = await response.json();
      if (info && info.scene.id === scene) surfaces.setHistogram(histogram);
    } catch (err) {
      surfaces.setHistogram(null);
      if (connection.isOpen) showError(`The field histogram is not available: ${err.message}`);
    }
  }, delayMs);
}
setInterval(() => {
  if (settings.time === null && !document.hidden) refreshHistogram(0);
}, 5000);

let lastSize = '';
function sendSize(force = false) {
  if (!info || !connection.isOpen) return;
  const [width, height] = quality.size();
  const key = `${width}x${height}`;
  if (key === lastSize && !force) return;
  lastSize = key;
  send({ type: 'resize', width, height });
  // Turned between portrait and landscape: the field of view follows (viewFov).
  if (settings.cam && sentFov !== null && currentPose().fov_y_deg !== sentFov) cameraChanged();
}
const quality = new Quality(settings, canvas, { resized: () => sendSize(), saved, streamChanged: () => sendStream() });

const effects = new EffectsPanel(settings, {
  changed: (changes) => { send({ type: 'effects', effects: changes }); showVolume(); },
  saved,
});

/** Headings of the panel's sections about the scalar field: the isosurfaces and the colour map. */
const FIELD_SECTIONS = ['h-surfaces', 'h-colors'];

// A scene whose field is drawn as a volume while transparency is on (`info.effects.volume`)
// has no isosurface then: the isovalue, further isosurface and colour map controls change
// nothing, so they are greyed and taken out of the tab order, with a note saying why.
function showVolume() {
  const fx = info?.effects;
  const volume = Boolean(fx?.volume) && Boolean(settings.fx.transparency ?? fx.settings.transparency);
  $('volume-note').hidden = !volume;
  for (const id of FIELD_SECTIONS) {
    for (const el of $(id).closest('section').children) {
      if (el.tagName === 'H2' || el.id === 'volume-note') continue;
      el.inert = volume;
      el.classList.toggle('idle', volume);
    }
  }
}

// --- the viewer's look, the overlay, bookmarks, recording ------------------------------------
const look = new Look(settings, {
  send: (changes) => {
    send({ type: 'effects', effects: changes });
    if (changes.transparency !== undefined) effects.noteSwitched('transparency', changes.transparency);
    showVolume();
  },
  saved,
});
const overlay = new Overlay(canvas, {
  getPose: () => (settings.cam ? currentPose() : null),
  look,
});
const bookmarks = new Bookmarks(settings, {
  flush: flushSettings,
  go: (q) => location.assign(serializeSettings(withBookmark(settings, q))),
});
const recorder = new Recorder(canvas, {
  pinTime: (t) => timeline.pinAt(t),
  getTime: () => settings.time,
  restore: (t) => (t === null ? timeline.follow() : timeline.pinAt(t)),
});

// The scene's bounds, for the clip box's fields and its first box.
async function loadBounds(id) {
  try {
    const response = await apiFetch(`/api/v1/scenes/${encodeURIComponent(id)}`);
    if (!response.ok) throw new Error(describeFailure(response));
    const scene = await response.json();
    if (info && info.scene.id === id) look.setBounds(scene.bounds ?? null);
  } catch (err) {
    if (connection.isOpen) showError(`The scene's bounds are not available: ${err.message}`);
  }
}

// --- session start and frames ----------------------------------------------------------------
function onInfo(message) {
  info = message;
  // The camera the user had (from the URL, or before a reconnect) wins over the scene's own.
  if (!settings.cam) settings.cam = orbitFromPose(message.camera, settings.up);
  // A surfel surface is no isosurface: no isovalue, further isosurfaces or colour map.
  const field = message.scalar_field !== false;
  for (const id of FIELD_SECTIONS) $(id).closest('section').hidden = !field;
  if (!field) Object.assign(settings, { iso: null, surf: [], cmap: null });
  surfaces.setInfo(message);
  quality.setInfo(message);
  effects.setInfo(message);
  setStatus('Waiting for the first frame…');
  // Restore the whole view: the server starts every session from the scene's defaults.
  sendStream();
  sendSize(true);
  const pose = currentPose();
  sentFov = pose.fov_y_deg;
  send({ type: 'camera', ...pose });
  for (const m of surfaces.messages()) send(m);
  const fx = effects.restoreChanges();
  if (fx) send({ type: 'effects', effects: fx });
  look.setInfo(message);
  showVolume();
  const style = look.restoreChanges();
  if (style) send({ type: 'effects', effects: style });
  if (!look.bounds) loadBounds(message.scene.id);
  overlay.update();
  timeline.restore();
  refreshHistogram(0);
  saved();
}

function onFrame(header, bytes) {
  stats.frame(header, bytes, connection.latencyOf(header.inputId));
  timeline.frameShown(header);
  recorder.frameShown(header);
  if (!gotFrame) {
    gotFrame = true;
    setStatus('');
    document.body.dataset.connection = 'streaming';
  }
  if (screenshotWanted && view.still) saveScreenshot();
}

// --- screenshot -----------------------------------------------------------------------------
const shotButton = $('screenshot');
function saveScreenshot() {
  screenshotWanted = false;
  shotButton.removeAttribute('aria-busy');
  const { header, png } = view.still;
  const time = header.sceneTime.toFixed(3).replace(/\.?0+$/, '');
  download(png, `isoray-${settings.scene}-t${time}-${header.width}x${header.height}.png`, 'image/png');
}
shotButton.addEventListener('click', () => {
  // The still frame is lossless; while the view moves, the next one comes once it rests.
  screenshotWanted = true;
  shotButton.setAttribute('aria-busy', 'true');
  if (view.still) saveScreenshot();
});

// --- overlay and panel -----------------------------------------------------------------------
const statsButton = $('stats-toggle');
function showStats(on) {
  settings.stats = on;
  stats.shown = on;
  statsButton.setAttribute('aria-pressed', String(on));
  saved();
}
showStats(settings.stats);
statsButton.addEventListener('click', () => showStats(!settings.stats));
document.addEventListener('keydown', (e) => {
  const typing = e.target instanceof HTMLElement && e.target.matches('input:not([type=range]):not([type=checkbox]), select, textarea');
  if (typing || e.ctrlKey || e.metaKey || e.altKey) return;
  if (e.key === 's' || e.key === 'S') showStats(!settings.stats);
});
const panelButton = $('panel-toggle');
panelButton.addEventListener('click', () => {
  const open = panelButton.getAttribute('aria-expanded') !== 'true';
  panelButton.setAttribute('aria-expanded', String(open));
  $('panel').hidden = !open;
});

// --- scenes ----------------------------------------------------------------------------------
const sceneSelect = $('scene');
function describe(s) {
  const noun = { metaballs: 'balls', tets: 'tetrahedra', surfels: 'surfels' }[s.kind] ?? 'primitives';
  const size = `${s.primitives.toLocaleString('en')} ${noun}`;
  const time = s.source === 'stored' ? `${s.steps} time step${s.steps === 1 ? '' : 's'}` : 'animated demo';
  // `5,202 surfels` already names its kind.
  return noun === s.kind ? `${size} · ${time}` : `${s.kind} · ${size} · ${time}`;
}

/** A scene's line in the picker: its name, less a `(kind)` the description repeats, and what it is. */
function optionLabel(s) {
  const name = s.name.endsWith(` (${s.kind})`) ? s.name.slice(0, -` (${s.kind})`.length) : s.name;
  return `${name} (${describe(s)})`;
}

async function loadSteps(scene) {
  if (scene.source !== 'stored') return null;
  const response = await apiFetch(`/api/v1/scenes/${encodeURIComponent(scene.id)}/steps`);
  if (!response.ok) throw new Error(`listing the steps of ${scene.id}: ${describeFailure(response)}`);
  return (await response.json()).steps.map((s) => ({ index: s.index, time: s.time }));
}

async function selectScene(id) {
  const scene = scenes.find((s) => s.id === id);
  settings.scene = id;
  sceneSelect.value = id;
  const details = $('scene-details');
  details.textContent = scene ? `${describe(scene)}. ${scene.description}` : '';
  details.title = details.textContent; // the whole line where the header cuts it short
  let steps = null;
  try {
    steps = scene ? await loadSteps(scene) : null;
  } catch (err) {
    showError(err.message);
  }
  timeline.setScene(scene, steps);
  gotFrame = false;
  saved();
  connection.open(id);
}

// A deployment of several processes lists every process's scenes; a process that did not
// answer is named in `unreachable_shards`, and the picker says its scenes are missing.
const shardsDown = document.getElementById('shards-down');
function showShards(list) {
  const down = list.unreachable_shards || [];
  shardsDown.hidden = down.length === 0;
  shardsDown.textContent = down.length === 0 ? ''
    : `${down.length} server${down.length === 1 ? '' : 's'} not answering: ${down.length === 1 ? 'its' : 'their'} scenes are missing from this list`;
  shardsDown.title = down.join('\n');
}

// Scenes pushed since the page loaded appear when the picker is opened.
let listing = null;
async function refreshScenes() {
  if (listing || !connection.isOpen) return;
  listing = apiFetch('/api/v1/scenes')
    .then(async (response) => {
      if (!response.ok) return;
      const list = await response.json();
      scenes = list.scenes;
      showShards(list);
      fillSelect(sceneSelect, scenes.map((s) => [s.id, optionLabel(s)]), settings.scene);
    })
    .catch(() => {})
    .finally(() => { listing = null; });
}
sceneSelect.addEventListener('focus', refreshScenes);
sceneSelect.addEventListener('pointerdown', refreshScenes);

sceneSelect.addEventListener('change', () => {
  // A new scene starts from its own default view.
  settings.cam = null;
  settings.iso = null;
  settings.time = null;
  settings.fx = {};
  settings.clip = null;
  settings.surf = [];
  settings.cmap = null;
  info = null;
  selectScene(sceneSelect.value);
});

let startDelayMs = 500;
async function start() {
  try {
    const response = await apiFetch('/api/v1/scenes');
    if (response.status === 401 || response.status === 403) {
      // Retrying cannot help; the user has to open the page with a token.
      setStatus(`Cannot list the scenes: ${describeFailure(response)}.`, { busy: false });
      return;
    }
    if (!response.ok) throw new Error(describeFailure(response));
    const list = await response.json();
    scenes = list.scenes;
    showShards(list);
  } catch (err) {
    setStatus(`Cannot list the scenes (${err.message}); retrying…`);
    setTimeout(start, startDelayMs);
    startDelayMs = Math.min(5000, startDelayMs * 2);
    return;
  }
  fillSelect(sceneSelect, scenes.map((s) => [s.id, optionLabel(s)]), settings.scene);
  if (!scenes.length) {
    setStatus('The server has no scenes yet.', { busy: false });
    return;
  }
  const id = scenes.some((s) => s.id === settings.scene) ? settings.scene : scenes[0].id;
  if (id !== settings.scene) {
    Object.assign(settings, { cam: null, iso: null, time: null, fx: {}, clip: null, surf: [], cmap: null });
  }
  selectScene(id);
}

// For tests and debugging: the live objects behind the page.
window.isoray = { settings, stats, view, connection, timeline, quality, effects, surfaces, reproject, look, overlay, bookmarks, recorder };
start();
