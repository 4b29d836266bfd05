//! Surfel hard cases (deforming-point-sampled-surfaces.txt), against `surfels::reference`
//! (brute-force `f64` MLS over every surfel: no tree, no fixed neighbourhoods, no iteration
//! from the leaf's ellipse) where its definition is the engine's (at rest, sheets that
//! resolve), or an analytic answer in `f64` written here: the clipped cube is a box (exact
//! at the faces' planes, where a reference cut by the faces' MLS fields, as `surfel_demos`
//! cuts the clipped cubes demo, would blend along the edges), a deformed ball an ellipsoid
//! shell (under a strong stretch the
//! reference's isotropic support reaches across the squashed body and blends its two sides,
//! a difference of definitions docs/accuracy.md measures).
//!
//! Steps are affine, `x ↦ A (x − p) + p + b`: eq. 1 with every node displaced by
//! `(A − I)(x_j − p) + b` and every Jacobian `A − I` is that map exactly (the weights sum to
//! one), so the reference's deformed surfels are computed here in `f64` and share no code
//! with `deform`. Robust: a reference hit that is not grazing, not near a rim or an edge and
//! (for the MLS reference) where the normals agree must be found within the case's bound, and
//! a ray that passes the object by a margin must miss; elsewhere any answer goes, so long as
//! it is finite (and, for the cube, inside the box).

use super::{check_image, check_rays, Answer, Case};
use glam::{DMat3, DVec3, Mat3, Vec3};
use isoray_render::kinds::surfels::model::{Surfel, SurfelModel, SurfelSet};
use isoray_render::kinds::surfels::reference::{first_hit, MlsSurfel};
use isoray_render::kinds::surfels::sample;
use isoray_render::kinds::surfels::scene::{SurfelOptions, SurfelRuntime, SurfelScene, UpdateMode};
use isoray_render::scene::{Geometry, PreparedGeometry};
use isoray_render::shade::Lighting;
use isoray_render::{Camera, Ray, Scene};
use std::sync::Arc;

fn model(surfels: Vec<Surfel>, nodes: Vec<Vec3>, clip: Vec<(u16, u16)>) -> Arc<SurfelModel> {
    let set = SurfelSet {
        surfels,
        nodes,
        clip,
        ..SurfelSet::default()
    };
    Arc::new(SurfelModel::new(set, usize::MAX).expect("a valid surfel set"))
}

/// An affine step: `x ↦ a (x − pivot) + pivot + b`.
#[derive(Clone, Copy)]
struct Affine {
    a: Mat3,
    pivot: Vec3,
    b: Vec3,
}

const REST: Affine = Affine {
    a: Mat3::IDENTITY,
    pivot: Vec3::ZERO,
    b: Vec3::ZERO,
};

/// The step `m` of `model`'s nodes, as a scene (the displacements `(a − I)(x − pivot) + b`
/// are small wherever the object is: `x − pivot` is exact in `f32`).
fn scene(model: &Arc<SurfelModel>, m: Affine, mode: UpdateMode) -> Scene {
    let g = m.a - Mat3::IDENTITY;
    let u: Arc<[Vec3]> = model
        .nodes
        .iter()
        .map(|&x| g * (x - m.pivot) + m.b)
        .collect();
    let step = SurfelScene::new(
        model.clone(),
        u,
        vec![g; model.nodes.len()].into(),
        SurfelOptions::new(mode, true),
        Arc::new(SurfelRuntime::default()),
    )
    .expect("a valid step");
    Scene {
        geometry: Geometry::Surfels(step),
        lighting: Lighting::default(),
    }
}

fn look(eye: [f32; 3], target: [f32; 3]) -> Camera {
    Camera {
        eye: Vec3::from(eye),
        target: Vec3::from(target),
        up: Vec3::Y,
        fov_y_deg: 40.0,
    }
}

/// Largest singular value of the 3×2 matrix `[p q]`.
fn sigma(p: DVec3, q: DVec3) -> f64 {
    let (a, b, c) = (p.length_squared(), p.dot(q), q.length_squared());
    (0.5 * (a + c) + (0.25 * (a - c) * (a - c) + b * b).sqrt()).sqrt()
}

