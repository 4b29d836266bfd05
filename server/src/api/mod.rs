//! REST API v1 for simulation codes, scripts and notebooks: create scenes, push time steps
//! (JSON, `.npy` or raw), list and fetch them, delete, and render one image.
//!
//! Every route is declared with `#[utoipa::path]` and registered through utoipa-axum's
//! `routes!`, so the OpenAPI document at `/api/v1/openapi.json` is generated from the same
//! handlers the router serves and cannot miss one. The websocket stream route lives in
//! `lib.rs` and is described here by a documentation-only path.
//!
//! Architecture invariant: handlers do I/O only. Parsing and writing steps run on blocking
//! threads (`spawn_blocking`), rendering and encoding on the render pool; both report back
//! through channels.

pub mod auth;
pub mod client;
pub mod convert;
pub mod error;
mod histogram;
pub mod tets;

use crate::kind::{SceneSetup, StepLayout};
use crate::scenes::SceneEntry;
use crate::store::ingest::{
    ingest_json, ingest_npy, ingest_raw, BodyAbort, BodyReader, IngestLimits, Target,
};
use crate::store::{CommitError, CommitOutcome, SceneMeta, StoredScene, StoredStep};
use crate::AppState;
use auth::{bearer, require, token_hash, RateLimiter};
use axum::body::{Body, Bytes};
use axum::extract::connect_info::ConnectInfo;
use axum::extract::rejection::PathRejection;
use axum::extract::{FromRequestParts, Path, RawQuery, State};
use axum::http::request::Parts;
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::{Extension, Json, Router};
use error::ApiError;
use futures_util::StreamExt;
use isoray_protocol::api::{
    ApiCamera, ApiErrorBody, CreateScene, CreatedScene, ImageFormat, JsonStep, JsonTetStep,
    LightSpec, LightingSpec, MeshInfo, MetaballDefaults, PushResult, RenderRequest, SceneInfo,
    SceneInfoList, SceneKind, StepInfo, StepList, TetMeshData, TetSpec, NPY_MEDIA_TYPE,
    RAW_MEDIA_TYPE,
};
use isoray_render::View;
use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;
use std::time::Duration;
use utoipa::OpenApi;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

/// Body chunks queued between the socket and the step writer.
const BODY_QUEUE: usize = 16;

/// Default image size of a one-shot render.
const DEFAULT_RENDER_SIZE: (u32, u32) = (640, 480);

#[derive(OpenApi)]
#[openapi(
    info(
        title = "isoray REST API",
        version = "1",
        description = "Push time steps of implicit-surface scenes, fetch them, and render \
            images. Binary steps are NumPy .npy arrays or raw little-endian arrays with a \
            16-byte header (magic `ISRA`, version 1, dtype 1=f32/2=f64, u16 columns, u64 rows); \
            rows are `x y z [radius [strength [r g b]]]` for metaballs, one scalar per mesh \
            vertex for tets (whose mesh is sent once, inline or with PUT .../mesh). Errors are \
            JSON `{code, message, field?, offset?}`."
    ),
    paths(stream_doc, index_doc, asset_doc, healthz_doc, metrics_doc),
    components(schemas(
        ApiErrorBody, CreateScene, CreatedScene, SceneInfo, SceneInfoList, StepInfo, StepList,
        PushResult, JsonStep, RenderRequest, ApiCamera, LightingSpec, LightSpec,
        MetaballDefaults, SceneKind, ImageFormat, TetSpec, TetMeshData, JsonTetStep, MeshInfo
    )),
    modifiers(&BearerSecurity),
    tags(
        (name = "scenes", description = "Scenes, their steps, and images of them"),
        (name = "server", description = "The browser viewer, health and metrics")
    )
)]
struct ApiDoc;

struct BearerSecurity;

impl utoipa::Modify for BearerSecurity {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
        let components = openapi.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()),
        );
    }
}

/// What the API handlers share besides the app state.
struct ApiShared {
    writes: RateLimiter,
    openapi_json: String,
}

/// The API's routes and its OpenAPI document.
fn openapi_router() -> OpenApiRouter<AppState> {
    OpenApiRouter::with_openapi(ApiDoc::openapi())
        .routes(routes!(list_scenes, create_scene))
        .routes(routes!(get_scene, delete_scene))
        .routes(routes!(list_steps))
        .routes(routes!(get_step, push_step, delete_step))
        .routes(routes!(get_step_data))
        .routes(routes!(render))
        .routes(routes!(histogram::histogram))
        .routes(routes!(tets::put_mesh))
        .routes(routes!(openapi_json))
}

