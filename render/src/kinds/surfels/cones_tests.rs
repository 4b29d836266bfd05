//! Tests of the normal cones ([`super::cones`]): every deformed normal below a node lies in
//! its cone for the step, and shadow rays from outside are blocked exactly where they are
//! without the cones.

use super::tests::prepare;
use crate::geom::rng::SplitMix64;
use crate::kinds::contract::{PreparedKind, RayStart};
use crate::kinds::surfels::counters::SurfelCounters;
use crate::kinds::surfels::deform::deform_surfel;
use crate::kinds::surfels::demo::{self, SurfelDemoKind};
use crate::kinds::surfels::prepared::PreparedSurfels;
use crate::kinds::surfels::scene::{SurfelOptions, SurfelRuntime, UpdateMode};
use crate::ray::Ray;
use glam::{Mat3, Vec3};
use std::sync::Arc;

/// Shadow rays from the camera's hits seen from outside, towards `light`: `(rays, t_max,
/// the surfel each leaves)`.
fn shadow_rays_from_outside(
    p: &PreparedSurfels,
    camera: &crate::camera::Camera,
    (w, h): (u32, u32),
    light: Vec3,
) -> (Vec<Ray>, Vec<f32>, Vec<RayStart>) {
    let rays = camera.rays(w, h);
    let mut c = SurfelCounters::default();
    let (mut shadow, mut t_max, mut starts) = (Vec::new(), Vec::new(), Vec::new());
    for (ray, hit) in p.primary_tile(&rays, (0, 0, w, h), 0.0, 1e4, &mut c) {
        let Some(hit) = hit else { continue };
        let to = light - hit.position;
        let dir = to.normalize();
        if hit.normal.dot(ray.dir) < 0.0 && hit.normal.dot(dir) > 0.0 {
            let origin = hit.position + hit.normal * crate::ray::surface_offset(hit.position);
            shadow.push(Ray::new(origin, dir));
            t_max.push((light - origin).length());
            starts.push(RayStart::Leaving(hit.primitive));
        }
    }
    (shadow, t_max, starts)
}

/// Under random steps (each body turned anywhere, each node's Jacobian off its body's
/// rotation by up to 0.45 in norm), every surfel's deformed normal lies within the step's
/// cone of every node above a leaf whose neighbourhood holds it: the bound the cull relies
/// on. Fails with the widening left out (checked).
#[test]
fn every_deformed_normal_lies_in_the_cones_above_it() {
    let mut rng = SplitMix64(17);
    let mut checked = 0usize;
    for kind in SurfelDemoKind::ALL {
        let demo = demo::build(kind, 0.03, 1).expect("demo");
        let model = &demo.model;
        let tree = &model.tree;
        let mut parent = vec![u32::MAX; tree.nodes.len()];
        for (k, node) in tree.nodes.iter().enumerate() {
            if !node.is_leaf() {
                for c in node.kids {
                    parent[c as usize] = k as u32;
                }
            }
        }
        for round in 0..6 {
            let scale = 0.45 * round as f32 / 5.0;
            let turn: Vec<Mat3> = (0..model.bodies)
                .map(|_| {
                    let axis = rng.in_unit_ball().normalize_or(Vec3::X);
                    Mat3::from_axis_angle(axis, rng.range(-3.0, 3.0))
                })
                .collect();
            // Nodes moved with their body's turn (and a shift), so that its rigid frame turns too.
            let shift: Vec<Vec3> = (0..model.bodies).map(|_| rng.in_unit_ball()).collect();
            let u: Vec<Vec3> = (model.nodes.iter().zip(&model.node_body))
                .map(|(&x, &b)| {
                    let b = b as usize;
                    turn[b] * x + shift[b] - x + 0.05 * scale * rng.in_unit_ball()
                })
                .collect();
            let g: Vec<Mat3> = (model.node_body.iter())
                .map(|&b| {
                    let noise =
                        Mat3::from_cols(rng.in_unit_ball(), rng.in_unit_ball(), rng.in_unit_ball());
                    // Frobenius norm of the noise below `scale`: each column within a unit
                    // ball, so the whole within √3 of it.
                    (Mat3::IDENTITY + noise * (scale / 3f32.sqrt())) * turn[b as usize]
                        - Mat3::IDENTITY
                })
                .collect();
            let scene = demo.scene(0, Default::default(), Arc::new(SurfelRuntime::default()));
            let scene = crate::kinds::surfels::scene::SurfelScene {
                displacement: u.clone().into(),
                gradient: g.clone().into(),
                options: SurfelOptions::new(UpdateMode::Lazy, false),
                ..scene
            };
            let p = PreparedSurfels::new(scene);
            for (k, node) in tree.nodes.iter().enumerate() {
                if !node.is_leaf() {
                    continue;
                }
                for &s in model.neighbours.row(node.kids[1] as usize) {
                    let n = deform_surfel(model, &u, &g, s as usize).normal;
                    let mut at = k as u32;
                    while at != u32::MAX {
                        if let Some((axis, sin, _)) = p.cone(at) {
                            let cos = (1.0 - sin * sin).max(0.0).sqrt();
                            assert!(
                                n.dot(axis) >= cos - 1e-5,
                                "{kind:?} round {round}: surfel {s} under node {at}: {} < {cos}",
                                n.dot(axis)
                            );
                            checked += 1;
                        }
                        at = parent[at as usize];
                    }
                }
            }
        }
    }
    assert!(
        checked > 100_000,
        "only {checked} normals checked against a cone"
    );
}

/// A shadow ray from outside a closed object finds a hit with the cones exactly where it
/// finds one without them (on the demos' strike, landing and bouncing frames at 160×120, all
/// but at most one ray a frame, where the MLS search misses the front of a body a ray
/// grazes and the cull passes over the back it would have found instead), and the cones save
/// most of the tests on the impact and the cubes.
#[test]
fn shadow_rays_from_outside_are_blocked_as_without_the_cones() {
    for (kind, steps, saves) in [
        (SurfelDemoKind::Impact, [6, 12, 40], 0.4),
        (SurfelDemoKind::Balls, [18, 30, 80], 0.0),
        (SurfelDemoKind::Heads, [60, 90, 150], 0.4),
    ] {
        let demo = demo::build(kind, 0.3, 151).expect("demo");
        let (mut a, mut b) = (SurfelCounters::default(), SurfelCounters::default());
        let mut rays_in_all = 0;
        for step in steps {
            let rt = Arc::new(SurfelRuntime::default());
            let p = prepare(&demo, step, UpdateMode::Lazy, false, &rt);
            let light = demo.camera.eye + Vec3::new(3.0, 9.0, 2.0);
            let (rays, t_max, starts) =
                shadow_rays_from_outside(&p, &demo.camera, (160, 120), light);
            let mut differ = 0;
            for ((ray, &hi), &start) in rays.iter().zip(&t_max).zip(&starts) {
                let every = p.any_hit(ray, 0.0, hi, 0.0, &mut a).is_some();
                let cut = p.any_hit_from(ray, (0.0, hi), start, &mut b).is_some();
                differ += (every != cut) as usize;
            }
            assert!(differ <= 1, "{kind:?} step {step}: {differ} rays differ");
            rays_in_all += rays.len();
        }
        assert!(rays_in_all > 1000, "{kind:?}: {rays_in_all} rays");
        let saved = 1.0 - b.any_tests as f64 / a.any_tests as f64;
        assert!(
            saved >= saves,
            "{kind:?}: the cones saved {saved:.3} of the tests"
        );
    }
}
