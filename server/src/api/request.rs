//! Reading request bodies: JSON within the size and time limits, and binary bodies forwarded
//! chunk by chunk to a blocking reader (`crate::body::BodyReader`), plus the push formats.

use crate::api::strict_json::StrictDe;
use crate::body::BodyAbort;
use crate::error::AppError;
use crate::state::AppState;
use axum::body::{Body, Bytes};
use axum::http::{header, HeaderMap, StatusCode};
use futures_util::StreamExt;
use isoray_protocol::api::{NPY_MEDIA_TYPE, RAW_MEDIA_TYPE};
use std::time::Duration;

/// Body chunks queued between the socket and the step writer.
pub const BODY_QUEUE: usize = 16;

/// The body formats a push accepts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PushFormat {
    Json,
    Npy,
    Raw,
}

/// A JSON body as the OpenAPI document describes it: objects where it says object, whole
/// numbers however written where it says integer (`api::strict_json`), nothing after the value.
pub fn parse_json<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> Result<T, AppError> {
    let mut de = serde_json::Deserializer::from_slice(bytes);
    let value: T = serde_path_to_error::deserialize(StrictDe(&mut de)).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        // serde_json reports line and column; for a one-line body the column is the offset.
        let offset = (inner.line() == 1).then(|| inner.column().saturating_sub(1) as u64);
        let what = crate::error::plain_words(&inner.to_string());
        let mut err = match known_field(&path) {
            Some(field) => {
                AppError::bad_request("invalid_json", format!("{field}: {what}")).field(field)
            }
            None if bytes.iter().all(u8::is_ascii_whitespace) => {
                AppError::bad_request("invalid_json", "the body is empty: send a JSON object")
            }
            None => AppError::bad_request("invalid_json", format!("the body: {what}")),
        };
        if let Some(o) = offset.filter(|_| inner.column() > 0) {
            err = err.offset(o);
        }
        err
    })?;
    de.end().map_err(|e| {
        AppError::bad_request("invalid_json", format!("after the JSON value: {e}"))
            .offset(e.column().saturating_sub(1) as u64)
    })?;
    Ok(value)
}

/// The field a `serde_path_to_error` path names, up to its first segment the parser could not
/// name (`?`: an error while reading a key, such as a trailing comma); `None` for the whole
/// body (`.`, or nothing known).
fn known_field(path: &str) -> Option<&str> {
    let known = match path.find('?') {
        Some(at) => path[..at].trim_end_matches('.'),
        None => path,
    };
    (!known.is_empty() && known != ".").then_some(known)
}

/// A JSON body must say so: `Content-Type: application/json` (parameters such as
/// `charset` allowed), else 415. A browser page of another origin cannot send that without
/// a CORS preflight (`api::origin`), so this keeps such pages from posting `text/plain`
/// bodies that the server would read as JSON.
pub fn require_json(headers: &HeaderMap) -> Result<(), AppError> {
    if media_type(headers) == "application/json" {
        return Ok(());
    }
    Err(AppError::new(
        StatusCode::UNSUPPORTED_MEDIA_TYPE,
        "unsupported_media_type",
        format!(
            "Content-Type `{}`: this body is JSON; send `Content-Type: application/json`",
            content_type(headers)
        ),
    )
    .field("Content-Type"))
}

fn content_type(headers: &HeaderMap) -> &str {
    headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
}

/// The media type of `Content-Type`, lower case, without parameters.
fn media_type(headers: &HeaderMap) -> String {
    content_type(headers)
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase()
}

pub async fn read_json<T: serde::de::DeserializeOwned>(
    app: &AppState,
    headers: &HeaderMap,
    body: Body,
) -> Result<T, AppError> {
    require_json(headers)?;
    let limit = app.config().max_json_bytes;
    let timeout = Duration::from_secs(app.config().push_timeout_secs);
    let read = axum::body::to_bytes(body, usize::try_from(limit).unwrap_or(usize::MAX));
    let bytes = tokio::time::timeout(timeout, read)
        .await
        .map_err(|_| {
            AppError::new(
                StatusCode::REQUEST_TIMEOUT,
                "timeout",
                format!(
                    "the body did not arrive within {} s (--push-timeout-secs)",
                    timeout.as_secs()
                ),
            )
        })?
        .map_err(|e| {
            too_large(limit).with_message(format!(
                "the body could not be read within the limit of {limit} bytes: {e}"
            ))
        })?;
    parse_json(&bytes)
}

pub fn too_large(limit: u64) -> AppError {
    AppError::new(
        StatusCode::PAYLOAD_TOO_LARGE,
        "body_too_large",
        format!("the body exceeds the limit of {limit} bytes"),
    )
    .offset(limit)
}

pub async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> T + Send + 'static,
) -> Result<T, AppError> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| AppError::internal(format!("blocking task failed: {e}")))
}

