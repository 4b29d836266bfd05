// Isosurface controls: one slider per isosurface over the range the server suggests, with the
// value typed exactly in a number box beside it, and a histogram of the field's values drawn
// behind the slider when the server provides one. This is the scene's main isosurface (one
// isovalue); further isosurfaces are the look's (look.js).
import { $ } from './ui.js';

export class Surfaces {
  /** `changed(index, value)` is called when the user moves a surface's isovalue. */
  constructor(settings, { changed }) {
    this.settings = settings;
    this.changed = changed;
    this.info = null;
    this.histogram = null; // { lo, hi, counts } over the slider's range
    this.container = $('surfaces');
    new ResizeObserver(() => {
      for (const canvas of this.container.querySelectorAll('canvas.histogram')) this.#drawHistogram(canvas);
    }).observe(this.container);
  }

  /** Builds the controls for the session described by `info` (the server's `info` message). */
  setInfo(info) {
    const firstInfo = this.info === null || this.info.scene.id !== info.scene.id;
    this.info = info;
    // One isovalue; a link with several (from an older client) starts from the scene's.
    if (!this.settings.iso || (firstInfo && this.settings.iso.length > 1)) this.settings.iso = [info.isovalue];
    this.settings.iso = [this.#clamp(this.settings.iso[0])];
    this.#build();
  }

  /** The isovalue inputs that restore the view after (re)connecting. */
  messages() {
    if (!this.info) return [];
    return this.settings.iso[0] === this.info.isovalue ? [] : [{ type: 'isovalue', value: this.settings.iso[0] }];
  }

  setHistogram(histogram) {
    this.histogram = histogram;
    for (const canvas of this.container.querySelectorAll('canvas.histogram')) this.#drawHistogram(canvas);
  }

  #clamp(v) {
    const [lo, hi] = this.info.isovalue_range;
    // The range is open: keep a hair inside it.
    const eps = (hi - lo) * 1e-9;
    return Math.min(hi - eps, Math.max(lo + eps, v));
  }

  #build() {
    const [lo, hi] = this.info.isovalue_slider;
    this.container.replaceChildren(...this.settings.iso.map((value, i) => {
      const row = document.createElement('div');
      row.className = 'surface';
      const id = `isovalue${i === 0 ? '' : `-${i}`}`;
      const label = document.createElement('label');
      label.htmlFor = id;
      label.textContent = this.settings.iso.length > 1 ? `Isovalue ${i + 1}` : 'Isovalue';
      const track = document.createElement('div');
      track.className = 'track';
      const canvas = document.createElement('canvas');
      canvas.className = 'histogram';
      canvas.setAttribute('aria-hidden', 'true');
      const slider = document.createElement('input');
      slider.type = 'range';
      slider.id = id;
      slider.min = String(lo);
      slider.max = String(hi);
      slider.step = String((hi - lo) / 1000);
      slider.value = String(value);
      const number = document.createElement('input');
      number.type = 'number';
      number.className = 'exact';
      number.step = 'any';
      number.min = String(this.info.isovalue_range[0]);
      number.max = String(this.info.isovalue_range[1]);
      number.value = fmt(value);
      number.setAttribute('aria-label', `${label.textContent}, exact value`);
      const set = (v, from) => {
        if (!Number.isFinite(v)) return;
        v = this.#clamp(v);
        this.settings.iso[i] = v;
        if (from !== slider) slider.value = String(v);
        if (from !== number) number.value = fmt(v);
        this.changed(i, v);
      };
      slider.addEventListener('input', () => set(Number(slider.value), slider));
      number.addEventListener('change', () => set(Number(number.value), number));
      track.append(canvas, slider);
      row.append(label, track, number);
      return row;
    }));
    for (const canvas of this.container.querySelectorAll('canvas.histogram')) this.#drawHistogram(canvas);
  }

  #drawHistogram(canvas) {
    const h = this.histogram;
    const dpr = window.devicePixelRatio || 1;
    const w = canvas.clientWidth || 200, ht = canvas.clientHeight || 24;
    canvas.width = Math.round(w * dpr);
    canvas.height = Math.round(ht * dpr);
    const g = canvas.getContext('2d');
    g.clearRect(0, 0, canvas.width, canvas.height);
    canvas.dataset.bins = h ? String(h.counts.length) : '0';
    canvas.dataset.samples = h ? String(h.samples) : '0';
    if (!h || !h.counts.length) return;
    // Log scale: field values pile up near zero far from the surface.
    const max = Math.log1p(Math.max(...h.counts));
    const [lo, hi] = this.info.isovalue_slider;
    const binW = (h.hi - h.lo) / h.counts.length;
    g.fillStyle = '#4f6f9f';
    h.counts.forEach((c, k) => {
      const x0 = ((h.lo + k * binW - lo) / (hi - lo)) * canvas.width;
      const x1 = ((h.lo + (k + 1) * binW - lo) / (hi - lo)) * canvas.width;
      const bh = max > 0 ? (Math.log1p(c) / max) * canvas.height : 0;
      g.fillRect(x0, canvas.height - bh, Math.max(1, x1 - x0), bh);
    });
  }
}

function fmt(v) {
  return String(+v.toPrecision(6));
}
