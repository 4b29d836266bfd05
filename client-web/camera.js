// The orbit camera and its controls: mouse (drag orbits, shift- or right-drag pans, wheel
// zooms), touch (one finger orbits, two fingers pinch to zoom and move to pan) and keyboard
// (arrows orbit, shift+arrows pan, +/- zoom, Home or r resets). The orbit turns around a
// chosen view-up axis (±x, ±y, ±z), the way ParaView and VisIt set "view up".

const PITCH_LIMIT = 1.55; // just short of ±90°, where the view direction meets the up axis
const MIN_DISTANCE = 1e-3;
const MAX_DISTANCE = 1e5;

/** Orthonormal basis (a, u, b) for an up axis: u is up, yaw turns from b towards a. */
export function basis(up) {
  const sign = up[0] === '-' ? -1 : 1;
  const axis = { x: 0, y: 1, z: 2 }[up[1]];
  const unit = (i, s = 1) => [0, 1, 2].map((j) => (j === i ? s : 0));
  // Cyclic order keeps the basis right-handed: (x, y, z) for y up, (y, z, x) for z up, ...
  const u = unit(axis, sign);
  const a = unit((axis + 2) % 3, sign);
  const b = unit((axis + 1) % 3);
  return { a, u, b };
}

const dot = (p, q) => p[0] * q[0] + p[1] * q[1] + p[2] * q[2];
const cross = (p, q) => [p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0]];
const scale = (p, s) => p.map((v) => v * s);
const add = (p, q) => p.map((v, i) => v + q[i]);
const norm = (p) => Math.hypot(...p);
const normalize = (p) => scale(p, 1 / (norm(p) || 1));

/** The orbit that gives the camera pose `{eye, target, fov_y_deg}` around up axis `up`. */
export function orbitFromPose(pose, up) {
  const { a, u, b } = basis(up);
  const off = pose.eye.map((e, i) => e - pose.target[i]);
  const distance = Math.max(MIN_DISTANCE, norm(off));
  const pitch = clampPitch(Math.asin(Math.max(-1, Math.min(1, dot(off, u) / distance))));
  return { yaw: Math.atan2(dot(off, a), dot(off, b)), pitch, distance, target: [...pose.target], fov: pose.fov_y_deg };
}

/** Widest vertical field of view a portrait view is given, degrees. */
const MAX_VIEW_FOV = 150;

/**
 * The vertical field of view, degrees, of a view `aspect` (width / height) wide for an orbit's
 * `fov`: the orbit's own for a landscape or square view. A portrait view widens it so that its
 * horizontal field of view is the orbit's: a phone held upright sees across what a square view
 * sees, instead of a narrow slice of the scene.
 */
export function viewFov(fov, aspect) {
  if (!(aspect > 0 && aspect < 1)) return fov;
  const half = Math.atan(Math.tan((fov * Math.PI) / 360) / aspect);
  return Math.min(MAX_VIEW_FOV, (half * 360) / Math.PI);
}

/** The camera message fields (`eye`, `target`, `up`, `fov_y_deg`) of an orbit seen by a view `aspect` wide. */
export function poseFromOrbit(o, up, aspect = 1) {
  const { a, u, b } = basis(up);
  const cp = Math.cos(o.pitch);
  const dir = add(add(scale(a, cp * Math.sin(o.yaw)), scale(u, Math.sin(o.pitch))), scale(b, cp * Math.cos(o.yaw)));
  return { eye: add(o.target, scale(dir, o.distance)), target: [...o.target], up: u, fov_y_deg: viewFov(o.fov, aspect) };
}

function clampPitch(p) {
  return Math.max(-PITCH_LIMIT, Math.min(PITCH_LIMIT, p));
}

/** Turns the orbit by `dYaw`, `dPitch` radians. */
export function rotate(o, dYaw, dPitch) {
  o.yaw += dYaw;
  o.pitch = clampPitch(o.pitch + dPitch);
}

/** Moves the target in the view plane by `dx`, `dy` (fractions of the height of a view `aspect` wide). */
export function pan(o, up, dx, dy, aspect = 1) {
  const pose = poseFromOrbit(o, up, aspect);
  const forward = normalize(pose.target.map((t, i) => t - pose.eye[i]));
  const right = normalize(cross(forward, pose.up));
  const screenUp = cross(right, forward);
  // One view height at the target's distance spans 2·d·tan(fov/2) world units.
  const span = 2 * o.distance * Math.tan((pose.fov_y_deg * Math.PI) / 360);
  o.target = add(o.target, add(scale(right, -dx * span), scale(screenUp, dy * span)));
}

/** Scales the distance to the target by `factor` (below 1 moves closer). */
export function zoom(o, factor) {
  o.distance = Math.max(MIN_DISTANCE, Math.min(MAX_DISTANCE, o.distance * factor));
}

