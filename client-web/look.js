// The viewer's own look of a scene, as ParaView users expect to set it: a clip box (numeric
// fields over the scene's bounds from `GET /api/v1/scenes/{id}`, and handles dragged in the
// view, see overlay.js), further isosurfaces (the scene's own, switched and edited, or the
// viewer's) added and removed with a colour and opacity each,
// and a colour map of the isovalue with its legend. Each goes to the server as the `clip`,
// `surfaces` and `color_map` fields of an `effects` message, and lives in the URL.
import { $ } from './ui.js';
import { COLOR_MAPS } from './settings.js';

const AXES = ['x', 'y', 'z'];
const MAX_SURFACES = 4;
const SURFACE_COLORS = ['e05a47', '4fb06c', 'd9a93a', 'b164c8'];

/** The sRGB stops of each map, as the server's colormap.rs has them (for the legend). */
export const MAP_STOPS = {
  viridis: ['440154', '482878', '3e4989', '31688e', '26828e', '1f9e89', '35b779', '6ece58', 'b5de2b', 'fde725'],
  inferno: ['000004', '1b0c41', '4a0c6b', '781c6d', 'a52c60', 'cf4446', 'ed6925', 'fb9b06', 'f7d13d', 'fcffa4'],
  cool_warm: ['3b4cc0', '6788ee', '9abbff', 'c9d7f0', 'edd1c2', 'f7a889', 'e26952', 'b40426'],
  grey: ['000000', 'ffffff'],
};
const MAP_LABELS = { viridis: 'Viridis', inferno: 'Inferno', cool_warm: 'Cool to warm', grey: 'Grey' };

/** An sRGB hex colour as linear-light channels in [0, 1] (the server shades in linear light). */
export function linearOf(hex) {
  return [0, 2, 4].map((i) => {
    const s = parseInt(hex.slice(i, i + 2), 16) / 255;
    return s <= 0.04045 ? s / 12.92 : ((s + 0.055) / 1.055) ** 2.4;
  });
}

/** Linear-light channels in [0, 1] as an sRGB hex colour (what `linearOf` reads back). */
export function hexOf(linear) {
  return linear.map((l) => {
    const c = Math.min(1, Math.max(0, l));
    const s = c <= 0.0031308 ? c * 12.92 : 1.055 * c ** (1 / 2.4) - 0.055;
    return Math.round(s * 255).toString(16).padStart(2, '0');
  }).join('');
}

const fmt = (v) => String(+Number(v).toPrecision(5));

/**
 * Decimals of the clip fields: a thousandth of the scene's largest extent (or finer), so a
 * field holds about six characters whatever the scene's units ("-4.465" for a box 9 across,
 * "-46.83" for one 90 across) instead of five significant digits ("-0.039019").
 */
const clipDecimals = (bounds) => {
  const extent = bounds ? Math.max(...bounds.max.map((v, i) => v - bounds.min[i])) : 2;
  return Number.isFinite(extent) && extent > 0 ? Math.min(6, Math.max(0, -Math.floor(Math.log10(extent / 1000)))) : 3;
};

/** `v` to `decimals`, rounded towards `-Infinity` (`dir` -1), `+Infinity` (1) or the nearest (0). */
const roundTo = (v, decimals, dir = 0) => {
  const scale = 10 ** decimals;
  const round = dir < 0 ? Math.floor : dir > 0 ? Math.ceil : Math.round;
  return +(round(v * scale) / scale).toFixed(decimals);
};

