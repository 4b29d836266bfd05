//! `GET /api/v1/scenes/{id}/histogram`: the distribution of the scalar field's values, which
//! the browser draws behind the isovalue slider (as ParaView and VisIt do beside their
//! contour values), so a user sees where the field has mass before moving the surface there.
//!
//! How it works, for metaballs: a regular grid over the scene's bounds, at most [`MAX_GRID`] points per axis;
//! every metaball adds `q · f(s)` to the grid points inside its support (a splat, so the cost
//! is the balls' support volume in cells, not balls × points). Points that no support reaches
//! are left out: they are empty space, not field. The grid shrinks when the splat would cost
//! more than [`MAX_SPLAT_CELLS`]. For a tetrahedral mesh, whose field is given at its
//! vertices: those values. Runs on the render pool.

use super::error::ApiError;
use super::{check_view, scene_of};
use crate::AppState;
use axum::extract::{Path, RawQuery, State};
use axum::http::HeaderMap;
use axum::Json;
use glam::Vec3;
use isoray_protocol::api::{ApiErrorBody, FieldHistogram};
use isoray_render::metaball::MetaballScene;
use isoray_render::scene::Geometry;

/// Grid points along the longest side of the scene's bounds.
pub const MAX_GRID: u32 = 64;
/// Largest number of (ball, grid point) pairs one histogram evaluates.
pub const MAX_SPLAT_CELLS: f64 = 5.0e7;
const DEFAULT_BINS: usize = 64;
const MAX_BINS: usize = 1024;

/// The field's values at the grid points inside any support, binned over `[lo, hi)`.
pub fn field_histogram(scene: &MetaballScene, lo: f32, hi: f32, bins: usize) -> Histogram {
    let mut out = Histogram {
        counts: vec![0; bins],
        below: 0,
        above: 0,
        samples: 0,
        grid: [0; 3],
        evaluations: 0,
    };
    let Some((min, max)) = scene.bounds() else {
        return out;
    };
    let extent = (max - min).max(Vec3::splat(1e-6));
    let mut cell = extent.max_element() / MAX_GRID as f32;
    // Splat cost: each ball touches about (2R / cell)³ grid points.
    let cost = |cell: f32| -> f64 {
        scene
            .balls
            .iter()
            .map(|b| (2.0 * f64::from(b.radius) / f64::from(cell) + 1.0).powi(3))
            .sum()
    };
    let estimate = cost(cell);
    if estimate > MAX_SPLAT_CELLS {
        cell *= (estimate / MAX_SPLAT_CELLS).cbrt() as f32;
        while cost(cell) > MAX_SPLAT_CELLS {
            cell *= 1.1;
        }
    }
    let dims = (extent / cell)
        .ceil()
        .max(Vec3::ONE)
        .as_uvec3()
        .min(glam::UVec3::splat(MAX_GRID));
    out.grid = dims.to_array();
    let (nx, ny, nz) = (dims.x as usize, dims.y as usize, dims.z as usize);
    // Grid point (i, j, k) sits at the centre of its cell.
    let point = |i: usize, j: usize, k: usize| {
        min + Vec3::new(i as f32 + 0.5, j as f32 + 0.5, k as f32 + 0.5) * cell
    };
    let mut field = vec![0f32; nx * ny * nz];
    let mut inside = vec![false; nx * ny * nz];
    let index_range = |c: f32, r: f32, lo: f32, n: usize| {
        let first = (((c - r - lo) / cell) - 0.5).floor().max(0.0) as usize;
        let last = ((((c + r - lo) / cell) - 0.5).ceil().max(0.0) as usize).min(n - 1);
        first..=last
    };
    for ball in &scene.balls {
        let (c, r) = (ball.center, ball.radius);
        for k in index_range(c.z, r, min.z, nz) {
            for j in index_range(c.y, r, min.y, ny) {
                for i in index_range(c.x, r, min.x, nx) {
                    out.evaluations += 1;
                    let s = ball.s_at(point(i, j, k));
                    if s < 1.0 {
                        let at = (k * ny + j) * nx + i;
                        field[at] += ball.strength * scene.kernel.value(s);
                        inside[at] = true;
                    }
                }
            }
        }
    }
    let values = field
        .iter()
        .zip(&inside)
        .filter(|(_, &i)| i)
        .map(|(&v, _)| v);
    bin_values(&mut out, values, lo, hi);
    out
}

