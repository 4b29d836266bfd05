//! `GET /api/v1/scenes/{id}/histogram`: the distribution of the scalar field's values, which
//! the browser draws behind the isovalue slider (as ParaView and VisIt do beside their
//! contour values), so a user sees where the field has mass before moving the surface there.
//!
//! Each kind samples its own field (`kinds::histogram` dispatches: a grid splat for metaballs,
//! the vertex values of a tet mesh); this handler parses the query, picks the state and runs
//! the job on the job pool (`crate::jobs`), off the async runtime.

use crate::api::access::viewable_scene;
use crate::error::AppError;
use crate::state::AppState;
use axum::extract::{Path, RawQuery, State};
use axum::http::HeaderMap;
use axum::Json;
use isoray_protocol::api::{ApiErrorBody, FieldHistogram};

const DEFAULT_BINS: usize = 64;
const MAX_BINS: usize = 1024;

/// The query: `time` (seconds; absent: the live state), `bins`, and the range `lo`, `hi`
/// (default: the scene's isovalue slider).
struct Query {
    time: Option<f64>,
    bins: usize,
    range: Option<(f64, f64)>,
}

fn parse_query(query: &str) -> Result<Query, AppError> {
    let mut q = Query {
        time: None,
        bins: DEFAULT_BINS,
        range: None,
    };
    let (mut lo, mut hi) = (None, None);
    // Percent-decoded (`1e%2B36`), as a client's URL encoder writes it.
    for (k, v) in form_urlencoded::parse(query.as_bytes()) {
        let (k, v): (&str, &str) = (&k, &v);
        let number = |name: &'static str| {
            v.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    AppError::bad_request(
                        "invalid_query",
                        format!("{name}=`{v}` is not a finite number"),
                    )
                    .field(name)
                })
        };
        match k {
            "time" => {
                q.time = Some(crate::kinds::convert::scene_time(number("time")?, "time")?);
            }
            "bins" => {
                q.bins = v
                    .parse::<usize>()
                    .ok()
                    .filter(|b| (1..=MAX_BINS).contains(b))
                    .ok_or_else(|| {
                        AppError::bad_request(
                            "invalid_value",
                            format!("bins=`{v}` must be an integer in 1..={MAX_BINS}"),
                        )
                        .field("bins")
                    })?;
            }
            "lo" => lo = Some(number("lo")?),
            "hi" => hi = Some(number("hi")?),
            other => {
                return Err(AppError::bad_request(
                    "invalid_query",
                    format!("unknown query parameter `{other}` (time, bins, lo, hi)"),
                )
                .field(other.to_string()))
            }
        }
    }
    match (lo, hi) {
        (None, None) => {}
        (Some(lo), Some(hi)) if lo < hi => q.range = Some((lo, hi)),
        (Some(_), Some(_)) => {
            return Err(AppError::relational("invalid_value", "lo must be below hi").field("lo"))
        }
        (None, Some(_)) => {
            return Err(AppError::relational("invalid_query", "hi needs lo").field("lo"))
        }
        (Some(_), None) => {
            return Err(AppError::relational("invalid_query", "lo needs hi").field("hi"))
        }
    }
    Ok(q)
}

/// Histogram of the field's values, for the slider's background.
#[utoipa::path(
    get,
    path = "/api/v1/scenes/{id}/histogram",
    tag = "scenes",
    params(
        ("id" = String, Path, description = "Scene id"),
        ("time" = Option<f64>, Query, description = "Scene time in seconds (default: the live state)"),
        ("bins" = Option<u32>, Query, description = "Number of bins, 1..=1024 (default 64)"),
        ("lo" = Option<f64>, Query, description = "Lower end of the binned range (default: the isovalue slider's)"),
        ("hi" = Option<f64>, Query, description = "Upper end of the binned range")
    ),
    responses(
        (status = 200, description = "OK", body = FieldHistogram),
        (status = 400, description = "Invalid query", body = ApiErrorBody),
        (status = 401, description = "Token missing", body = ApiErrorBody), (status = 403, description = "Token wrong", body = ApiErrorBody),
        (status = 404, description = "Not found", body = ApiErrorBody)
    )
)]
pub async fn histogram(
    State(app): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
    RawQuery(query): RawQuery,
) -> Result<Json<FieldHistogram>, AppError> {
    let entry = viewable_scene(&app, &headers, &id)?;
    let q = parse_query(query.as_deref().unwrap_or(""))?;
    let (lo, hi) = q.range.unwrap_or_else(|| {
        let (lo, hi) = entry.demo().isovalue_slider();
        (f64::from(lo), f64::from(hi))
    });
    let live_time = app.scenes().live_time();
    let job = app.jobs().run(move || {
        let (state, time) = match entry.stored_scene() {
            Some(scene) => {
                let step = match q.time {
                    Some(t) => scene.at_time(t),
                    None => scene.latest(),
                };
                let time = step.as_ref().map_or(0.0, |s| s.header.time);
                (entry.prepared_step(step.as_deref()), time)
            }
            None => {
                let time = q.time.unwrap_or(live_time);
                (entry.prepared_at(time, false, None), time)
            }
        };
        let geometry = &state.prepared.scene().geometry;
        let histogram = crate::kinds::histogram_of(geometry, lo as f32, hi as f32, q.bins);
        (histogram, time)
    });
    let (h, time) = job.await.map_err(AppError::internal)?;
    Ok(Json(FieldHistogram {
        lo,
        hi,
        counts: h.counts,
        below: h.below,
        above: h.above,
        samples: h.samples,
        grid: h.grid,
        time,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_queries_name_the_parameter() {
        for (query, field) in [
            ("bins=0", "bins"),
            ("bins=x", "bins"),
            ("time=-1", "time"),
            ("time=NaN", "time"),
            ("lo=1&hi=0", "lo"),
            ("hi=1", "lo"),
            ("colour=red", "colour"),
        ] {
            let err = parse_query(query).err().expect("rejected");
            assert_eq!(err.field.as_deref(), Some(field), "{query}");
        }
        let ok = parse_query("time=2.5&bins=16&lo=0.1&hi=1").expect("valid");
        assert_eq!(
            (ok.time, ok.bins, ok.range),
            (Some(2.5), 16, Some((0.1, 1.0)))
        );
    }
}
