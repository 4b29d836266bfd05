// isoray websocket protocol v1: the binary frame header and the depth block (see
// protocol/PROTOCOL.md).

export const PROTOCOL_VERSION = 1;
export const FRAME_HEADER_LEN = 64;
export const CODEC_JPEG = 1;
export const CODEC_PNG = 2;
export const CODEC_H264 = 3;
/** Image types of the codecs a browser decodes with `createImageBitmap`. */
export const CODECS = { [CODEC_JPEG]: 'image/jpeg', [CODEC_PNG]: 'image/png' };
/** Codec names as `stream` messages and `info.codecs` spell them. */
export const CODEC_NAMES = { [CODEC_JPEG]: 'jpeg', [CODEC_PNG]: 'png', [CODEC_H264]: 'h264' };
/** Codec names as people read them (the stats overlay). */
export const CODEC_LABELS = { [CODEC_JPEG]: 'JPEG', [CODEC_PNG]: 'PNG', [CODEC_H264]: 'H.264' };
/** A frame header's codec number as people read it; a number the page does not know stays a number. */
export const codecLabel = (codec) => CODEC_LABELS[codec] ?? `codec ${codec}`;
export const FLAG_STILL = 1;
export const FLAG_KEYFRAME = 2;
export const FLAG_DEPTH = 4;
// With FLAG_STILL: the last frame of the resting view's refinement.
export const FLAG_FINAL = 8;
export const DEPTH_HEADER_LEN = 48;

/** Reads the 64-byte little-endian header at the front of a frame. */
export function parseFrameHeader(buffer) {
  if (buffer.byteLength < FRAME_HEADER_LEN) throw new Error(`frame of ${buffer.byteLength} bytes is shorter than its header`);
  const v = new DataView(buffer);
  const magic = String.fromCharCode(v.getUint8(0), v.getUint8(1), v.getUint8(2), v.getUint8(3));
  if (magic !== 'ISRF') throw new Error('frame does not start with ISRF');
  return {
    version: v.getUint16(4, true),
    headerLen: v.getUint16(6, true),
    sequence: Number(v.getBigUint64(8, true)),
    inputId: Number(v.getBigUint64(16, true)),
    width: v.getUint32(24, true),
    height: v.getUint32(28, true),
    codec: v.getUint8(32),
    flags: v.getUint8(33),
    quality: v.getUint8(34),
    updateUs: v.getUint32(36, true),
    buildUs: v.getUint32(40, true),
    traceUs: v.getUint32(44, true),
    encodeUs: v.getUint32(48, true),
    payloadLen: v.getUint32(52, true),
    sceneTime: v.getFloat64(56, true),
  };
}

/**
 * The image payload and the depth block of a frame, as views into `buffer`:
 * `{ image: Uint8Array, depth: Uint8Array | null }`.
 */
export function splitPayload(header, buffer) {
  const start = header.headerLen;
  const rest = buffer.byteLength - start;
  if (header.payloadLen === 0) return { image: new Uint8Array(buffer, start), depth: null };
  if (header.payloadLen > rest) throw new Error(`frame ${header.sequence}: image of ${header.payloadLen} bytes, only ${rest} after the header`);
  const image = new Uint8Array(buffer, start, header.payloadLen);
  const hasDepth = (header.flags & FLAG_DEPTH) !== 0;
  const depth = hasDepth ? new Uint8Array(buffer, start + header.payloadLen) : null;
  return { image, depth };
}

/**
 * Reads a depth block's fixed part: `{ width, height, near, camera: { eye, target, up,
 * fov_y_deg }, png: Uint8Array }`.
 */
export function parseDepthBlock(bytes) {
  if (bytes.byteLength < DEPTH_HEADER_LEN) throw new Error(`depth block of ${bytes.byteLength} bytes is shorter than its header`);
  const v = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const f = (i) => v.getFloat32(i, true);
  return {
    width: v.getUint16(0, true),
    height: v.getUint16(2, true),
    near: f(4),
    camera: {
      eye: [f(8), f(12), f(16)],
      target: [f(20), f(24), f(28)],
      up: [f(32), f(36), f(40)],
      fov_y_deg: f(44),
    },
    png: bytes.subarray(DEPTH_HEADER_LEN),
  };
}
