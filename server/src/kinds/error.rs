//! What a kind's checks report: the first problem with a scene description, a mesh or a step,
//! with what the HTTP layer needs to answer it (a stable code, a message for people, the
//! field and the byte offset where the input went wrong) and what sort of failure it is. The
//! kinds know nothing of HTTP: `crate::error` maps [`KindErrorKind`] to a status.

/// What sort of failure a [`KindError`] is; the HTTP layer picks the status from it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KindErrorKind {
    /// The input is wrong (400).
    Invalid,
    /// The kind is known but the engine cannot trace it yet (422).
    Unsupported,
    /// The scene is not ready for this (a tet step before the mesh: 409).
    NotReady,
    /// Every value fits the OpenAPI document's schema, but together (or with the scene) they
    /// break a rule a JSON Schema cannot state, which the document names in prose: eye and
    /// target differ, low below high, indices within the mesh, an isovalue inside the scene's
    /// range (422). A 400 means the request breaks the schema itself.
    Relational,
}

/// A kind's check failed.
#[derive(Debug, thiserror::Error)]
#[error("{message}")]
pub struct KindError {
    pub kind: KindErrorKind,
    pub code: &'static str,
    pub message: String,
    pub field: Option<String>,
    pub offset: Option<u64>,
}

impl KindError {
    pub fn new(kind: KindErrorKind, code: &'static str, message: impl Into<String>) -> KindError {
        KindError {
            kind,
            code,
            message: message.into(),
            field: None,
            offset: None,
        }
    }

    /// Wrong input (400).
    pub fn invalid(code: &'static str, message: impl Into<String>) -> KindError {
        KindError::new(KindErrorKind::Invalid, code, message)
    }

    /// Values that break a rule between them (422), see [`KindErrorKind::Relational`].
    pub fn relational(code: &'static str, message: impl Into<String>) -> KindError {
        KindError::new(KindErrorKind::Relational, code, message)
    }

    pub fn field(mut self, field: impl Into<String>) -> KindError {
        self.field = Some(field.into());
        self
    }

    pub fn offset(mut self, offset: u64) -> KindError {
        self.offset = Some(offset);
        self
    }

    pub fn with_message(mut self, message: String) -> KindError {
        self.message = message;
        self
    }
}
