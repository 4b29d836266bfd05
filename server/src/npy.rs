//! Reading NumPy `.npy` headers: the values of the header's Python dict literal. Shared by
//! step ingest and the tet mesh upload. Writing a little-endian `f32` array (version 1.0):
//! the `format: "npy"` render output.

/// The text after `'key':` in a `.npy` header's Python dict literal.
pub fn dict_value<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let at = header.find(&format!("'{key}'"))?;
    let rest = &header[at + key.len() + 2..];
    Some(
        rest.trim_start()
            .strip_prefix(':')
            .unwrap_or(rest)
            .trim_start(),
    )
}

/// The dimensions of a `.npy` header's `shape` value, `(a, b, ...)`; the error says why it
/// could not be read.
pub fn shape(shape: &str) -> Result<Vec<u64>, String> {
    let inner = shape
        .strip_prefix('(')
        .and_then(|s| s.split(')').next())
        .ok_or_else(|| "unreadable shape".to_string())?;
    inner
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.trim_end_matches('L').parse::<u64>())
        .collect::<Result<Vec<_>, _>>()
        .map_err(|_| format!("unreadable shape ({inner})"))
}

/// A version 1.0 `.npy` file of little-endian `f32` values with `shape` (C order): the magic,
/// the header dict padded with spaces to a multiple of 64 bytes and ended by a newline, then
/// the values.
pub fn write_f32(shape: &[usize], values: &[f32]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape_text = if dims.len() == 1 {
        format!("({},)", dims[0])
    } else {
        format!("({})", dims.join(", "))
    };
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape_text}, }}");
    // 6 magic + 2 version + 2 length bytes, then the header, padded so the data is aligned.
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat(unpadded.next_multiple_of(64) - unpadded));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + values.len() * 4);
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn written_arrays_read_back() {
        let bytes = super::write_f32(&[2, 3, 4], &[1.5; 24]);
        assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
        let len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        assert_eq!((10 + len) % 64, 0, "data aligned");
        let header = std::str::from_utf8(&bytes[10..10 + len]).expect("ascii");
        assert!(header.ends_with('\n'));
        let shape = super::dict_value(header, "shape").expect("a shape");
        assert_eq!(super::shape(shape), Ok(vec![2, 3, 4]));
        assert_eq!(bytes.len(), 10 + len + 24 * 4);
        assert_eq!(&bytes[10 + len..10 + len + 4], &1.5f32.to_le_bytes());
    }
}
