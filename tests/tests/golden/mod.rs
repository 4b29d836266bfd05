//! Golden images: a small fixed scene per primitive kind and effect, rendered by the engine
//! and compared with a committed reference PNG in `tests/golden/`.
//!
//! The references are not the engine's output. [`reference`] renders each scene analytically
//! in `f64` (one metaball's isosurface is an exact sphere; shadows, reflections, refraction,
//! transparency, volumes, clip box and nested isosurfaces have closed forms; soft shadows and
//! occlusion a deterministic quadrature), and every run checks that the committed PNG still is
//! that analytic image (to one 8-bit step, for `powf` rounding across platforms). Then the
//! engine's image must match it within the tolerance below. On a mismatch the test writes
//! `<name>-actual.png` and `<name>-difference.png` beside the reference; setting
//! `ISORAY_BLESS_GOLDEN=1` rewrites the references from the analytic renderer (never from the
//! engine), for when the scenes themselves change on purpose. `ISORAY_GOLDEN_OUT=DIR` writes
//! every engine image to `DIR`, to compare engine changes byte for byte.
//!
//! Every primitive kind gets the same cases: metaballs (one ball: spheres) and tets (a linear
//! field on a box of tets: squares); the volume case is metaballs only (the tet paper has no
//! density to absorb). A new kind adds a [`Kind`] arm.

mod reference;

use glam::{DVec3, Vec3};
use isoray_render::effects::Effects;
use isoray_render::kinds::metaballs::{Kernel, Metaball, MetaballScene};
use isoray_render::kinds::tets::generate::{box_mesh, sample};
use isoray_render::kinds::tets::TetScene;
use isoray_render::scene::Geometry;
use isoray_render::shade::{ClipBox, Floor, Isosurface, Light, Lighting, Material, Volume};
use isoray_render::{Accumulator, Camera, CpuBackend, Scene, View};
use reference::{RefLight, RefMaterial, RefScene, RefShape};
use std::path::PathBuf;
use std::sync::Arc;

const WIDTH: u32 = 96;
const HEIGHT: u32 = 72;
const CENTER: Vec3 = Vec3::new(0.0, 1.2, 0.0);
/// Support radius 2: at `T = 1/2` the isosurface is the unit sphere.
const SUPPORT: f32 = 2.0;
const BALL_COLOR: Vec3 = Vec3::new(0.8, 0.3, 0.2);

/// Tolerances, per case. Deterministic effects differ from the analytic image only where the
/// engine's `f32` hit (root tolerance 1e-4) and the exact one fall on different sides of an
/// edge within a pixel (silhouettes, total internal reflection), and by `f32` shading rounding.
/// Measured on these scenes: at worst PSNR 38.6 dB and 0.38% of pixels more than 4 steps off
/// (metaball refraction); most cases are bit-exact. Sampled effects (soft shadows, occlusion)
/// also carry the sampling noise of their 64 passes: with the stratified points every pass
/// continues (`Sampling::Stratified`) PSNR ≥ 55.4 dB and ≤ 0.11% of pixels beyond 4 steps;
/// with independent points (before) PSNR 47.5–50.4 dB and up to 1.5% of pixels beyond 4 steps
/// (the tets' square has the widest penumbra), which the sampled tolerance now refuses.
/// The thresholds sit between those and what a wrong effect does: scaling mirror reflection
/// by 0.9 put 11% of pixels beyond 4 steps, halving the Fresnel reflectance 2.8%.
struct Tolerance {
    min_psnr_db: f64,
    /// Share of pixels whose largest channel difference exceeds `big_step` 8-bit steps.
    max_bad_share: f64,
    big_step: u8,
}

const EXACT: Tolerance = Tolerance {
    min_psnr_db: 36.0,
    max_bad_share: 0.01,
    big_step: 4,
};
const SAMPLED: Tolerance = Tolerance {
    min_psnr_db: 52.0,
    max_bad_share: 0.005,
    big_step: 4,
};

/// The primitive kinds, each with one small analytic field.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Metaballs,
    Tets,
}

/// The tet case's box (the field is `f = y` on it) and its session isovalue.
const SLAB_LO: Vec3 = Vec3::new(-1.5, 0.2, -1.5);
const SLAB_HI: Vec3 = Vec3::new(1.5, 2.2, 1.5);