/// The model's surfels under `m`, in `f64`, as the reference sees them.
fn reference_surfels(model: &SurfelModel, m: Affine) -> Vec<MlsSurfel> {
    let (a, pivot, b) = (m.a.as_dmat3(), m.pivot.as_dvec3(), m.b.as_dvec3());
    (model.surfels.iter().enumerate())
        .map(|(k, s)| mls_surfel(model, k, a * (s.centre.as_dvec3() - pivot) + pivot + b, a))
        .collect()
}

/// Surfel `k` of `model` moved to `centre`, its tangent axes by the Jacobian `jac`.
pub(super) fn mls_surfel(model: &SurfelModel, k: usize, centre: DVec3, jac: DMat3) -> MlsSurfel {
    let s = &model.surfels[k];
    let (t1, t2) = (s.t1.as_dvec3(), s.t2.as_dvec3());
    let (d1, d2) = (jac * t1, jac * t2);
    let side = s.normal.as_dvec3().dot(t1.cross(t2)).signum();
    let stretch = sigma(d1, d2) / sigma(t1, t2);
    MlsSurfel {
        centre,
        normal: d1.cross(d2).normalize() * side,
        support: model.support[k] as f64 * stretch,
        reach: sigma(d1, d2) * s.radius as f64,
    }
}

/// `(enter, exit)` of the ray `o + t d` with the box `[lo, hi]`, in `f64` (written here).
fn box_span(lo: DVec3, hi: DVec3, o: DVec3, d: DVec3) -> Option<(f64, f64)> {
    let (mut near, mut far) = (0.0f64, f64::INFINITY);
    for i in 0..3 {
        if d[i] == 0.0 {
            if o[i] < lo[i] || o[i] > hi[i] {
                return None;
            }
            continue;
        }
        let (a, b) = ((lo[i] - o[i]) / d[i], (hi[i] - o[i]) / d[i]);
        near = near.max(a.min(b));
        far = far.min(a.max(b));
    }
    (near <= far).then_some((near, far))
}

/// Anything goes (no NaN and the suite's other checks still hold).
pub(super) const FREE: Answer = Answer {
    low: Some(f64::NEG_INFINITY),
    high: None,
    robust: false,
    normal: None,
};

/// How well the normals agree at `x` under the reference's weights (eq. 2, each surfel at
/// its own support): `|Σ w n| / Σ w`, 1 where they all agree, 0 where they cancel. Where it
/// is low the MLS surface itself is ill-conditioned (its normal is a near-cancellation), and
/// two definitions of the neighbourhood may place it anywhere between the sheets.
pub(super) fn coherence(surfels: &[MlsSurfel], x: DVec3) -> f64 {
    let (mut sw, mut sn) = (0.0, DVec3::ZERO);
    for s in surfels {
        let r = x.distance(s.centre) / s.support;
        if r < 1.0 {
            let w = 1.0 + r * r * (-6.0 + r * (8.0 - 3.0 * r));
            sw += w;
            sn += w * s.normal;
        }
    }
    if sw > 0.0 {
        sn.length() / sw
    } else {
        0.0
    }
}

/// A robust answer from the MLS reference: a hit where `interior` says the hit point is
/// well inside the surface's extent, the ray is not grazing and the normals there agree
/// (coherence ≥ 0.9), a miss where `passes` says the ray passes the object by a margin, else
/// [`FREE`].
fn mls_answer(
    surfels: &[MlsSurfel],
    ray: &Ray,
    interior: impl Fn(DVec3) -> bool,
    passes: impl Fn(DVec3, DVec3) -> bool,
) -> Answer {
    let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
    match first_hit(surfels, o, d, 0.0, 1e4) {
        Some(h)
            if interior(o + h.t * d)
                && h.normal.dot(d) < -0.3
                && coherence(surfels, o + h.t * d) >= 0.9 =>
        {
            let t = h.t * d.length();
            Answer {
                low: Some(t),
                high: Some(t),
                robust: true,
                normal: Some(h.normal),
            }
        }
        None if passes(o, d) => Answer {
            low: None,
            high: None,
            robust: false,
            normal: None,
        },
        Some(_) | None => FREE,
    }
}

