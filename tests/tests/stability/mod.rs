//! The stability suite: hard cases for every kind's intersector, each named for what it
//! covers (issue 13), and demo scenes of every kind at a viewer's size (a wrong pixel in
//! 300,000 shows on screen and in none of the 32×24 cases). Every case renders an image's depth
//! and normals (`Backend::render_surface`, the `format: "npy"` output) and asserts:
//! - no NaN or infinity in a hit's distance or normal, and a miss is exactly `[∞, 0, 0, 0]`;
//! - watertight: no pixel missed where the `f64` reference (sharing no code with the tracer)
//!   finds the surface robustly, and no hit where it finds none;
//! - the hit distance within the case's stated bound of the reference, and a robust hit's
//!   normal within the case's stated angle of the reference's (where the reference's normal
//!   has the engine's definition: not for tets, whose engine normals are smooth; and not
//!   where the ray grazes the surface within the rounding budget before it crosses it, where
//!   a hit at the graze is right and its normal another);
//! - the same bytes on a repeat and on one and two threads.
//!
//! Some cases add explicit rays (along the axes, through box faces, edges and corners).
//! `metaballs`, `tets` and `surfels` hold the cases of each kind (`surfel_demos` the surfel
//! demos at a viewer's size); a new kind is a new module
//! using [`check_image`] and [`check_rays`] with its own reference. The demos' hard shadow
//! rays are checked apart (`metaball_shadows`, `surfel_shadows` and
//! `tets::the_tet_demos_shadow_rays`): each ray as [`shadow_rays`] casts it, answered by the
//! renderer's own batch (`integrator::trace_shadows`) and by the kind's reference, which
//! says where it must be blocked and where it must pass. Cases far from the origin
//! (`scene_and_camera_1e5_from_the_origin`, `surfels_and_camera_1e5_from_the_origin`) take the
//! bounds of their twins at the origin: the prepared scene recentres in `f64`.
//!
//! Deliberately broken intersectors: `RUSTFLAGS='--cfg isoray_mutation="slab-infinities"'
//! cargo test -p isoray-tests --test root stability` builds the engine with a slab test that
//! drops its infinity handling (a ray parallel to a box face misses the box), and the named cases
//! `rays_along_axes_through_box_faces_edges_and_corners` (both kinds) fail;
//! `--cfg isoray_mutation="surfel-clip"` makes surfels ignore their clipping relations (§4.3),
//! and `sharp_clipped_corners` fails (hits on the faces' unclipped run-on past the edges,
//! outside the box), as does `the_clipped_cubes_demo_at_a_viewers_size` (2026-12-07, the same
//! early return switched on by hand: 3,358 of 76,800 pixels hit where the reference has no
//! surface, at step 0). Both at once (surfels never call the slab test; metaballs and tets never
//! clip): `RUSTFLAGS='--cfg isoray_mutation="slab-infinities" --cfg
//! isoray_mutation="surfel-clip"' cargo test -p isoray-tests --test root stability` failed
//! exactly those three cases (2026-12-02: 27 metaball rays, 60 tet rays, 63 surfel rays,
//! e.g. `(-1.2, -1.01, 4) → −z` hit at z = 0.99 beside the cube); 17 passed.

mod metaball_shadows;
mod metaballs;
mod surfel_demos;
mod surfel_shadows;
mod surfels;
mod tets;

use glam::DVec3;
use isoray_render::integrator::{ShadowQuery, T_MAX};
use isoray_render::kinds::contract::RayStart;
use isoray_render::kinds::counters::SceneCounters;
use isoray_render::ray::surface_offset;
use isoray_render::shade::{facing, Light};
use isoray_render::{Backend, Camera, PreparedScene, Ray, Scene, SurfaceBuffer, View};
use std::sync::Arc;

/// What the reference says about one ray: the first hit at the isovalue lowered and raised
/// by the case's rounding budget (`None` where the field never gets there).
#[derive(Clone, Copy, Debug)]
pub struct Answer {
    /// First `t` at `T - ε`: no correct hit lies before it.
    pub low: Option<f64>,
    /// First `t` at `T + ε`: a correct finder hits by then (when the stretch there is one it
    /// resolves; a grazing ray may miss).
    pub high: Option<f64>,
    /// Whether a finder must hit (the surface is crossed robustly, not grazed).
    pub robust: bool,
    /// The reference's unit normal there, where it is comparable (a robust hit of a kind
    /// whose engine normal has the reference's definition).
    pub normal: Option<DVec3>,
}

/// One hard case.
pub struct Case {
    pub name: &'static str,
    pub scene: Scene,
    pub camera: Camera,
    pub isovalue: f32,
    /// Largest allowed |t - t_ref| (world units) beyond the `[low, high]` band.
    pub bound: f64,
    /// Largest allowed angle (degrees) between a robust hit's normal and the reference's.
    pub normal_deg: f64,
}

