// What the viewer draws over the rendered view: the clip box's edges with six handles (one per
// face) to drag along their axis, as ParaView's box widget does, and the orientation axes
// widget, which turns with the camera. Both are projected with the session's camera
// (camera.js `projector`), so they line up with the server's image.
import { $ } from './ui.js';
import { projector } from './camera.js';

const SVG = 'http://www.w3.org/2000/svg';
const AXES = ['x', 'y', 'z'];
const AXIS_COLORS = ['#e5534b', '#57ab5a', '#539bf5'];
const WIDGET = 36; // half size of the axes widget, CSS pixels

function el(name, attrs = {}) {
  const e = document.createElementNS(SVG, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, String(v));
  return e;
}

export class Overlay {
  /**
   * `getPose()` returns the camera pose now (or null), `look` is the Look whose clip box the
   * handles move.
   */
  constructor(canvas, { getPose, look }) {
    this.canvas = canvas;
    this.getPose = getPose;
    this.look = look;
    this.svg = $('overlay');
    this.edges = el('g', { class: 'clip-edges' });
    this.svg.append(this.edges);
    this.handles = [];
    const layer = $('clip-handles');
    for (const end of ['min', 'max']) {
      AXES.forEach((axis, k) => {
        const b = document.createElement('button');
        b.type = 'button';
        b.className = 'clip-handle';
        b.id = `handle-${end}-${axis}`;
        b.dataset.index = String((end === 'min' ? 0 : 3) + k);
        b.setAttribute('aria-label', `Clip box ${end} ${axis} face: drag, or arrow keys to move it`);
        b.style.borderColor = AXIS_COLORS[k];
        this.#attachDrag(b, end === 'min' ? 0 : 3, k);
        layer.append(b);
        this.handles.push(b);
      });
    }
    this.axes = $('axes');
    this.axisLines = AXES.map((axis, k) => {
      const line = el('line', { x1: WIDGET, y1: WIDGET, x2: WIDGET, y2: WIDGET, stroke: AXIS_COLORS[k], 'stroke-width': 2.5, 'stroke-linecap': 'round', 'data-axis': axis });
      const label = el('text', { fill: AXIS_COLORS[k], 'font-size': 12, 'text-anchor': 'middle', 'dominant-baseline': 'central' });
      label.textContent = axis.toUpperCase();
      this.axes.append(line, label);
      return { line, label };
    });
    look.onClip(() => this.update());
    new ResizeObserver(() => this.update()).observe(canvas);
  }

  /** Redraws both widgets for the camera now. */
  update() {
    const pose = this.getPose();
    if (!pose) return;
    const w = this.canvas.clientWidth, h = this.canvas.clientHeight;
    if (!w || !h) return;
    const cam = projector(pose, w, h);
    this.#drawAxes(cam);
    this.#drawClip(cam, w, h);
  }

