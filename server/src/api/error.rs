//! The REST API's error: a status, a stable code, a message for people, and the field or
//! byte offset where the request went wrong. Server-side failures are logged once, here, and
//! their details stay out of the response.

use crate::store::ingest::{IngestError, IngestErrorKind};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;
use isoray_protocol::api::ApiErrorBody;

#[derive(Debug)]
pub struct ApiError {
    pub status: StatusCode,
    pub code: &'static str,
    pub message: String,
    pub field: Option<String>,
    pub offset: Option<u64>,
}

impl ApiError {
    pub fn new(status: StatusCode, code: &'static str, message: impl Into<String>) -> ApiError {
        ApiError {
            status,
            code,
            message: message.into(),
            field: None,
            offset: None,
        }
    }

    pub fn bad_request(code: &'static str, message: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::BAD_REQUEST, code, message)
    }

    pub fn field(mut self, field: impl Into<String>) -> ApiError {
        self.field = Some(field.into());
        self
    }

    pub fn offset(mut self, offset: u64) -> ApiError {
        self.offset = Some(offset);
        self
    }

    pub fn not_found(message: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::NOT_FOUND, "not_found", message)
    }

    /// A failure of the server itself; `detail` is logged, not sent.
    pub fn internal(detail: impl std::fmt::Display) -> ApiError {
        ApiError::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "internal",
            format!("internal error: {detail}"),
        )
    }
}

impl From<IngestError> for ApiError {
    fn from(e: IngestError) -> ApiError {
        let status = match e.kind {
            IngestErrorKind::Invalid => StatusCode::BAD_REQUEST,
            IngestErrorKind::TooLarge => StatusCode::PAYLOAD_TOO_LARGE,
            IngestErrorKind::Timeout => StatusCode::REQUEST_TIMEOUT,
            IngestErrorKind::Io => StatusCode::INTERNAL_SERVER_ERROR,
        };
        ApiError {
            status,
            code: e.code,
            message: e.message,
            field: e.field,
            offset: e.offset,
        }
    }
}

impl IntoResponse for ApiError {
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
        (self.status, Json(body)).into_response()
    }
}
