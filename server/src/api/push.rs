//! Pushing a step: `PUT /api/v1/scenes/{id}/steps/{index}` with a JSON, `.npy` or raw body,
//! read as a stream, checked value by value and written crash-safely.

use crate::api::access::{parse_index, path_error, writable_scene, ApiShared, ClientAddr};
use crate::api::request::{
    blocking, declared_length, forward_body, push_format, read_json, too_large, PushFormat,
    BODY_QUEUE,
};
use crate::body::BodyReader;
use crate::error::AppError;
use crate::kinds::{check_ready, SceneSetup, StepLayout};
use crate::state::AppState;
use crate::store::format::HEADER_LEN;
use crate::store::ingest::{
    ingest_json, ingest_json_tets, ingest_npy, ingest_raw, IngestLimits, Target, WrittenStep,
};
use crate::store::{CommitError, CommitOutcome};
use axum::body::Body;
use axum::extract::rejection::PathRejection;
use axum::extract::{Path, RawQuery, State};
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::{Extension, Json};
use isoray_protocol::api::{ApiErrorBody, JsonStep, JsonTetStep, PushResult};
use std::sync::Arc;
use std::time::Duration;

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct PushQuery {
    #[serde(default)]
    replace: Option<bool>,
    #[serde(default)]
    time: Option<f64>,
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
        (status = 429, description = "Too many writes", body = ApiErrorBody),
        (status = 507, description = "The server's disk is full; nothing was stored", body = ApiErrorBody)
    )
)]
pub async fn push_step(
    State(app): State<AppState>,
    Extension(shared): Extension<Arc<ApiShared>>,
    ClientAddr(client): ClientAddr,
    headers: HeaderMap,
    path: Result<Path<(String, String)>, PathRejection>,
    RawQuery(query): RawQuery,
    body: Body,
) -> Result<Response, AppError> {
    let Path((id, index)) = path.map_err(path_error)?;
    let scene = writable_scene(&app, &headers, &id)?;
    shared.writes.check(client)?;
    check_ready(&scene.setup)?;
    let index = parse_index(&app, &index)?;
    let query: PushQuery = serde_urlencoded_lite(query.as_deref().unwrap_or(""))?;
    let time = query.time.unwrap_or(index as f64);
    if !time.is_finite() {
        return Err(
            AppError::bad_request("invalid_value", format!("time {time} is not finite"))
                .field("time"),
        );
    }
    let format = push_format(&headers)?;
    let config = app.config();
    let store = app
        .scenes()
        .store()
        .cloned()
        .ok_or_else(|| AppError::internal("stored scene without a store"))?;
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
    let declared = declared_length(&headers);
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
        PushFormat::Json => {
            let step: AnyJsonStep = read_json(&app, &headers, body).await?;
            match (limits.layout, step.by_kind()?) {
                (StepLayout::Metaballs, Ok(step)) => {
                    blocking(move || ingest_json(&step, &limits, target)).await??
                }
                (StepLayout::Tets { .. }, Err(step)) => {
                    blocking(move || ingest_json_tets(&step, &limits, target)).await??
                }
                // Node positions: a metaball step's shape without its optional columns.
                (StepLayout::Surfels { .. }, Ok(step)) => {
                    let step = surfel_step(step)?;
                    blocking(move || ingest_json(&step, &limits, target)).await??
                }
                (StepLayout::Metaballs, Err(_))
                | (StepLayout::Tets { .. }, Ok(_))
                | (StepLayout::Surfels { .. }, Err(_)) => {
                    return Err(AppError::relational(
                        "wrong_kind",
                        format!(
                            "scene `{id}` is of kind `{}`: {}",
                            scene.meta.kind.as_str(),
                            match limits.layout {
                                StepLayout::Metaballs => "its JSON steps are {\"positions\": ...}",
                                StepLayout::Tets { .. } =>
                                    "its JSON steps are {\"scalars\": [...]} (and, for a \
                                     deforming mesh, \"positions\")",
                                StepLayout::Surfels { .. } =>
                                    "its JSON steps are {\"positions\": ...} (node positions only)",
                            }
                        ),
                    ))
                }
            }
        }
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
                .map_err(|e| AppError::internal(format!("step writer failed: {e}")))?;
            result?
        }
    };
    // A step that moves a tet mesh is checked as a whole, like the mesh was: the rows passed
    // one by one, but a tet is inverted only by its four corners together.
    let written = if limits.layout.checks_whole_step(written.header.columns) {
        let check_scene = Arc::clone(&scene);
        blocking(move || check_whole_step(&check_scene.setup, written)).await??
    } else {
        written
    };
    let replace = query.replace.unwrap_or(false);
    let commit_scene = Arc::clone(&scene);
    let commit_store = Arc::clone(&store);
    let (outcome, evicted) = blocking(move || commit_store.commit(&commit_scene, written, replace))
        .await?
        .map_err(|e| match e {
            CommitError::Conflict { .. } => {
                AppError::new(StatusCode::CONFLICT, "conflict", e.to_string()).field("index")
            }
            CommitError::SceneGone => AppError::not_found(format!("scene `{id}` was deleted")),
            CommitError::Io(e) => AppError::store_write(e),
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

/// A JSON step of any kind, as the document says (`oneOf` JsonStep, JsonTetStep; a surfel
/// scene's step is a JsonStep with positions only, JsonSurfelStep): which one is decided by
/// its fields, then checked against the scene's kind (422 if it is another's).
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct AnyJsonStep {
    #[serde(default)]
    positions: Option<Vec<[f64; 3]>>,
    #[serde(default)]
    radii: Option<Vec<f64>>,
    #[serde(default)]
    strengths: Option<Vec<f64>>,
    #[serde(default)]
    colors: Option<Vec<[f64; 3]>>,
    /// Absent, or an array: the document's JsonTetStep requires the array and JsonStep has
    /// no such field, so `"scalars": null` matches neither and is refused (400).
    #[serde(default, deserialize_with = "present_array")]
    scalars: Option<Vec<f64>>,
}

/// A field that may be left out but, when given, must be an array (not `null`).
fn present_array<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<Vec<f64>>, D::Error> {
    <Vec<f64> as serde::Deserialize>::deserialize(d).map(Some)
}

impl AnyJsonStep {
    /// A metaball step (`Ok`) or a tet step (`Err`): `scalars` makes a tet step (with the
    /// moved vertex `positions` of a deforming mesh beside them), `positions` alone a
    /// metaball step; a mixture, or neither, is a 400.
    #[allow(clippy::type_complexity)]
    fn by_kind(self) -> Result<Result<JsonStep, JsonTetStep>, AppError> {
        let ball_fields = self.radii.is_some() || self.strengths.is_some() || self.colors.is_some();
        match (self.positions, self.scalars) {
            (Some(positions), None) => Ok(Ok(JsonStep {
                positions,
                radii: self.radii,
                strengths: self.strengths,
                colors: self.colors,
            })),
            (positions, Some(scalars)) if !ball_fields => {
                Ok(Err(JsonTetStep { scalars, positions }))
            }
            (_, Some(_)) => Err(AppError::bad_request(
                "invalid_json",
                "a tet step is {\"scalars\": [...]} with optional moved vertex \"positions\"; \
                 `radii`, `strengths` and `colors` belong to metaball steps",
            )
            .field("scalars")),
            (None, None) => Err(AppError::bad_request(
                "invalid_json",
                "a step needs `positions` (metaballs) or `scalars` (tets)",
            )
            .field("positions")),
        }
    }
}

/// Reads a written (not yet committed) step back and runs its kind's whole-step checks; on
/// an error the temporary file goes with `written`, so nothing stored changes.
fn check_whole_step(setup: &SceneSetup, written: WrittenStep) -> Result<WrittenStep, AppError> {
    let bytes = std::fs::read(written.temp.path())
        .map_err(|e| AppError::internal(format!("cannot read the written step back: {e}")))?;
    let payload = bytes.get(HEADER_LEN..).unwrap_or_default();
    setup.check_step(written.header.columns, payload)?;
    Ok(written)
}

/// A surfel step is the nodes' positions only: a metaball step's radii, strengths or colours
/// fit the document's `JsonStep` but not a surfel scene (422 naming the column).
fn surfel_step(step: JsonStep) -> Result<JsonStep, AppError> {
    let extra = [
        ("radii", step.radii.is_some()),
        ("strengths", step.strengths.is_some()),
        ("colors", step.colors.is_some()),
    ]
    .into_iter()
    .find(|(_, present)| *present);
    match extra {
        Some((name, _)) => Err(AppError::relational(
            "wrong_kind",
            format!("a surfel scene's step is the node positions only, without `{name}`"),
        )
        .field(name)),
        None => Ok(JsonStep {
            positions: step.positions,
            radii: None,
            strengths: None,
            colors: None,
        }),
    }
}

/// Parses `replace=true&time=1.5` without another dependency: both values are plain tokens.
fn serde_urlencoded_lite(query: &str) -> Result<PushQuery, AppError> {
    let mut q = PushQuery {
        replace: None,
        time: None,
    };
    // Percent-decoded (`time=1e%2B3`), as a client's URL encoder writes it.
    for (k, v) in form_urlencoded::parse(query.as_bytes()) {
        let (k, v): (&str, &str) = (&k, &v);
        match k {
            "replace" => {
                q.replace = Some(match v {
                    "true" | "1" | "" => true,
                    "false" | "0" => false,
                    _ => {
                        return Err(AppError::bad_request(
                            "invalid_query",
                            format!("replace=`{v}`: true or false"),
                        )
                        .field("replace"))
                    }
                })
            }
            "time" => {
                q.time = Some(v.parse().map_err(|_| {
                    AppError::bad_request("invalid_query", format!("time=`{v}` is not a number"))
                        .field("time")
                })?)
            }
            "token" => {}
            other => {
                return Err(AppError::bad_request(
                    "invalid_query",
                    format!("unknown query parameter `{other}` (replace, time)"),
                )
                .field(other.to_string()))
            }
        }
    }
    Ok(q)
}