impl Kind {
    fn name(self) -> &'static str {
        match self {
            Kind::Metaballs => "metaballs",
            Kind::Tets => "tets",
        }
    }

    /// The session's isovalue.
    fn isovalue(self) -> f32 {
        match self {
            Kind::Metaballs => 0.5,
            Kind::Tets => 1.2,
        }
    }

    /// A further isosurface that the first one does not hide.
    fn extra_isovalue(self) -> f32 {
        match self {
            // The outer shell around the unit sphere.
            Kind::Metaballs => 0.15,
            // A square above the first.
            Kind::Tets => 1.7,
        }
    }

    /// A clip box that exposes what the surface hides.
    fn clip_box(self) -> (Vec3, Vec3) {
        match self {
            // The upper half of the sphere.
            Kind::Metaballs => (Vec3::new(-5.0, 1.2, -5.0), Vec3::new(5.0, 5.0, 5.0)),
            // The quarter x > 0, z > 0 of the square.
            Kind::Tets => (Vec3::new(0.0, -5.0, 0.0), Vec3::new(5.0, 5.0, 5.0)),
        }
    }

    fn tet_scene() -> TetScene {
        let mesh = Arc::new(box_mesh([6, 5, 6], SLAB_LO, SLAB_HI, 0.0, 1));
        let scalars = sample(mesh.vertices(), |p| p.y);
        TetScene::new(mesh, scalars)
            .expect("a finite field")
            .with_color_range(-1.0, 2.0)
    }

    fn geometry(self) -> Geometry {
        match self {
            Kind::Metaballs => Geometry::Metaballs(MetaballScene::new(
                Kernel::Wyvill,
                vec![Metaball::sphere(CENTER, SUPPORT, 1.0, BALL_COLOR)],
            )),
            Kind::Tets => Geometry::Tets(Kind::tet_scene()),
        }
    }

    fn shape(self) -> RefShape {
        match self {
            Kind::Metaballs => RefShape::Ball {
                center: d(CENTER),
                support: SUPPORT as f64,
                color: d(BALL_COLOR),
            },
            Kind::Tets => RefShape::Slab {
                lo: d(SLAB_LO),
                hi: d(SLAB_HI),
            },
        }
    }

    /// The colour the primitive gives isosurface `isovalue` (the tets' colour map).
    fn albedo(self, isovalue: f32) -> DVec3 {
        match self {
            Kind::Metaballs => d(BALL_COLOR),
            Kind::Tets => d(Kind::tet_scene().color_of(isovalue)),
        }
    }
}

/// One golden scene: the engine's and the reference's descriptions of the same thing.
struct Case {
    kind: Kind,
    name: &'static str,
    engine: Scene,
    effects: Effects,
    passes: u32,
    reference: RefScene,
    tolerance: Tolerance,
}

fn camera() -> Camera {
    Camera {
        eye: Vec3::new(0.0, 2.6, 5.5),
        target: Vec3::new(0.0, 0.8, 0.0),
        up: Vec3::Y,
        fov_y_deg: 45.0,
    }
}

fn d(v: Vec3) -> DVec3 {
    v.as_dvec3()
}

/// The common parts: the kind's field, a floor, a background.
fn base(kind: Kind) -> (Lighting, RefScene) {
    let floor_colors = [Vec3::splat(0.7), Vec3::splat(0.25)];
    let lighting = Lighting {
        lights: Vec::new(),
        ambient: Vec3::splat(0.1),
        background_top: Vec3::new(0.3, 0.4, 0.6),
        background_bottom: Vec3::new(0.05, 0.05, 0.06),
        materials: vec![
            Material {
                specular: 0.0,
                ..Material::default()
            },
            // The floor's.
            Material {
                specular: 0.0,
                ..Material::default()
            },
        ],
        floor: Some(Floor {
            height: 0.0,
            material: 1,
            colors: floor_colors,
            checker: 0.75,
        }),
        ..Lighting::default()
    };
    let reference = RefScene {
        shape: kind.shape(),
        surfaces: vec![(
            kind.isovalue() as f64,
            RefMaterial::default(),
            kind.albedo(kind.isovalue()),
        )],
        radii: Vec::new(),
        floor_height: 0.0,
        floor_colors: floor_colors.map(d),
        checker: 0.75,
        floor_material: RefMaterial::default(),
        pixel_spread: 2.0 * (camera().fov_y_deg as f64 * 0.5).to_radians().tan() / HEIGHT as f64,
        lights: Vec::new(),
        ambient: DVec3::splat(0.1),
        background: [d(lighting.background_bottom), d(lighting.background_top)],
        clip: None,
        volume: None,
        occlusion_distance: 1.0,
        shadows: false,
        soft: false,
        ao: false,
        reflection_depth: 0,
        refraction_depth: 0,
        layers: 0,
    };
    (lighting, reference)
}

