//! The server's one HTTP error type: a status, a stable code and a message for the user.
//! Internals never reach the response body; they are logged once, here.

use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;
use isoray_protocol::ErrorMessage;

#[derive(Debug)]
pub struct AppError {
    pub status: StatusCode,
    pub code: &'static str,
    pub message: String,
}

impl AppError {
    pub fn not_found(message: impl Into<String>) -> AppError {
        AppError {
            status: StatusCode::NOT_FOUND,
            code: "not_found",
            message: message.into(),
        }
    }
}

impl IntoResponse for AppError {
    fn into_response(self) -> Response {
        if self.status.is_server_error() {
            tracing::error!(code = self.code, message = %self.message, "request failed");
        }
        let body = ErrorMessage {
            code: self.code.to_string(),
            message: self.message,
            input_id: None,
        };
        (self.status, Json(body)).into_response()
    }
}
