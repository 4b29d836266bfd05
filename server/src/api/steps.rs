//! A scene's steps: list, get (description and data), delete.

use crate::api::access::{
    parse_index, path_error, stored_of, viewable_scene, writable_scene, ApiShared, ClientAddr,
};
use crate::api::client::npy_header_f32;
use crate::api::request::blocking;
use crate::error::AppError;
use crate::state::AppState;
use crate::store::StoredStep;
use axum::body::{Body, Bytes};
use axum::extract::rejection::PathRejection;
use axum::extract::{Path, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::{Extension, Json};
use isoray_protocol::api::{ApiErrorBody, StepInfo, StepList, NPY_MEDIA_TYPE};
use std::sync::Arc;

/// The stored steps of a scene, by index.
#[utoipa::path(
    get,
    path = "/api/v1/scenes/{id}/steps",
    tag = "scenes",
    params(("id" = String, Path, description = "Scene id")),
    responses((status = 200, description = "OK", body = StepList), (status = 404, description = "Not found", body = ApiErrorBody))
)]
pub async fn list_steps(
    State(app): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> Result<Json<StepList>, AppError> {
    let entry = viewable_scene(&app, &headers, &id)?;
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
) -> Result<Arc<StoredStep>, AppError> {
    let entry = viewable_scene(app, headers, id)?;
    let scene = stored_of(&entry)?;
    let index = parse_index(app, index)?;
    scene.step(index).ok_or_else(|| {
        AppError::not_found(format!("scene `{id}` has no step {index}")).field("index")
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
pub async fn get_step(
    State(app): State<AppState>,
    headers: HeaderMap,
    path: Result<Path<(String, String)>, PathRejection>,
) -> Result<Json<StepInfo>, AppError> {
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
pub async fn get_step_data(
    State(app): State<AppState>,
    headers: HeaderMap,
    path: Result<Path<(String, String)>, PathRejection>,
) -> Result<Response, AppError> {
    let Path((id, index)) = path.map_err(path_error)?;
    let step = step_of(&app, &headers, &id, &index)?;
    let head = npy_header_f32(step.header.rows, step.header.columns);
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
pub async fn delete_step(
    State(app): State<AppState>,
    Extension(shared): Extension<Arc<ApiShared>>,
    ClientAddr(client): ClientAddr,
    headers: HeaderMap,
    path: Result<Path<(String, String)>, PathRejection>,
) -> Result<StatusCode, AppError> {
    let Path((id, index)) = path.map_err(path_error)?;
    let scene = writable_scene(&app, &headers, &id)?;
    shared.writes.check(client)?;
    let index = parse_index(&app, &index)?;
    let store = app
        .scenes()
        .store()
        .cloned()
        .ok_or_else(|| AppError::internal("stored scene without a store"))?;
    let found = blocking(move || store.delete_step(&scene, index))
        .await?
        .map_err(AppError::internal)?;
    if found {
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(AppError::not_found(format!("scene `{id}` has no step {index}")).field("index"))
    }
}
