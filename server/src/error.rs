//! The server's one HTTP error type, for the REST API and the stream route alike: a status, a
//! stable code, a message for people, and the field or byte offset where the request went
//! wrong. The body is `ApiErrorBody` (`{code, message, field?, offset?}`); without a field or
//! offset it is `{code, message}`, as the stream route has always answered. Server-side
//! failures are logged once, here, and their details stay out of the response.
//!
//! The domain's errors come in through `From`: a kind's spec or data check
//! ([`KindError`](crate::kinds::error::KindError)) and a push's ([`IngestError`]).

use crate::kinds::error::{KindError, KindErrorKind};
use crate::store::ingest::{IngestError, IngestErrorKind};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;
use isoray_protocol::api::ApiErrorBody;

#[derive(Debug)]
pub struct AppError {
    pub status: StatusCode,
    pub code: &'static str,
    pub message: String,
    pub field: Option<String>,
    pub offset: Option<u64>,
    /// Seconds after which a refused request may succeed: sent as `Retry-After` (429).
    pub retry_after: Option<u64>,
}

impl AppError {
    pub fn new(status: StatusCode, code: &'static str, message: impl Into<String>) -> AppError {
        AppError {
            status,
            code,
            message: message.into(),
            field: None,
            offset: None,
            retry_after: None,
        }
    }

    pub fn bad_request(code: &'static str, message: impl Into<String>) -> AppError {
        AppError::new(StatusCode::BAD_REQUEST, code, message)
    }

    /// Values that fit the OpenAPI document's schema but break a rule between them (or with
    /// the scene) that the document states in prose: 422 (see `KindErrorKind::Relational`).
    pub fn relational(code: &'static str, message: impl Into<String>) -> AppError {
        AppError::new(StatusCode::UNPROCESSABLE_ENTITY, code, message)
    }

    pub fn field(mut self, field: impl Into<String>) -> AppError {
        self.field = Some(field.into());
        self
    }

    pub fn offset(mut self, offset: u64) -> AppError {
        self.offset = Some(offset);
        self
    }

    pub fn not_found(message: impl Into<String>) -> AppError {
        AppError::new(StatusCode::NOT_FOUND, "not_found", message)
    }

    /// A failure of the server itself; `detail` is logged, not sent.
    pub fn internal(detail: impl std::fmt::Display) -> AppError {
        AppError::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "internal",
            format!("internal error: {detail}"),
        )
    }

    /// A store write that failed: 507 when the disk or quota is full (nothing was stored,
    /// what is stored is unchanged), else 500.
    pub fn store_write(e: std::io::Error) -> AppError {
        if crate::store::ingest::storage_full(&e) {
            AppError::new(
                StatusCode::INSUFFICIENT_STORAGE,
                "storage_full",
                crate::store::ingest::STORAGE_FULL,
            )
        } else {
            AppError::internal(e)
        }
    }

    /// The same error with another message.
    pub fn with_message(mut self, message: String) -> AppError {
        self.message = message;
        self
    }
}

impl From<IngestError> for AppError {
    fn from(e: IngestError) -> AppError {
        let status = match e.kind {
            IngestErrorKind::Invalid => StatusCode::BAD_REQUEST,
            IngestErrorKind::TooLarge => StatusCode::PAYLOAD_TOO_LARGE,
            IngestErrorKind::Timeout => StatusCode::REQUEST_TIMEOUT,
            IngestErrorKind::Io => StatusCode::INTERNAL_SERVER_ERROR,
            IngestErrorKind::StorageFull => StatusCode::INSUFFICIENT_STORAGE,
            IngestErrorKind::Relational => StatusCode::UNPROCESSABLE_ENTITY,
        };
        AppError {
            status,
            code: e.code,
            message: e.message,
            field: e.field,
            offset: e.offset,
            retry_after: None,
        }
    }
}

impl From<KindError> for AppError {
    fn from(e: KindError) -> AppError {
        let status = match e.kind {
            KindErrorKind::Invalid => StatusCode::BAD_REQUEST,
            KindErrorKind::Unsupported => StatusCode::UNPROCESSABLE_ENTITY,
            KindErrorKind::NotReady => StatusCode::CONFLICT,
            KindErrorKind::Relational => StatusCode::UNPROCESSABLE_ENTITY,
        };
        AppError {
            status,
            code: e.code,
            message: e.message,
            field: e.field,
            offset: e.offset,
            retry_after: None,
        }
    }
}

impl IntoResponse for AppError {
    fn into_response(self) -> Response {
        let message = if self.status.is_server_error() {
            tracing::error!(code = self.code, message = %self.message, "API request failed");
            "the server failed to handle this request; see its log".to_string()
        } else {
            self.message
        };
        let body = ApiErrorBody {
            code: self.code.to_string(),
            message,
            field: self.field,
            offset: self.offset,
        };
        let mut response = (self.status, Json(body)).into_response();
        if let Some(secs) = self.retry_after {
            response
                .headers_mut()
                .insert(axum::http::header::RETRY_AFTER, secs.into());
        }
        response
    }
}

/// serde's error text without the server's type names, for the REST API's JSON bodies and the
/// stream's messages alike: "expected struct CreateScene" means a JSON object to a client.
pub fn plain_words(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = rest.find("expected struct ") {
        out.push_str(&rest[..at]);
        out.push_str("expected a JSON object");
        rest = &rest[at + "expected struct ".len()..];
        rest = rest.trim_start_matches(|c: char| c.is_alphanumeric() || c == '_');
    }
    out.push_str(rest);
    out
}

#[cfg(test)]
mod tests {
    use super::plain_words;

    #[test]
    fn plain_words_drops_every_struct_name() {
        assert_eq!(
            plain_words("expected struct CreateScene, or expected struct Step_2 at line 1"),
            "expected a JSON object, or expected a JSON object at line 1"
        );
        assert_eq!(plain_words("expected a string"), "expected a string");
    }
}
