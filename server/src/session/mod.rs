//! One viewer's websocket session: read inputs, render when something changed, send frames.
//!
//! Three loops run together in the session's task and end together:
//! - the reader applies inputs to the session's [`Settings`], records acknowledgements (and
//!   from them the bandwidth the client receives) and wakes the renderer;
//! - the renderer waits until the view or the scene time changed *and* the frame slot is
//!   empty, plans the frame (size, codec, JPEG quality, depth channel) with the adaptive
//!   [`Controller`], hands it to the fair [`RenderScheduler`](crate::schedule) (never rendering
//!   on the async runtime), and puts the encoded result in the slot;
//! - the writer takes frames from the slot and error messages from a small queue and sends
//!   them, with a ping every `--ping-interval-secs`.
//!
//! Interactive and still frames: while inputs arrive or the scene animates, frames are
//! *interactive*: JPEG (or, once motion is sustained and the client decodes it, H.264) at a
//! resolution and quality the controller picks to hold the session's frame rate within its
//! share of the pool and its measured bandwidth. When input stops on a still scene, one
//! full-size lossless PNG *still* frame follows, then nothing until something changes. A
//! hidden client (`stream` message with `visible: false`) gets nothing and costs nothing.
//!
//! Flow control: the slot holds at most one frame, and the renderer starts a frame only while
//! fewer than [`FRAME_WINDOW`] sent frames await the client's `ack`. A client that stops
//! reading stops acknowledging, so the renderer stops: it costs one frame of memory and no
//! CPU, and no backlog builds up in socket buffers. When it reads and acknowledges again, the
//! next frame rendered shows the newest state.
//!
//! The files: `socket` runs the three loops; `flow` holds what they share (the frame slot,
//! the settings, the bandwidth estimate); `render` is the renderer's loop, which makes each
//! frame with the one frame function (`crate::frame`); `controller` plans size, codec and
//! quality; `bandwidth` estimates what the client receives; `stats` the counters `/metrics`
//! and the tests read.

pub mod bandwidth;
pub mod controller;
pub mod flow;
pub mod render;
pub mod socket;
pub mod stats;

pub use flow::FRAME_WINDOW;
