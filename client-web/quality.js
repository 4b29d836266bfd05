// Quality controls and the render size. The size follows the canvas's size on screen times
// devicePixelRatio times the user's resolution scale, capped by the server's limit (keeping
// the aspect ratio). The codec preference offers what both the server (`info.codecs`) and
// this browser decode; the target frame rate runs up to the server's cap (`info.max_fps`).
// Both travel in the `stream` message.
import { $, fillSelect } from './ui.js';

const CODEC_LABELS = {
  h264: 'H.264 video while moving',
  jpeg: 'JPEG while moving',
  png: 'PNG only (lossless, heavy)',
};

/**
 * The `stream.codecs` list for a preference among the `offered` codecs (those both ends
 * decode, in the browser's order). The server picks by what the list holds, not its order:
 * PNG for the still frame when listed, then for moving frames H.264 once motion is sustained
 * if JPEG is also listed, H.264 at once if not, else JPEG, else PNG. So `auto` (or a codec
 * not offered) lists everything; `jpeg` leaves H.264 out; `h264` leaves JPEG out; `png`
 * lists PNG alone.
 */
export function codecOrder(preference, offered) {
  if (!offered.includes(preference)) return [...offered];
  if (preference === 'png') return ['png'];
  if (preference === 'jpeg') return offered.filter((c) => c !== 'h264');
  // H.264 needs an image codec beside it for the still frame (the server insists).
  return offered.includes('png') ? ['h264', 'png'] : [...offered];
}

/** The codecs both ends decode, in the browser's order (all the browser's before `info`). */
export function offeredCodecs(decodable, serverCodecs) {
  return serverCodecs && serverCodecs.length ? decodable.filter((c) => serverCodecs.includes(c)) : [...decodable];
}

/**
 * The fields of the `stream` message the Quality panel decides: `codecs`, and `fps` — the
 * user's target, or the server's maximum once `info` tells it (an absent `fps` would keep
 * the session's previous target).
 */
export function streamFields({ codec, fps }, info, decodable) {
  const fields = { codecs: codecOrder(codec, offeredCodecs(decodable, info?.codecs)) };
  const target = fps ?? (info?.max_fps > 0 ? info.max_fps : null);
  if (target !== null) fields.fps = info?.max_fps > 0 ? Math.min(target, info.max_fps) : target;
  return fields;
}

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
  /**
   * `resized()` is called when the wanted render size may have changed, `streamChanged()`
   * when the codec preference or target frame rate did, `saved()` after any change.
   */
  constructor(settings, canvas, { resized, saved, streamChanged }) {
    this.settings = settings;
    this.canvas = canvas;
    this.info = null;
    this.decodable = ['jpeg', 'png']; // what this browser decodes (decode.js says)
    this.el = {
      scale: $('scale'), scaleOut: $('scale-out'), size: $('render-size'),
      codecRow: $('codec-row'), codec: $('codec'), fpsRow: $('fps-row'), fps: $('fps'), fpsOut: $('fps-out'),
    };
    this.el.codec.addEventListener('change', () => {
      settings.codec = this.el.codec.value;
      streamChanged();
      saved();
    });
    this.el.fps.addEventListener('input', () => { this.el.fpsOut.textContent = `${this.el.fps.value} fps`; });
    this.el.fps.addEventListener('change', () => {
      const fps = Number(this.el.fps.value);
      // The slider's top is the server's maximum, kept as "the maximum" (null) in the URL.
      settings.fps = fps >= Number(this.el.fps.max) ? null : fps;
      this.#render();
      streamChanged();
      saved();
    });
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
    this.#build();
  }

  /** The codecs this browser decodes, in its order of preference. */
  setDecodable(codecs) {
    this.decodable = codecs;
    this.#build();
  }

  /** The `stream` message fields this panel sets (see `streamFields`). */
  streamFields() {
    return streamFields(this.settings, this.info, this.decodable);
  }

  #build() {
    const offered = offeredCodecs(this.decodable, this.info?.codecs);
    const choices = [['auto', 'Automatic'], ...offered.map((c) => [c, CODEC_LABELS[c] ?? c])];
    fillSelect(this.el.codec, choices, this.settings.codec);
    this.el.codecRow.hidden = !(this.info?.codecs?.length > 0);
    const maxFps = this.info?.max_fps;
    this.el.fpsRow.hidden = !(maxFps >= 1);
    if (maxFps >= 1) {
      this.el.fps.max = String(Math.floor(maxFps));
      this.el.fps.value = String(this.settings.fps ?? Math.floor(maxFps));
    }
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
    const maxFps = this.info?.max_fps;
    const fps = this.settings.fps;
    this.el.fpsOut.textContent = fps === null || (maxFps >= 1 && fps >= maxFps)
      ? `server’s maximum${maxFps >= 1 ? ` (${+maxFps.toFixed(2)} fps)` : ''}`
      : `${fps} fps`;
    const [w, h] = this.size();
    this.el.size.textContent = `Render size ${w}×${h}`;
  }
}