/// The generated OpenAPI document.
pub fn openapi() -> utoipa::openapi::OpenApi {
    openapi_router().split_for_parts().1
}

/// The API router, to merge into the app's.
pub fn router(config: &crate::Config) -> Router<AppState> {
    let (router, doc) = openapi_router().split_for_parts();
    let shared = Arc::new(ApiShared {
        writes: RateLimiter::new(config.write_rate, config.write_burst),
        openapi_json: doc
            .to_pretty_json()
            .expect("the generated OpenAPI document serializes"),
    });
    router.layer(Extension(shared))
}

/// The client's address, when the server was started with connection info.
struct ClientAddr(Option<IpAddr>);

impl<S: Send + Sync> FromRequestParts<S> for ClientAddr {
    type Rejection = std::convert::Infallible;

    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<ClientAddr, Self::Rejection> {
        Ok(ClientAddr(
            parts
                .extensions
                .get::<ConnectInfo<SocketAddr>>()
                .map(|c| c.0.ip()),
        ))
    }
}

/// The websocket that streams frames of a scene (protocol v1, see PROTOCOL.md). Served by
/// the app router; described here, like the other routes of `lib.rs`, so the document lists
/// every route (a test checks each `.route(...)` in the source against it).
#[utoipa::path(
    get,
    path = "/api/v1/scenes/{id}/stream",
    tag = "scenes",
    params(
        ("id" = String, Path, description = "Scene id"),
        ("token" = Option<String>, Query, description = "View token, when the server needs one")
    ),
    responses(
        (status = 101, description = "Switching to the websocket protocol"),
        (status = 400, description = "Not a websocket request", body = ApiErrorBody),
        (status = 401, description = "View token missing (header or `?token=`)", body = ApiErrorBody),
        (status = 403, description = "View token wrong", body = ApiErrorBody),
        (status = 404, description = "No such scene", body = ApiErrorBody),
        (status = 421, description = "The id names another shard: the load balancer misrouted the request", body = ApiErrorBody)
    )
)]
#[allow(dead_code)] // documentation only: `lib.rs` routes this path to `stream`
async fn stream_doc() {}

/// The browser viewer.
#[utoipa::path(
    get,
    path = "/",
    tag = "server",
    responses((status = 200, description = "The viewer's page", content_type = "text/html"))
)]
#[allow(dead_code)] // documentation only: `lib.rs` routes this path
async fn index_doc() {}

/// A file of the browser viewer (`app.js`, `protocol.js`, `style.css`, ...).
#[utoipa::path(
    get,
    path = "/{file}",
    tag = "server",
    params(("file" = String, Path, description = "File name")),
    responses(
        (status = 200, description = "The file"),
        (status = 404, description = "No such file", content_type = "text/plain")
    )
)]
#[allow(dead_code)] // documentation only: `lib.rs` routes this path
async fn asset_doc() {}

/// Liveness: answers `ok` while the server runs.
#[utoipa::path(
    get,
    path = "/healthz",
    tag = "server",
    responses((status = 200, description = "`ok`", content_type = "text/plain"))
)]
#[allow(dead_code)] // documentation only: `lib.rs` routes this path
async fn healthz_doc() {}

/// Prometheus metrics in the text exposition format.
#[utoipa::path(
    get,
    path = "/metrics",
    tag = "server",
    responses((status = 200, description = "Metrics", content_type = "text/plain"))
)]
#[allow(dead_code)] // documentation only: `lib.rs` routes this path
async fn metrics_doc() {}

/// This document.
#[utoipa::path(
    get,
    path = "/api/v1/openapi.json",
    tag = "scenes",
    responses((status = 200, description = "The OpenAPI document", content_type = "application/json"))
)]
async fn openapi_json(Extension(shared): Extension<Arc<ApiShared>>) -> Response {
    (
        [(header::CONTENT_TYPE, "application/json")],
        shared.openapi_json.clone(),
    )
        .into_response()
}

fn scene_of(app: &AppState, id: &str) -> Result<Arc<SceneEntry>, ApiError> {
    app.scenes().get(id).ok_or_else(|| {
        match crate::placement::misrouted(app.config().shard.as_deref(), id) {
            Some(why) => ApiError::new(StatusCode::MISDIRECTED_REQUEST, "misrouted", why),
            None => ApiError::not_found(format!("no scene with id `{id}`")),
        }
        .field("id")
    })
}

