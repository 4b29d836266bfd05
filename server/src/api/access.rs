//! Who asks and for what: the scene a path names (or why it is not here), the view, write
//! and create checks, the client's address, and what the handlers share.

use crate::api::auth::{bearer, require, token_hash, RateLimiter};
use crate::clients::{client_address, Network};
use crate::error::AppError;
use crate::scenes::entry::SceneEntry;
use crate::state::AppState;
use crate::store::StoredScene;
use axum::extract::connect_info::ConnectInfo;
use axum::extract::rejection::PathRejection;
use axum::extract::FromRequestParts;
use axum::http::request::Parts;
use axum::http::{HeaderMap, StatusCode};
use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;

/// What the API handlers share besides the app state.
pub struct ApiShared {
    pub writes: RateLimiter,
    /// `POST .../render`, per client.
    pub renders: RateLimiter,
    /// `--trusted-proxy`: peers whose `X-Forwarded-For` names the client.
    pub trusted_proxies: Vec<Network>,
    pub openapi_json: String,
    /// Scene creations in progress, counted against `--max-scenes` with the stored ones.
    pub creating: std::sync::Mutex<usize>,
}

/// A place for one more scene under `--max-scenes`, held while it is created.
pub struct SceneSlot<'a>(&'a std::sync::Mutex<usize>);

impl Drop for SceneSlot<'_> {
    fn drop(&mut self) {
        let mut n = self.0.lock().unwrap_or_else(|e| e.into_inner());
        *n = n.saturating_sub(1);
    }
}

/// Reserves a place for a new scene, or says that `--max-scenes` are stored already.
pub fn reserve_scene<'a>(app: &AppState, shared: &'a ApiShared) -> Result<SceneSlot<'a>, AppError> {
    let max = app.config().max_scenes;
    let mut creating = shared.creating.lock().unwrap_or_else(|e| e.into_inner());
    let stored = app.scenes().stored_count();
    if stored + *creating >= max {
        return Err(AppError::new(
            StatusCode::CONFLICT,
            "too_many_scenes",
            format!("this server holds {stored} scenes, its limit (--max-scenes {max}); delete one first"),
        ));
    }
    *creating += 1;
    Ok(SceneSlot(&shared.creating))
}

/// The client's address, when the server was started with connection info: the peer's, or
/// the one a trusted proxy forwarded (`crate::clients`).
pub struct ClientAddr(pub Option<IpAddr>);

impl<S: Send + Sync> FromRequestParts<S> for ClientAddr {
    type Rejection = std::convert::Infallible;

    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<ClientAddr, Self::Rejection> {
        let peer = parts
            .extensions
            .get::<ConnectInfo<SocketAddr>>()
            .map(|c| c.0.ip());
        let trusted = parts
            .extensions
            .get::<Arc<ApiShared>>()
            .map(|s| s.trusted_proxies.as_slice())
            .unwrap_or_default();
        Ok(ClientAddr(
            peer.map(|p| client_address(p, &parts.headers, trusted)),
        ))
    }
}

pub fn scene_of(app: &AppState, id: &str) -> Result<Arc<SceneEntry>, AppError> {
    app.scenes().get(id).ok_or_else(|| {
        match crate::placement::misrouted(app.config().shard.as_deref(), id) {
            Some(why) => AppError::new(StatusCode::MISDIRECTED_REQUEST, "misrouted", why),
            None => AppError::not_found(format!("no scene with id `{id}`")),
        }
        .field("id")
    })
}

pub fn stored_of(entry: &SceneEntry) -> Result<Arc<StoredScene>, AppError> {
    entry.stored_scene().cloned().ok_or_else(|| {
        AppError::new(
            StatusCode::CONFLICT,
            "built_in_scene",
            format!(
                "scene `{}` is a built-in demo; create a scene to push steps",
                entry.id()
            ),
        )
        .field("id")
    })
}

/// Viewing needs the view token (or a write/admin token) when `--view-token` is set.
pub fn check_view(
    app: &AppState,
    headers: &HeaderMap,
    entry: Option<&SceneEntry>,
) -> Result<(), AppError> {
    check_view_token(app, bearer(headers), entry)
}

/// [`check_view`] for the websocket stream, whose token may also come as `?token=...`
/// (a browser cannot set headers on a websocket).
pub fn check_stream_view(
    app: &AppState,
    headers: &HeaderMap,
    query: Option<&str>,
    entry: &SceneEntry,
) -> Result<(), AppError> {
    let from_query = query.and_then(query_token);
    check_view_token(app, bearer(headers).or(from_query.as_deref()), Some(entry))
}

