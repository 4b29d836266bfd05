//! The protocol's version and the identifier of a client input: what every message module
//! shares, below all of them.

/// The protocol version this crate describes. Carried in every frame header and in `info`.
pub const PROTOCOL_VERSION: u16 = 1;

/// Identifier a client attaches to each input so it can match frames to inputs. JSON numbers
/// are doubles in a browser, so the server accepts integers up to 2^53 only.
pub type InputId = u64;

/// Largest `input_id` a client may send (the largest integer a JavaScript number holds exactly).
pub const MAX_INPUT_ID: u64 = (1 << 53) - 1;
