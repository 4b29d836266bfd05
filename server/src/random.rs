//! Random hex strings from the OS generator: scene ids, write tokens, temporary file names.

/// `bytes` random bytes from the OS, as lowercase hex.
pub fn random_hex(bytes: usize) -> String {
    let mut buf = vec![0u8; bytes];
    // The OS generator failing means the machine cannot make secrets at all; there is no
    // safe fallback for a token.
    getrandom::fill(&mut buf).expect("the operating system's random generator works");
    buf.iter().map(|b| format!("{b:02x}")).collect()
}
