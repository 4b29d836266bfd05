// A minimal WebM (Matroska/EBML) reader for the recording test: the video track's codec and
// size, and every frame (SimpleBlock or Block) with its timestamp and keyframe flag. Written
// from the Matroska specification for this test; it shares no code with the recorder.

const MASTER = new Set([
  0x18538067, // Segment
  0x1f43b675, // Cluster
  0xa0, // BlockGroup
  0x1654ae6b, // Tracks
  0xae, // TrackEntry
  0xe0, // Video
]);

/** A variable-length integer at `pos`: { value, length }; `keepMarker` for element ids. */
function vint(buf, pos, keepMarker) {
  const first = buf[pos];
  let length = 1;
  while (length <= 8 && !(first & (0x80 >> (length - 1)))) length += 1;
  if (length > 8) throw new Error(`bad EBML length byte ${first} at ${pos}`);
  let value = keepMarker ? first : first & (0xff >> length);
  let allOnes = value === (0xff >> length);
  for (let i = 1; i < length; i++) {
    value = value * 256 + buf[pos + i];
    if (buf[pos + i] !== 0xff) allOnes = false;
  }
  return { value, length, unknown: !keepMarker && allOnes };
}

const uint = (buf, pos, len) => { let v = 0; for (let i = 0; i < len; i++) v = v * 256 + buf[pos + i]; return v; };

/** `{ codec, width, height, timecodeScale, frames: [{ ms, key, data }] }` of a WebM file. */
export function readWebm(buf) {
  const out = { codec: null, width: 0, height: 0, timecodeScale: 1e6, frames: [] };
  let clusterTime = 0;
  const walk = (start, end) => {
    let pos = start;
    while (pos < end) {
      const id = vint(buf, pos, true);
      const size = vint(buf, pos + id.length, false);
      const body = pos + id.length + size.length;
      const bodyEnd = size.unknown ? end : Math.min(end, body + size.value);
      const v = id.value;
      if (v === 0x1f43b675) clusterTime = 0;
      if (MASTER.has(v)) {
        walk(body, bodyEnd);
      } else if (v === 0xe7) {
        clusterTime = uint(buf, body, bodyEnd - body);
      } else if (v === 0x2ad7b1) {
        out.timecodeScale = uint(buf, body, bodyEnd - body);
      } else if (v === 0x86) {
        out.codec = Buffer.from(buf.subarray(body, bodyEnd)).toString('latin1');
      } else if (v === 0xb0) {
        out.width = uint(buf, body, bodyEnd - body);
      } else if (v === 0xba) {
        out.height = uint(buf, body, bodyEnd - body);
      } else if (v === 0xa3 || v === 0xa1) {
        const track = vint(buf, body, false);
        let p = body + track.length;
        const rel = (buf[p] << 8 | buf[p + 1]) << 16 >> 16;
        const flags = buf[p + 2];
        p += 3;
        if (flags & 0x06) throw new Error('laced blocks are not expected from MediaRecorder');
        const ticks = clusterTime + rel;
        out.frames.push({ ms: (ticks * out.timecodeScale) / 1e6, key: v === 0xa3 ? Boolean(flags & 0x80) : out.frames.length === 0, data: buf.subarray(p, bodyEnd) });
      }
      if (size.unknown && !MASTER.has(v)) throw new Error(`unknown size for element ${v.toString(16)}`);
      pos = bodyEnd;
    }
  };
  walk(0, buf.length);
  return out;
}
