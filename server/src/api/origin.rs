//! Which web pages may use the server from a browser: the CORS policy (`--allowed-origins`;
//! none by default, so only the server's own pages) and the same list checked against the
//! `Origin` of a websocket upgrade, which CORS does not cover (a page may open a websocket
//! to any server; only the server can refuse it).
//!
//! JSON bodies must also say `Content-Type: application/json` (`api::request::read_json`):
//! a cross-origin page can send that only after a preflight, which this policy refuses, so
//! a stranger's page cannot create scenes or render through a visitor's browser.

use crate::error::AppError;
use axum::http::{header, HeaderMap, HeaderValue, Method, StatusCode};
use std::time::Duration;
use tower_http::cors::{AllowOrigin, CorsLayer};

/// The CORS layer: the listed origins may call the API with its methods and the headers it
/// reads; any other origin gets no CORS headers, so its pages can neither pass a preflight
/// nor read an answer.
pub fn cors_layer(allowed: &[String]) -> CorsLayer {
    let origins: Vec<HeaderValue> = allowed
        .iter()
        .filter_map(|o| HeaderValue::from_str(o).ok())
        .collect();
    CorsLayer::new()
        .allow_origin(AllowOrigin::list(origins))
        .allow_methods([Method::GET, Method::POST, Method::PUT, Method::DELETE])
        .allow_headers([header::AUTHORIZATION, header::CONTENT_TYPE])
        .max_age(Duration::from_secs(600))
}

/// A websocket upgrade's `Origin` must be the server's own (its authority is the request's
/// `Host`) or a listed one. A request without `Origin` is not from a browser page, and is
/// allowed (scripts, `isoray-bench`, other servers).
pub fn check_upgrade_origin(allowed: &[String], headers: &HeaderMap) -> Result<(), AppError> {
    let Some(origin) = headers.get(header::ORIGIN) else {
        return Ok(());
    };
    let origin = origin.to_str().unwrap_or("");
    let host = headers.get(header::HOST).and_then(|h| h.to_str().ok());
    let same = match (origin.split_once("://"), host) {
        (Some((_, authority)), Some(host)) => authority.eq_ignore_ascii_case(host),
        _ => false,
    };
    if same || allowed.iter().any(|a| a.eq_ignore_ascii_case(origin)) {
        Ok(())
    } else {
        Err(AppError::new(
            StatusCode::FORBIDDEN,
            "origin_not_allowed",
            format!(
                "a page from `{origin}` may not open viewers on this server (--allowed-origins)"
            ),
        )
        .field("Origin"))
    }
}