fn stored_of(entry: &SceneEntry) -> Result<Arc<StoredScene>, ApiError> {
    entry.stored_scene().cloned().ok_or_else(|| {
        ApiError::new(
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
fn check_view(
    app: &AppState,
    headers: &HeaderMap,
    entry: Option<&SceneEntry>,
) -> Result<(), ApiError> {
    check_view_token(app, bearer(headers), entry)
}

/// [`check_view`] for the websocket stream, whose token may also come as `?token=...`
/// (a browser cannot set headers on a websocket).
pub fn check_stream_view(
    app: &AppState,
    headers: &HeaderMap,
    query: Option<&str>,
    entry: &SceneEntry,
) -> Result<(), ApiError> {
    let from_query = query.and_then(|q| q.split('&').find_map(|p| p.strip_prefix("token=")));
    check_view_token(app, bearer(headers).or(from_query), Some(entry))
}

fn check_view_token(
    app: &AppState,
    presented: Option<&str>,
    entry: Option<&SceneEntry>,
) -> Result<(), ApiError> {
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

fn check_write(app: &AppState, headers: &HeaderMap, scene: &StoredScene) -> Result<(), ApiError> {
    let admin = app.config().admin_token.as_deref().map(token_hash);
    let mut accepted = vec![scene.meta.write_token_sha256.as_str()];
    if let Some(a) = &admin {
        accepted.push(a);
    }
    require(bearer(headers), &accepted, "writing to this scene")
}

/// With `--admin-token`, only the admin may create scenes; without it anyone may (the write
/// rate limit still applies).
fn check_create(app: &AppState, headers: &HeaderMap) -> Result<(), ApiError> {
    match app.config().admin_token.as_deref() {
        Some(admin) => require(bearer(headers), &[&token_hash(admin)], "creating scenes"),
        None => Ok(()),
    }
}

fn path_error(e: PathRejection) -> ApiError {
    ApiError::bad_request("invalid_path", e.body_text())
}

fn parse_index(app: &AppState, raw: &str) -> Result<u64, ApiError> {
    let index: u64 = raw.parse().map_err(|_| {
        ApiError::bad_request(
            "invalid_index",
            format!("step index `{raw}` is not a non-negative integer"),
        )
        .field("index")
    })?;
    let max = app.config().max_step_index;
    if index > max {
        return Err(ApiError::bad_request(
            "index_out_of_range",
            format!("step index {index} is beyond the limit of {max} (--max-step-index)"),
        )
        .field("index"));
    }
    Ok(index)
}

fn parse_json<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> Result<T, ApiError> {
    let de = &mut serde_json::Deserializer::from_slice(bytes);
    serde_path_to_error::deserialize(de).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        // serde_json reports line and column; for a one-line body the column is the offset.
        let offset = (inner.line() == 1).then(|| inner.column().saturating_sub(1) as u64);
        let mut err = ApiError::bad_request("invalid_json", format!("{path}: {inner}"));
        if path != "." {
            err = err.field(path);
        }
        match offset {
            Some(o) if inner.column() > 0 => err.offset(o),
            _ => err,
        }
    })
}

async fn read_json<T: serde::de::DeserializeOwned>(
    app: &AppState,
    body: Body,
) -> Result<T, ApiError> {
    let limit = app.config().max_json_bytes;
    let timeout = Duration::from_secs(app.config().push_timeout_secs);
    let read = axum::body::to_bytes(body, usize::try_from(limit).unwrap_or(usize::MAX));
    let bytes = tokio::time::timeout(timeout, read)
        .await
        .map_err(|_| {
            ApiError::new(
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

fn too_large(limit: u64) -> ApiError {
    ApiError::new(
        StatusCode::PAYLOAD_TOO_LARGE,
        "body_too_large",
        format!("the body exceeds the limit of {limit} bytes"),
    )
    .offset(limit)
}

impl ApiError {
    fn with_message(mut self, message: String) -> ApiError {
        self.message = message;
        self
    }
}

async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> T + Send + 'static,
) -> Result<T, ApiError> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| ApiError::internal(format!("blocking task failed: {e}")))
}

/// Every scene: the built-in demos and the pushed ones.
#[utoipa::path(
    get,
    path = "/api/v1/scenes",
    tag = "scenes",
    responses(
        (status = 200, description = "OK", body = SceneInfoList),
        (status = 401, description = "Token missing", body = ApiErrorBody), (status = 403, description = "Token wrong", body = ApiErrorBody)
    )
)]
async fn list_scenes(
    State(app): State<AppState>,
    headers: HeaderMap,
) -> Result<Json<SceneInfoList>, ApiError> {
    check_view(&app, &headers, None)?;
    Ok(Json(SceneInfoList {
        scenes: app.scenes().entries().iter().map(|e| e.info()).collect(),
    }))
}

/// Creates a scene. The answer carries its write token, shown only this once. With
/// `--admin-token`, creating needs it; with `--shard`, the id starts with the shard's name.
#[utoipa::path(
    post,
    path = "/api/v1/scenes",
    tag = "scenes",
    request_body = CreateScene,
    security((), ("bearer" = [])),
    responses(
        (status = 201, description = "Created", body = CreatedScene),
        (status = 400, description = "Invalid field", body = ApiErrorBody),
        (status = 401, description = "Admin token missing (server started with --admin-token)", body = ApiErrorBody),
        (status = 403, description = "Not the admin token", body = ApiErrorBody),
        (status = 413, description = "Body too large", body = ApiErrorBody),
        (status = 422, description = "Kind not supported yet", body = ApiErrorBody),
        (status = 429, description = "Too many writes", body = ApiErrorBody),
        (status = 503, description = "No scene store", body = ApiErrorBody)
    )
)]
async fn create_scene(
    State(app): State<AppState>,
    Extension(shared): Extension<Arc<ApiShared>>,
    ClientAddr(client): ClientAddr,
    headers: HeaderMap,
    body: Body,
) -> Result<(StatusCode, Json<CreatedScene>), ApiError> {
    shared.writes.check(client)?;
    check_create(&app, &headers)?;
    let spec: CreateScene = read_json(&app, body).await?;
    for (field, text, max) in [
        ("name", &spec.name, 200),
        ("description", &spec.description, 4000),
    ] {
        if text.as_ref().is_some_and(|t| t.chars().count() > max) {
            return Err(ApiError::bad_request(
                "invalid_value",
                format!("{field} is longer than {max} characters"),
            )
            .field(field));
        }
    }
    let setup = SceneSetup::from_spec(
        &spec,
        &crate::effects::EffectLimits::from_config(app.config()),
    )?;
    let store = app.scenes().store().cloned().ok_or_else(|| {
        ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "no_store",
            "this server has no scene store (--demos-only, or its data directory is unusable)",
        )
    })?;
    let token = auth::random_hex(32);
    let meta = SceneMeta {
        id: crate::placement::new_scene_id(app.config().shard.as_deref()),
        kind: spec.kind,
        spec,
        write_token_sha256: token_hash(&token),
        created_unix_secs: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs()),
    };
    let scene = blocking(move || store.create_scene(meta, setup))
        .await?
        .map_err(ApiError::internal)?;
    let entry = app.scenes().add_stored(scene);
    tracing::info!(scene = entry.id(), "scene created");
    Ok((
        StatusCode::CREATED,
        Json(CreatedScene {
            scene: entry.info(),
            write_token: token,
        }),
    ))
}