fn scene_of(kind: Kind, lighting: Lighting) -> Scene {
    Scene {
        geometry: kind.geometry(),
        lighting,
    }
}

fn sun() -> (Light, RefLight) {
    let to_light = Vec3::new(0.6, 1.0, 0.3).normalize();
    let color = Vec3::splat(0.9);
    (
        Light::Directional { to_light, color },
        RefLight::Directional {
            to_light: d(to_light),
            color: d(color),
        },
    )
}

fn ref_material(m: &Material) -> RefMaterial {
    RefMaterial {
        diffuse: d(m.diffuse),
        specular: m.specular as f64,
        shininess: m.shininess as f64,
        reflectivity: m.reflectivity as f64,
        ior: m.ior as f64,
        opacity: m.opacity as f64,
    }
}

fn cases() -> Vec<Case> {
    let mut out = Vec::new();
    for kind in [Kind::Metaballs, Kind::Tets] {
        out.extend(kind_cases(kind));
        out.extend(more_cases(kind));
    }
    out
}

fn kind_cases(kind: Kind) -> Vec<Case> {
    let mut out = Vec::new();
    let effects = Effects::OFF;

    // Hard shadow of the sphere on the floor, with a specular lobe on the sphere.
    {
        let (mut l, mut r) = base(kind);
        let (sun, ref_sun) = sun();
        l.lights.push(sun);
        r.lights.push(ref_sun);
        l.materials[0] = Material {
            specular: 0.4,
            shininess: 24.0,
            ..Material::default()
        };
        l.floor.as_mut().expect("floor").checker = 0.0;
        r.checker = 0.0;
        r.surfaces[0].1 = ref_material(&l.materials[0]);
        r.shadows = true;
        out.push(Case {
            kind,
            name: "shadows",
            engine: scene_of(kind, l),
            effects: Effects {
                shadows: true,
                ..effects
            },
            passes: 1,
            reference: r,
            tolerance: EXACT,
        });
    }

    // Soft shadow from a sphere area light.
    {
        let (mut l, mut r) = base(kind);
        let (center, radius, color) = (Vec3::new(2.0, 4.0, 1.0), 0.8f32, Vec3::splat(18.0));
        l.lights.push(Light::Sphere {
            center,
            radius,
            color,
        });
        r.lights.push(RefLight::Sphere {
            center: d(center),
            radius: radius as f64,
            color: d(color),
        });
        l.floor.as_mut().expect("floor").checker = 0.0;
        r.checker = 0.0;
        r.shadows = true;
        r.soft = true;
        out.push(Case {
            kind,
            name: "soft-shadows",
            engine: scene_of(kind, l),
            effects: Effects {
                shadows: true,
                soft_shadows: true,
                light_samples: 4,
                ..effects
            },
            passes: 64,
            reference: r,
            tolerance: SAMPLED,
        });
    }

    // A mirror sphere reflecting the checkered floor, one bounce.
    {
        let (mut l, mut r) = base(kind);
        let (sun, ref_sun) = sun();
        l.lights.push(sun);
        r.lights.push(ref_sun);
        l.materials[0].reflectivity = 0.7;
        r.surfaces[0].1 = ref_material(&l.materials[0]);
        r.reflection_depth = 1;
        out.push(Case {
            kind,
            name: "reflections",
            engine: scene_of(kind, l),
            effects: Effects {
                reflections: true,
                depth: 1,
                ..effects
            },
            passes: 1,
            reference: r,
            tolerance: EXACT,
        });
    }

    // A glass sphere: Fresnel-weighted reflection and refraction, three bounces.
    {
        let (mut l, mut r) = base(kind);
        let (sun, ref_sun) = sun();
        l.lights.push(sun);
        r.lights.push(ref_sun);
        l.materials[0].opacity = 0.0;
        l.materials[0].ior = 1.5;
        r.surfaces[0].1 = ref_material(&l.materials[0]);
        r.reflection_depth = 0;
        r.refraction_depth = 3;
        r.layers = 0;
        out.push(Case {
            kind,
            name: "refraction",
            engine: scene_of(kind, l),
            effects: Effects {
                transparency: true,
                refraction: true,
                depth: 3,
                layers: 0,
                ..effects
            },
            passes: 1,
            reference: r,
            tolerance: EXACT,
        });
    }
    out
}