/// A tetrahedral mesh's scalar field: its values at the mesh's vertices, binned (the point
/// data histogram ParaView shows); `grid` is `[vertices, 1, 1]`.
pub fn vertex_histogram(scalars: &[f32], lo: f32, hi: f32, bins: usize) -> Histogram {
    let mut out = Histogram {
        counts: vec![0; bins],
        below: 0,
        above: 0,
        samples: 0,
        grid: [u32::try_from(scalars.len()).unwrap_or(u32::MAX), 1, 1],
        evaluations: scalars.len() as u64,
    };
    bin_values(&mut out, scalars.iter().copied(), lo, hi);
    out
}

fn bin_values(out: &mut Histogram, values: impl Iterator<Item = f32>, lo: f32, hi: f32) {
    let bins = out.counts.len();
    let width = (hi - lo) / bins as f32;
    for v in values {
        out.samples += 1;
        if v < lo {
            out.below += 1;
        } else if v >= hi {
            out.above += 1;
        } else {
            let bin = (((v - lo) / width) as usize).min(bins - 1);
            out.counts[bin] += 1;
        }
    }
}

/// What [`field_histogram`] counted.
#[derive(Clone, Debug, PartialEq)]
pub struct Histogram {
    pub counts: Vec<u64>,
    pub below: u64,
    pub above: u64,
    pub samples: u64,
    pub grid: [u32; 3],
    /// Values computed: (ball, grid point) pairs for metaballs, at most [`MAX_SPLAT_CELLS`].
    pub evaluations: u64,
}

/// The query: `time` (seconds; absent: the live state), `bins`, and the range `lo`, `hi`
/// (default: the scene's isovalue slider).
struct Query {
    time: Option<f64>,
    bins: usize,
    range: Option<(f64, f64)>,
}