/// One scene.
#[utoipa::path(
    get,
    path = "/api/v1/scenes/{id}",
    tag = "scenes",
    params(("id" = String, Path, description = "Scene id")),
    responses(
        (status = 200, description = "OK", body = SceneInfo),
        (status = 404, description = "Not found", body = ApiErrorBody),
        (status = 421, description = "The id names another shard (every scene route may answer this)", body = ApiErrorBody)
    )
)]
async fn get_scene(
    State(app): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> Result<Json<SceneInfo>, ApiError> {
    let entry = scene_of(&app, &id)?;
    check_view(&app, &headers, Some(&entry))?;
    Ok(Json(entry.info()))
}

/// Deletes a pushed scene and all its steps.
#[utoipa::path(
    delete,
    path = "/api/v1/scenes/{id}",
    tag = "scenes",
    params(("id" = String, Path, description = "Scene id")),
    security(("bearer" = [])),
    responses(
        (status = 204, description = "Deleted"),
        (status = 401, description = "Token missing", body = ApiErrorBody), (status = 403, description = "Token wrong", body = ApiErrorBody),
        (status = 404, description = "Not found", body = ApiErrorBody), (status = 409, description = "Conflict", body = ApiErrorBody),
        (status = 429, description = "Too many writes", body = ApiErrorBody)
    )
)]
async fn delete_scene(
    State(app): State<AppState>,
    Extension(shared): Extension<Arc<ApiShared>>,
    ClientAddr(client): ClientAddr,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    shared.writes.check(client)?;
    let entry = scene_of(&app, &id)?;
    let scene = stored_of(&entry)?;
    check_write(&app, &headers, &scene)?;
    let store = app
        .scenes()
        .store()
        .cloned()
        .ok_or_else(|| ApiError::internal("stored scene without a store"))?;
    let scene_id = id.clone();
    blocking(move || store.delete_scene(&scene_id))
        .await?
        .map_err(ApiError::internal)?;
    app.scenes().remove_stored(&id);
    tracing::info!(scene = %id, "scene deleted");
    Ok(StatusCode::NO_CONTENT)
}

