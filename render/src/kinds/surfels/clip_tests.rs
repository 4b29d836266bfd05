//! The clipping of §4.3 on a cube of six clipped faces: sharp edges at 4× supersampling,
//! each face's normals up to its edges, and rays leaving a flat face.

use crate::camera::Camera;
use crate::geom::rng::SplitMix64;
use crate::kinds::surfels::counters::SurfelCounters;
use crate::kinds::surfels::model::{SurfelModel, SurfelSet};
use crate::kinds::surfels::prepared::PreparedSurfels;
use crate::kinds::surfels::sample;
use crate::kinds::surfels::scene::{SurfelOptions, SurfelScene};
use crate::ray::Ray;
use glam::Vec3;
use std::sync::Arc;

/// The cube [-1, 1]³ of six faces of 44 × 44 surfels (40 across, two more past each edge)
/// clipped by one another, at rest.
fn clipped_cube() -> PreparedSurfels {
    let (surfels, clip) = sample::cube(Vec3::ZERO, 1.0, 40, [Vec3::ONE; 6], 0);
    let nodes = sample::lattice(Vec3::splat(-1.0), Vec3::splat(1.0), 0.5, |_| true);
    let set = SurfelSet {
        surfels,
        nodes,
        clip,
        ..SurfelSet::default()
    };
    let model = Arc::new(SurfelModel::new(set, usize::MAX).expect("valid"));
    PreparedSurfels::new(SurfelScene::rest(model, SurfelOptions::default()))
}

#[test]
fn clipped_edges_stay_sharp_at_4x_supersampling() {
    // One cube [-1, 1]³ of six clipped faces seen head on: the front face's right edge is
    // x = 1 at z = 1, so a pixel's coverage along a row is the share of its 2×2 samples
    // whose rays cross z = 1 at x ≤ 1. Unclipped, the faces run two spacings past the edge.
    let p = clipped_cube();
    let camera = Camera {
        eye: Vec3::new(0.0, 0.0, 5.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 40.0,
    };
    let (w, h) = (64u32, 48u32);
    let rays = camera.rays(2 * w, 2 * h);
    let row = h / 2 + 3;
    let mut c = SurfelCounters::default();
    let mut edge_engine = 0.0f32;
    let mut edge_analytic = 0.0f32;
    for x in w / 2..w {
        let (mut engine, mut analytic) = (0.0f32, 0.0f32);
        for (sx, sy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            let ray = rays.through_pixel(2 * x + sx, 2 * row + sy);
            if p.nearest(&ray, 0.0, 100.0, None, &mut c).is_some() {
                engine += 0.25;
            }
            let t = (1.0 - ray.origin.z) / ray.dir.z;
            let at = ray.at(t);
            if at.x.abs() <= 1.0 && at.y.abs() <= 1.0 {
                analytic += 0.25;
            }
        }
        assert!(
            (engine - analytic).abs() <= 0.25,
            "pixel {x}: coverage {engine} vs analytic {analytic}"
        );
        edge_engine += engine;
        edge_analytic += analytic;
    }
    // The edge position along the row (sum of coverages) within a quarter pixel.
    assert!(
        (edge_engine - edge_analytic) <= 0.25,
        "{edge_engine} vs {edge_analytic}"
    );
    assert!(c.clipped > 0, "clipping rejected nothing: {c:?}");
    assert!(edge_analytic > 5.0 && edge_analytic < (w / 2) as f32 - 5.0);
}

/// A cube of six clipped faces seen from a corner, three faces and their edges in view:
/// every hit lies on the cube and its normal is its face's, right up to the edges (each
/// face's MLS neighbourhoods stay on that face). With neighbourhoods that reach across an
/// edge into the next face, hits near the edges blend the two faces' normals (up to 45°
/// off) and stand off the cube, so this fails.
#[test]
fn clipped_faces_keep_their_normals_up_to_the_edges() {
    let p = clipped_cube();
    let camera = Camera {
        eye: Vec3::new(2.6, 2.1, 3.2),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 50.0,
    };
    let (w, h) = (120u32, 90u32);
    let rays = camera.rays(w, h);
    let mut c = SurfelCounters::default();
    let (mut hits, mut near_edges) = (0, 0);
    for y in 0..h {
        for x in 0..w {
            let Some(hit) = p.nearest(&rays.through_pixel(x, y), 0.0, 100.0, None, &mut c) else {
                continue;
            };
            let at = hit.position;
            let axis = at.abs().max_position();
            let mut face = Vec3::ZERO;
            face[axis] = at[axis].signum();
            let off = (at[axis].abs() - 1.0).abs();
            let angle = hit.normal.dot(face).clamp(-1.0, 1.0).acos().to_degrees();
            assert!(
                off < 2e-3 && angle < 2.0,
                "pixel ({x}, {y}): hit {at} is {off} off the cube, normal {} is {angle}° off {face}",
                hit.normal
            );
            hits += 1;
            // Within two surfel spacings (0.1) of an edge: the second largest coordinate.
            let mut sorted = at.abs().to_array();
            sorted.sort_by(f32::total_cmp);
            near_edges += (sorted[1] > 0.9) as usize;
        }
    }
    assert!(
        hits > 3000 && near_edges > 200,
        "{hits} hits, {near_edges} near the edges"
    );
}

/// A shadow ray leaving a flat face gathers no neighbourhood and runs no MLS iteration on
/// the leaves around its start: their ellipses lie behind it (`t0 < t_min`), so each is
/// passed over after the plane test. Without that rule every such ray iterated on several
/// leaves only to converge behind its start. A ray from inside still meets the face where
/// it is.
#[test]
fn a_ray_leaving_a_flat_face_skips_the_leaves_behind_its_start() {
    use crate::kinds::contract::PreparedKind;
    let p = clipped_cube();
    let mut rng = SplitMix64(5);
    let (mut leaving, mut inside) = (SurfelCounters::default(), SurfelCounters::default());
    for _ in 0..64 {
        let (x, z) = (rng.range(-0.8, 0.8), rng.range(-0.8, 0.8));
        let dir = Vec3::new(rng.range(-0.5, 0.5), 1.0, rng.range(-0.5, 0.5)).normalize();
        let out = Ray::new(Vec3::new(x, 1.0 + 1e-3, z), dir);
        assert!(p.any_hit(&out, 0.0, 10.0, 0.0, &mut leaving).is_none());
        let from_inside = Ray::new(Vec3::new(x, 0.9, z), dir);
        let hit = p
            .nearest(&from_inside, 0.0, 10.0, None, &mut inside)
            .expect("the top face is met from inside");
        let want = 0.1 / dir.y;
        assert!(
            (hit.t - want).abs() < 2e-3,
            "from ({x}, 0.9, {z}) along {dir}: t {} against {want}",
            hit.t
        );
    }
    assert!(
        leaving.surfel_tests > 64 && leaving.iterations == 0,
        "leaving rays: {} leaf tests, {} MLS iterations",
        leaving.surfel_tests,
        leaving.iterations
    );
    assert!(inside.iterations >= 64);
}