/// A square plate of half-width `half` in the `xz` plane, `thickness` thick: a top sheet
/// (normals `+y`) and a bottom sheet (normals `−y`) of surfels `spacing` apart.
fn plate(half: f32, thickness: f32, spacing: f32) -> Vec<Surfel> {
    let n = (2.0 * half / spacing).round() as i32;
    let mut out = Vec::new();
    for (side, normal) in [(1.0f32, Vec3::Y), (-1.0, Vec3::NEG_Y)] {
        let (t1, t2) = sample::tangents(normal);
        for i in 0..=n {
            for j in 0..=n {
                out.push(Surfel {
                    centre: Vec3::new(
                        -half + i as f32 * spacing,
                        side * 0.5 * thickness,
                        -half + j as f32 * spacing,
                    ),
                    t1,
                    t2,
                    normal,
                    colour: Vec3::ONE,
                    radius: 0.8 * spacing,
                    group: 0,
                });
            }
        }
    }
    out
}

#[test]
fn near_opposite_normals_in_one_neighbourhood() {
    // Plates thinner than the MLS support: surfels' 16 nearest take in surfels of the other
    // sheet, whose normals are opposite. At 2 spacings the sheets still resolve (the other
    // sheet's weights are small); at 1.2 spacings the averaged normal nearly cancels between
    // them, the MLS surface is ill-conditioned and only finiteness, determinism and the
    // robust pixels (coherent normals) are asked for.
    for (name, thickness) in [
        ("near_opposite_normals_in_one_neighbourhood", 0.2f32),
        ("near_opposite_normals_cancelling_in_a_thin_plate", 0.12),
    ] {
        let (half, spacing) = (1.0f32, 0.1f32);
        let nodes = sample::lattice(Vec3::splat(-1.2), Vec3::splat(1.2), 0.6, |_| true);
        let m = model(plate(half, thickness, spacing), nodes, Vec::new());
        let mixed = (0..m.len())
            .filter(|&k| {
                let me = m.surfels[k].normal.y;
                (m.neighbours.row(k).iter()).any(|&n| m.surfels[n as usize].normal.y * me < 0.0)
            })
            .count();
        assert!(mixed > m.len() / 2, "{name}: {mixed} mixed neighbourhoods");
        let surfels = reference_surfels(&m, REST);
        let case = Case {
            name,
            scene: scene(&m, REST, UpdateMode::Lazy),
            camera: look([0.6, 1.8, 1.6], [0.0, 0.0, 0.0]),
            isovalue: 0.0,
            bound: 2e-2,
            normal_deg: 5.0,
        };
        let (h, rim) = (half as f64, 0.4);
        let lo = DVec3::new(-h - rim, -0.5 * thickness as f64 - rim, -h - rim);
        let interior = |p: DVec3| p.x.abs() < h - rim && p.z.abs() < h - rim;
        let passes = |o: DVec3, d: DVec3| box_span(lo, -lo, o, d).is_none();
        // Rays along the sheets' normals, through the rim and between the sheets' surfels.
        let rays: Vec<Ray> = (0..24)
            .map(|i| {
                let x = -1.15 + 0.1 * i as f32 + 0.0125;
                Ray::new(Vec3::new(x, 2.0, 0.05 * i as f32 - 0.6), Vec3::NEG_Y)
            })
            .collect();
        let answer = |ray: &Ray| mls_answer(&surfels, ray, interior, passes);
        let robust = rays.iter().filter(|r| answer(r).robust).count();
        eprintln!(
            "{name}: {mixed} of {} neighbourhoods mixed, {robust} robust rays",
            m.len()
        );
        check_rays(&case, &rays, answer);
        check_image(&case, answer);
    }
}

