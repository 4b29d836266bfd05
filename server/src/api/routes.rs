//! The API's router and its OpenAPI document.
//!
//! Every route is declared with `#[utoipa::path]` and registered through utoipa-axum's
//! `routes!`, so the OpenAPI document at `/api/v1/openapi.json` is generated from the same
//! handlers the router serves and cannot miss one. The websocket stream route and the
//! viewer's routes live in `serve.rs` and are described here by documentation-only paths.

use crate::api::access::ApiShared;
use crate::api::auth::RateLimiter;
use crate::api::contract;
use crate::api::histogram;
use crate::api::push;
use crate::api::render;
use crate::api::scenes;
use crate::api::steps;
use crate::api::tets;
use crate::config::Config;
use crate::state::AppState;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::{Extension, Router};
use isoray_protocol::api::{
    ApiCamera, ApiErrorBody, CreateScene, CreatedScene, ImageFormat, JsonStep, JsonTetStep,
    LightSpec, LightingSpec, MeshInfo, MetaballDefaults, PushResult, RenderRequest, SceneBounds,
    SceneInfo, SceneInfoList, SceneKind, StepInfo, StepList, TetMeshData, TetSpec,
};
use isoray_protocol::api_surfels::{
    JsonSurfelStep, SurfelData, SurfelMesh, SurfelPoints, SurfelSpec,
};
use isoray_protocol::effects::{ClipBoxSpec, ColorMapSpec, SurfaceStyleSpec};
use std::sync::Arc;
use utoipa::OpenApi;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

#[derive(OpenApi)]
#[openapi(
    info(
        title = "isoray REST API",
        version = "1",
        description = "Push time steps of implicit-surface scenes, fetch them, and render \
            images. Binary steps are NumPy .npy arrays or raw little-endian arrays with a \
            16-byte header (magic `ISRA`, version 1, dtype 1=f32/2=f64, u16 columns, u64 rows); \
            rows are `x y z [radius [strength [r g b]]]` for metaballs, one scalar per mesh \
            vertex for tets (whose mesh is sent once, inline or with PUT .../mesh), each \
            simulation node's position x y z for surfels (whose surfels and rest nodes come \
            inline at creation; the server embeds them and builds the sphere hierarchy once; a \
            step deformed so far that the hierarchy stops pruning falls back to a rebuild for \
            that step). Errors are JSON `{code, message, field?, offset?}`."
    ),
    paths(stream_doc, index_doc, asset_doc, healthz_doc, metrics_doc),
    components(schemas(
        ApiErrorBody, CreateScene, CreatedScene, SceneInfo, SceneInfoList, StepInfo, StepList,
        PushResult, JsonStep, RenderRequest, ApiCamera, LightingSpec, LightSpec,
        MetaballDefaults, SceneKind, ImageFormat, TetSpec, TetMeshData, JsonTetStep, MeshInfo,
        // A viewer's look (in `effects` of a render request) and a scene's bounds.
        SceneBounds, ClipBoxSpec, SurfaceStyleSpec, ColorMapSpec,
        // Surfel scenes: the object at creation, node positions per step.
        SurfelSpec, SurfelData, SurfelPoints, SurfelMesh, JsonSurfelStep
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

/// The API's routes and its OpenAPI document.
fn openapi_router() -> OpenApiRouter<AppState> {
    OpenApiRouter::with_openapi(ApiDoc::openapi())
        .routes(routes!(scenes::list_scenes, scenes::create_scene))
        .routes(routes!(scenes::get_scene, scenes::delete_scene))
        .routes(routes!(steps::list_steps))
        .routes(routes!(
            steps::get_step,
            push::push_step,
            steps::delete_step
        ))
        .routes(routes!(steps::get_step_data))
        .routes(routes!(render::render))
        .routes(routes!(histogram::histogram))
        .routes(routes!(tets::put_mesh))
        .routes(routes!(openapi_json))
}

/// The generated OpenAPI document.
pub fn openapi() -> utoipa::openapi::OpenApi {
    openapi_router().split_for_parts().1
}

/// The API router, to merge into the app's.
pub fn router(config: &Config) -> Router<AppState> {
    let (router, doc) = openapi_router().split_for_parts();
    let shared = Arc::new(ApiShared {
        writes: RateLimiter::new(config.write_rate, config.write_burst, "writes"),
        renders: RateLimiter::new(config.render_rate, config.render_burst, "renders"),
        trusted_proxies: crate::clients::trusted(&config.trusted_proxy),
        creating: std::sync::Mutex::new(0),
        openapi_json: served_document(&doc, config),
    });
    router.layer(Extension(shared))
}

/// The document as served: the generated one completed with this server's constraints
/// (`api::contract`).
fn served_document(doc: &utoipa::openapi::OpenApi, config: &Config) -> String {
    let mut value = serde_json::to_value(doc).expect("the generated OpenAPI document serializes");
    contract::apply(&mut value, config);
    serde_json::to_string_pretty(&value).expect("a JSON value serializes")
}

/// The websocket that streams frames of a scene (protocol v1, see PROTOCOL.md). Served by
/// the app router; described here, like the other routes of `serve.rs`, so the document lists
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
        (status = 403, description = "View token wrong, or a browser page whose `Origin` is neither this server's nor one of --allowed-origins", body = ApiErrorBody),
        (status = 404, description = "No such scene", body = ApiErrorBody),
        (status = 421, description = "The id names another shard: the load balancer misrouted the request", body = ApiErrorBody)
    )
)]
#[allow(dead_code)] // documentation only: `serve.rs` routes this path to `stream`
async fn stream_doc() {}

/// The browser viewer.
#[utoipa::path(
    get,
    path = "/",
    tag = "server",
    responses((status = 200, description = "The viewer's page", content_type = "text/html"))
)]
#[allow(dead_code)] // documentation only: `serve.rs` routes this path
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
#[allow(dead_code)] // documentation only: `serve.rs` routes this path
async fn asset_doc() {}

/// Liveness: answers `ok` while the server runs.
#[utoipa::path(
    get,
    path = "/healthz",
    tag = "server",
    responses((status = 200, description = "`ok`", content_type = "text/plain"))
)]
#[allow(dead_code)] // documentation only: `serve.rs` routes this path
async fn healthz_doc() {}

/// Prometheus metrics in the text exposition format.
#[utoipa::path(
    get,
    path = "/metrics",
    tag = "server",
    responses(
        (status = 200, description = "Metrics", content_type = "text/plain"),
        (status = 401, description = "Metrics token missing (server started with --metrics-token)", body = ApiErrorBody),
        (status = 403, description = "Not the metrics token", body = ApiErrorBody)
    )
)]
#[allow(dead_code)] // documentation only: `serve.rs` routes this path
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
