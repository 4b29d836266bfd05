//! Reading NumPy `.npy` headers: the values of the header's Python dict literal. Shared by
//! step ingest and the tet mesh upload.

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
