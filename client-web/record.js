// Recording a time range to a WebM file: each frame is the canvas once the server's still
// (lossless) image of its time is on screen. All frames are fetched first, at the server's
// pace, then encoded with WebCodecs, frame i stamped i/fps (webm.js), so the file has exactly
// one frame per time at exact intervals. Browsers without a VP8 VideoEncoder hand the frames
// to a MediaRecorder at the chosen rate instead (it stamps frames as they arrive, and may drop
// one on a busy machine), as VideoFrames through a MediaStreamTrackGenerator or drawn on a
// canvas captured with `captureStream(0)` and `requestFrame`. A progress
// bar counts the frames fetched and encoded; the file is offered as a download at the end.
import { $ } from './ui.js';
import { canEncode, encodeWebm } from './webm.js';

// Frames are kept as images until encoded: at most a minute at 10 fps, 20 s at 30 fps.
const MAX_FRAMES = 600;

export class Recorder {
  /**
   * `pinTime(t)` shows scene time `t` and returns its input id (null when offline);
   * `getTime()` is the pinned time now (null: live), which `restore(t)` returns to.
   */
  constructor(canvas, { pinTime, getTime, restore }) {
    this.canvas = canvas;
    this.pinTime = pinTime;
    this.getTime = getTime;
    this.restoreTime = restore;
    this.waiting = null; // { inputId, resolve } while a frame is awaited
    this.blob = null;
    this.frames = 0;
    this.button = $('record');
    this.progress = $('rec-progress');
    this.button.addEventListener('click', () => {
      if (this.busy) this.cancelled = true;
      else this.record().catch((err) => this.#done(`Recording failed: ${err.message}`));
    });
  }

  /** Called for every frame shown. */
  frameShown(header) {
    const w = this.waiting;
    if (w && header.inputId >= w.inputId && (header.flags & 1) === 1) {
      this.waiting = null;
      w.resolve();
    }
  }

  #frameOf(time) {
    const inputId = this.pinTime(time);
    if (inputId === null || inputId === undefined) return Promise.reject(new Error('the server is not connected'));
    return new Promise((resolve) => { this.waiting = { inputId, resolve }; });
  }

  /** Records scene times from..to (the fields' values) at the chosen rate. */
  async record() {
    const from = Number($('rec-from').value), to = Number($('rec-to').value), fps = Number($('rec-fps').value);
    if (!(Number.isFinite(from) && Number.isFinite(to) && to > from && from >= 0 && fps > 0)) {
      $('rec-status').textContent = 'Choose a time range with “to” after “from”.';
      return;
    }
    const count = Math.min(MAX_FRAMES, Math.round((to - from) * fps));
    const type = typeof MediaRecorder === 'function'
      ? ['video/webm;codecs=vp8', 'video/webm;codecs=vp9', 'video/webm'].find((t) => MediaRecorder.isTypeSupported(t))
      : undefined;
    if (!type && typeof VideoEncoder !== 'function') throw new Error('this browser cannot record WebM');
    this.busy = true;
    this.cancelled = false;
    this.button.textContent = 'Stop recording';
    this.button.setAttribute('aria-pressed', 'true');
    // Progress: the frames fetched, then the frames encoded.
    this.progress.max = 2 * count;
    this.progress.value = 0;
    this.progress.hidden = false;
    $('rec-download').hidden = true;
    $('rec-status').textContent = `Rendering ${count} frames…`;
    const before = this.getTime();
    // First every frame of the range, as the server renders it (at its own pace)...
    const images = [];
    try {
      for (let i = 0; i < count && !this.cancelled; i++) {
        await this.#frameOf(+(from + i / fps).toFixed(6));
        images.push(await createImageBitmap(this.canvas));
        this.progress.value = images.length;
      }
    } finally {
      this.restoreTime(before);
    }
    // ...then encoded: with WebCodecs, frame i stamped at i/fps exactly; else MediaRecorder.
    $('rec-status').textContent = `Encoding ${images.length} frames…`;
    const frames = images.length;
    if (!frames) {
      this.#done('Nothing recorded.');
      return;
    }
    if (await canEncode(images[0].width, images[0].height)) {
      this.encoder = 'webcodecs';
      this.blob = await encodeWebm(images, fps, (n) => { this.progress.value = count + n; });
    } else {
      this.encoder = 'mediarecorder';
      this.blob = await this.#mediaRecorder(images, fps, type, count);
    }
    this.frames = frames;
    const link = $('rec-download');
    if (link.href) URL.revokeObjectURL(link.href);
    link.href = URL.createObjectURL(this.blob);
    link.download = `isoray-t${from}-${to}-${fps}fps.webm`;
    link.hidden = false;
    this.#done(`Recorded ${frames} frames (${(frames / fps).toFixed(2)} s).`);
  }

  /** The frames handed to a MediaRecorder at `fps` (it stamps them as they arrive). */
  async #mediaRecorder(images, fps, type, count) {
    if (!type) throw new Error('this browser cannot record WebM');
    const source = frameSource(images[0]);
    const recorder = new MediaRecorder(source.stream, { mimeType: type, videoBitsPerSecond: 8e6 });
    const chunks = [];
    recorder.ondataavailable = (e) => { if (e.data.size) chunks.push(e.data); };
    const stopped = new Promise((resolve) => { recorder.onstop = resolve; });
    recorder.start();
    let frames = 0;
    const t0 = performance.now();
    try {
      for (const [i, image] of images.entries()) {
        const wait = t0 + (i * 1000) / fps - performance.now();
        if (wait > 0) await new Promise((r) => setTimeout(r, wait));
        await source.frame(image, Math.round((i * 1e6) / fps));
        image.close();
        frames += 1;
        this.progress.value = count + frames;
      }
      // The last frame lasts one frame interval too.
      const wait = t0 + (images.length * 1000) / fps - performance.now();
      if (wait > 0) await new Promise((r) => setTimeout(r, wait));
    } finally {
      recorder.stop();
      await stopped;
      source.stop();
    }
    return new Blob(chunks, { type: 'video/webm' });
  }

  #done(text) {
    this.busy = false;
    this.waiting = null;
    this.button.textContent = 'Record WebM';
    this.button.setAttribute('aria-pressed', 'false');
    $('rec-status').textContent = text;
  }
}

/** Where the recorder's frames come from: `frame(image, timestamp_us)` adds one. */
function frameSource(first) {
  if (typeof MediaStreamTrackGenerator === 'function') {
    // eslint-disable-next-line no-undef
    const generator = new MediaStreamTrackGenerator({ kind: 'video' });
    const writer = generator.writable.getWriter();
    return {
      stream: new MediaStream([generator]),
      frame: (image, timestamp) => writer.write(new VideoFrame(image, { timestamp })),
      stop: () => writer.close().catch(() => {}),
    };
  }
  const canvas = document.createElement('canvas');
  [canvas.width, canvas.height] = [first.width, first.height];
  const g = canvas.getContext('2d');
  const stream = canvas.captureStream(0);
  const track = stream.getVideoTracks()[0];
  return {
    stream,
    frame: async (image) => { g.drawImage(image, 0, 0, canvas.width, canvas.height); track.requestFrame(); },
    stop: () => track.stop(),
  };
}
