// Quality controls and the render size. The size follows the canvas's size on screen times
// devicePixelRatio times the user's resolution scale, capped by the server's limit (keeping
// the aspect ratio). Codec, quality and target frame rate appear only when the server's
// `info` offers them.
import { $ } from './ui.js';

/** Render size in pixels for a canvas of `cssWidth` × `cssHeight` CSS pixels. */
export function renderSize(cssWidth, cssHeight, dpr, scale, maxWidth, maxHeight) {
  let w = Math.max(1, cssWidth * dpr * scale);
  let h = Math.max(1, cssHeight * dpr * scale);
  const fit = Math.min(1, maxWidth / w, maxHeight / h);
  w = Math.max(1, Math.min(maxWidth, Math.round(w * fit)));
  h = Math.max(1, Math.min(maxHeight, Math.round(h * fit)));
  return [w, h];
}

export class Quality {
  /** `resized()` is called when the wanted render size may have changed. */
  constructor(settings, canvas, { resized, saved }) {
    this.settings = settings;
    this.canvas = canvas;
    this.info = null;
    this.el = { scale: $('scale'), scaleOut: $('scale-out'), size: $('render-size') };
    this.el.scale.value = String(settings.scale);
    this.el.scale.addEventListener('input', () => {
      settings.scale = Number(this.el.scale.value);
      this.#render();
      resized();
      saved();
    });
    new ResizeObserver(() => { this.#render(); resized(); }).observe(canvas);
    matchMedia(`(resolution: ${window.devicePixelRatio}dppx)`).addEventListener('change', () => resized());
    this.#render();
  }

  setInfo(info) {
    this.info = info;
    this.#render();
  }

  /** The size frames should have now. */
  size() {
    const rect = this.canvas.getBoundingClientRect();
    const maxW = this.info?.max_width ?? 4096, maxH = this.info?.max_height ?? 4096;
    return renderSize(rect.width, rect.height, window.devicePixelRatio || 1, this.settings.scale, maxW, maxH);
  }

  #render() {
    this.el.scaleOut.textContent = `${Math.round(this.settings.scale * 100)}%`;
    const [w, h] = this.size();
    this.el.size.textContent = `Render size ${w}×${h}`;
  }
}
