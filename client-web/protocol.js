// isoray websocket protocol v1: the binary frame header (see protocol/PROTOCOL.md).

export const PROTOCOL_VERSION = 1;
export const FRAME_HEADER_LEN = 64;
export const CODECS = { 1: 'image/jpeg', 2: 'image/png' };

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
    updateUs: v.getUint32(36, true),
    buildUs: v.getUint32(40, true),
    traceUs: v.getUint32(44, true),
    encodeUs: v.getUint32(48, true),
    sceneTime: v.getFloat64(56, true),
  };
}