/// Forwards the body to the step writer, enforcing the size and time limits. If the writer
/// stops early (it found an error), the rest of a body whose declared length is within the
/// limit is read and dropped, so the client sees the answer rather than a reset connection.
pub async fn forward_body(
    body: Body,
    tx: tokio::sync::mpsc::Sender<Result<Bytes, BodyAbort>>,
    limit: u64,
    declared: Option<u64>,
    timeout: Duration,
) -> u64 {
    let deadline = tokio::time::Instant::now() + timeout;
    let mut stream = body.into_data_stream();
    let mut total = 0u64;
    let mut writer_open = true;
    loop {
        let next = tokio::time::timeout_at(deadline, stream.next()).await;
        let abort = match next {
            Err(_) => Some(BodyAbort::Timeout),
            Ok(None) => break,
            Ok(Some(Err(_))) => Some(BodyAbort::Broken("the client stopped sending")),
            Ok(Some(Ok(chunk))) => {
                total += chunk.len() as u64;
                if total > limit {
                    Some(BodyAbort::TooLarge(limit))
                } else {
                    if writer_open && tx.send(Ok(chunk)).await.is_err() {
                        writer_open = false;
                        if declared.is_none() {
                            break;
                        }
                    }
                    None
                }
            }
        };
        if let Some(abort) = abort {
            let _ = tx.send(Err(abort)).await;
            break;
        }
    }
    total
}

pub fn push_format(headers: &HeaderMap) -> Result<PushFormat, AppError> {
    let ct = content_type(headers);
    match media_type(headers).as_str() {
        "application/json" => Ok(PushFormat::Json),
        m if m == NPY_MEDIA_TYPE => Ok(PushFormat::Npy),
        m if m == RAW_MEDIA_TYPE => Ok(PushFormat::Raw),
        _ => Err(AppError::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported_media_type",
            format!(
                "Content-Type `{ct}`: a step is application/json, {NPY_MEDIA_TYPE} or {RAW_MEDIA_TYPE}"
            ),
        )
        .field("Content-Type")),
    }
}

/// The `Content-Length` a request declares, if any.
pub fn declared_length(headers: &HeaderMap) -> Option<u64> {
    headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok())
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::Deserialize;

    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Body {
        name: String,
        inner: Option<Inner>,
    }

    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Inner {
        size: u32,
    }

    /// (message, field, offset) of the error `parse_json::<Body>` gives for `body`.
    fn error_of(body: &str) -> (String, Option<String>, Option<u64>) {
        let err = parse_json::<Body>(body.as_bytes()).expect_err(body);
        (err.message.clone(), err.field.clone(), err.offset)
    }

    #[test]
    fn json_errors_name_the_field_or_the_body_in_plain_words() {
        let (message, field, offset) = error_of(r#"{"name": 5}"#);
        assert!(
            message.starts_with("name: invalid type: integer `5`, expected a string"),
            "{message}"
        );
        assert_eq!((field.as_deref(), offset), (Some("name"), Some(9)));

        let (message, field, _) = error_of(r#"{"name": "a", "inner": {"size": -1}}"#);
        assert!(
            message.starts_with("inner.size: invalid value"),
            "{message}"
        );
        assert_eq!(field.as_deref(), Some("inner.size"));

        // The whole body of the wrong type: no server type name, no field.
        let (message, field, offset) = error_of("5");
        assert!(
            message.starts_with("the body: invalid type: integer `5`, expected a JSON object"),
            "{message}"
        );
        assert!(!message.contains("Body"), "{message}");
        assert_eq!((field, offset), (None, Some(0)));

        // A key that cannot be read (a trailing comma, a missing one): the object it is in.
        let (message, field, offset) = error_of(r#"{"name": "a",}"#);
        assert!(message.starts_with("the body: trailing comma"), "{message}");
        assert_eq!((field, offset), (None, Some(13)));
        let (message, field, _) = error_of(r#"{"name": "a", "inner": {"size": 1,}}"#);
        assert!(message.starts_with("inner: trailing comma"), "{message}");
        assert_eq!(field.as_deref(), Some("inner"));
        let (message, _, _) = error_of(r#"{"name": "a" "inner": null}"#);
        assert!(
            message.starts_with("the body: expected `,` or `}`"),
            "{message}"
        );

        let (message, field, _) = error_of("  ");
        assert_eq!(
            (message.as_str(), field),
            ("the body is empty: send a JSON object", None)
        );
        let (message, _, _) = error_of(r#"{"name": "a""#);
        assert!(
            message.starts_with("the body: EOF while parsing an object"),
            "{message}"
        );
    }

    #[test]
    fn known_field_stops_at_the_first_unnamed_segment() {
        assert_eq!(known_field("surfels.nodes[3].?"), Some("surfels.nodes[3]"));
        assert_eq!(known_field("?"), None);
        assert_eq!(known_field("."), None);
    }
}
