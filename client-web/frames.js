// Showing frames: decode a frame's payload, draw it on the canvas, and keep the last lossless
// still frame so the screenshot button can save exactly what the server rendered.
import { FrameDecoder } from './decode.js';
import { CODEC_PNG } from './protocol.js';

export const FLAG_STILL = 1;

export class FrameView {
  /** `onImage(frame)` sees each decoded frame (`decode.js`) right after it is drawn. */
  constructor(canvas, { onImage } = {}) {
    this.canvas = canvas;
    this.ctx = canvas.getContext('2d');
    this.decoder = new FrameDecoder();
    this.onImage = onImage;
    this.framesShown = 0;
    this.lastHeader = null;
    this.still = null; // { header, png: Uint8Array } of the last still PNG frame shown
  }

  /** Decodes (any codec of `decode.js`) and draws one frame; returns its header. */
  async show(buffer) {
    const frame = await this.decoder.decode(buffer);
    const { header, image, payload, depth } = frame;
    try {
      this.draw(image, header);
      if (this.onImage) this.onImage(frame);
    } finally {
      image.close();
      if (depth) depth.bitmap.close();
    }
    this.lastHeader = header;
    this.still = (header.flags & FLAG_STILL) && header.codec === CODEC_PNG ? { header, png: payload } : null;
    this.framesShown += 1;
    this.canvas.dataset.frames = String(this.framesShown);
    return header;
  }

  /** Draws a decoded image (any CanvasImageSource) of the frame's size. */
  draw(image, header) {
    if (this.canvas.width !== header.width || this.canvas.height !== header.height) {
      this.canvas.width = header.width;
      this.canvas.height = header.height;
    }
    this.ctx.drawImage(image, 0, 0, header.width, header.height);
  }
}

/** Saves `bytes` as a file named `name` through a temporary link. */
export function download(bytes, name, type) {
  const url = URL.createObjectURL(new Blob([bytes], { type }));
  const link = document.createElement('a');
  link.href = url;
  link.download = name;
  document.body.append(link);
  link.click();
  link.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10000);
}