fn parse_query(query: &str) -> Result<Query, ApiError> {
    let mut q = Query {
        time: None,
        bins: DEFAULT_BINS,
        range: None,
    };
    let (mut lo, mut hi) = (None, None);
    for pair in query.split('&').filter(|p| !p.is_empty()) {
        let (k, v) = pair.split_once('=').unwrap_or((pair, ""));
        let number = |name: &'static str| {
            v.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    ApiError::bad_request(
                        "invalid_query",
                        format!("{name}=`{v}` is not a finite number"),
                    )
                    .field(name)
                })
        };
        match k {
            "time" => {
                let t = number("time")?;
                if !(0.0..=1.0e9).contains(&t) {
                    return Err(ApiError::bad_request(
                        "invalid_value",
                        format!("time {t} must be in [0, 1e9]"),
                    )
                    .field("time"));
                }
                q.time = Some(t);
            }
            "bins" => {
                q.bins = v
                    .parse::<usize>()
                    .ok()
                    .filter(|b| (1..=MAX_BINS).contains(b))
                    .ok_or_else(|| {
                        ApiError::bad_request(
                            "invalid_value",
                            format!("bins=`{v}` must be an integer in 1..={MAX_BINS}"),
                        )
                        .field("bins")
                    })?;
            }
            "lo" => lo = Some(number("lo")?),
            "hi" => hi = Some(number("hi")?),
            other => {
                return Err(ApiError::bad_request(
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
            return Err(ApiError::bad_request("invalid_value", "lo must be below hi").field("lo"))
        }
        (None, Some(_)) => {
            return Err(ApiError::bad_request("invalid_query", "hi needs lo").field("lo"))
        }
        (Some(_), None) => {
            return Err(ApiError::bad_request("invalid_query", "lo needs hi").field("hi"))
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
pub(super) async fn histogram(
    State(app): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
    RawQuery(query): RawQuery,
) -> Result<Json<FieldHistogram>, ApiError> {
    let entry = scene_of(&app, &id)?;
    check_view(&app, &headers, Some(&entry))?;
    let q = parse_query(query.as_deref().unwrap_or(""))?;
    let (lo, hi) = q.range.unwrap_or_else(|| {
        let (lo, hi) = entry.demo().isovalue_slider();
        (f64::from(lo), f64::from(hi))
    });
    let live_time = app.scenes().live_time();
    let (tx, rx) = tokio::sync::oneshot::channel();
    app.backend().spawn(move || {
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
        let histogram = match &state.prepared.scene().geometry {
            Geometry::Metaballs(m) => field_histogram(m, lo as f32, hi as f32, q.bins),
            Geometry::Tets(t) => vertex_histogram(t.scalars(), lo as f32, hi as f32, q.bins),
        };
        let _ = tx.send((histogram, time));
    });
    let (h, time) = rx
        .await
        .map_err(|_| ApiError::internal("the render pool dropped the job"))?;
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
    use isoray_render::metaball::{Kernel, Metaball};

    /// One ball: the grid points where the field is at least `t` fill the sphere of radius
    /// `R · sqrt(s(t))`, so their count is that sphere's volume in cells.
    #[test]
    fn one_ball_matches_the_sphere_volumes() {
        let radius = 2.0;
        let scene = MetaballScene::new(
            Kernel::Wyvill,
            vec![Metaball::sphere(Vec3::ZERO, radius, 1.0, Vec3::ONE)],
        );
        let bins = 100;
        let h = field_histogram(&scene, 0.0, 1.0, bins);
        assert_eq!(h.grid, [MAX_GRID; 3]);
        let cell = 2.0 * radius as f64 / MAX_GRID as f64;
        let ball_cells = |r: f64| 4.0 / 3.0 * std::f64::consts::PI * r.powi(3) / cell.powi(3);
        let total = ball_cells(radius as f64);
        assert!(
            (h.samples as f64 - total).abs() < 0.02 * total,
            "{} samples inside the support, expected about {total:.0}",
            h.samples
        );
        for t in [0.1f32, 0.3, 0.5, 0.8] {
            let at_least: u64 = h.counts[(t * bins as f32).round() as usize..].iter().sum();
            let r_t = radius as f64 * f64::from(Kernel::Wyvill.s_at_value(t)).sqrt();
            let expected = ball_cells(r_t);
            assert!(
                (at_least as f64 - expected).abs() < 0.03 * expected + 50.0,
                "field ≥ {t}: {at_least} points, expected about {expected:.0}"
            );
        }
        assert_eq!(h.samples, h.below + h.above + h.counts.iter().sum::<u64>());
    }

    #[test]
    fn overlapping_balls_add_and_empty_scenes_are_empty() {
        let two = MetaballScene::new(
            Kernel::Wyvill,
            vec![
                Metaball::sphere(Vec3::ZERO, 1.0, 1.0, Vec3::ONE),
                Metaball::sphere(Vec3::ZERO, 1.0, 1.0, Vec3::ONE),
            ],
        );
        let h = field_histogram(&two, 0.0, 2.0, 2);
        // Doubled strength: values above 1 exist (near the centre), none at or above 2.
        assert!(h.counts[1] > 0 && h.above == 0, "{h:?}");
        let empty = MetaballScene::new(Kernel::Wyvill, Vec::new());
        let h = field_histogram(&empty, 0.0, 1.0, 8);
        assert_eq!((h.samples, h.counts), (0, vec![0; 8]));
    }

    #[test]
    fn many_large_balls_shrink_the_grid_to_the_budget() {
        let balls = (0..20_000)
            .map(|i| Metaball::sphere(Vec3::new(i as f32 * 1e-4, 0.0, 0.0), 1.0, 1.0, Vec3::ONE))
            .collect();
        let h = field_histogram(&MetaballScene::new(Kernel::Wyvill, balls), 0.0, 1.0, 4);
        let points: u32 = h.grid.iter().product();
        assert!(points < MAX_GRID.pow(3), "grid {:?}", h.grid);
        assert!(
            h.evaluations as f64 <= MAX_SPLAT_CELLS && h.evaluations > 1_000_000,
            "{} evaluations on grid {:?}",
            h.evaluations,
            h.grid
        );
    }

    #[test]
    fn vertex_values_are_binned_with_the_outliers_counted() {
        let h = vertex_histogram(&[0.0, 0.1, 0.26, 0.5, 0.99, 1.0, -3.0], 0.0, 1.0, 4);
        assert_eq!(h.counts, vec![2, 1, 1, 1]);
        assert_eq!((h.below, h.above, h.samples), (1, 1, 7));
    }

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
