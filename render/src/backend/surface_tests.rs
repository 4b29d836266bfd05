//! The hit distances and normals a view's pixels see ([`CpuBackend::render_surface_effects`],
//! the render endpoint's `format: "npy"`) under a clip box, against the analytic sphere and
//! against the depths of the image the same effects give.

use super::cpu::CpuBackend;
use crate::camera::Camera;
use crate::effects::toggles::Effects;
use crate::geom::clip::ClipBox;
use crate::kinds::metaballs::kernel::Kernel;
use crate::kinds::metaballs::scene::{Metaball, MetaballScene};
use crate::scene::{Geometry, Scene};
use crate::shade::Lighting;
use crate::View;
use glam::{DVec3, Vec3};
use std::sync::Arc;

const SIZE: (u32, u32) = (48, 40);

/// One Wyvill ball of support radius 2 at the origin (a unit sphere at `T = 0.5`), its front
/// half (`z > 0`) inside the clip box, seen from `(0, 0, 5)`.
fn half_sphere() -> (Arc<Scene>, View) {
    let balls = vec![Metaball::sphere(Vec3::ZERO, 2.0, 1.0, Vec3::ONE)];
    let lighting = Lighting {
        clip_box: Some(ClipBox {
            min: Vec3::new(-3.0, -3.0, 0.0),
            max: Vec3::new(3.0, 3.0, 3.0),
        }),
        ..Lighting::default()
    };
    let scene = Scene {
        geometry: Geometry::Metaballs(MetaballScene::new(Kernel::Wyvill, balls)),
        lighting,
    };
    let view = View {
        width: SIZE.0,
        height: SIZE.1,
        camera: Camera {
            eye: Vec3::new(0.0, 0.0, 5.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            fov_y_deg: 30.0,
        },
        isovalue: 0.5,
    };
    (Arc::new(scene), view)
}

/// With the clip box on, a pixel sees the unit sphere only where its ray is inside the sphere
/// on the plane `z = 0` (every point of the sphere this camera sees in front lies at `z ≥
/// 0.2`): there it sees the sphere's back from inside, at the far root of `|e + t·d| = 1`,
/// with the outward normal there. Solved in `f64` from the camera's own rays; with the clip
/// box off the surface is the front (the near root), as without effects.
#[test]
fn a_clip_box_cuts_the_surface_a_pixel_sees() {
    let backend = CpuBackend::new(2).expect("pool");
    let (scene, view) = half_sphere();
    let prepared = scene.clone().prepare();
    let clip = Effects {
        clip_box: true,
        ..Effects::OFF
    };
    let clipped = backend.render_surface_effects(&prepared, &view, &clip);
    let whole = backend.render_surface_effects(&prepared, &view, &Effects::OFF);
    assert_eq!(
        whole.values,
        backend.render_surface(&prepared, &view).values,
        "without a clip box the surface is the primary hits'"
    );
    let rays = prepared.primary_rays(&view.camera, SIZE.0, SIZE.1);
    let (mut inside, mut outside, mut worst) = (0, 0, 0.0f64);
    for y in 0..SIZE.1 {
        for x in 0..SIZE.0 {
            let ray = rays.through_pixel(x, y);
            let (e, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3().normalize());
            let i = ((y * SIZE.0 + x) * 4) as usize;
            let (cut, full) = (&clipped.values[i..i + 4], &whole.values[i..i + 4]);
            // |e + t·d|² = 1: t² + 2 (e·d) t + |e|² - 1 = 0.
            let (b, c) = (e.dot(d), e.length_squared() - 1.0);
            let disc = b * b - c;
            let p0 = e + d * (-e.z / d.z);
            if disc > 0.0 && p0.length() < 0.995 {
                inside += 1;
                let t = -b + disc.sqrt();
                let n = (e + d * t).normalize();
                let got = DVec3::new(cut[1] as f64, cut[2] as f64, cut[3] as f64);
                worst = worst.max((cut[0] as f64 - t).abs());
                assert!(
                    (cut[0] as f64 - t).abs() < 2e-3,
                    "({x}, {y}): {cut:?}, t {t}"
                );
                assert!((got - n).length() < 1e-2, "({x}, {y}): {cut:?}, normal {n}");
                let near = -b - disc.sqrt();
                assert!((full[0] as f64 - near).abs() < 2e-3, "({x}, {y}): {full:?}");
            } else if disc < 0.0 || p0.length() > 1.005 {
                outside += 1;
                assert_eq!(cut, &[f32::INFINITY, 0.0, 0.0, 0.0], "({x}, {y})");
            }
        }
    }
    eprintln!("{inside} pixels see the back, {outside} nothing; worst |Δt| {worst:.2e}");
    assert!(inside > 200 && outside > 200, "{inside} and {outside}");
}

/// The distances under a clip box are the ones the image with the same effects is shaded at:
/// its depth along the view axis is the distance times the ray's share of that axis.
#[test]
fn a_clipped_surface_is_the_one_the_image_shows() {
    let backend = CpuBackend::new(2).expect("pool");
    let (scene, view) = half_sphere();
    let prepared = scene.prepare();
    let clip = Effects {
        clip_box: true,
        ..Effects::OFF
    };
    let surface = backend.render_surface_effects(&prepared, &view, &clip);
    let (image, _) = backend.render_effects(&prepared, &view, &clip);
    let rays = prepared.primary_rays(&view.camera, SIZE.0, SIZE.1);
    let forward = rays.forward();
    let mut hits = 0;
    for (i, &depth) in image.depth.iter().enumerate() {
        let (x, y) = (i as u32 % SIZE.0, i as u32 / SIZE.0);
        let t = surface.values[i * 4];
        let along = t * rays.through_pixel(x, y).dir.dot(forward);
        assert_eq!(
            t.is_finite(),
            depth.is_finite(),
            "({x}, {y}): {t} and {depth}"
        );
        if t.is_finite() {
            hits += 1;
            assert!(
                (along - depth).abs() <= 1e-5 * depth,
                "({x}, {y}): {along} {depth}"
            );
        }
    }
    assert!(hits > 200, "{hits} hits");
}