/// Renders the case's depth and normals on `threads` threads.
fn surface(prepared: &PreparedScene, view: &View, threads: usize) -> SurfaceBuffer {
    Backend::cpu(threads)
        .expect("a render pool")
        .render_surface(prepared, view)
}

const SIZE: (u32, u32) = (32, 24);

/// Checks the case's image against `reference` (given the engine's own pixel ray, in `f64`).
pub fn check_image(case: &Case, reference: impl Fn(&Ray) -> Answer) {
    check_image_at(case, SIZE, reference)
}

/// [`check_image`] at `size` pixels.
pub fn check_image_at(case: &Case, size: (u32, u32), reference: impl Fn(&Ray) -> Answer) {
    let prepared = Arc::new(case.scene.clone()).prepare();
    let view = View {
        width: size.0,
        height: size.1,
        camera: case.camera,
        isovalue: case.isovalue,
    };
    let one = surface(&prepared, &view, 1);
    assert_eq!(
        one,
        surface(&prepared, &view, 1),
        "{}: repeat differs",
        case.name
    );
    assert_eq!(
        one,
        surface(&prepared, &view, 2),
        "{}: 1 vs 2 threads differ",
        case.name
    );
    // The engine's own pixel rays, in the scene's frame; the reference gets each moved back
    // to the world (exactly: the eye is an f32 near the scene, see `LocalFrame`).
    let frame = *prepared.frame();
    let rays = prepared.primary_rays(&case.camera, size.0, size.1);
    let mut failures = Vec::new();
    let (mut hits, mut worst, mut outside, mut worst_deg) = (0, 0.0f64, 0.0f64, 0.0f64);
    for y in 0..size.1 {
        for x in 0..size.0 {
            let px = one.at(x, y);
            let local = rays.through_pixel(x, y);
            let origin = frame.world_from_local(local.origin);
            assert_eq!(
                origin.as_vec3().as_dvec3(),
                origin,
                "{}: inexact move",
                case.name
            );
            let ray = Ray {
                origin: origin.as_vec3(),
                dir: local.dir,
            };
            let got = px[0].is_finite().then_some(px[0] as f64);
            let answer = reference(&ray);
            if let Some(e) = judge(case, &answer, got, px) {
                failures.push(format!("pixel ({x}, {y}) {ray:?}: {e}"));
            }
            if got.is_some() {
                hits += 1;
            }
            if let (Some(t), Some(r), true) = (got, answer.low, answer.robust) {
                worst = worst.max((t - r).abs());
                let high = answer.high.map_or(0.0, |h| t - h);
                outside = outside.max(r - t).max(high);
                if let Some(n) = answer.normal {
                    worst_deg = worst_deg.max(angle_deg(px, n));
                }
            }
        }
    }
    eprintln!(
        "{}: {hits} hits, on robust pixels worst |t - t_low| {worst:.2e} ({outside:.2e} outside [t_low, t_high]) and normal {worst_deg:.2e}°, {} failures",
        case.name,
        failures.len()
    );
    assert!(
        failures.is_empty(),
        "{}: {} failing pixels, first: {}",
        case.name,
        failures.len(),
        failures[..failures.len().min(3)].join("\n")
    );
}

/// Checks explicit rays through `first_hit` against `reference`.
pub fn check_rays(case: &Case, rays: &[Ray], reference: impl Fn(&Ray) -> Answer) {
    let prepared = Arc::new(case.scene.clone()).prepare();
    let mut failures = Vec::new();
    for ray in rays {
        let hit = prepared.first_hit(&ray.in_frame(prepared.frame()), 0.0, 1.0e4, case.isovalue);
        let px = hit.map_or([f32::INFINITY, 0.0, 0.0, 0.0], |h| {
            [h.t, h.normal.x, h.normal.y, h.normal.z]
        });
        let got = hit.map(|h| h.t as f64);
        if let Some(e) = judge(case, &reference(ray), got, px) {
            failures.push(format!("{ray:?}: {e}"));
        }
    }
    eprintln!(
        "{}: {} rays, {} failures",
        case.name,
        rays.len(),
        failures.len()
    );
    assert!(
        failures.is_empty(),
        "{}: {} failing rays, first: {}",
        case.name,
        failures.len(),
        failures[..failures.len().min(3)].join("\n")
    );
}

