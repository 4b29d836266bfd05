// Showing frames: decode a frame's payload, draw it on the canvas, and keep the last lossless
// still frame so the screenshot button can save exactly what the server rendered.
import { parseFrameHeader, CODECS } from './protocol.js';

export const FLAG_STILL = 1;

export class FrameView {
  constructor(canvas) {
    this.canvas = canvas;
    this.ctx = canvas.getContext('2d');
    this.framesShown = 0;
    this.lastHeader = null;
    this.still = null; // { header, png: Uint8Array } of the last still PNG frame shown
  }

  /** Parses, decodes and draws one frame; returns its header. */
  async show(buffer) {
    const header = parseFrameHeader(buffer);
    const payload = new Uint8Array(buffer, header.headerLen);
    const mime = CODECS[header.codec];
    if (!mime) throw new Error(`frame ${header.sequence} has unknown codec ${header.codec}`);
    const bitmap = await createImageBitmap(new Blob([payload], { type: mime }));
    try {
      this.draw(bitmap, header);
    } finally {
      bitmap.close();
    }
    this.lastHeader = header;
    this.still = (header.flags & FLAG_STILL) && mime === 'image/png' ? { header, png: payload } : null;
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