/**
 * Attaches the controls to `element`. `getOrbit()` returns the orbit to change (or null while
 * there is none), `getUp()` the up axis; `changed()` is called after every change and
 * `reset()` when the user asks for the default view.
 */
export function attachControls(element, { getOrbit, getUp, getAspect = () => 1, changed, reset }) {
  const pointers = new Map(); // pointerId -> { x, y }
  let mode = null; // 'orbit' | 'pan' while one pointer is down
  let pinch = null; // { distance, x, y } while two are down

  const twoFingers = () => {
    const [p, q] = [...pointers.values()];
    return { distance: Math.hypot(p.x - q.x, p.y - q.y), x: (p.x + q.x) / 2, y: (p.y + q.y) / 2 };
  };

  element.addEventListener('pointerdown', (e) => {
    element.focus({ preventScroll: true });
    element.setPointerCapture(e.pointerId);
    pointers.set(e.pointerId, { x: e.clientX, y: e.clientY });
    mode = e.shiftKey || e.button === 2 || e.button === 1 ? 'pan' : 'orbit';
    pinch = pointers.size === 2 ? twoFingers() : null;
    element.classList.add('dragging');
  });
  element.addEventListener('pointermove', (e) => {
    const last = pointers.get(e.pointerId);
    const o = getOrbit();
    if (!last || !o) return;
    const dx = e.clientX - last.x, dy = e.clientY - last.y;
    last.x = e.clientX; last.y = e.clientY;
    const h = element.clientHeight || 1;
    if (pointers.size >= 2 && pinch) {
      const now = twoFingers();
      if (now.distance > 0 && pinch.distance > 0) zoom(o, pinch.distance / now.distance);
      pan(o, getUp(), (now.x - pinch.x) / h, (now.y - pinch.y) / h, getAspect());
      pinch = now;
    } else if (mode === 'pan') {
      pan(o, getUp(), dx / h, dy / h, getAspect());
    } else {
      rotate(o, -dx * (Math.PI / h), dy * (Math.PI / h));
    }
    changed();
  });
  const release = (e) => {
    pointers.delete(e.pointerId);
    pinch = pointers.size === 2 ? twoFingers() : null;
    if (pointers.size === 0) { mode = null; element.classList.remove('dragging'); }
  };
  element.addEventListener('pointerup', release);
  element.addEventListener('pointercancel', release);
  element.addEventListener('contextmenu', (e) => e.preventDefault());
  element.addEventListener('wheel', (e) => {
    e.preventDefault();
    const o = getOrbit();
    if (!o) return;
    // Pixel, line and page deltas all zoom a comparable amount per notch.
    const unit = [1, 16, 400][e.deltaMode] || 1;
    zoom(o, Math.exp(Math.max(-500, Math.min(500, e.deltaY * unit)) * 0.0015));
    changed();
  }, { passive: false });
  element.addEventListener('keydown', (e) => {
    if (e.ctrlKey || e.metaKey || e.altKey) return;
    const o = getOrbit();
    if (!o) return;
    const step = 0.05;
    const arrows = { ArrowLeft: [1, 0], ArrowRight: [-1, 0], ArrowUp: [0, 1], ArrowDown: [0, -1] }[e.key];
    if (arrows && e.shiftKey) pan(o, getUp(), -arrows[0] * step, arrows[1] * step);
    else if (arrows) rotate(o, arrows[0] * step, arrows[1] * step);
    else if (e.key === '+' || e.key === '=') zoom(o, 0.9);
    else if (e.key === '-' || e.key === '_') zoom(o, 1 / 0.9);
    else if (e.key === 'Home' || e.key === 'r') { e.preventDefault(); reset(); return; }
    else return;
    e.preventDefault();
    changed();
  });
}

/**
 * Projects world points to CSS pixels of a `width` × `height` view of the camera `pose`
 * (`{eye, target, up, fov_y_deg}`, a pinhole with a vertical field of view, as the server's
 * camera): returns `[x, y, depth]` (depth along the view direction; ≤ 0 is behind the eye).
 */
export function projector(pose, width, height) {
  const forward = normalize(pose.target.map((t, i) => t - pose.eye[i]));
  const right = normalize(cross(forward, pose.up));
  const up = cross(right, forward);
  const f = 1 / Math.tan((pose.fov_y_deg * Math.PI) / 360);
  const aspect = width / height;
  return {
    right, up, forward,
    project(p) {
      const d = p.map((v, i) => v - pose.eye[i]);
      const z = dot(d, forward);
      const x = (dot(d, right) / z) * (f / aspect);
      const y = (dot(d, up) / z) * f;
      return [(x + 1) * 0.5 * width, (1 - y) * 0.5 * height, z];
    },
  };
}
