//! The on-disk format of one stored step: a 64-byte header and the values as little-endian
//! f32, row-major, `rows × columns` of them.
//!
//! | offset | size | field |
//! | --- | --- | --- |
//! | 0 | 8 | magic `ISORAYST` |
//! | 8 | 4 | format version (1) |
//! | 12 | 4 | columns, 1..=16 (what they hold depends on the scene's kind: `crate::kind`) |
//! | 16 | 8 | rows |
//! | 24 | 8 | step index |
//! | 32 | 8 | step time (f64) |
//! | 40 | 16 | XXH3-128 of the payload |
//! | 56 | 8 | XXH3-64 of bytes 0..56 |
//!
//! The payload checksum doubles as the step's content identity: pushing the same index with
//! the same time, shape and checksum is a no-op.

use xxhash_rust::xxh3::xxh3_64;

pub const MAGIC: [u8; 8] = *b"ISORAYST";
pub const VERSION: u32 = 1;
pub const HEADER_LEN: usize = 64;

/// Most columns a step file may have, whatever the kind.
pub const MAX_COLUMNS: u32 = 16;

/// The fixed fields of a step file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepHeader {
    pub columns: u32,
    pub rows: u64,
    pub index: u64,
    pub time: f64,
    pub checksum: u128,
}

/// Why a step file cannot be trusted.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FormatError {
    #[error("file is {0} bytes, shorter than the 64-byte header")]
    Short(u64),
    #[error("bad magic: not a step file")]
    Magic,
    #[error("unknown format version {0}")]
    Version(u32),
    #[error("header checksum mismatch")]
    HeaderChecksum,
    #[error("bad column count {0}")]
    Columns(u32),
    #[error("payload is {actual} bytes, header says {expected}")]
    Length { actual: u64, expected: u64 },
    #[error("payload checksum mismatch")]
    PayloadChecksum,
}

impl StepHeader {
    pub fn payload_bytes(&self) -> u64 {
        self.rows.saturating_mul(u64::from(self.columns) * 4)
    }

    pub fn encode(&self) -> [u8; HEADER_LEN] {
        let mut b = [0u8; HEADER_LEN];
        b[0..8].copy_from_slice(&MAGIC);
        b[8..12].copy_from_slice(&VERSION.to_le_bytes());
        b[12..16].copy_from_slice(&self.columns.to_le_bytes());
        b[16..24].copy_from_slice(&self.rows.to_le_bytes());
        b[24..32].copy_from_slice(&self.index.to_le_bytes());
        b[32..40].copy_from_slice(&self.time.to_le_bytes());
        b[40..56].copy_from_slice(&self.checksum.to_le_bytes());
        let sum = xxh3_64(&b[0..56]);
        b[56..64].copy_from_slice(&sum.to_le_bytes());
        b
    }

    /// Parses and checks the header and the payload length; the payload checksum is checked
    /// separately by [`verify_payload`] because it reads every byte.
    pub fn decode(file: &[u8]) -> Result<StepHeader, FormatError> {
        if file.len() < HEADER_LEN {
            return Err(FormatError::Short(file.len() as u64));
        }
        let u32_at = |o: usize| u32::from_le_bytes(file[o..o + 4].try_into().expect("4 bytes"));
        let u64_at = |o: usize| u64::from_le_bytes(file[o..o + 8].try_into().expect("8 bytes"));
        if file[0..8] != MAGIC {
            return Err(FormatError::Magic);
        }
        if u64_at(56) != xxh3_64(&file[0..56]) {
            return Err(FormatError::HeaderChecksum);
        }
        let version = u32_at(8);
        if version != VERSION {
            return Err(FormatError::Version(version));
        }
        let header = StepHeader {
            columns: u32_at(12),
            rows: u64_at(16),
            index: u64_at(24),
            time: f64::from_bits(u64_at(32)),
            checksum: u128::from_le_bytes(file[40..56].try_into().expect("16 bytes")),
        };
        if !(1..=MAX_COLUMNS).contains(&header.columns) {
            return Err(FormatError::Columns(header.columns));
        }
        let actual = (file.len() - HEADER_LEN) as u64;
        if actual != header.payload_bytes() {
            return Err(FormatError::Length {
                actual,
                expected: header.payload_bytes(),
            });
        }
        Ok(header)
    }
}

/// Checks the payload against the header's checksum.
pub fn verify_payload(header: &StepHeader, payload: &[u8]) -> Result<(), FormatError> {
    if xxhash_rust::xxh3::xxh3_128(payload) == header.checksum {
        Ok(())
    } else {
        Err(FormatError::PayloadChecksum)
    }
}

/// The checksum as clients see it.
pub fn checksum_hex(checksum: u128) -> String {
    format!("{checksum:032x}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_round_trips_and_detects_damage() {
        let payload: Vec<u8> = (0..24u8).collect();
        let h = StepHeader {
            columns: 3,
            rows: 2,
            index: 7,
            time: 0.5,
            checksum: xxhash_rust::xxh3::xxh3_128(&payload),
        };
        let mut file = h.encode().to_vec();
        file.extend_from_slice(&payload);
        let back = StepHeader::decode(&file).expect("valid");
        assert_eq!(back, h);
        verify_payload(&back, &file[HEADER_LEN..]).expect("checksum matches");
        file[HEADER_LEN + 3] ^= 1;
        assert_eq!(
            verify_payload(&back, &file[HEADER_LEN..]),
            Err(FormatError::PayloadChecksum)
        );
        file[20] ^= 1;
        assert_eq!(StepHeader::decode(&file), Err(FormatError::HeaderChecksum));
        assert_eq!(
            StepHeader::decode(&file[..HEADER_LEN + 4]),
            Err(FormatError::HeaderChecksum)
        );
    }
}