/// The stored steps of a scene, by index.
#[utoipa::path(
    get,
    path = "/api/v1/scenes/{id}/steps",
    tag = "scenes",
    params(("id" = String, Path, description = "Scene id")),
    responses((status = 200, description = "OK", body = StepList), (status = 404, description = "Not found", body = ApiErrorBody))
)]
async fn list_steps(
    State(app): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> Result<Json<StepList>, ApiError> {
    let entry = scene_of(&app, &id)?;
    check_view(&app, &headers, Some(&entry))?;
    let steps = entry
        .stored_scene()
        .map(|s| s.steps().iter().map(|st| st.info()).collect())
        .unwrap_or_default();
    Ok(Json(StepList { steps }))
}

fn step_of(
    app: &AppState,
    headers: &HeaderMap,
    id: &str,
    index: &str,
) -> Result<Arc<StoredStep>, ApiError> {
    let entry = scene_of(app, id)?;
    check_view(app, headers, Some(&entry))?;
    let scene = stored_of(&entry)?;
    let index = parse_index(app, index)?;
    scene.step(index).ok_or_else(|| {
        ApiError::not_found(format!("scene `{id}` has no step {index}")).field("index")
    })
}

/// One step's description and checksum.
#[utoipa::path(
    get,
    path = "/api/v1/scenes/{id}/steps/{index}",
    tag = "scenes",
    params(("id" = String, Path, description = "Scene id"), ("index" = u64, Path, description = "Step index")),
    responses((status = 200, description = "OK", body = StepInfo), (status = 404, description = "Not found", body = ApiErrorBody))
)]
async fn get_step(
    State(app): State<AppState>,
    headers: HeaderMap,
    path: Result<Path<(String, String)>, PathRejection>,
) -> Result<Json<StepInfo>, ApiError> {
    let Path((id, index)) = path.map_err(path_error)?;
    Ok(Json(step_of(&app, &headers, &id, &index)?.info()))
}

/// Owns a mapped step so its payload can be sent without a copy.
struct StepPayload(Arc<StoredStep>);

impl AsRef<[u8]> for StepPayload {
    fn as_ref(&self) -> &[u8] {
        self.0.payload()
    }
}

/// One step's values as a `.npy` array of little-endian f32, `(rows, columns)`.
#[utoipa::path(
    get,
    path = "/api/v1/scenes/{id}/steps/{index}/data",
    tag = "scenes",
    params(("id" = String, Path, description = "Scene id"), ("index" = u64, Path, description = "Step index")),
    responses(
        (status = 200, description = "The step as .npy", content_type = "application/x-npy"),
        (status = 404, description = "Not found", body = ApiErrorBody)
    )
)]
async fn get_step_data(
    State(app): State<AppState>,
    headers: HeaderMap,
    path: Result<Path<(String, String)>, PathRejection>,
) -> Result<Response, ApiError> {
    let Path((id, index)) = path.map_err(path_error)?;
    let step = step_of(&app, &headers, &id, &index)?;
    let head = client::npy_header_f32(step.header.rows, step.header.columns);
    let len = head.len() + step.payload().len();
    let chunks = [
        Ok::<_, std::convert::Infallible>(Bytes::from(head)),
        Ok(Bytes::from_owner(StepPayload(step))),
    ];
    Ok((
        [
            (header::CONTENT_TYPE, NPY_MEDIA_TYPE.to_string()),
            (header::CONTENT_LENGTH, len.to_string()),
        ],
        Body::from_stream(futures_util::stream::iter(chunks)),
    )
        .into_response())
}