  #drawAxes(cam) {
    // Each world axis seen from the camera: its components along the screen's right and up.
    const order = AXES.map((_, k) => k).sort((a, b) => cam.forward[b] - cam.forward[a]);
    for (const k of order) {
      const { line, label } = this.axisLines[k];
      const dx = cam.right[k], dy = -cam.up[k];
      const x = WIDGET + dx * (WIDGET - 10), y = WIDGET + dy * (WIDGET - 10);
      line.setAttribute('x2', x.toFixed(2));
      line.setAttribute('y2', y.toFixed(2));
      line.dataset.dx = dx.toFixed(4);
      line.dataset.dy = dy.toFixed(4);
      label.setAttribute('x', (WIDGET + dx * (WIDGET - 3)).toFixed(2));
      label.setAttribute('y', (WIDGET + dy * (WIDGET - 3)).toFixed(2));
      // The axis nearest the viewer is drawn last, on top.
      this.axes.append(line, label);
    }
  }

  /**
   * The clip box as drawn and dragged: clamped to the scene's bounds widened by the clip
   * fields' margin, so a box that reaches far past the scene (Shells' own cuts a quadrant
   * with faces at ±100) shows its faces where they cut, with handles in view.
   */
  #shownBox() {
    const box = this.look.clip;
    const range = this.look.clipRange();
    if (!box || !range) return box;
    return box.map((v, i) => Math.min(range.hi[i % 3], Math.max(range.lo[i % 3], v)));
  }

  #drawClip(cam, w, h) {
    const box = this.#shownBox();
    this.edges.replaceChildren();
    for (const b of this.handles) b.hidden = !box;
    if (!box) return;
    const corner = (i) => [0, 1, 2].map((k) => box[(i >> k) & 1 ? k + 3 : k]);
    const points = [...Array(8).keys()].map((i) => cam.project(corner(i)));
    for (let i = 0; i < 8; i++) {
      for (let k = 0; k < 3; k++) {
        const j = i | (1 << k);
        if (j === i) continue;
        const [a, b] = [points[i], points[j]];
        if (a[2] <= 0 || b[2] <= 0) continue;
        this.edges.append(el('line', { x1: a[0].toFixed(1), y1: a[1].toFixed(1), x2: b[0].toFixed(1), y2: b[1].toFixed(1) }));
      }
    }
    for (const b of this.handles) {
      const [x, y, z] = cam.project(this.#faceCentre(box, Number(b.dataset.index)));
      const inside = z > 0 && x >= 0 && y >= 0 && x <= w && y <= h;
      b.hidden = !inside;
      b.style.left = `${x}px`;
      b.style.top = `${y}px`;
    }
  }

  #faceCentre(box, index) {
    const k = index % 3;
    return [0, 1, 2].map((i) => (i === k ? box[index] : (box[i] + box[i + 3]) / 2));
  }

  /** Screen pixels per world unit along axis `k` at the handle, as a vector. */
  #screenAxis(box, index) {
    const pose = this.getPose();
    const cam = projector(pose, this.canvas.clientWidth, this.canvas.clientHeight);
    const c = this.#faceCentre(box, index);
    const k = index % 3;
    const size = Math.max(1e-6, box[k + 3] - box[k]);
    const step = c.map((v, i) => (i === k ? v + size * 0.01 : v));
    const [a, b] = [cam.project(c), cam.project(step)];
    return [(b[0] - a[0]) / (size * 0.01), (b[1] - a[1]) / (size * 0.01)];
  }

  #move(index, k, delta) {
    // The dragged face moves from where it is drawn; the others keep their values.
    const box = [...this.look.clip];
    const shown = this.#shownBox();
    const size = shown[k + 3] - shown[k];
    const gap = Math.max(1e-4, Math.abs(size) * 1e-3);
    box[index] = shown[index] + delta;
    if (index < 3) box[index] = Math.min(box[index], box[k + 3] - gap);
    else box[index] = Math.max(box[index], box[k] + gap);
    box[index] = +box[index].toPrecision(6);
    this.look.setClip(box);
  }

  #attachDrag(button, offset, k) {
    const index = offset + k;
    let last = null;
    let pending = 0;
    let queued = false;
    button.addEventListener('pointerdown', (e) => {
      e.preventDefault();
      button.setPointerCapture(e.pointerId);
      last = [e.clientX, e.clientY];
      button.classList.add('dragging');
    });
    button.addEventListener('pointermove', (e) => {
      if (!last || !this.look.clip) return;
      const [sx, sy] = this.#screenAxis(this.#shownBox(), index);
      const len2 = sx * sx + sy * sy;
      const dx = e.clientX - last[0], dy = e.clientY - last[1];
      last = [e.clientX, e.clientY];
      // The drag's component along the axis as drawn, in world units.
      if (len2 > 1e-9) pending += (dx * sx + dy * sy) / len2;
      if (queued) return;
      queued = true;
      requestAnimationFrame(() => {
        queued = false;
        if (pending !== 0 && this.look.clip) this.#move(index, k, pending);
        pending = 0;
      });
    });
    const end = () => { last = null; button.classList.remove('dragging'); };
    button.addEventListener('pointerup', end);
    button.addEventListener('pointercancel', end);
    button.addEventListener('keydown', (e) => {
      const sign = { ArrowUp: 1, ArrowRight: 1, ArrowDown: -1, ArrowLeft: -1 }[e.key];
      if (!sign || !this.look.clip) return;
      e.preventDefault();
      const box = this.#shownBox();
      this.#move(index, k, sign * 0.02 * (box[k + 3] - box[k]));
    });
  }
}
