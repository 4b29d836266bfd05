// Effect toggles, built from the server's `info.effects`: a switch for each effect the scene
// can use (`available`) and nothing for the others, and the quality settings (bounces,
// transparent layers, samples) of the effects offered. The user's choices are kept in the
// URL and sent again after a reconnect.
import { $ } from './ui.js';

const LABELS = {
  shadows: 'Shadows',
  soft_shadows: 'Soft shadows',
  reflections: 'Reflections',
  refraction: 'Refraction',
  transparency: 'Transparency',
  ambient_occlusion: 'Ambient occlusion',
  clip_box: 'Clip box',
  isosurfaces: 'Further isosurfaces',
};

/** Quality settings: [name, label, shown when any of these effects is offered, minimum, limit key]. */
const QUALITY = [
  ['depth', 'Bounces', ['reflections', 'refraction'], 0, 'max_depth'],
  ['layers', 'Transparent layers', ['transparency'], 0, 'max_depth'],
  ['light_samples', 'Light samples', ['soft_shadows'], 1, 'max_samples'],
  ['ao_samples', 'Occlusion samples', ['ambient_occlusion'], 1, 'max_samples'],
];

export class EffectsPanel {
  /** `changed(changes)` is called with an `effects` message body when the user changes one. */
  constructor(settings, { changed, saved }) {
    this.settings = settings;
    this.changed = changed;
    this.saved = saved;
    this.info = null;
    this.section = $('effects-section');
    this.container = $('effects');
  }

  /** Builds the toggles for the session described by `info`. */
  setInfo(info) {
    this.info = info.effects ?? null;
    const available = this.info ? this.info.available.filter((name) => name in LABELS) : [];
    // Settings the user made for effects this scene does not offer are dropped.
    for (const key of Object.keys(this.settings.fx)) {
      const q = QUALITY.find(([name]) => name === key);
      const offered = q ? q[2].some((e) => available.includes(e)) : available.includes(key);
      if (!offered) delete this.settings.fx[key];
    }
    // The clip box and the further isosurfaces have their own sections (the look's), which
    // switch `clip_box` and `isosurfaces` too.
    const toggles = available.filter((name) => name !== 'clip_box' && name !== 'isosurfaces');
    this.section.hidden = toggles.length === 0;
    const rows = toggles.map((name) => {
      const label = document.createElement('label');
      label.className = 'check';
      const box = document.createElement('input');
      box.type = 'checkbox';
      box.id = `fx-${name}`;
      box.checked = this.#value(name);
      box.addEventListener('change', () => this.#set(name, box.checked));
      label.append(box, ` ${LABELS[name]}`);
      const row = document.createElement('div');
      row.append(label);
      return row;
    });
    for (const [name, text, needs, min, limitKey] of QUALITY) {
      if (!needs.some((e) => available.includes(e))) continue;
      const max = this.info[limitKey];
      const row = document.createElement('div');
      row.className = 'quality';
      const label = document.createElement('label');
      label.htmlFor = `fx-${name}`;
      label.textContent = `${text} `;
      const out = document.createElement('output');
      out.htmlFor = `fx-${name}`;
      const input = document.createElement('input');
      input.type = 'range';
      input.id = `fx-${name}`;
      input.min = String(min);
      input.max = String(max);
      input.step = '1';
      input.value = String(Math.min(max, Math.max(min, this.#value(name))));
      out.textContent = input.value;
      label.append(out);
      input.addEventListener('input', () => { out.textContent = input.value; });
      input.addEventListener('change', () => this.#set(name, Number(input.value)));
      row.append(label, input);
      rows.push(row);
    }
    this.container.replaceChildren(...rows);
  }

  /** The `effects` message body that restores the user's choices, or null if they made none. */
  restoreChanges() {
    const changes = { ...this.settings.fx };
    return Object.keys(changes).length ? changes : null;
  }

  /** Notes an effect another panel switched (a see-through isosurface turns transparency on). */
  noteSwitched(name, value) {
    if (!this.info) return;
    this.#keep(name, value);
    const box = document.getElementById(`fx-${name}`);
    if (box && box.type === 'checkbox') box.checked = value;
  }

  #value(name) {
    return name in this.settings.fx ? this.settings.fx[name] : this.info.settings[name];
  }

  #set(name, value) {
    this.#keep(name, value);
    this.changed({ [name]: value });
    this.saved();
  }

  /** Notes `name` in the settings only where it differs from the scene's start, so URLs stay short. */
  #keep(name, value) {
    if (value === this.info.settings[name]) delete this.settings.fx[name];
    else this.settings.fx[name] = value;
  }
}
