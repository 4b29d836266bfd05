//! `POST /api/v1/scenes/{id}/render`: one image of a scene, PNG or JPEG, or its hit
//! distances and normals as a `.npy` array.

use crate::api::access::{viewable_scene, ApiShared, ClientAddr};
use crate::api::request::read_json;
use crate::error::AppError;
use crate::frame::{self, FrameRequest, Pass};
use crate::kinds::convert;
use crate::state::AppState;
use axum::body::Body;
use axum::extract::{Path, State};
use axum::http::{header, HeaderMap};
use axum::response::{IntoResponse, Response};
use axum::Extension;
use isoray_protocol::api::{ApiErrorBody, ImageFormat, RenderRequest};
use isoray_protocol::Codec;
use isoray_render::View;
use std::sync::Arc;

/// Default image size of a one-shot render.
const DEFAULT_RENDER_SIZE: (u32, u32) = (640, 480);

/// Renders one image of a scene on the job pool: PNG (lossless) or JPEG; or, with
/// `format: "npy"`, an `(H, W, 4)` float32 array of hit distance and outward normal per pixel
/// (infinity and a zero normal for a miss).
#[utoipa::path(
    post,
    path = "/api/v1/scenes/{id}/render",
    tag = "scenes",
    params(("id" = String, Path, description = "Scene id")),
    request_body = RenderRequest,
    responses(
        (status = 200, description = "The image", content(("image/png"), ("image/jpeg"), ("application/x-npy"))),
        (status = 400, description = "Invalid request", body = ApiErrorBody),
        (status = 415, description = "Content-Type is not application/json", body = ApiErrorBody),
        (status = 404, description = "Not found", body = ApiErrorBody)
    )
)]
pub async fn render(
    State(app): State<AppState>,
    Extension(shared): Extension<Arc<ApiShared>>,
    ClientAddr(client): ClientAddr,
    headers: HeaderMap,
    Path(id): Path<String>,
    body: Body,
) -> Result<Response, AppError> {
    let entry = viewable_scene(&app, &headers, &id)?;
    // The most expensive request: limited per client (behind --trusted-proxy, per forwarded
    // client), after the view check.
    shared.renders.check(client)?;
    let req: RenderRequest = read_json(&app, &headers, body).await?;
    let Output {
        width,
        height,
        quality,
        passes,
    } = output(&req, app.config())?;
    let look = entry.demo();
    let camera = match &req.camera {
        Some(c) => convert::camera(c, "camera")?,
        None => look.default_camera(),
    };
    let field = entry.kind().has_field();
    let isovalue = match req.isovalue {
        Some(v) => convert::isovalue(v, entry.isovalue_range(), field, "isovalue")?,
        None => look.default_isovalue(),
    };
    let time = convert::scene_time(req.time.unwrap_or(0.0), "time")?;
    let step = match (entry.stored_scene(), req.step) {
        (Some(_), Some(_)) if req.time.is_some() => {
            return Err(AppError::relational(
                "invalid_value",
                "time picks a stored scene's step as step does; give one of them",
            )
            .field("time"))
        }
        // The scene (the URL's resource) exists; a body naming a step it does not hold is a
        // request whose fields disagree with the store: 422, like `step` on a built-in scene.
        (Some(scene), Some(i)) => Some(scene.step(i).ok_or_else(|| {
            AppError::relational("invalid_value", format!("scene `{id}` has no step {i}"))
                .field("step")
        })?),
        // The step a viewer's time input shows: the latest at or before `time`.
        (Some(scene), None) if req.time.is_some() => scene.at_time(time),
        (Some(scene), None) => scene.latest(),
        (None, Some(_)) => {
            return Err(AppError::relational(
                "invalid_value",
                "built-in scenes have no steps; use time",
            )
            .field("step"))
        }
        (None, None) => None,
    };
    let limits = crate::effects::EffectLimits::from_config(app.config());
    let scene_look = crate::style::SceneLook {
        lighting: entry.lighting(),
        has_field: field,
        isovalue_range: entry.isovalue_range(),
        slider: entry.demo().isovalue_slider(),
    };
    let (fx, style) =
        crate::style::one_shot(&scene_look, req.effects.as_ref(), &limits).map_err(|e| {
            let field = format!("effects.{}", e.field);
            match e.relational {
                true => AppError::relational("invalid_value", e.message).field(field),
                false => AppError::bad_request("invalid_value", e.message).field(field),
            }
        })?;
    let view = View {
        width,
        height,
        camera,
        isovalue,
    };
    let format = req.format;
    let job_app = app.clone();
    let job = app.jobs().run(move || {
        let state = match (&step, entry.stored_scene()) {
            (_, Some(_)) => entry.prepared_step(step.as_deref()),
            (_, None) => entry.prepared_at(time, false, None),
        };
        let codec = match format {
            ImageFormat::Png => Codec::Png,
            ImageFormat::Jpeg => Codec::Jpeg,
            ImageFormat::Npy => {
                let backend = job_app.backend();
                return Ok(frame::surface_npy(
                    backend,
                    &state,
                    &view,
                    &fx,
                    Some(&style),
                ));
            }
        };
        let request = FrameRequest {
            style: Some(&style),
            pass: match passes {
                1 => Pass::Single,
                n => Pass::Accumulate(n),
            },
            ..FrameRequest::image(view, &fx, codec, quality)
        };
        frame::render(job_app.backend(), &state, &request, None).map(|f| f.payload)
    });
    let image = job
        .await
        .map_err(AppError::internal)?
        .map_err(AppError::internal)?;
    let content_type = match format {
        ImageFormat::Png => "image/png",
        ImageFormat::Jpeg => "image/jpeg",
        ImageFormat::Npy => "application/x-npy",
    };
    Ok(([(header::CONTENT_TYPE, content_type)], image).into_response())
}

