//! The one reader of streamed request bodies, shared by step ingest (`store::ingest`) and the
//! tet mesh upload (`kinds::tets::mesh_body`).
//!
//! How it works: the HTTP handler forwards body chunks over a bounded channel to a blocking
//! thread, where [`BodyReader`] turns them back into a `Read` and counts the bytes it has
//! returned, so that every error can name the byte offset where the body went wrong. When
//! the async side stops early (size or time limit, broken connection) it sends a
//! [`BodyAbort`], which the next read reports. Each consumer words a [`BodyError`] as its
//! own error type.

use axum::body::Bytes;
use std::io::Read;

/// What the async side tells the reader when it stops forwarding the body early.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum BodyAbort {
    #[error("the body exceeds the limit of {0} bytes")]
    TooLarge(u64),
    #[error("the body did not arrive within the time limit")]
    Timeout,
    #[error("the connection failed while reading the body: {0}")]
    Broken(&'static str),
}

/// Why the body did not hold what the reader asked for.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum BodyError {
    /// The body ended at `offset`, `missing` bytes short of the end of `what`.
    #[error(
        "the body ends at byte offset {offset} inside {what}; {missing} more bytes were expected"
    )]
    Truncated {
        offset: u64,
        missing: usize,
        what: String,
    },
    /// Reading failed at `offset`: the async side's `abort`, if it stopped, or `error`.
    /// `at_end`: while checking that the body had ended.
    #[error("{error}")]
    Read {
        offset: u64,
        abort: Option<BodyAbort>,
        error: String,
        at_end: bool,
    },
    /// A byte at `offset` follows the end of `what`.
    #[error("the body continues past {what} at byte offset {offset}")]
    Trailing { offset: u64, what: &'static str },
}

/// A `Read` over body chunks sent from the async runtime. Counts the bytes it has returned.
pub struct BodyReader {
    rx: tokio::sync::mpsc::Receiver<Result<Bytes, BodyAbort>>,
    buf: Bytes,
    offset: u64,
    abort: Option<BodyAbort>,
}

impl BodyReader {
    pub fn new(rx: tokio::sync::mpsc::Receiver<Result<Bytes, BodyAbort>>) -> BodyReader {
        BodyReader {
            rx,
            buf: Bytes::new(),
            offset: 0,
            abort: None,
        }
    }

    /// A reader over bytes already in memory (JSON bodies, files, tests).
    pub fn from_bytes(bytes: Bytes) -> BodyReader {
        let (_tx, rx) = tokio::sync::mpsc::channel(1);
        BodyReader {
            rx,
            buf: bytes,
            offset: 0,
            abort: None,
        }
    }

    /// Bytes returned so far: the offset of the next byte in the body.
    pub fn offset(&self) -> u64 {
        self.offset
    }

    /// Reads exactly `out.len()` bytes, or reports where the body ended inside `what`.
    pub fn fill(&mut self, out: &mut [u8], what: &str) -> Result<(), BodyError> {
        let mut got = 0;
        while got < out.len() {
            let n = self
                .read(&mut out[got..])
                .map_err(|e| self.read_error(e, false))?;
            if n == 0 {
                return Err(BodyError::Truncated {
                    offset: self.offset,
                    missing: out.len() - got,
                    what: what.to_string(),
                });
            }
            got += n;
        }
        Ok(())
    }

    /// Fails if any byte follows the end of `what`.
    pub fn expect_end(&mut self, what: &'static str) -> Result<(), BodyError> {
        let mut one = [0u8; 1];
        let at = self.offset;
        match self.read(&mut one).map_err(|e| self.read_error(e, true))? {
            0 => Ok(()),
            _ => Err(BodyError::Trailing { offset: at, what }),
        }
    }

    fn read_error(&self, e: std::io::Error, at_end: bool) -> BodyError {
        BodyError::Read {
            offset: self.offset,
            abort: self.abort,
            error: e.to_string(),
            at_end,
        }
    }
}

impl Read for BodyReader {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        while self.buf.is_empty() {
            if self.abort.is_some() {
                return Err(std::io::Error::other("body aborted"));
            }
            match self.rx.blocking_recv() {
                Some(Ok(chunk)) => self.buf = chunk,
                Some(Err(abort)) => {
                    self.abort = Some(abort);
                    return Err(std::io::Error::other(abort));
                }
                None => return Ok(0),
            }
        }
        let n = out.len().min(self.buf.len());
        out[..n].copy_from_slice(&self.buf.split_to(n));
        self.offset += n as u64;
        Ok(n)
    }
}
