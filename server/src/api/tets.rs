//! `PUT /api/v1/scenes/{id}/mesh`: a tet scene's static mesh, sent once. The mesh's checks
//! and readers are the tet kind's (`kinds::tets`); this handler reads the body, stores the
//! mesh crash-safely beside `scene.json` (see `store::mesh`) and answers. Sending the same
//! mesh again is a no-op, a different one a 409.

use crate::api::access::{path_error, writable_scene, ApiShared, ClientAddr};
use crate::api::request::{
    blocking, declared_length, forward_body, push_format, read_json, too_large, PushFormat,
    BODY_QUEUE,
};
use crate::body::BodyReader;
use crate::error::AppError;
use crate::kinds::tets::mesh::mesh_from_json;
use crate::kinds::tets::mesh_body::{read_binary_mesh, too_many_tets, MeshLimits};
use crate::state::AppState;
use axum::body::Body;
use axum::extract::rejection::PathRejection;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode};
use axum::{Extension, Json};
use isoray_protocol::api::{ApiErrorBody, MeshInfo, TetMeshData};
use std::sync::Arc;
use std::time::Duration;

/// Sends a tet scene's mesh: JSON (`TetMeshData`), two `.npy` arrays one after the other
/// (`(V, 3)` float, then `(T, 4)` integer), or two raw `ISRA` arrays. The mesh is checked in
/// full and stored once; the same mesh again is a no-op, a different one a 409.
#[utoipa::path(
    put,
    path = "/api/v1/scenes/{id}/mesh",
    tag = "scenes",
    params(("id" = String, Path, description = "Scene id (a tet scene)")),
    request_body(
        description = "The mesh: JSON, or two arrays back to back (.npy, or raw with the ISRA header)",
        content(
            (TetMeshData = "application/json"),
            ("application/x-npy"),
            ("application/octet-stream")
        )
    ),
    security(("bearer" = [])),
    responses(
        (status = 200, description = "The same mesh was already there", body = MeshInfo),
        (status = 201, description = "Stored", body = MeshInfo),
        (status = 400, description = "Invalid mesh; names the field (tet and corner) or byte offset", body = ApiErrorBody),
        (status = 401, description = "Token missing", body = ApiErrorBody), (status = 403, description = "Token wrong", body = ApiErrorBody),
        (status = 404, description = "Not found", body = ApiErrorBody),
        (status = 408, description = "Body too slow", body = ApiErrorBody),
        (status = 409, description = "Not a tet scene, or a different mesh is there", body = ApiErrorBody),
        (status = 413, description = "Body too large", body = ApiErrorBody),
        (status = 415, description = "Unsupported media type", body = ApiErrorBody),
        (status = 429, description = "Too many writes", body = ApiErrorBody)
    )
)]
pub async fn put_mesh(
    State(app): State<AppState>,
    Extension(shared): Extension<Arc<ApiShared>>,
    ClientAddr(client): ClientAddr,
    headers: HeaderMap,
    path: Result<Path<String>, PathRejection>,
    body: Body,
) -> Result<(StatusCode, Json<MeshInfo>), AppError> {
    let Path(id) = path.map_err(path_error)?;
    let scene = writable_scene(&app, &headers, &id)?;
    shared.writes.check(client)?;
    let Some(slot) = scene.setup.mesh_slot() else {
        return Err(AppError::new(
            StatusCode::CONFLICT,
            "not_a_tet_scene",
            format!(
                "scene `{id}` is of kind `{}`; only tet scenes have a mesh",
                scene.meta.kind.as_str()
            ),
        )
        .field("id"));
    };
    let slot = Arc::clone(slot);
    let format = push_format(&headers)?;
    let config = app.config();
    let limits = MeshLimits {
        max_tets: config.max_primitives as u64,
        max_vertices: u64::from(u32::MAX),
    };
    let body_limit = match format {
        PushFormat::Json => config.max_json_bytes,
        PushFormat::Npy | PushFormat::Raw => config.max_push_bytes,
    };
    let declared = declared_length(&headers);
    if declared.is_some_and(|n| n > body_limit) {
        return Err(too_large(body_limit).field("Content-Length"));
    }
    let mesh = match format {
        PushFormat::Json => {
            let data: TetMeshData = read_json(&app, &headers, body).await?;
            let n = data.cells.len() as u64;
            if n > limits.max_tets {
                return Err(too_many_tets(n, limits.max_tets).into());
            }
            blocking(move || mesh_from_json(&data, "")).await??
        }
        PushFormat::Npy | PushFormat::Raw => {
            let (tx, rx) = tokio::sync::mpsc::channel(BODY_QUEUE);
            let worker = tokio::task::spawn_blocking(move || {
                let mut reader = BodyReader::new(rx);
                read_binary_mesh(&mut reader, format == PushFormat::Npy, &limits)
            });
            let timeout = Duration::from_secs(config.push_timeout_secs);
            let _received = forward_body(body, tx, body_limit, declared, timeout).await;
            worker
                .await
                .map_err(|e| AppError::internal(format!("mesh reader failed: {e}")))??
        }
    };
    let dir = scene.dir().to_path_buf();
    let (outcome, checksum, mesh) = blocking(move || {
        let _one = slot.lock_upload();
        if let Some(existing) = slot.get() {
            return if **existing == mesh {
                Ok((
                    "unchanged",
                    crate::store::mesh::checksum(existing),
                    Arc::clone(existing),
                ))
            } else {
                Err(AppError::new(
                    StatusCode::CONFLICT,
                    "mesh_exists",
                    "this scene already has a different mesh; a tet scene's mesh never changes \
                     (create a new scene for a new mesh)",
                )
                .field("mesh"))
            };
        }
        let checksum = crate::store::mesh::write(&dir, &mesh).map_err(AppError::store_write)?;
        let mesh = Arc::new(mesh);
        slot.set(Arc::clone(&mesh));
        Ok(("created", checksum, mesh))
    })
    .await??;
    tracing::info!(scene = %id, tets = mesh.tets().len(), outcome, "tet mesh stored");
    let status = if outcome == "created" {
        StatusCode::CREATED
    } else {
        StatusCode::OK
    };
    Ok((
        status,
        Json(MeshInfo {
            vertices: mesh.vertices().len() as u64,
            tets: mesh.tets().len() as u64,
            checksum: crate::store::format::checksum_hex(checksum),
            outcome: outcome.into(),
        }),
    ))
}
