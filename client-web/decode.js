// Decoding frames of every codec the server may send: JPEG and PNG with the browser's image
// decoder, H.264 with WebCodecs' VideoDecoder (in order: each H.264 frame predicts from the
// last), and the depth block's PNG without colour conversion, so its bytes arrive intact.
import { parseFrameHeader, splitPayload, parseDepthBlock, CODECS, CODEC_H264, FLAG_KEYFRAME } from './protocol.js';

/** A probe configuration of the H.264 streams the server sends (constrained baseline). */
const H264_PROBE = 'avc1.42C01F';

/**
 * The codec names this browser decodes, in the order the client prefers them: H.264 when
 * WebCodecs can decode it (the server sends it only for sustained motion), then the images.
 * `?h264=off` in the page's URL leaves H.264 out.
 */
export async function supportedCodecs(search = location.search) {
  const codecs = [];
  const wanted = new URLSearchParams(search).get('h264') !== 'off';
  if (wanted && typeof VideoDecoder !== 'undefined') {
    try {
      const { supported } = await VideoDecoder.isConfigSupported({ codec: H264_PROBE, optimizeForLatency: true });
      if (supported) codecs.push('h264');
    } catch {
      // Not decodable here: the server falls back to JPEG.
    }
  }
  codecs.push('jpeg', 'png');
  return codecs;
}

/** `avc1.PPCCLL` from the SPS of an Annex B access unit (null when it has none). */
export function h264CodecString(bytes) {
  for (let i = 0; i + 7 < bytes.length; i++) {
    const startCode = bytes[i] === 0 && bytes[i + 1] === 0 && (bytes[i + 2] === 1 || (bytes[i + 2] === 0 && bytes[i + 3] === 1));
    if (!startCode) continue;
    const nal = i + (bytes[i + 2] === 1 ? 3 : 4);
    if ((bytes[nal] & 0x1f) === 7) {
      const hex = (b) => b.toString(16).padStart(2, '0').toUpperCase();
      return `avc1.${hex(bytes[nal + 1])}${hex(bytes[nal + 2])}${hex(bytes[nal + 3])}`;
    }
  }
  return null;
}

export class FrameDecoder {
  constructor() {
    this.video = null; // VideoDecoder
    this.videoCodec = null; // its codec string
    this.pending = []; // resolvers of H.264 frames in decode order
  }

  /**
   * Decodes one frame: `{ header, image, payload, depth }`, where `image` is an ImageBitmap or
   * a VideoFrame (close it when done), `payload` the image bytes and `depth` the parsed depth
   * block with its texels as an ImageBitmap (`depth.bitmap`, close it too) or null.
   */
  async decode(buffer) {
    const header = parseFrameHeader(buffer);
    const { image: payload, depth: depthBytes } = splitPayload(header, buffer);
    const depthPromise = depthBytes ? decodeDepth(depthBytes) : Promise.resolve(null);
    let image;
    if (header.codec === CODEC_H264) {
      image = await this.#decodeH264(header, payload);
    } else {
      const mime = CODECS[header.codec];
      if (!mime) throw new Error(`frame ${header.sequence} has unknown codec ${header.codec}`);
      image = await createImageBitmap(new Blob([payload], { type: mime }));
    }
    let depth = null;
    try {
      depth = await depthPromise;
    } catch (err) {
      image.close();
      throw err;
    }
    return { header, image, payload, depth };
  }

  #decodeH264(header, payload) {
    const keyframe = (header.flags & FLAG_KEYFRAME) !== 0;
    if (keyframe) {
      const codec = h264CodecString(payload);
      if (!codec) throw new Error(`H.264 keyframe ${header.sequence} has no SPS`);
      if (!this.video || this.video.state === 'closed' || codec !== this.videoCodec) this.#configure(codec);
    } else if (!this.video || this.video.state !== 'configured') {
      throw new Error(`H.264 frame ${header.sequence} arrived before any keyframe`);
    }
    return new Promise((resolve, reject) => {
      this.pending.push({ resolve, reject });
      this.video.decode(new EncodedVideoChunk({
        type: keyframe ? 'key' : 'delta',
        timestamp: header.sequence * 1000,
        data: payload,
      }));
      // No flush: after one the decoder wants a keyframe. `optimizeForLatency` and a stream
      // without reordering (baseline profile) make it output each picture at once.
    });
  }

  #configure(codec) {
    if (this.video && this.video.state !== 'closed') this.video.close();
    this.#failPending(new Error('the H.264 stream started over'));
    this.videoCodec = codec;
    this.video = new VideoDecoder({
      output: (frame) => {
        const next = this.pending.shift();
        if (next) next.resolve(frame);
        else frame.close();
      },
      error: (err) => this.#failPending(err),
    });
    this.video.configure({ codec, optimizeForLatency: true });
  }

  #failPending(err) {
    const pending = this.pending;
    this.pending = [];
    for (const p of pending) p.reject(err);
  }
}

/** The depth block with its texels decoded byte for byte. */
async function decodeDepth(bytes) {
  const block = parseDepthBlock(bytes);
  block.bitmap = await createImageBitmap(new Blob([block.png], { type: 'image/png' }), {
    colorSpaceConversion: 'none',
    premultiplyAlpha: 'none',
  });
  return block;
}