/// The `token` parameter of a query string, percent-decoded as a browser's
/// `encodeURIComponent` (or `URLSearchParams`) encoded it; the first one wins.
pub fn query_token(query: &str) -> Option<String> {
    form_urlencoded::parse(query.as_bytes())
        .find(|(name, _)| name == "token")
        .map(|(_, value)| value.into_owned())
}

fn check_view_token(
    app: &AppState,
    presented: Option<&str>,
    entry: Option<&SceneEntry>,
) -> Result<(), AppError> {
    let Some(view) = &app.config().view_token else {
        return Ok(());
    };
    let mut accepted = vec![token_hash(view)];
    if let Some(admin) = &app.config().admin_token {
        accepted.push(token_hash(admin));
    }
    if let Some(scene) = entry.and_then(|e| e.stored_scene()) {
        accepted.push(scene.meta.write_token_sha256.clone());
    }
    let refs: Vec<&str> = accepted.iter().map(String::as_str).collect();
    require(presented, &refs, "viewing")
}

/// The scene a view names, after the view token: with `--view-token`, a request without a
/// token is refused (401) before the scene is looked up.
pub fn viewable_scene(
    app: &AppState,
    headers: &HeaderMap,
    id: &str,
) -> Result<Arc<SceneEntry>, AppError> {
    if app.config().view_token.is_some() && bearer(headers).is_none() {
        require(None, &[], "viewing")?;
    }
    let entry = scene_of(app, id)?;
    check_view(app, headers, Some(&entry))?;
    Ok(entry)
}

/// The stored scene a write names, authorization first: a request without a token is refused
/// (401) before anything else is looked at; then the scene (404, 421), the token (403: the
/// scene's write token or the admin token; a built-in demo, or a scene not here, has only the
/// admin token), and last whether the scene takes writes at all (409 for a built-in demo).
pub fn writable_scene(
    app: &AppState,
    headers: &HeaderMap,
    id: &str,
) -> Result<Arc<StoredScene>, AppError> {
    const WHAT: &str = "writing to this scene";
    if bearer(headers).is_none() {
        require(None, &[], WHAT)?;
    }
    let admin = app.config().admin_token.as_deref().map(token_hash);
    let admin: Vec<&str> = admin.as_deref().into_iter().collect();
    let entry = match scene_of(app, id) {
        Ok(entry) => entry,
        // Only the admin token may learn that a scene is not here (or on another shard): any
        // other token could only be some scene's write token, which this one is not (403).
        Err(e) => {
            require(bearer(headers), &admin, WHAT)?;
            return Err(e);
        }
    };
    match entry.stored_scene() {
        Some(scene) => {
            check_write(app, headers, scene)?;
            Ok(Arc::clone(scene))
        }
        None => {
            require(bearer(headers), &admin, WHAT)?;
            stored_of(&entry)
        }
    }
}

pub fn check_write(
    app: &AppState,
    headers: &HeaderMap,
    scene: &StoredScene,
) -> Result<(), AppError> {
    let admin = app.config().admin_token.as_deref().map(token_hash);
    let mut accepted = vec![scene.meta.write_token_sha256.as_str()];
    if let Some(a) = &admin {
        accepted.push(a);
    }
    require(bearer(headers), &accepted, "writing to this scene")
}

/// With `--admin-token`, only the admin may create scenes; without it anyone may (the write
/// rate limit still applies).
pub fn check_create(app: &AppState, headers: &HeaderMap) -> Result<(), AppError> {
    match app.config().admin_token.as_deref() {
        Some(admin) => require(bearer(headers), &[&token_hash(admin)], "creating scenes"),
        None => Ok(()),
    }
}

pub fn path_error(e: PathRejection) -> AppError {
    AppError::bad_request("invalid_path", e.body_text())
}

pub fn parse_index(app: &AppState, raw: &str) -> Result<u64, AppError> {
    let index: u64 = raw.parse().map_err(|_| {
        AppError::bad_request(
            "invalid_index",
            format!("step index `{raw}` is not a non-negative integer"),
        )
        .field("index")
    })?;
    let max = app.config().max_step_index;
    if index > max {
        return Err(AppError::bad_request(
            "index_out_of_range",
            format!("step index {index} is beyond the limit of {max} (--max-step-index)"),
        )
        .field("index"));
    }
    Ok(index)
}