/// Deletes one step.
#[utoipa::path(
    delete,
    path = "/api/v1/scenes/{id}/steps/{index}",
    tag = "scenes",
    params(("id" = String, Path, description = "Scene id"), ("index" = u64, Path, description = "Step index")),
    security(("bearer" = [])),
    responses(
        (status = 204, description = "Deleted"),
        (status = 401, description = "Token missing", body = ApiErrorBody), (status = 403, description = "Token wrong", body = ApiErrorBody),
        (status = 404, description = "Not found", body = ApiErrorBody), (status = 429, description = "Too many writes", body = ApiErrorBody)
    )
)]
async fn delete_step(
    State(app): State<AppState>,
    Extension(shared): Extension<Arc<ApiShared>>,
    ClientAddr(client): ClientAddr,
    headers: HeaderMap,
    path: Result<Path<(String, String)>, PathRejection>,
) -> Result<StatusCode, ApiError> {
    shared.writes.check(client)?;
    let Path((id, index)) = path.map_err(path_error)?;
    let entry = scene_of(&app, &id)?;
    let scene = stored_of(&entry)?;
    check_write(&app, &headers, &scene)?;
    let index = parse_index(&app, &index)?;
    let store = app
        .scenes()
        .store()
        .cloned()
        .ok_or_else(|| ApiError::internal("stored scene without a store"))?;
    let found = blocking(move || store.delete_step(&scene, index))
        .await?
        .map_err(ApiError::internal)?;
    if found {
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(ApiError::not_found(format!("scene `{id}` has no step {index}")).field("index"))
    }
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct PushQuery {
    #[serde(default)]
    replace: Option<bool>,
    #[serde(default)]
    time: Option<f64>,
}

/// The body formats a push accepts.
#[derive(Clone, Copy, Debug, PartialEq)]
enum PushFormat {
    Json,
    Npy,
    Raw,
}

/// Pushes one time step. Same index and same content: a no-op (200, `unchanged`); same index
/// and different content: 409 unless `?replace=true`. The body is read as a stream, checked
/// value by value, and written crash-safely; a rejected push changes nothing stored.
#[utoipa::path(
    put,
    path = "/api/v1/scenes/{id}/steps/{index}",
    tag = "scenes",
    params(
        ("id" = String, Path, description = "Scene id"),
        ("index" = u64, Path, description = "Step index, at most --max-step-index"),
        ("replace" = Option<bool>, Query, description = "Overwrite a step with different content"),
        ("time" = Option<f64>, Query, description = "Simulation time of the step (default: its index)")
    ),
    request_body(
        description = "The step: JSON for small data; .npy or raw (16-byte ISRA header) for large",
        content(
            (JsonStep = "application/json"),
            ("application/x-npy"),
            ("application/octet-stream")
        )
    ),
    security(("bearer" = [])),
    responses(
        (status = 200, description = "Unchanged or replaced", body = PushResult),
        (status = 201, description = "Created", body = PushResult),
        (status = 400, description = "Invalid body; names the field or byte offset", body = ApiErrorBody),
        (status = 401, description = "Token missing", body = ApiErrorBody), (status = 403, description = "Token wrong", body = ApiErrorBody),
        (status = 404, description = "Not found", body = ApiErrorBody),
        (status = 408, description = "Body too slow", body = ApiErrorBody),
        (status = 409, description = "Different content at this index", body = ApiErrorBody),
        (status = 413, description = "Body too large", body = ApiErrorBody),
        (status = 415, description = "Unsupported media type", body = ApiErrorBody),
        (status = 429, description = "Too many writes", body = ApiErrorBody)
    )
)]
async fn push_step(
    State(app): State<AppState>,
    Extension(shared): Extension<Arc<ApiShared>>,
    ClientAddr(client): ClientAddr,
    headers: HeaderMap,
    path: Result<Path<(String, String)>, PathRejection>,
    RawQuery(query): RawQuery,
    body: Body,
) -> Result<Response, ApiError> {
    shared.writes.check(client)?;
    let Path((id, index)) = path.map_err(path_error)?;
    let entry = scene_of(&app, &id)?;
    let scene = stored_of(&entry)?;
    check_write(&app, &headers, &scene)?;
    tets::check_ready(&scene.setup)?;
    let index = parse_index(&app, &index)?;
    let query: PushQuery = serde_urlencoded_lite(query.as_deref().unwrap_or(""))?;
    let time = query.time.unwrap_or(index as f64);
    if !time.is_finite() {
        return Err(
            ApiError::bad_request("invalid_value", format!("time {time} is not finite"))
                .field("time"),
        );
    }
    let format = push_format(&headers)?;
    let config = app.config();
    let store = app
        .scenes()
        .store()
        .cloned()
        .ok_or_else(|| ApiError::internal("stored scene without a store"))?;
    let retention = store.retention();
    let limits = IngestLimits {
        layout: scene.setup.layout(),
        max_rows: config.max_primitives as u64,
        max_step_bytes: retention.max_bytes_per_scene.min(retention.max_total_bytes),
    };
    let body_limit = match format {
        PushFormat::Json => config.max_json_bytes,
        PushFormat::Npy | PushFormat::Raw => config.max_push_bytes,
    };
    let declared = headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if declared.is_some_and(|n| n > body_limit) {
        return Err(too_large(body_limit).field("Content-Length"));
    }
    let target = Target {
        temp_path: store.temp_step_path(&scene),
        index,
        time,
    };
    let written = match format {
        // The JSON shape is per kind (rows of balls for metaballs).
        PushFormat::Json => match limits.layout {
            StepLayout::Metaballs => {
                let step: JsonStep = read_json(&app, body).await?;
                blocking(move || ingest_json(&step, &limits, target)).await??
            }
            StepLayout::Tets { .. } => {
                let step: JsonTetStep = read_json(&app, body).await?;
                blocking(move || tets::ingest_json_tets(&step, &limits, target)).await??
            }
        },
        PushFormat::Npy | PushFormat::Raw => {
            let (tx, rx) = tokio::sync::mpsc::channel(BODY_QUEUE);
            let worker = tokio::task::spawn_blocking(move || {
                let reader = BodyReader::new(rx);
                match format {
                    PushFormat::Npy => ingest_npy(reader, &limits, target),
                    _ => ingest_raw(reader, &limits, target),
                }
            });
            let timeout = Duration::from_secs(config.push_timeout_secs);
            let _received = forward_body(body, tx, body_limit, declared, timeout).await;
            let result = worker
                .await
                .map_err(|e| ApiError::internal(format!("step writer failed: {e}")))?;
            result?
        }
    };
    let replace = query.replace.unwrap_or(false);
    let commit_scene = Arc::clone(&scene);
    let commit_store = Arc::clone(&store);
    let (outcome, evicted) = blocking(move || commit_store.commit(&commit_scene, written, replace))
        .await?
        .map_err(|e| match e {
            CommitError::Conflict { .. } => {
                ApiError::new(StatusCode::CONFLICT, "conflict", e.to_string()).field("index")
            }
            CommitError::SceneGone => ApiError::not_found(format!("scene `{id}` was deleted")),
            CommitError::Io(e) => ApiError::internal(e),
        })?;
    let (status, outcome, step) = match outcome {
        CommitOutcome::Created(s) => (StatusCode::CREATED, "created", s),
        CommitOutcome::Unchanged(s) => (StatusCode::OK, "unchanged", s),
        CommitOutcome::Replaced(s) => (StatusCode::OK, "replaced", s),
    };
    tracing::debug!(scene = %id, index, outcome, bytes = step.file_bytes, "step pushed");
    Ok((
        status,
        Json(PushResult {
            step: step.info(),
            outcome: outcome.into(),
            evicted,
        }),
    )
        .into_response())
}