/// What is wrong with one answer, if anything.
fn judge(case: &Case, r: &Answer, got: Option<f64>, px: [f32; 4]) -> Option<String> {
    if px.iter().any(|v| v.is_nan()) {
        return Some(format!("NaN in {px:?}"));
    }
    match got {
        None if px[1..] != [0.0, 0.0, 0.0] => Some(format!("a miss with a normal {px:?}")),
        None if r.robust => Some(format!("missed; reference {r:?}")),
        None => None,
        Some(_) if !px[1..].iter().all(|v| v.is_finite()) => Some(format!("normal {px:?}")),
        Some(_) if ((px[1] * px[1] + px[2] * px[2] + px[3] * px[3]).sqrt() - 1.0).abs() > 1e-3 => {
            Some(format!("normal not of unit length {px:?}"))
        }
        Some(t) => match (r.low, r.high) {
            (None, _) => Some(format!("false hit at {t}; reference {r:?}")),
            (Some(lo), hi) if t < lo - case.bound || hi.is_some_and(|h| t > h + case.bound) => {
                Some(format!(
                    "hit at {t} outside the band {r:?} ± {}",
                    case.bound
                ))
            }
            _ => match r.normal {
                Some(n)
                    if r.robust
                        && matches!(
                            angle_deg(px, n).partial_cmp(&case.normal_deg),
                            None | Some(std::cmp::Ordering::Greater)
                        ) =>
                {
                    Some(format!(
                        "normal {:.3e}° from the reference's {n:?} (bound {}°)",
                        angle_deg(px, n),
                        case.normal_deg
                    ))
                }
                _ => None,
            },
        },
    }
}

/// Degrees between a pixel's normal and a reference normal.
fn angle_deg(px: [f32; 4], n: DVec3) -> f64 {
    DVec3::new(px[1] as f64, px[2] as f64, px[3] as f64)
        .normalize()
        .dot(n)
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

/// One shadow ray of an image, as the renderer casts it.
pub struct Shadow {
    pub query: ShadowQuery,
    pub pixel: (u32, u32),
    /// The cosine between the light and the (viewer-facing) normal at its start.
    pub cos: f32,
    /// Whether it starts on the floor (else on the kind's surface).
    pub on_floor: bool,
}

/// The shadow rays towards the first light of every pixel of `camera`'s `size` image whose
/// nearest hit (the kind's surface at `isovalue`, or the floor) faces that light, in the
/// scene's frame, each from the hit lifted by `surface_offset` along its viewer-facing
/// normal, over `[0, t_max]` as `integrator::visibility` casts it (a point light: to the
/// point; a sphere light: to its surface; directional: `T_MAX`).
pub fn shadow_rays(
    prepared: &PreparedScene,
    camera: &Camera,
    size: (u32, u32),
    isovalue: f32,
) -> Vec<Shadow> {
    let lighting = prepared.lighting_in_frame();
    let Some(&light) = lighting.lights.first() else {
        return Vec::new();
    };
    let rays = prepared.primary_rays(camera, size.0, size.1);
    let mut c = SceneCounters::default();
    let hits = prepared.primary_hits(&rays, (0, 0, size.0, size.1), isovalue, T_MAX, &mut c);
    let mut out = Vec::new();
    for (k, (ray, hit)) in hits.iter().enumerate() {
        let floor = (lighting.floor.as_ref())
            .map(|f| f.distance(ray))
            .filter(|&t| t > 0.0 && hit.is_none_or(|h| t < h.t));
        let (position, normal, primitive) = match (floor, hit) {
            (Some(t), _) => (ray.at(t), glam::Vec3::Y, None),
            (None, Some(h)) => (h.position, h.normal, Some(h.primitive)),
            (None, None) => continue,
        };
        let on_floor = primitive.is_none();
        // Seen from outside, the ray leaves the primitive's surface on the side it was seen
        // from, as the integrator's `RayStart::Leaving` says.
        let start = match primitive {
            Some(p) if normal.dot(ray.dir) < 0.0 => RayStart::Leaving(p),
            _ => RayStart::Unknown,
        };
        let normal = facing(normal, ray.dir);
        let Some(sample) = light.toward(position) else {
            continue;
        };
        let cos = normal.dot(sample.to_light);
        if cos <= 0.0 {
            continue;
        }
        let (t_max, towards) = match light {
            Light::Directional { .. } => (T_MAX, None),
            Light::Point { position, .. } => (sample.distance.min(T_MAX), Some(position)),
            Light::Sphere { center, radius, .. } => {
                ((sample.distance - radius).clamp(0.0, T_MAX), Some(center))
            }
        };
        let origin = position + normal * surface_offset(position);
        out.push(Shadow {
            query: ShadowQuery {
                ray: Ray {
                    origin,
                    dir: sample.to_light,
                },
                t_max,
                light: towards,
                start,
            },
            pixel: (k as u32 % size.0, k as u32 / size.0),
            cos,
            on_floor,
        });
    }
    out
}