export class Look {
  /** `send(changes)` sends an `effects` message body; `saved()` writes the URL. */
  constructor(settings, { send, saved }) {
    this.settings = settings;
    this.send = send;
    this.saved = saved;
    this.info = null;
    this.bounds = null; // { min, max } of the scene
    this.listeners = new Set();
    this.clipOn = $('clip-on');
    this.clipOn.addEventListener('change', () => this.#switchClip(this.clipOn.checked));
    this.clipInputs = [];
    for (const [i, end] of [['min', 0], ['max', 3]].map(([end, o]) => [o, end])) {
      AXES.forEach((axis, k) => {
        const input = $(`clip-${end}-${axis}`);
        input.addEventListener('change', () => {
          const v = Number(input.value);
          if (!Number.isFinite(v) || !this.clip) return;
          const box = [...this.clip];
          box[i + k] = v;
          if (box[k] < box[k + 3]) this.setClip(box); else this.#showClip();
        });
        this.clipInputs[i + k] = input;
      });
    }
    $('surface-add').addEventListener('click', () => this.#addSurface());
    $('surfaces-on').addEventListener('change', () => this.#switchSurfaces($('surfaces-on').checked));
    this.list = $('further');
    this.mapSelect = $('cmap');
    this.mapSelect.replaceChildren(new Option('None (scene colours)', ''), ...COLOR_MAPS.map((m) => new Option(MAP_LABELS[m], m)));
    this.mapSelect.addEventListener('change', () => this.#mapChanged());
    this.mapLo = $('cmap-lo');
    this.mapHi = $('cmap-hi');
    for (const input of [this.mapLo, this.mapHi]) input.addEventListener('change', () => this.#mapChanged());
  }

  /** Calls `fn()` whenever the clip box changes (the overlay redraws its handles). */
  onClip(fn) { this.listeners.add(fn); }

  /** The scene's bounds (from `GET /api/v1/scenes/{id}`), the ranges of the clip fields. */
  setBounds(bounds) {
    this.bounds = bounds;
    const d = clipDecimals(bounds);
    const range = this.clipRange();
    for (const [i, input] of this.clipInputs.entries()) {
      input.min = range ? String(roundTo(range.lo[i % 3], d, -1)) : '';
      input.max = range ? String(roundTo(range.hi[i % 3], d, 1)) : '';
    }
    this.#showClip();
  }

  /** Where a clip box is useful: the scene's bounds widened by a twentieth per axis, or null. */
  clipRange() {
    const b = this.bounds;
    if (!b) return null;
    const pad = b.max.map((v, k) => (v - b.min[k]) * 0.05);
    return { lo: b.min.map((v, k) => v - pad[k]), hi: b.max.map((v, k) => v + pad[k]) };
  }

  /** A new session: restores the look from the settings. */
  setInfo(info) {
    const newScene = this.info === null || this.info.scene.id !== info.scene.id;
    this.info = info;
    if (newScene) this.bounds = null;
    for (const input of this.clipInputs) input.step = 'any';
    if (this.settings.cmap === null) {
      [this.mapLo.value, this.mapHi.value] = info.isovalue_slider.map(fmt);
    }
    this.settings.surf = this.settings.surf.filter((s) => s.v > info.isovalue_range[0] && s.v < info.isovalue_range[1]);
    // A row drawn like a surface this scene does not have (a link from another scene) is plain.
    const own = info.effects?.surfaces?.length ?? 0;
    for (const s of this.settings.surf) if (s.k !== undefined && !(s.k < own)) delete s.k;
    this.#buildSurfaces();
    this.#showClip();
    this.#showMap();
  }

  /** The `effects` message body that restores the look after (re)connecting, or null. */
  restoreChanges() {
    const fx = {};
    if (this.settings.clip) Object.assign(fx, this.#clipChanges(this.settings.clip));
    if (this.settings.surf.length) Object.assign(fx, this.#surfaceChanges());
    if (this.settings.cmap) fx.color_map = { name: this.settings.cmap.name, range: [this.settings.cmap.lo, this.settings.cmap.hi] };
    return Object.keys(fx).length ? fx : null;
  }

  // --- clip box ------------------------------------------------------------------------------

  #defaultClip() {
    // The half of the scene's box nearest +z cut away, so switching it on shows an effect.
    // Its corners at the fields' decimals (outwards), so the fields show the box exactly.
    const b = this.bounds ?? { min: [-1, -1, -1], max: [1, 1, 1] };
    const r = this.clipRange() ?? { lo: [-1.1, -1.1, -1.1], hi: [1.1, 1.1, 1.1] };
    const d = clipDecimals(this.bounds);
    const mid = (b.min[2] + b.max[2]) / 2;
    const lo = r.lo.slice(0, 2).map((v) => roundTo(v, d, -1));
    const hi = r.hi.map((v) => roundTo(v, d, 1));
    return [...lo, roundTo(mid, d), ...hi];
  }

  #clipChanges(box) {
    return box ? { clip_box: true, clip: { min: box.slice(0, 3), max: box.slice(3) } } : { clip_box: false };
  }

  /** The scene's own clip box (`info.effects.clip`) as `[min…, max…]`, or null. */
  #sceneClip() {
    const c = this.info?.effects?.clip;
    return c ? [...c.min, ...c.max] : null;
  }

  /**
   * Switches clipping on or off: on, the viewer's box if it set one, else the scene's own
   * (the effect `clip_box`, kept in the URL's effects where it differs from the scene's
   * start), else a box of its own; off, the viewer's box is dropped.
   */
  #switchClip(on) {
    if (!on || this.settings.clip || !this.#sceneClip()) {
      if (this.#sceneClip()) this.#keepEffect(on);
      this.setClip(on ? (this.settings.clip ?? this.#defaultClip()) : null);
      return;
    }
    this.#keepEffect(true);
    // The scene's box by value: a box this viewer set earlier in the session would still
    // stand in for it on the server.
    const own = this.#sceneClip();
    this.send({ clip_box: true, clip: { min: own.slice(0, 3), max: own.slice(3) } });
    this.saved();
    this.#showClip();
  }

  /** Whether the session started with `clip_box` on (the scene's choice). */
  #clipAtStart() {
    return this.info?.effects?.settings?.clip_box;
  }

  /** Notes `clip_box` in the URL's effects where it differs from the scene's start. */
  #keepEffect(on) {
    if (on === this.#clipAtStart()) delete this.settings.fx.clip_box;
    else this.settings.fx.clip_box = on;
  }

  /** Sets the viewer's own clip box (`null`: off), sends it and keeps it in the URL. */
  setClip(box) {
    if (box && this.#sceneClip()) this.#keepEffect(true);
    this.settings.clip = box;
    this.send(this.#clipChanges(box));
    this.saved();
    this.#showClip();
  }

  /**
   * The box that cuts the view, or null when nothing does: the viewer's own, else the scene's
   * while its `clip_box` effect is on.
   */
  get clip() {
    if (this.settings.clip) return this.settings.clip;
    const own = this.#sceneClip();
    const on = this.settings.fx.clip_box ?? this.#clipAtStart();
    return own && on ? own : null;
  }

  #showClip() {
    const box = this.clip;
    this.clipOn.checked = Boolean(box);
    for (const [i, input] of this.clipInputs.entries()) {
      input.disabled = !box;
      input.value = box ? String(roundTo(box[i], clipDecimals(this.bounds))) : '';
    }
    for (const fn of this.listeners) fn(box);
  }

  // --- further isosurfaces -------------------------------------------------------------------
  //
  // The section lists the further isosurfaces in effect: the viewer's own (`settings.surf`),
  // else the scene's (`info.effects.surfaces`), which the switch `#surfaces-on` (the effect
  // `isosurfaces`) shows or hides. A change to a scene's surface makes the list the viewer's,
  // by value, each adopted row still drawn with its scene surface's material
  // (`scene_surface`); switching off drops the viewer's list, and on again shows the scene's own.

  /** The scene's own further isosurfaces as rows `{ v, c, o, k }` (`k`: its index), or `[]`. */
  #sceneSurfaces() {
    return (this.info?.effects?.surfaces ?? []).map((s, k) => ({ v: s.isovalue, c: hexOf(s.color), o: s.opacity, k }));
  }

  /** Whether the session started with the scene's further isosurfaces on. */
  #surfacesAtStart() {
    return Boolean(this.info?.effects?.settings?.isosurfaces);
  }

  /** Whether further isosurfaces are drawn: the viewer's whenever it has some, else the scene's while on. */
  #surfacesOn() {
    return this.settings.surf.length > 0 || (this.settings.fx.isosurfaces ?? this.#surfacesAtStart());
  }

  /** Notes `isosurfaces` in the URL's effects where it differs from the scene's start. */
  #keepSurfaces(on) {
    if (on === this.#surfacesAtStart()) delete this.settings.fx.isosurfaces;
    else this.settings.fx.isosurfaces = on;
  }

  /** Before the viewer changes a scene's surface: the scene's list, by value, becomes the viewer's. */
  #adopt() {
    if (this.settings.surf.length === 0 && this.#surfacesOn()) this.settings.surf = this.#sceneSurfaces();
  }

  #switchSurfaces(on) {
    this.settings.surf = [];
    this.#keepSurfaces(on);
    this.send({ isosurfaces: on, scene_surfaces: true });
    this.saved();
    this.#buildSurfaces();
  }

  #surfaceChanges() {
    // A scene's surface, adopted, keeps its material (`scene_surface`); an added one is plain.
    const surfaces = this.settings.surf.map((s) => {
      const out = { isovalue: s.v, color: linearOf(s.c), opacity: s.o };
      if (s.k !== undefined) out.scene_surface = s.k;
      return out;
    });
    const fx = { isosurfaces: surfaces.length > 0, surfaces };
    // A see-through surface needs transparency on.
    if (this.settings.surf.some((s) => s.o < 1)) fx.transparency = true;
    return fx;
  }

  #surfacesChanged() {
    if (this.#sceneSurfaces().length === 0) {
      this.send(this.#surfaceChanges());
    } else if (this.settings.surf.length) {
      this.#keepSurfaces(true);
      this.send(this.#surfaceChanges());
    } else {
      // The last one removed: the scene's own again, switched off.
      this.#switchSurfaces(false);
      return;
    }
    this.saved();
  }

  #addSurface() {
    if (!this.info || this.settings.surf.length >= MAX_SURFACES) return;
    this.#adopt();
    if (this.settings.surf.length >= MAX_SURFACES) return;
    const [lo, hi] = this.info.isovalue_slider;
    const main = this.settings.iso ? this.settings.iso[0] : this.info.isovalue;
    // Half way between the main surface and the low end of the slider: an enclosing shell.
    const v = +(main - (main - lo) * 0.5).toPrecision(6);
    const n = this.settings.surf.length;
    this.settings.surf.push({ v: Math.min(hi, Math.max(lo, v)), c: SURFACE_COLORS[n % SURFACE_COLORS.length], o: 1 });
    this.#buildSurfaces();
    this.#surfacesChanged();
    this.list.querySelector(`#further-${n} input[type=number]`)?.focus();
  }

  #buildSurfaces() {
    if (!this.info) return;
    const scene = this.#sceneSurfaces();
    const own = this.settings.surf.length === 0 && scene.length > 0;
    const on = this.#surfacesOn();
    $('surfaces-own').hidden = scene.length === 0;
    $('surfaces-on').checked = on;
    $('surface-add').hidden = false;
    $('surface-add').disabled = this.settings.surf.length >= MAX_SURFACES;
    // A scene's surface is the viewer's once changed: `edit` adopts the list, then changes it.
    const edit = (i, change) => {
      const adopting = this.settings.surf.length === 0;
      this.#adopt();
      // Rows greyed while off take no input; nothing to change if one did.
      if (!this.settings.surf[i]) return;
      change(this.settings.surf[i]);
      if (adopting) this.#buildSurfaces();
      this.#surfacesChanged();
    };
    const noun = own ? 'scene isosurface' : scene.length ? 'further isosurface' : 'added isosurface';
    const rows = own ? scene : this.settings.surf;
    this.list.replaceChildren(...rows.map((s, i) => {
      const name = `${noun} ${i + 1}`;
      const row = document.createElement('fieldset');
      row.className = 'further';
      row.id = `further-${i}`;
      row.disabled = !on;
      const legend = document.createElement('legend');
      legend.textContent = name[0].toUpperCase() + name.slice(1);
      const value = document.createElement('input');
      value.type = 'number';
      value.step = 'any';
      value.min = String(this.info.isovalue_range[0]);
      value.max = String(this.info.isovalue_range[1]);
      value.value = fmt(s.v);
      value.setAttribute('aria-label', `Isovalue of ${name}`);
      value.addEventListener('change', () => {
        const v = Number(value.value);
        if (!(v > this.info.isovalue_range[0] && v < this.info.isovalue_range[1])) { value.value = fmt(s.v); return; }
        edit(i, (t) => { t.v = v; });
      });
      const color = document.createElement('input');
      color.type = 'color';
      color.value = `#${s.c}`;
      color.setAttribute('aria-label', `Colour of ${name}`);
      color.addEventListener('change', () => edit(i, (t) => { t.c = color.value.slice(1).toLowerCase(); }));
      const opacityId = `further-opacity-${i}`;
      const opacityLabel = document.createElement('label');
      opacityLabel.htmlFor = opacityId;
      opacityLabel.textContent = 'Opacity';
      const opacity = document.createElement('input');
      opacity.type = 'range';
      opacity.id = opacityId;
      opacity.min = '0';
      opacity.max = '1';
      opacity.step = '0.05';
      opacity.value = String(s.o);
      opacity.addEventListener('change', () => edit(i, (t) => { t.o = Number(opacity.value); }));
      const remove = document.createElement('button');
      remove.type = 'button';
      remove.className = 'remove';
      remove.textContent = 'Remove';
      remove.setAttribute('aria-label', `Remove ${name}`);
      remove.addEventListener('click', () => {
        this.#adopt();
        this.settings.surf.splice(i, 1);
        this.#buildSurfaces();
        this.#surfacesChanged();
        $('surface-add').focus();
      });
      const line = document.createElement('div');
      line.className = 'row';
      line.append(value, color, remove);
      row.append(legend, line, opacityLabel, opacity);
      return row;
    }));
  }

  // --- colour map ----------------------------------------------------------------------------

  #mapChanged() {
    const name = this.mapSelect.value;
    const lo = Number(this.mapLo.value), hi = Number(this.mapHi.value);
    if (name && !(Number.isFinite(lo) && Number.isFinite(hi) && lo < hi)) {
      this.#showMap();
      return;
    }
    this.settings.cmap = name ? { name, lo, hi } : null;
    this.send({ color_map: name ? { name, range: [lo, hi] } : { name: 'none' } });
    this.saved();
    this.#showMap();
  }

  #showMap() {
    const map = this.settings.cmap;
    this.mapSelect.value = map ? map.name : '';
    if (map) { this.mapLo.value = fmt(map.lo); this.mapHi.value = fmt(map.hi); }
    const legend = $('legend');
    legend.hidden = !map;
    if (!map) return;
    const stops = MAP_STOPS[map.name];
    $('legend-bar').style.background = `linear-gradient(to right, ${stops.map((s) => `#${s}`).join(', ')})`;
    $('legend-lo').textContent = fmt(map.lo);
    $('legend-hi').textContent = fmt(map.hi);
    legend.setAttribute('aria-label', `Colour map ${MAP_LABELS[map.name]} from ${fmt(map.lo)} to ${fmt(map.hi)}`);
    legend.dataset.map = map.name;
  }
}