/// Forwards the body to the step writer, enforcing the size and time limits. If the writer
/// stops early (it found an error), the rest of a body whose declared length is within the
/// limit is read and dropped, so the client sees the answer rather than a reset connection.
async fn forward_body(
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

fn push_format(headers: &HeaderMap) -> Result<PushFormat, ApiError> {
    let ct = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("");
    let media = ct
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase();
    match media.as_str() {
        "application/json" => Ok(PushFormat::Json),
        m if m == NPY_MEDIA_TYPE => Ok(PushFormat::Npy),
        m if m == RAW_MEDIA_TYPE => Ok(PushFormat::Raw),
        _ => Err(ApiError::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported_media_type",
            format!(
                "Content-Type `{ct}`: a step is application/json, {NPY_MEDIA_TYPE} or {RAW_MEDIA_TYPE}"
            ),
        )
        .field("Content-Type")),
    }
}

/// Parses `replace=true&time=1.5` without another dependency: both values are plain tokens.
fn serde_urlencoded_lite(query: &str) -> Result<PushQuery, ApiError> {
    let mut q = PushQuery {
        replace: None,
        time: None,
    };
    for pair in query.split('&').filter(|p| !p.is_empty()) {
        let (k, v) = pair.split_once('=').unwrap_or((pair, ""));
        match k {
            "replace" => {
                q.replace = Some(match v {
                    "true" | "1" | "" => true,
                    "false" | "0" => false,
                    _ => {
                        return Err(ApiError::bad_request(
                            "invalid_query",
                            format!("replace=`{v}`: true or false"),
                        )
                        .field("replace"))
                    }
                })
            }
            "time" => {
                q.time = Some(v.parse().map_err(|_| {
                    ApiError::bad_request("invalid_query", format!("time=`{v}` is not a number"))
                        .field("time")
                })?)
            }
            "token" => {}
            other => {
                return Err(ApiError::bad_request(
                    "invalid_query",
                    format!("unknown query parameter `{other}` (replace, time)"),
                )
                .field(other.to_string()))
            }
        }
    }
    Ok(q)
}

