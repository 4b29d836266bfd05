//! The binary frame header: 64 bytes, little-endian, in front of every frame payload.
//!
//! | offset | size | field |
//! | --- | --- | --- |
//! | 0 | 4 | magic `ISRF` |
//! | 4 | 2 | protocol version (1) |
//! | 6 | 2 | header length in bytes (64) |
//! | 8 | 8 | frame sequence number, from 1, per session |
//! | 16 | 8 | last applied `input_id` (0 before any input) |
//! | 24 | 4 | width in pixels |
//! | 28 | 4 | height in pixels |
//! | 32 | 1 | codec (1 JPEG, 2 PNG, 3 H.264) |
//! | 33 | 1 | flags (bit 0 still frame, bit 1 keyframe, bit 2 depth block follows the image, bit 3 the last frame of a resting view) |
//! | 34 | 1 | JPEG quality 1–100 (0 for other codecs) |
//! | 35 | 1 | reserved, zero |
//! | 36 | 4 | state update time, microseconds |
//! | 40 | 4 | acceleration structure build time, microseconds |
//! | 44 | 4 | trace time, microseconds |
//! | 48 | 4 | encode time, microseconds |
//! | 52 | 4 | image payload length in bytes (0: the rest of the message) |
//! | 56 | 8 | scene time the frame shows, seconds (f64) |

use thiserror::Error;

/// Bytes in the header.
pub const FRAME_HEADER_LEN: usize = 64;
/// First four bytes of every frame.
pub const FRAME_MAGIC: [u8; 4] = *b"ISRF";

/// Flag bit: the frame is the settled, full-quality view.
pub const FLAG_STILL: u8 = 1;
/// Flag bit: an H.264 frame that decodes on its own (IDR picture with SPS and PPS).
pub const FLAG_KEYFRAME: u8 = 2;
/// Flag bit: a depth block follows the image payload (see `PROTOCOL.md`, "Depth block").
pub const FLAG_DEPTH: u8 = 4;
/// Flag bit: the last frame of a resting view's refinement (with [`FLAG_STILL`]); nothing more
/// is sent until something changes.
pub const FLAG_FINAL: u8 = 8;

/// How the payload is encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Codec {
    Jpeg,
    Png,
    /// One H.264 access unit, Annex B byte stream, constrained baseline profile.
    H264,
}

impl Codec {
    /// Every codec of the protocol, in the order of their numbers.
    pub const ALL: [Codec; 3] = [Codec::Jpeg, Codec::Png, Codec::H264];

    pub fn to_u8(self) -> u8 {
        match self {
            Codec::Jpeg => 1,
            Codec::Png => 2,
            Codec::H264 => 3,
        }
    }

    pub fn from_u8(value: u8) -> Option<Codec> {
        match value {
            1 => Some(Codec::Jpeg),
            2 => Some(Codec::Png),
            3 => Some(Codec::H264),
            _ => None,
        }
    }

    /// The name clients use for the codec in `stream` messages and `info.codecs`.
    pub fn name(self) -> &'static str {
        match self {
            Codec::Jpeg => "jpeg",
            Codec::Png => "png",
            Codec::H264 => "h264",
        }
    }

    pub fn from_name(name: &str) -> Option<Codec> {
        Codec::ALL.into_iter().find(|c| c.name() == name)
    }
}

/// Time spent in each stage of producing a frame, microseconds. On a GPU-traced frame the
/// device's stages go in the same fields: its upload (frame uniform, lighting, and the state's
/// arrays when the state changed) is added to `build_us`, `trace_us` is the rest of the
/// trace (the kernel), and its readback is added to `encode_us`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StageTimings {
    /// Bringing the scene's state to the frame's time (simulation state update). Reported
    /// by the first frame that shows the state (0 on later ones); for a live demo's state
    /// built ahead, the build ran while the previous frame traced (PROTOCOL.md, stage times).
    pub update_us: u32,
    /// Building or refitting the acceleration structure (plus a GPU frame's upload); reported
    /// like `update_us`.
    pub build_us: u32,
    pub trace_us: u32,
    /// Encoding the image and depth block (plus a GPU frame's readback).
    pub encode_us: u32,
}

/// The decoded header.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameHeader {
    pub version: u16,
    pub sequence: u64,
    pub input_id: u64,
    pub width: u32,
    pub height: u32,
    pub codec: Codec,
    pub flags: u8,
    /// JPEG quality, 1–100; 0 for other codecs.
    pub quality: u8,
    /// Bytes of the image payload after the header; a depth block follows it when
    /// [`FLAG_DEPTH`] is set. 0 means the image is the rest of the message.
    pub payload_len: u32,
    pub timings: StageTimings,
    pub scene_time: f64,
}

/// Why bytes are not a frame.
#[derive(Debug, Error, PartialEq)]
pub enum FrameHeaderError {
    #[error("frame is {0} bytes, shorter than the {FRAME_HEADER_LEN}-byte header")]
    TooShort(usize),
    #[error("frame does not start with the magic bytes ISRF")]
    BadMagic,
    #[error("unknown codec {0}")]
    UnknownCodec(u8),
    #[error(
        "image payload of {payload} bytes does not fit the {available} bytes after the header"
    )]
    PayloadLength { payload: u32, available: usize },
}