fn more_cases(kind: Kind) -> Vec<Case> {
    let mut out = Vec::new();
    let effects = Effects::OFF;

    // Ambient occlusion only: the sphere just above the floor darkens it.
    {
        let (mut l, mut r) = base(kind);
        l.ambient = Vec3::splat(0.8);
        r.ambient = DVec3::splat(0.8);
        l.occlusion_distance = 1.5;
        r.occlusion_distance = 1.5;
        r.ao = true;
        out.push(Case {
            kind,
            name: "occlusion",
            engine: scene_of(kind, l),
            effects: Effects {
                ambient_occlusion: true,
                ao_samples: 8,
                ..effects
            },
            passes: 64,
            reference: r,
            tolerance: SAMPLED,
        });
    }

    // A half-transparent sphere (IOR 1): front and back faces peeled, the floor behind.
    {
        let (mut l, mut r) = base(kind);
        let (sun, ref_sun) = sun();
        l.lights.push(sun);
        r.lights.push(ref_sun);
        l.materials[0].opacity = 0.4;
        r.surfaces[0].1 = ref_material(&l.materials[0]);
        r.layers = 2;
        out.push(Case {
            kind,
            name: "transparency",
            engine: scene_of(kind, l),
            effects: Effects {
                transparency: true,
                layers: 2,
                ..effects
            },
            passes: 1,
            reference: r,
            tolerance: EXACT,
        });
    }

    // The field as an absorbing volume (metaballs only: tets have no density).
    if kind == Kind::Metaballs {
        let (mut l, mut r) = base(kind);
        let (sun, ref_sun) = sun();
        l.lights.push(sun);
        r.lights.push(ref_sun);
        let (density, color) = (0.9f32, Vec3::new(0.9, 0.9, 1.0));
        l.volume = Some(Volume { density, color });
        r.volume = Some((density as f64, d(color)));
        out.push(Case {
            kind,
            name: "volume",
            engine: scene_of(kind, l),
            effects: Effects {
                transparency: true,
                ..effects
            },
            passes: 1,
            reference: r,
            tolerance: EXACT,
        });
    }

    // The upper half cut away: the inside of the lower half, lit and shadowed through the cut.
    {
        let (mut l, mut r) = base(kind);
        let (sun, ref_sun) = sun();
        l.lights.push(sun);
        r.lights.push(ref_sun);
        let (min, max) = kind.clip_box();
        l.clip_box = Some(ClipBox { min, max });
        r.clip = Some((d(min), d(max)));
        r.shadows = true;
        out.push(Case {
            kind,
            name: "clip-box",
            engine: scene_of(kind, l),
            effects: Effects {
                clip_box: true,
                shadows: true,
                ..effects
            },
            passes: 1,
            reference: r,
            tolerance: EXACT,
        });
    }

    // Two isosurfaces: a translucent outer shell (T = 0.15) around the opaque sphere.
    {
        let (mut l, mut r) = base(kind);
        let (sun, ref_sun) = sun();
        l.lights.push(sun);
        r.lights.push(ref_sun);
        let shell = Material {
            diffuse: Vec3::new(0.4, 0.6, 1.0),
            opacity: 0.35,
            specular: 0.0,
            ..Material::default()
        };
        l.materials.push(shell);
        let extra = kind.extra_isovalue();
        l.isosurfaces.push(Isosurface {
            isovalue: extra,
            material: 2,
            color: None,
        });
        r.surfaces
            .push((extra as f64, ref_material(&shell), kind.albedo(extra)));
        r.layers = 3;
        out.push(Case {
            kind,
            name: "isosurfaces",
            engine: scene_of(kind, l),
            effects: Effects {
                isosurfaces: true,
                transparency: true,
                layers: 3,
                ..effects
            },
            passes: 1,
            reference: r,
            tolerance: EXACT,
        });
    }
    out
}

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("golden")
}