/// What a render request asks of its image, checked.
struct Output {
    width: u32,
    height: u32,
    quality: u8,
    passes: u32,
}

/// The image's size (default 640 × 480 within `--max-size`), JPEG quality (default 90) and
/// passes (default 1, at most `--max-refine-passes`), or a 400 naming the field.
fn output(req: &RenderRequest, config: &crate::config::Config) -> Result<Output, AppError> {
    let max = config.max_size;
    let width = req.width.unwrap_or(DEFAULT_RENDER_SIZE.0.min(max));
    let height = req.height.unwrap_or(DEFAULT_RENDER_SIZE.1.min(max));
    for (field, v) in [("width", width), ("height", height)] {
        if v == 0 || v > max {
            return Err(AppError::bad_request(
                "invalid_value",
                format!("{field} {v} must be in 1..={max}"),
            )
            .field(field));
        }
    }
    let quality = req.quality.unwrap_or(90);
    if !(1..=100).contains(&quality) {
        return Err(
            AppError::bad_request("invalid_value", "quality must be in 1..=100").field("quality"),
        );
    }
    let passes = req.passes.unwrap_or(1);
    let max_passes = config.max_refine_passes;
    if !(1..=max_passes).contains(&passes) {
        return Err(AppError::bad_request(
            "invalid_value",
            format!(
                "passes {passes} must be in 1..={max_passes} (the server's --max-refine-passes)"
            ),
        )
        .field("passes"));
    }
    if passes > 1 && req.format == ImageFormat::Npy {
        // Distances and normals are not averaged: a mean of depths across an edge is a
        // surface no pixel sees.
        return Err(AppError::relational(
            "invalid_value",
            format!(
                "passes {passes}: an npy render is one pass through the pixels' centres (leave \
                 passes out or give 1)"
            ),
        )
        .field("passes"));
    }
    Ok(Output {
        width,
        height,
        quality,
        passes,
    })
}
