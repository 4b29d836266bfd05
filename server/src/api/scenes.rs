//! Scenes: list, create, get, delete.

use crate::api::access::{
    check_create, check_view, reserve_scene, viewable_scene, writable_scene, ApiShared, ClientAddr,
};
use crate::api::auth::token_hash;
use crate::api::peers::{merge, peer_scenes};
use crate::api::request::{blocking, read_json};
use crate::error::AppError;
use crate::kinds::SceneSetup;
use crate::state::AppState;
use crate::store::SceneMeta;
use axum::body::Body;
use axum::extract::{Path, RawQuery, State};
use axum::http::{HeaderMap, StatusCode};
use axum::{Extension, Json};
use isoray_protocol::api::{
    ApiErrorBody, CreateScene, CreatedScene, SceneBounds, SceneInfo, SceneInfoList,
};
use std::sync::Arc;

/// Every scene: the built-in demos and the pushed ones, of this process and of its peers
/// (`--peers`), merged; peers that did not answer in time are named in `unreachable_shards`.
#[utoipa::path(
    get,
    path = "/api/v1/scenes",
    tag = "scenes",
    params(
        ("scope" = Option<String>, Query, description = "`all` (default): this process's scenes and its peers'; `local`: this process's only (what peers ask each other)")
    ),
    responses(
        (status = 200, description = "OK", body = SceneInfoList),
        (status = 400, description = "Unknown query parameter or scope", body = ApiErrorBody),
        (status = 401, description = "Token missing", body = ApiErrorBody), (status = 403, description = "Token wrong", body = ApiErrorBody)
    )
)]
pub async fn list_scenes(
    State(app): State<AppState>,
    headers: HeaderMap,
    RawQuery(query): RawQuery,
) -> Result<Json<SceneInfoList>, AppError> {
    check_view(&app, &headers, None)?;
    let mut local_only = false;
    for (k, v) in form_urlencoded::parse(query.as_deref().unwrap_or("").as_bytes()) {
        match (k.as_ref(), v.as_ref()) {
            ("scope", "local") => local_only = true,
            ("scope", "all") => local_only = false,
            ("scope", other) => {
                return Err(AppError::bad_request(
                    "invalid_query",
                    format!("scope=`{other}`: all or local"),
                )
                .field("scope"))
            }
            (other, _) => {
                return Err(AppError::bad_request(
                    "invalid_query",
                    format!("unknown query parameter `{other}` (scope)"),
                )
                .field(other.to_string()))
            }
        }
    }
    let local: Vec<_> = app.scenes().entries().iter().map(|e| e.info()).collect();
    if local_only || app.config().peers.is_empty() {
        return Ok(Json(SceneInfoList {
            scenes: local,
            unreachable_shards: Vec::new(),
        }));
    }
    let authorization = headers
        .get(axum::http::header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .map(str::to_string);
    let peers = peer_scenes(app.config(), authorization).await;
    Ok(Json(SceneInfoList {
        scenes: merge(local, peers.scenes),
        unreachable_shards: peers.unreachable,
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
        (status = 400, description = "Invalid field (a surfel scene: NaN, zero-length tangent axes, no nodes ...)", body = ApiErrorBody),
        (status = 401, description = "Admin token missing (server started with --admin-token)", body = ApiErrorBody),
        (status = 403, description = "Not the admin token", body = ApiErrorBody),
        (status = 409, description = "The server holds --max-scenes scenes already", body = ApiErrorBody),
        (status = 413, description = "Body too large", body = ApiErrorBody),
        (status = 415, description = "Content-Type is not application/json", body = ApiErrorBody),
        (status = 422, description = "Kind not supported yet", body = ApiErrorBody),
        (status = 429, description = "Too many writes", body = ApiErrorBody),
        (status = 503, description = "No scene store", body = ApiErrorBody),
        (status = 507, description = "The server's disk is full; nothing was stored", body = ApiErrorBody)
    )
)]
pub async fn create_scene(
    State(app): State<AppState>,
    Extension(shared): Extension<Arc<ApiShared>>,
    ClientAddr(client): ClientAddr,
    headers: HeaderMap,
    body: Body,
) -> Result<(StatusCode, Json<CreatedScene>), AppError> {
    check_create(&app, &headers)?;
    shared.writes.check(client)?;
    let spec: CreateScene = read_json(&app, &headers, body).await?;
    let _slot = reserve_scene(&app, &shared)?;
    for (field, text, max) in [
        ("name", &spec.name, 200),
        ("description", &spec.description, 4000),
    ] {
        if text.as_ref().is_some_and(|t| t.chars().count() > max) {
            return Err(AppError::bad_request(
                "invalid_value",
                format!("{field} is longer than {max} characters"),
            )
            .field(field));
        }
    }
    // A surfel scene's object is embedded and its hierarchy built here: seconds for a large
    // one, so off the async runtime.
    crate::kinds::refuse_field_settings(&spec)?;
    let limits = crate::effects::EffectLimits::from_config(app.config());
    let (spec, setup) = blocking(move || {
        let setup = SceneSetup::from_spec(&spec, &limits);
        (spec, setup)
    })
    .await?;
    let setup = setup?;
    let store = app.scenes().store().cloned().ok_or_else(|| {
        AppError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "no_store",
            "this server has no scene store (--demos-only, or its data directory is unusable)",
        )
    })?;
    let token = crate::random::random_hex(32);
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
        .map_err(AppError::store_write)?;
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
pub async fn get_scene(
    State(app): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> Result<Json<SceneInfo>, AppError> {
    let entry = viewable_scene(&app, &headers, &id)?;
    let mut info = entry.info();
    // The bounds need the state (prepared, or from the cache): on the job pool.
    let bounds = app.jobs().run(move || {
        let state = match entry.stored_scene() {
            Some(scene) => entry.prepared_step(scene.latest().as_deref()),
            None => entry.prepared_at(0.0, false, None),
        };
        state.prepared.scene().geometry.bounds()
    });
    info.bounds = bounds
        .await
        .map_err(AppError::internal)?
        .map(|(min, max)| SceneBounds {
            min: min.as_dvec3().to_array(),
            max: max.as_dvec3().to_array(),
        });
    Ok(Json(info))
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
pub async fn delete_scene(
    State(app): State<AppState>,
    Extension(shared): Extension<Arc<ApiShared>>,
    ClientAddr(client): ClientAddr,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> Result<StatusCode, AppError> {
    writable_scene(&app, &headers, &id)?;
    shared.writes.check(client)?;
    let store = app
        .scenes()
        .store()
        .cloned()
        .ok_or_else(|| AppError::internal("stored scene without a store"))?;
    let scene_id = id.clone();
    blocking(move || store.delete_scene(&scene_id))
        .await?
        .map_err(AppError::internal)?;
    app.scenes().remove_stored(&id);
    tracing::info!(scene = %id, "scene deleted");
    Ok(StatusCode::NO_CONTENT)
}