#[test]
fn sharp_clipped_corners() {
    // The cube [-1, 1]³ of six faces that run two spacings past the edges, cut back by the
    // clipping relations (§4.3): the analytic box is the answer. Away from the edges (4
    // spacings: the MLS neighbourhoods reach 2.3) a face is an exact plane; near them the
    // faces blend, and the hit must still lie in the box (clipping is exact to the planes).
    let per_side = 16;
    let s = 2.0 / per_side as f64;
    let (surfels, clip) = sample::cube(Vec3::ZERO, 1.0, per_side, [Vec3::ONE; 6], 0);
    let nodes = sample::lattice(Vec3::splat(-1.0), Vec3::splat(1.0), 0.5, |_| true);
    let m = model(surfels, nodes, clip);
    let case = Case {
        name: "sharp_clipped_corners",
        scene: scene(&m, REST, UpdateMode::Lazy),
        camera: look([2.6, 2.1, 3.0], [0.0, 0.0, 0.0]),
        isovalue: 0.0,
        bound: 1e-3,
        normal_deg: 0.05,
    };
    let answer = |ray: &Ray| {
        let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
        // Clipping cuts at the faces' planes; along an edge the blended faces bulge out by
        // up to 0.4 spacings (0.05). Unclipped, the faces would run on 2 spacings (0.25).
        let e = 0.1;
        let Some((enter, exit)) = box_span(DVec3::splat(-1.0 - e), DVec3::splat(1.0 + e), o, d)
        else {
            return Answer {
                low: None,
                high: None,
                robust: false,
                normal: None,
            };
        };
        let margin = 4.0 * s;
        if let Some((t, _)) = box_span(DVec3::splat(-1.0), DVec3::ONE, o, d) {
            let p = o + t * d;
            let face = (0..3).max_by(|&a, &b| p[a].abs().total_cmp(&p[b].abs()));
            let face = face.expect("three axes");
            let inner = (0..3).all(|i| i == face || p[i].abs() < 1.0 - margin);
            let mut normal = DVec3::ZERO;
            normal[face] = p[face].signum();
            if inner && normal.dot(d) < -0.2 {
                return Answer {
                    low: Some(t),
                    high: Some(t),
                    robust: true,
                    normal: Some(normal),
                };
            }
        }
        Answer {
            low: Some(enter),
            high: Some(exit),
            robust: false,
            normal: None,
        }
    };
    // Rays along the axes, just beside each face's plane (where the unclipped faces run on)
    // and along the edges.
    let mut rays = Vec::new();
    for a in [
        -1.2f32, -1.01, -1.0, -0.99, -0.5, 0.0, 0.5, 0.99, 1.0, 1.01, 1.2,
    ] {
        for b in [-1.01f32, -0.99, 0.3, 0.99, 1.0, 1.01, 1.1] {
            rays.push(Ray::new(Vec3::new(a, b, 4.0), Vec3::NEG_Z));
            rays.push(Ray::new(Vec3::new(4.0, a, b), Vec3::NEG_X));
            rays.push(Ray::new(Vec3::new(b, 4.0, a), Vec3::NEG_Y));
        }
    }
    check_rays(&case, &rays, answer);
    check_image(&case, answer);
}

/// A sphere of surfels with simulation nodes through it.
fn ball(centre: Vec3) -> Arc<SurfelModel> {
    let surfels = sample::sphere(centre, 1.0, 900, Vec3::ONE, 0);
    let nodes = sample::lattice(
        centre - Vec3::splat(1.2),
        centre + Vec3::splat(1.2),
        0.6,
        |_| true,
    );
    model(surfels, nodes, Vec::new())
}

/// The case of the ball deformed by `m`, seen from `eye` (relative to the moved centre).
fn ball_case(name: &'static str, m: Affine, eye: [f32; 3], bound: f64, normal_deg: f64) -> Case {
    let moved = m.pivot + m.b;
    let eye = Vec3::from(eye) + moved;
    Case {
        name,
        scene: scene(&ball(m.pivot), m, UpdateMode::Auto),
        camera: look(eye.to_array(), moved.to_array()),
        isovalue: 0.0,
        bound,
        normal_deg,
    }
}

/// The mode the case's step was traced in.
fn used(case: &Case) -> UpdateMode {
    let prepared = Arc::new(case.scene.clone()).prepare();
    let PreparedGeometry::Surfels(p) = prepared.geometry() else {
        unreachable!("a surfel case");
    };
    p.used
}