impl FrameHeader {
    /// The header as it goes on the wire.
    pub fn encode(&self) -> [u8; FRAME_HEADER_LEN] {
        let mut out = [0u8; FRAME_HEADER_LEN];
        out[0..4].copy_from_slice(&FRAME_MAGIC);
        out[4..6].copy_from_slice(&self.version.to_le_bytes());
        out[6..8].copy_from_slice(&(FRAME_HEADER_LEN as u16).to_le_bytes());
        out[8..16].copy_from_slice(&self.sequence.to_le_bytes());
        out[16..24].copy_from_slice(&self.input_id.to_le_bytes());
        out[24..28].copy_from_slice(&self.width.to_le_bytes());
        out[28..32].copy_from_slice(&self.height.to_le_bytes());
        out[32] = self.codec.to_u8();
        out[33] = self.flags;
        out[34] = self.quality;
        out[36..40].copy_from_slice(&self.timings.update_us.to_le_bytes());
        out[40..44].copy_from_slice(&self.timings.build_us.to_le_bytes());
        out[44..48].copy_from_slice(&self.timings.trace_us.to_le_bytes());
        out[48..52].copy_from_slice(&self.timings.encode_us.to_le_bytes());
        out[52..56].copy_from_slice(&self.payload_len.to_le_bytes());
        out[56..64].copy_from_slice(&self.scene_time.to_le_bytes());
        out
    }

    /// The image payload of `frame` (the whole message, header included) and the depth block
    /// after it, if the header announces one.
    pub fn split_payload<'a>(
        &self,
        frame: &'a [u8],
    ) -> Result<(&'a [u8], Option<&'a [u8]>), FrameHeaderError> {
        let rest = frame.get(FRAME_HEADER_LEN..).unwrap_or_default();
        if self.payload_len == 0 {
            return Ok((rest, None));
        }
        let len = self.payload_len as usize;
        if len > rest.len() {
            return Err(FrameHeaderError::PayloadLength {
                payload: self.payload_len,
                available: rest.len(),
            });
        }
        let (image, depth) = rest.split_at(len);
        Ok((image, (self.flags & FLAG_DEPTH != 0).then_some(depth)))
    }

    /// Reads the header from the front of a frame; the payload is `&bytes[FRAME_HEADER_LEN..]`.
    pub fn decode(bytes: &[u8]) -> Result<FrameHeader, FrameHeaderError> {
        if bytes.len() < FRAME_HEADER_LEN {
            return Err(FrameHeaderError::TooShort(bytes.len()));
        }
        if bytes[0..4] != FRAME_MAGIC {
            return Err(FrameHeaderError::BadMagic);
        }
        let u16_at = |i: usize| u16::from_le_bytes([bytes[i], bytes[i + 1]]);
        let u32_at = |i: usize| {
            let mut b = [0u8; 4];
            b.copy_from_slice(&bytes[i..i + 4]);
            u32::from_le_bytes(b)
        };
        let u64_at = |i: usize| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&bytes[i..i + 8]);
            u64::from_le_bytes(b)
        };
        let codec = Codec::from_u8(bytes[32]).ok_or(FrameHeaderError::UnknownCodec(bytes[32]))?;
        Ok(FrameHeader {
            version: u16_at(4),
            sequence: u64_at(8),
            input_id: u64_at(16),
            width: u32_at(24),
            height: u32_at(28),
            codec,
            flags: bytes[33],
            quality: bytes[34],
            payload_len: u32_at(52),
            timings: StageTimings {
                update_us: u32_at(36),
                build_us: u32_at(40),
                trace_us: u32_at(44),
                encode_us: u32_at(48),
            },
            scene_time: f64::from_bits(u64_at(56)),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_round_trips_and_matches_the_documented_offsets() {
        let header = FrameHeader {
            version: 1,
            sequence: 0x0102_0304_0506_0708,
            input_id: 42,
            width: 640,
            height: 480,
            codec: Codec::Jpeg,
            flags: FLAG_STILL | FLAG_DEPTH,
            quality: 85,
            payload_len: 1234,
            timings: StageTimings {
                update_us: 1,
                build_us: 2,
                trace_us: 3,
                encode_us: 4,
            },
            scene_time: 1.5,
        };
        let bytes = header.encode();
        assert_eq!(&bytes[0..4], b"ISRF");
        assert_eq!(bytes[8], 0x08, "sequence is little-endian");
        assert_eq!(
            u32::from_le_bytes([bytes[24], bytes[25], bytes[26], bytes[27]]),
            640
        );
        assert_eq!(bytes[32], 1);
        assert_eq!(bytes[33], 5, "flags: still and depth");
        assert_eq!(bytes[34], 85, "JPEG quality");
        assert_eq!(
            u32::from_le_bytes([bytes[52], bytes[53], bytes[54], bytes[55]]),
            1234
        );
        assert_eq!(FrameHeader::decode(&bytes), Ok(header));
        assert_eq!(
            FrameHeader::decode(&bytes[..10]),
            Err(FrameHeaderError::TooShort(10))
        );
        let mut bad = bytes;
        bad[32] = 9;
        assert_eq!(
            FrameHeader::decode(&bad),
            Err(FrameHeaderError::UnknownCodec(9))
        );
    }

    #[test]
    fn codec_numbers_and_names_round_trip() {
        for codec in Codec::ALL {
            assert_eq!(Codec::from_u8(codec.to_u8()), Some(codec));
            assert_eq!(Codec::from_name(codec.name()), Some(codec));
        }
        assert_eq!(Codec::from_name("vp9"), None);
    }
}