fn reference_image(r: &RefScene) -> image::RgbImage {
    let mut r = r.clone();
    r.solve();
    let cam = camera();
    image::RgbImage::from_fn(WIDTH, HEIGHT, |x, y| {
        let dir = reference::camera_ray(
            d(cam.eye),
            d(cam.target),
            d(cam.up),
            cam.fov_y_deg as f64,
            (WIDTH, HEIGHT),
            (x, y),
        );
        let c = r.radiance(d(cam.eye), dir, 0.0, 0, r.layers);
        image::Rgb([
            reference::srgb8(c.x),
            reference::srgb8(c.y),
            reference::srgb8(c.z),
        ])
    })
}

fn engine_image(backend: &CpuBackend, case: &Case) -> image::RgbImage {
    let scene = Arc::new(case.engine.clone()).prepare();
    let view = View {
        width: WIDTH,
        height: HEIGHT,
        camera: camera(),
        isovalue: case.kind.isovalue(),
    };
    let mut acc = Accumulator::new(case.passes);
    // Force every pass: the comparison is at a fixed sample count.
    acc.threshold = 0.0;
    let fb = backend.refine_until_converged(&scene, &view, &case.effects, &mut acc);
    assert_eq!(acc.passes(), case.passes, "{}", case.name);
    image::RgbImage::from_raw(fb.width, fb.height, fb.rgb).expect("frame size")
}

struct Diff {
    psnr_db: f64,
    bad_share: f64,
    max_step: u8,
}

fn compare(a: &image::RgbImage, b: &image::RgbImage, big_step: u8) -> Diff {
    let mut sq = 0.0f64;
    let mut bad = 0usize;
    let mut max_step = 0u8;
    for (pa, pb) in a.pixels().zip(b.pixels()) {
        let mut worst = 0u8;
        for c in 0..3 {
            let diff = pa[c].abs_diff(pb[c]);
            sq += (diff as f64).powi(2);
            worst = worst.max(diff);
        }
        max_step = max_step.max(worst);
        bad += (worst > big_step) as usize;
    }
    let mse = sq / (3 * a.pixels().len()) as f64;
    Diff {
        psnr_db: if mse == 0.0 {
            f64::INFINITY
        } else {
            10.0 * (255.0f64 * 255.0 / mse).log10()
        },
        bad_share: bad as f64 / a.pixels().len() as f64,
        max_step,
    }
}

fn difference_image(a: &image::RgbImage, b: &image::RgbImage) -> image::RgbImage {
    image::RgbImage::from_fn(a.width(), a.height(), |x, y| {
        let (pa, pb) = (a.get_pixel(x, y), b.get_pixel(x, y));
        let m = (0..3).map(|c| pa[c].abs_diff(pb[c])).max().unwrap_or(0);
        image::Rgb([m.saturating_mul(4), 0, 0])
    })
}

