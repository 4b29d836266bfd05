// Encoding recorded frames to WebM with WebCodecs: each frame gets its own timestamp (frame
// i at i/fps s), so the file holds exactly one frame per time at exact intervals however
// busy the machine is (MediaRecorder stamps frames with their arrival times and may drop one
// when its encoder falls behind). The muxer writes the Matroska subset WebM players read:
// EBML header, Segment with Info and one VP8 video track, Clusters of SimpleBlocks, each
// cluster starting at a keyframe.

/** Whether this browser can encode `width`×`height` VP8 with WebCodecs. */
export async function canEncode(width, height) {
  if (typeof VideoEncoder !== 'function' || typeof VideoFrame !== 'function') return false;
  try {
    const { supported } = await VideoEncoder.isConfigSupported(encoderConfig(width, height, 10));
    return Boolean(supported);
  } catch {
    return false;
  }
}

function encoderConfig(width, height, fps) {
  return { codec: 'vp8', width, height, bitrate: 8e6, framerate: fps };
}

/**
 * Encodes `images` (ImageBitmaps of one size, closed here) as a WebM `Blob` at `fps`;
 * `progress(n)` is told how many frames are encoded so far.
 */
export async function encodeWebm(images, fps, progress) {
  const { width, height } = images[0];
  const chunks = [];
  let failure = null;
  const encoder = new VideoEncoder({
    output: (chunk) => {
      const data = new Uint8Array(chunk.byteLength);
      chunk.copyTo(data);
      chunks.push({ ms: Math.round(chunk.timestamp / 1000), key: chunk.type === 'key', data });
      progress(chunks.length);
    },
    error: (e) => { failure = e; },
  });
  encoder.configure(encoderConfig(width, height, fps));
  const keyEvery = Math.max(1, Math.round(2 * fps)); // a keyframe (and a cluster) every 2 s
  for (const [i, image] of images.entries()) {
    const frame = new VideoFrame(image, { timestamp: Math.round((i * 1e6) / fps), duration: Math.round(1e6 / fps) });
    encoder.encode(frame, { keyFrame: i % keyEvery === 0 });
    frame.close();
    image.close();
  }
  await encoder.flush();
  encoder.close();
  if (failure) throw failure;
  if (chunks.length !== images.length) throw new Error(`the encoder gave ${chunks.length} of ${images.length} frames`);
  return new Blob([muxWebm(chunks, width, height, fps)], { type: 'video/webm' });
}

// --- EBML ------------------------------------------------------------------------------

const concat = (parts) => {
  const out = new Uint8Array(parts.reduce((n, p) => n + p.length, 0));
  let at = 0;
  for (const p of parts) { out.set(p, at); at += p.length; }
  return out;
};

/** Big-endian bytes of a non-negative integer (at least one). */
function uintBytes(v) {
  const b = [];
  do { b.unshift(v % 256); v = Math.floor(v / 256); } while (v > 0);
  return Uint8Array.from(b);
}

/** An element's size as an 8-byte EBML variable-length integer. */
function sizeBytes(n) {
  const b = new Uint8Array(8);
  b[0] = 0x01;
  for (let i = 7, v = n; i >= 1; i--, v = Math.floor(v / 256)) b[i] = v % 256;
  return b;
}

/** An element: its id (marker bits included, as the specification writes it) and payload. */
function el(id, payload) {
  const body = payload instanceof Uint8Array ? payload : concat(payload);
  return concat([uintBytes(id), sizeBytes(body.length), body]);
}

const uint = (id, v) => el(id, uintBytes(v));
const str = (id, s) => el(id, new TextEncoder().encode(s));
const float = (id, v) => {
  const b = new Uint8Array(8);
  new DataView(b.buffer).setFloat64(0, v);
  return el(id, b);
};

/** The WebM file of encoded `chunks` ({ ms, key, data }, in order, the first a keyframe). */
export function muxWebm(chunks, width, height, fps) {
  const header = el(0x1a45dfa3, [
    uint(0x4286, 1), uint(0x42f7, 1), uint(0x42f2, 4), uint(0x42f3, 8),
    str(0x4282, 'webm'), uint(0x4287, 2), uint(0x4285, 2),
  ]);
  const info = el(0x1549a966, [
    uint(0x2ad7b1, 1e6), // timestamps in ms
    str(0x4d80, 'isoray'), str(0x5741, 'isoray'),
    float(0x4489, (chunks.length * 1000) / fps),
  ]);
  const tracks = el(0x1654ae6b, [el(0xae, [
    uint(0xd7, 1), uint(0x73c5, 1), uint(0x83, 1), uint(0x9c, 0),
    uint(0x23e383, Math.round(1e9 / fps)), str(0x86, 'V_VP8'),
    el(0xe0, [uint(0xb0, width), uint(0xba, height)]),
  ])]);
  const clusters = [];
  let blocks = [], start = 0;
  const close = () => { if (blocks.length) clusters.push(el(0x1f43b675, [uint(0xe7, start), ...blocks])); blocks = []; };
  for (const c of chunks) {
    // A cluster per keyframe, and never a block more than 32 s after its cluster's start.
    if (c.key || c.ms - start > 32000) { close(); start = c.ms; }
    const head = Uint8Array.of(0x81, ((c.ms - start) >> 8) & 0xff, (c.ms - start) & 0xff, c.key ? 0x80 : 0);
    blocks.push(el(0xa3, concat([head, c.data])));
  }
  close();
  return concat([header, el(0x18538067, [info, tracks, ...clusters])]);
}