/// Renders one image of a scene on the render pool: PNG (lossless) or JPEG.
#[utoipa::path(
    post,
    path = "/api/v1/scenes/{id}/render",
    tag = "scenes",
    params(("id" = String, Path, description = "Scene id")),
    request_body = RenderRequest,
    responses(
        (status = 200, description = "The image", content(("image/png"), ("image/jpeg"))),
        (status = 400, description = "Invalid request", body = ApiErrorBody),
        (status = 404, description = "Not found", body = ApiErrorBody)
    )
)]
async fn render(
    State(app): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
    body: Body,
) -> Result<Response, ApiError> {
    let entry = scene_of(&app, &id)?;
    check_view(&app, &headers, Some(&entry))?;
    let req: RenderRequest = read_json(&app, body).await?;
    let max = app.config().max_size;
    let width = req.width.unwrap_or(DEFAULT_RENDER_SIZE.0);
    let height = req.height.unwrap_or(DEFAULT_RENDER_SIZE.1);
    for (field, v) in [("width", width), ("height", height)] {
        if v == 0 || v > max {
            return Err(ApiError::bad_request(
                "invalid_value",
                format!("{field} {v} must be in 1..={max}"),
            )
            .field(field));
        }
    }
    let look = entry.demo();
    let camera = match &req.camera {
        Some(c) => convert::camera(c, "camera")?,
        None => look.default_camera(),
    };
    let isovalue = match req.isovalue {
        Some(v) => {
            let (lo, hi) = entry.isovalue_range();
            if !(v.is_finite() && v > f64::from(lo) && v < f64::from(hi)) {
                return Err(ApiError::bad_request(
                    "invalid_value",
                    format!("isovalue {v} is outside ({lo}, {hi})"),
                )
                .field("isovalue"));
            }
            v as f32
        }
        None => look.default_isovalue(),
    };
    let quality = req.quality.unwrap_or(90);
    if !(1..=100).contains(&quality) {
        return Err(
            ApiError::bad_request("invalid_value", "quality must be in 1..=100").field("quality"),
        );
    }
    let step = match (entry.stored_scene(), req.step) {
        (Some(scene), Some(i)) => Some(scene.step(i).ok_or_else(|| {
            ApiError::not_found(format!("scene `{id}` has no step {i}")).field("step")
        })?),
        (Some(scene), None) => scene.latest(),
        (None, Some(_)) => {
            return Err(ApiError::bad_request(
                "invalid_value",
                "built-in scenes have no steps; use time",
            )
            .field("step"))
        }
        (None, None) => None,
    };
    let time = req.time.unwrap_or(0.0);
    if !(time.is_finite() && (0.0..=1.0e9).contains(&time)) {
        return Err(
            ApiError::bad_request("invalid_value", "time must be in [0, 1e9]").field("time"),
        );
    }
    let limits = crate::effects::EffectLimits::from_config(app.config());
    let mut fx = crate::effects::clamp(&entry.lighting().effects, &limits);
    if let Some(changes) = &req.effects {
        fx = crate::effects::apply(&fx, changes, &limits).map_err(|e| {
            ApiError::bad_request("invalid_value", e.message).field(format!("effects.{}", e.field))
        })?;
    }
    let view = View {
        width,
        height,
        camera,
        isovalue,
    };
    let format = req.format;
    let (tx, rx) = tokio::sync::oneshot::channel();
    let job_app = app.clone();
    app.backend().spawn(move || {
        let state = match (&step, entry.stored_scene()) {
            (_, Some(_)) => entry.prepared_step(step.as_deref()),
            (_, None) => entry.prepared_at(time, false, None),
        };
        let (fb, _) = job_app
            .backend()
            .render_effects(&state.prepared, &view, &fx);
        let encoded = match format {
            ImageFormat::Png => crate::encode::png(&fb),
            ImageFormat::Jpeg => crate::encode::jpeg(&fb, quality),
        };
        let _ = tx.send(encoded);
    });
    let image = rx
        .await
        .map_err(|_| ApiError::internal("the render pool dropped the job"))?
        .map_err(ApiError::internal)?;
    let content_type = match format {
        ImageFormat::Png => "image/png",
        ImageFormat::Jpeg => "image/jpeg",
    };
    Ok(([(header::CONTENT_TYPE, content_type)], image).into_response())
}