#[test]
fn effects_match_their_analytic_references_for_every_primitive_kind() {
    let bless = std::env::var_os("ISORAY_BLESS_GOLDEN").is_some_and(|v| v == "1");
    let backend = CpuBackend::new(2).expect("pool");
    let mut failures = Vec::new();
    for case in cases() {
        let path = dir().join(format!("{}-{}.png", case.kind.name(), case.name));
        let analytic = reference_image(&case.reference);
        if bless {
            analytic.save(&path).expect("write the reference");
        }
        let committed = image::open(&path)
            .unwrap_or_else(|e| panic!("{}: {e} (ISORAY_BLESS_GOLDEN=1 writes it)", path.display()))
            .to_rgb8();
        let stale = compare(&committed, &analytic, 1);
        assert!(
            stale.max_step <= 1,
            "{} is not the analytic reference any more (max step {}); rerun with \
             ISORAY_BLESS_GOLDEN=1 if the scene changed on purpose",
            path.display(),
            stale.max_step
        );
        let actual = engine_image(&backend, &case);
        if let Some(out) = std::env::var_os("ISORAY_GOLDEN_OUT") {
            // Every engine image, for byte-for-byte comparisons across engine changes.
            let name = format!("{}-{}.png", case.kind.name(), case.name);
            actual
                .save(PathBuf::from(out).join(name))
                .expect("write the engine image");
        }
        let diff = compare(&actual, &committed, case.tolerance.big_step);
        eprintln!(
            "golden {:<9} {:<14} PSNR {:>6.2} dB, {:.3}% of pixels beyond {} steps, max step {}",
            case.kind.name(),
            case.name,
            diff.psnr_db,
            100.0 * diff.bad_share,
            case.tolerance.big_step,
            diff.max_step
        );
        if diff.psnr_db < case.tolerance.min_psnr_db
            || diff.bad_share > case.tolerance.max_bad_share
        {
            let stem = path.with_extension("");
            actual
                .save(format!("{}-actual.png", stem.display()))
                .expect("write actual");
            difference_image(&actual, &committed)
                .save(format!("{}-difference.png", stem.display()))
                .expect("write difference");
            failures.push(format!(
                "{} {}: PSNR {:.2} dB (min {}), {:.3}% bad pixels (max {}%)",
                case.kind.name(),
                case.name,
                diff.psnr_db,
                case.tolerance.min_psnr_db,
                100.0 * diff.bad_share,
                100.0 * case.tolerance.max_bad_share
            ));
        }
    }
    assert!(failures.is_empty(), "golden images differ: {failures:#?}");
}

/// The analytic shadow extent itself: along the floor line below the sphere, away from the
/// sun, the shadow ends where the ray towards the sun grazes the unit sphere. The engine's
/// image must switch from shadow to light within one pixel of that point.
#[test]
fn hard_shadow_ends_where_the_analytic_shadow_ends() {
    let backend = CpuBackend::new(2).expect("pool");
    let case = kind_cases(Kind::Metaballs)
        .into_iter()
        .find(|c| c.name == "shadows")
        .expect("shadow case");
    let image = engine_image(&backend, &case);
    // The floor point (x, 0, z) is shadowed iff the line to the sun passes within 1 of the
    // centre: |(p - c) × s|² < 1 with (p - c)·s > 0.
    let sun = Vec3::new(0.6, 1.0, 0.3).normalize().as_dvec3();
    let shadowed = |p: DVec3| {
        let v = p - d(CENTER);
        v.dot(sun) < 0.0 && v.cross(sun).length_squared() < 1.0
    };
    let cam = camera();
    let mut checked = 0;
    for y in 0..HEIGHT {
        for x in 0..WIDTH {
            let dir = reference::camera_ray(
                d(cam.eye),
                d(cam.target),
                d(cam.up),
                cam.fov_y_deg as f64,
                (WIDTH, HEIGHT),
                (x, y),
            );
            let o = d(cam.eye);
            // Floor pixels not covered by the sphere, away from the shadow edge by > 1 px.
            let t = -o.y / dir.y;
            if t.is_nan() || t <= 0.0 {
                continue;
            }
            let oc = o - d(CENTER);
            let b = oc.dot(dir);
            if b * b - (oc.length_squared() - 1.0) > -0.05 {
                continue;
            }
            let p = o + t * dir;
            let px = 0.15; // about two pixels' footprint on the floor near the sphere
            let neighbours = [
                DVec3::new(px, 0.0, 0.0),
                DVec3::new(-px, 0.0, 0.0),
                DVec3::new(0.0, 0.0, px),
                DVec3::new(0.0, 0.0, -px),
            ];
            let here = shadowed(p);
            if neighbours.iter().any(|&n| shadowed(p + n) != here) {
                continue;
            }
            // Lit floor: ambient 0.1·0.7 plus the sun's 0.9·0.7·cos; shadowed: ambient only.
            let lum = image.get_pixel(x, y)[0];
            let ambient_only = reference::srgb8(0.1 * 0.7);
            if here {
                assert!(
                    lum <= ambient_only + 2,
                    "({x},{y}) should be in shadow: {lum}"
                );
            } else {
                assert!(lum > ambient_only + 40, "({x},{y}) should be lit: {lum}");
            }
            checked += here as usize;
        }
    }
    assert!(checked > 50, "{checked} shadowed floor pixels checked");
}