/// The analytic answer for the unit sphere about `m.pivot` moved by `m`, in `f64`: in rest
/// space (the ray mapped back by `m⁻¹`, which keeps its parameter `t`) a hit lies in the
/// shell `1 − inner ≤ |x| ≤ 1 + outer` (the MLS surface of a sampled sphere lies just inside
/// it; under a deformation the fixed neighbourhoods keep it between the surfels' discs).
/// Robust where the ray enters the inner sphere at a rest-space incidence cosine above 0.3;
/// a ray passing 0.3 outside the sphere must miss.
fn shell_answer(m: Affine, outer: f64, inner: f64, ray: &Ray) -> Answer {
    let inverse = m.a.as_dmat3().inverse();
    let o = inverse * (ray.origin.as_dvec3() - m.pivot.as_dvec3() - m.b.as_dvec3());
    let d = inverse * ray.dir.as_dvec3();
    let dd = d.length_squared();
    let mid = -o.dot(d) / dd;
    let miss2 = (o + mid * d).length_squared();
    let enter = |r: f64| (miss2 < r * r).then(|| mid - ((r * r - miss2) / dd).sqrt());
    if miss2.sqrt() > 1.3 {
        return Answer {
            low: None,
            high: None,
            robust: false,
            normal: None,
        };
    }
    match (enter(1.0 + outer), enter(1.0 - inner)) {
        (Some(lo), Some(hi)) if -(o + hi * d).normalize().dot(d.normalize()) > 0.3 => {
            // The ellipsoid's normal at the unit sphere's entry: m⁻ᵀ x.
            let x = o + enter(1.0).unwrap_or(hi) * d;
            Answer {
                low: Some(lo),
                high: Some(hi),
                robust: true,
                normal: Some((inverse.transpose() * x).normalize()),
            }
        }
        (lo, _) => Answer {
            low: lo.or(Some(f64::NEG_INFINITY)),
            high: None,
            robust: false,
            normal: None,
        },
    }
}

#[test]
fn extreme_deformation_falls_back_to_rebuild() {
    // Stretched 6× along one axis, squashed to 0.3 along another and turned: |G| ≈ 5.2 > 4,
    // so the rest hierarchy says nothing useful and the step must be rebuilt, and still
    // trace the deformed surface. Against the analytic shell: the brute-force reference
    // blends every surfel in an isotropic support, which under this stretch reaches across
    // the squashed body and mixes its two sides (docs/accuracy.md: a difference of
    // definitions, largest on deformed steps), so it is no reference here.
    let m = Affine {
        a: Mat3::from_rotation_z(0.5) * Mat3::from_diagonal(Vec3::new(6.0, 0.3, 1.5)),
        pivot: Vec3::ZERO,
        b: Vec3::new(0.4, -0.3, 0.2),
    };
    let case = ball_case(
        "extreme_deformation_falls_back_to_rebuild",
        m,
        [2.0, 3.0, 16.0],
        1e-3,
        // The stretched discs tilt the MLS normal off the ellipsoid's (32° measured); a
        // flipped or garbage normal is still far outside.
        45.0,
    );
    assert_eq!(used(&case), UpdateMode::Rebuild);
    check_image(&case, |ray| shell_answer(m, 0.02, 0.1, ray));
}

/// Strong, but inside what the lazy hierarchy takes (|G| ≈ 2.2 ≤ 4).
fn strong(pivot: Vec3) -> Affine {
    Affine {
        a: Mat3::from_rotation_y(0.7) * Mat3::from_diagonal(Vec3::new(2.6, 0.45, 1.2)),
        pivot,
        b: Vec3::new(0.4, -0.3, 0.2),
    }
}

#[test]
fn strong_deformation_traced_lazily() {
    // The eq. 9 spheres are loose but must still contain every deformed surfel.
    let m = strong(Vec3::ZERO);
    let case = ball_case(
        "strong_deformation_traced_lazily",
        m,
        [2.0, 3.0, 9.0],
        1e-3,
        30.0,
    );
    assert_eq!(used(&case), UpdateMode::Lazy);
    check_image(&case, |ray| shell_answer(m, 0.02, 0.1, ray));
}

#[test]
fn surfels_and_camera_1e5_from_the_origin() {
    // A ball at rest at the origin, then built 1e5 from it, against the brute-force
    // reference with one bound: traced at 1e5 in f32, every deformed centre and eq. 12's
    // weighted averages would be rounded to 0.008; the prepared scene recentres in f64.
    for (name, at) in [
        ("surfels_at_the_origin", 0.0f32),
        ("surfels_and_camera_1e5_from_the_origin", 1.0e5),
    ] {
        let m = Affine {
            pivot: Vec3::splat(at),
            ..REST
        };
        let case = ball_case(name, m, [0.8, 1.2, 3.5], 3e-3, 1.0);
        let surfels = reference_surfels(&ball(m.pivot), m);
        let pivot = m.pivot.as_dvec3();
        let passes = |o: DVec3, d: DVec3| {
            let t = (pivot - o).dot(d) / d.length_squared();
            (o + t * d).distance(pivot) > 1.3
        };
        check_image(&case, |ray| mls_answer(&surfels, ray, |_| true, passes));
    }
}
