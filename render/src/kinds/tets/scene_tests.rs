//! Whole-engine tests of tet scenes: analytic fields with known surfaces, agreement with the
//! `f64` reference, and every build, time scheme and traversal giving the same image.

use crate::camera::Camera;
use crate::geom::clip::ClipBox;
use crate::geom::rng::SplitMix64;
use crate::kinds::tets::bvh::BuildKind;
use crate::kinds::tets::counters::TetCounters;
use crate::kinds::tets::generate::{box_mesh, sample};
use crate::kinds::tets::mesh::{TetMesh, TetScene};
use crate::kinds::tets::packet::{PacketScratch, RayPacket};
use crate::kinds::tets::prepared::{Normals, PreparedTets, TetOptions, TimeScheme};
use crate::kinds::tets::reference::{barycentric_min, reference_hit};
use crate::kinds::tets::traverse::{TetHit, TetQuery};
use crate::ray::Ray;
use glam::{DVec3, Vec3};
use std::sync::Arc;

/// `f = |x|` sampled on a jittered Kuhn grid over `[-1, 1]³`: isosurfaces are spheres.
fn radial_mesh(cells: usize) -> (Arc<TetMesh>, Arc<[f32]>) {
    let mesh = Arc::new(box_mesh(
        [cells; 3],
        Vec3::splat(-1.0),
        Vec3::splat(1.0),
        0.15,
        42,
    ));
    let scalars = sample(mesh.vertices(), |p| p.length());
    (mesh, scalars)
}

fn prepared(scene: &TetScene, options: TetOptions) -> PreparedTets {
    PreparedTets::new(scene.clone(), options)
}

fn all_options() -> Vec<TetOptions> {
    let mut out = Vec::new();
    for build in BuildKind::ALL {
        for time in [TimeScheme::Rebuild, TimeScheme::Refit] {
            out.push(TetOptions {
                build,
                time,
                normals: Normals::Faceted,
            });
        }
    }
    out
}

/// The hit of every pixel of a `w × h` image, single rays.
fn hits_single(
    p: &PreparedTets,
    camera: &Camera,
    w: u32,
    h: u32,
    q: &TetQuery,
) -> Vec<Option<TetHit>> {
    let rays = camera.rays(w, h);
    let mut c = TetCounters::default();
    let mut out = Vec::new();
    for y in 0..h {
        for x in 0..w {
            out.push(p.first_hit(&rays.through_pixel(x, y), 0.0, 1e4, q, &mut c));
        }
    }
    out
}

/// The same image traced in `tile × tile` packets.
fn hits_packets(
    p: &PreparedTets,
    camera: &Camera,
    (w, h): (u32, u32),
    tile: u32,
    q: &TetQuery,
    c: &mut TetCounters,
) -> Vec<Option<TetHit>> {
    let rays = camera.rays(w, h);
    let mut out = vec![None; (w * h) as usize];
    let mut scratch = PacketScratch::default();
    let mut dirs = Vec::new();
    let mut hits = Vec::new();
    for y0 in (0..h).step_by(tile as usize) {
        for x0 in (0..w).step_by(tile as usize) {
            let (x1, y1) = ((x0 + tile).min(w), (y0 + tile).min(h));
            let packet = RayPacket::tile(&rays, (x0, y0, x1, y1), &mut dirs);
            hits.resize(packet.dirs.len(), None);
            p.first_hits_packet(&packet, 0.0, 1e4, q, &mut scratch, &mut hits, c);
            let mut k = 0;
            for y in y0..y1 {
                for x in x0..x1 {
                    out[(y * w + x) as usize] = hits[k];
                    k += 1;
                }
            }
        }
    }
    out
}

fn camera() -> Camera {
    Camera {
        eye: Vec3::new(0.4, 0.7, 3.2),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 40.0,
    }
}

#[test]
fn spheres_of_a_radial_field_within_the_interpolation_bound() {
    // f = |x| is convex with Hessian norm 1/|x|. For p in a tet with barycentric weights λ,
    // the linear interpolant I f satisfies 0 ≤ I f(p) − f(p) ≤ ½ Σ λ_i |v_i − p|² / r_min
    // (Taylor about p; Σ λ_i (v_i − p) = 0), r_min the least |x| over the tet. At a hit
    // I f(p) = R, so R − δ ≤ |p| ≤ R with δ = ½ Σ λ_i |v_i − p|² / r_min, checked per hit in
    // f64, with 2·10⁻⁶ of slack for the f32 arithmetic. Rays through the ball of radius
    // R − δ_max must hit (the discrete surface encloses it), rays outside radius R miss.
    let (mesh, scalars) = radial_mesh(20);
    let radius = 0.7f32;
    let scene = TetScene::new(mesh.clone(), scalars).expect("valid");
    let eye = Vec3::new(0.0, 0.0, 3.0);
    let mut delta_max = 0.0f64;
    let mut hits = 0;
    for options in all_options() {
        let p = prepared(&scene, options);
        let q = TetQuery::single(radius);
        let mut c = TetCounters::default();
        for i in 0..41 {
            for j in 0..41 {
                let target = Vec3::new(-1.0 + i as f32 * 0.05, -1.0 + j as f32 * 0.05, 0.0);
                let ray = Ray::new(eye, target - eye);
                let miss_distance = ray.origin.cross(ray.dir).length() as f64;
                match p.first_hit(&ray, 0.0, 100.0, &q, &mut c) {
                    Some(hit) => {
                        hits += 1;
                        let ids = mesh.tets()[hit.tet as usize];
                        let v = ids.map(|k| mesh.vertices()[k as usize].as_dvec3());
                        let h = ray.at(hit.t).as_dvec3();
                        assert!(barycentric_min(v, h) > -1e-4, "the hit lies in its tet");
                        let bary = barycentric(v, h);
                        let spread: f64 =
                            (0..4).map(|k| bary[k] * (v[k] - h).length_squared()).sum();
                        let diameter = (0..4)
                            .flat_map(|a| (0..4).map(move |b| (a, b)))
                            .map(|(a, b)| (v[a] - v[b]).length())
                            .fold(0.0, f64::max);
                        let r_min = (h.length() - diameter).max(1e-3);
                        let delta = 0.5 * spread / r_min;
                        delta_max = delta_max.max(delta);
                        let r = h.length();
                        let r0 = radius as f64;
                        assert!(
                            r <= r0 + 2e-6 && r >= r0 - delta - 2e-6,
                            "|p| = {r}, bound [{}, {r0}] ({options:?})",
                            r0 - delta
                        );
                    }
                    None => assert!(
                        miss_distance > radius as f64 - 0.05,
                        "a ray {miss_distance} from the centre missed ({options:?})"
                    ),
                }
            }
        }
    }
    assert!(hits > 1000, "{hits} hits checked");
    assert!(
        delta_max < 0.05,
        "the bound is informative: δ_max = {delta_max}"
    );
    // Now the must-hit side with the bound measured over the mesh.
    let p = prepared(&scene, TetOptions::default());
    let q = TetQuery::single(radius);
    let mut c = TetCounters::default();
    let mut rng = SplitMix64(1);
    for _ in 0..2000 {
        let target = rng.in_unit_ball() * (radius - delta_max as f32 - 1e-3);
        let ray = Ray::new(eye, target - eye);
        assert!(
            p.first_hit(&ray, 0.0, 100.0, &q, &mut c).is_some(),
            "{target}"
        );
        let outside = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), 0.0);
        let ray = Ray::new(eye, outside - eye);
        if ray.origin.cross(ray.dir).length() > radius + 1e-4 {
            assert!(p.first_hit(&ray, 0.0, 100.0, &q, &mut c).is_none());
        }
    }
}

fn barycentric(v: [DVec3; 4], h: DVec3) -> [f64; 4] {
    let vol = |a: DVec3, b: DVec3, c: DVec3, d: DVec3| (b - a).cross(c - a).dot(d - a);
    let total = vol(v[0], v[1], v[2], v[3]);
    [
        vol(h, v[1], v[2], v[3]) / total,
        vol(v[0], h, v[2], v[3]) / total,
        vol(v[0], v[1], h, v[3]) / total,
        vol(v[0], v[1], v[2], h) / total,
    ]
}

#[test]
fn hits_agree_with_the_f64_reference() {
    let mesh = Arc::new(box_mesh(
        [7, 6, 5],
        Vec3::splat(-1.0),
        Vec3::splat(1.0),
        0.25,
        5,
    ));
    let scalars = sample(mesh.vertices(), |p| {
        (3.0 * p.x).sin() * (2.0 * p.y).cos() + 0.5 * p.z * p.z - 0.3 * p.x * p.y
    });
    let scene = TetScene::new(mesh.clone(), scalars.clone()).expect("valid");
    let p = prepared(&scene, TetOptions::default());
    let mut rng = SplitMix64(99);
    let mut c = TetCounters::default();
    let (mut both, mut neither) = (0, 0);
    for _ in 0..3000 {
        let iso = rng.range(-0.8, 0.8);
        let eye = rng.in_unit_ball().normalize_or(Vec3::Z) * 3.0;
        let target = rng.in_unit_ball();
        let ray = Ray::new(eye, target - eye);
        let got = p.first_hit(&ray, 0.0, 100.0, &TetQuery::single(iso), &mut c);
        let want = reference_hit(
            mesh.vertices(),
            &scalars,
            mesh.tets(),
            eye.as_dvec3(),
            ray.dir.as_dvec3(),
            0.0,
            100.0,
            iso as f64,
        );
        match (got, want) {
            (Some(g), Some((t, _))) => {
                both += 1;
                assert!((g.t as f64 - t).abs() < 2e-5, "t {} vs {t}", g.t);
            }
            (None, None) => neither += 1,
            (g, w) => panic!("f32 {g:?} vs f64 {w:?}"),
        }
    }
    assert!(both > 500 && neither > 100, "{both} hits, {neither} misses");
}

#[test]
fn every_build_time_scheme_and_traversal_gives_the_same_hits() {
    let (mesh, scalars) = radial_mesh(12);
    // A deforming step too: refit keeps the rest pose's tree, rebuild makes a new one.
    let moved: Arc<[Vec3]> = mesh
        .vertices()
        .iter()
        .map(|p| *p + 0.04 * Vec3::new((3.0 * p.y).sin(), (2.0 * p.z).cos(), (4.0 * p.x).sin()))
        .collect::<Vec<_>>()
        .into();
    let still = TetScene::new(mesh.clone(), scalars.clone()).expect("valid");
    let deformed = still.clone().with_positions(moved).expect("still valid");
    let clip = ClipBox::new(
        Vec3::new(0.0, 0.0, f32::NEG_INFINITY),
        Vec3::splat(f32::INFINITY),
    )
    .expect("valid");
    let queries = [
        TetQuery::single(0.6),
        TetQuery::new(&[0.3, 0.55, 0.8], None).expect("valid"),
        TetQuery::new(&[0.4, 0.75], Some(clip)).expect("valid"),
    ];
    let (w, h) = (48, 40);
    for scene in [&still, &deformed] {
        for q in &queries {
            let reference =
                hits_single(&prepared(scene, TetOptions::default()), &camera(), w, h, q);
            let hit_count = reference.iter().filter(|x| x.is_some()).count();
            assert!(
                hit_count > 300 && hit_count < (w * h) as usize,
                "{hit_count}"
            );
            for options in all_options() {
                let p = prepared(scene, options);
                assert_eq!(
                    hits_single(&p, &camera(), w, h, q),
                    reference,
                    "{options:?}"
                );
                for tile in [2, 16] {
                    let mut c = TetCounters::default();
                    let got = hits_packets(&p, &camera(), (w, h), tile, q, &mut c);
                    assert_eq!(got, reference, "{options:?}, {tile}×{tile} packets");
                }
            }
        }
    }
}

#[test]
fn large_packets_amortise_traversal() {
    // Table 4's claim on a view the surface fills: 16×16 packets visit far fewer nodes and
    // make far fewer isorange tests and isopolygon extractions than 2×2 packets, and fewer
    // box tests, for the same hits.
    let (mesh, scalars) = radial_mesh(16);
    let scene = TetScene::new(mesh, scalars).expect("valid");
    let p = prepared(&scene, TetOptions::default());
    let q = TetQuery::single(0.6);
    let close = Camera {
        eye: Vec3::new(0.2, 0.3, 1.6),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 40.0,
    };
    let (w, h) = (64, 64);
    let mut small = TetCounters::default();
    let mut large = TetCounters::default();
    let a = hits_packets(&p, &close, (w, h), 2, &q, &mut small);
    let b = hits_packets(&p, &close, (w, h), 16, &q, &mut large);
    assert_eq!(a, b);
    assert!(
        large.hits * 2 > large.rays,
        "the surface fills the view: {large:?}"
    );
    assert!(large.nodes * 10 < small.nodes, "{large:?} vs {small:?}");
    assert!(
        large.ray_box_tests < small.ray_box_tests,
        "{large:?} vs {small:?}"
    );
    assert!(
        large.isorange_tests * 10 < small.isorange_tests,
        "{large:?} vs {small:?}"
    );
    assert!(
        large.extractions * 4 < small.extractions,
        "{large:?} vs {small:?}"
    );
    assert!(small.polygons_culled > 0 && large.polygons_culled > 0);
}

#[test]
fn multiple_isosurfaces_peel_front_to_back_and_any_hit_agrees() {
    let (mesh, scalars) = radial_mesh(16);
    let scene = TetScene::new(mesh, scalars).expect("valid");
    let p = prepared(&scene, TetOptions::default());
    let q = TetQuery::new(&[0.4, 0.7], None).expect("valid");
    let ray = Ray::new(Vec3::new(0.01, 0.02, 3.0), Vec3::NEG_Z);
    let mut c = TetCounters::default();
    let mut t_min = 0.0;
    let mut layers = Vec::new();
    while let Some(hit) = p.first_hit(&ray, t_min, 100.0, &q, &mut c) {
        layers.push((hit.surface, hit.t));
        t_min = hit.t + 1e-4;
    }
    let surfaces: Vec<u8> = layers.iter().map(|l| l.0).collect();
    assert_eq!(surfaces, [1, 0, 0, 1], "{layers:?}");
    for ((_, t), want) in layers.iter().zip([2.3, 2.6, 3.4, 3.7]) {
        assert!((t - want).abs() < 0.03, "{layers:?}");
    }
    // Any hit: true exactly when a first hit exists within the segment.
    let mut rng = SplitMix64(4);
    for _ in 0..500 {
        let eye = Vec3::new(rng.range(-0.9, 0.9), rng.range(-0.9, 0.9), 3.0);
        let ray = Ray::new(
            eye,
            Vec3::new(rng.range(-0.3, 0.3), rng.range(-0.3, 0.3), -1.0),
        );
        let t_max = rng.range(1.0, 5.0);
        let first = p.first_hit(&ray, 0.0, t_max, &q, &mut c);
        let any = p.any_hit(&ray, 0.0, t_max, &q, &mut c);
        assert_eq!(any.is_some(), first.is_some());
        if let (Some(a), Some(f)) = (any, first) {
            assert!(
                a.t >= f.t && a.t <= t_max,
                "any hit {a:?} lies on the segment"
            );
        }
    }
    // A NaN isovalue (a bad view) matches nothing and does not panic.
    assert!(p
        .first_hit(&ray, 0.0, 100.0, &TetQuery::single(f32::NAN), &mut c)
        .is_none());
}

#[test]
fn the_clip_box_removes_surface_and_skips_subtrees() {
    let (mesh, scalars) = radial_mesh(16);
    let scene = TetScene::new(mesh, scalars).expect("valid");
    let p = prepared(&scene, TetOptions::default());
    let clip = ClipBox::new(
        Vec3::new(0.0, f32::NEG_INFINITY, f32::NEG_INFINITY),
        Vec3::splat(f32::INFINITY),
    )
    .expect("valid");
    let q = TetQuery::new(&[0.7], Some(clip)).expect("valid");
    let plain = TetQuery::single(0.7);
    let mut c = TetCounters::default();
    // Straight through the removed half: nothing left.
    let ray = Ray::new(Vec3::new(0.3, 0.0, 3.0), Vec3::NEG_Z);
    assert!(p.first_hit(&ray, 0.0, 100.0, &plain, &mut c).is_some());
    assert!(p.first_hit(&ray, 0.0, 100.0, &q, &mut c).is_none());
    // Through the kept half: unchanged.
    let ray = Ray::new(Vec3::new(-0.3, 0.0, 3.0), Vec3::NEG_Z);
    assert_eq!(
        p.first_hit(&ray, 0.0, 100.0, &q, &mut c),
        p.first_hit(&ray, 0.0, 100.0, &plain, &mut c)
    );
    // Slanted across the cut: the hit is the inside of the far half-shell.
    let ray = Ray::new(Vec3::new(2.0, 0.0, 2.0), Vec3::new(-1.0, 0.0, -1.0));
    let hit = p
        .first_hit(&ray, 0.0, 100.0, &q, &mut c)
        .expect("hits the kept half");
    let at = ray.at(hit.t);
    assert!(at.x < 0.0, "{at}");
    assert!(c.clipped_subtrees > 0, "whole subtrees were skipped");
    // Clipped geometry casts no shadow.
    let shadow = Ray::new(Vec3::new(0.3, 0.0, 3.0), Vec3::NEG_Z);
    assert!(p.any_hit(&shadow, 0.0, 100.0, &q, &mut c).is_none());
}

#[test]
fn normals_point_down_the_gradient() {
    let (mesh, scalars) = radial_mesh(16);
    let scene = TetScene::new(mesh, scalars).expect("valid");
    for normals in [Normals::Faceted, Normals::Smooth] {
        let p = prepared(
            &scene,
            TetOptions {
                normals,
                ..TetOptions::default()
            },
        );
        let q = TetQuery::single(0.7);
        let mut c = TetCounters::default();
        let mut rng = SplitMix64(8);
        let mut worst = 0.0f32;
        for _ in 0..300 {
            let target = rng.in_unit_ball() * 0.5;
            let ray = Ray::new(Vec3::new(0.0, 0.0, 3.0), target - Vec3::new(0.0, 0.0, 3.0));
            let hit = p.first_hit(&ray, 0.0, 100.0, &q, &mut c).expect("hits");
            let rec = p.hit_record(&ray, &hit, &q);
            assert!((rec.normal.length() - 1.0).abs() < 1e-4);
            assert_eq!(rec.primitive, hit.tet);
            // Out of the solid |x| > v: towards the centre.
            worst = worst.max(1.0 + rec.normal.dot(rec.position.normalize()));
        }
        let limit = match normals {
            Normals::Faceted => 0.05,
            Normals::Smooth => 0.01,
        };
        assert!(worst < limit, "{normals:?}: 1 − cos = {worst}");
    }
}

#[test]
fn the_demo_renders_the_same_on_one_and_two_threads() {
    use crate::scenes::DemoScene;
    use crate::CpuBackend;
    let demo = DemoScene::TetGyroid;
    let scene = Arc::new(demo.state_at(0.75)).prepare();
    let view = demo.default_view(41, 29);
    let one = CpuBackend::new(1).expect("pool").render(&scene, &view);
    let two = CpuBackend::new(2).expect("pool").render(&scene, &view);
    assert_eq!(one, two);
    assert!(one.hit_count() > 100 && one.hit_count() < 41 * 29);
    let verts = match scene.geometry() {
        crate::scene::PreparedGeometry::Tets(t) => t.vertices().len(),
        _ => 0,
    };
    assert_eq!(
        verts,
        crate::kinds::tets::generate::demo_mesh().vertices().len()
    );
}

#[test]
fn the_server_path_traces_tiles_as_packets_with_the_same_image() {
    use crate::integrator::trace_primary;
    use crate::scenes::DemoScene;
    use crate::shade::linear_to_srgb8;
    use crate::CpuBackend;
    let demo = DemoScene::TetGyroid;
    let scene = Arc::new(demo.state_at(2.5)).prepare();
    let view = demo.default_view(53, 37);
    let fb = CpuBackend::new(2).expect("pool").render(&scene, &view);
    let rays = view.camera.rays(view.width, view.height);
    for y in 0..view.height {
        for x in 0..view.width {
            let (c, _) = trace_primary(
                &scene,
                &rays.through_pixel(x, y),
                view.isovalue,
                rays.pixel_spread(),
            );
            let i = ((y * view.width + x) * 3) as usize;
            assert_eq!(
                fb.rgb[i..i + 3],
                [c.x, c.y, c.z].map(linear_to_srgb8),
                "pixel {x}, {y}"
            );
        }
    }
    assert!(fb.hit_count() > 200);
}

#[test]
fn the_effects_layer_covers_tets() {
    // §7 on the demo: shadows (any-hit rays through the tet BVH), a second transparent
    // isosurface peeled front to back, and the clip box, each changing the image and the
    // rays traced, deterministically.
    use crate::effects::{Effects, RayKind};
    use crate::scenes::DemoScene;
    use crate::CpuBackend;
    let demo = DemoScene::TetGyroid;
    let scene = Arc::new(demo.state_at(1.0)).prepare();
    let view = demo.default_view(48, 36);
    let one = CpuBackend::new(1).expect("pool");
    let two = CpuBackend::new(2).expect("pool");
    let (plain, plain_rays) = one.render_effects(&scene, &view, &Effects::OFF);
    let with = |effects: Effects| {
        let (a, rays) = one.render_effects(&scene, &view, &effects);
        let (b, _) = two.render_effects(&scene, &view, &effects);
        assert_eq!(a, b, "{effects:?} is deterministic across threads");
        assert_ne!(a, plain, "{effects:?} changes the image");
        rays.rays
    };
    assert_eq!(plain_rays.rays.total(), 48 * 36);
    let shadows = with(Effects {
        shadows: true,
        ..Effects::OFF
    });
    assert!(shadows.get(RayKind::Shadow) > 100, "{shadows:?}");
    let layers = with(Effects {
        isosurfaces: true,
        transparency: true,
        ..Effects::OFF
    });
    assert!(layers.get(RayKind::Transparency) > 100, "{layers:?}");
    let clipped = with(Effects {
        clip_box: true,
        ..Effects::OFF
    });
    assert_eq!(clipped.get(RayKind::Shadow), 0);
    let all = with(Effects {
        shadows: true,
        isosurfaces: true,
        transparency: true,
        clip_box: true,
        ..Effects::OFF
    });
    assert!(all.get(RayKind::Shadow) > 0 && all.get(RayKind::Transparency) > 0);
}

/// `p` turned about `z` by `turns` full turns at the top, none at the bottom (`z = -1`).
fn twisted(p: Vec3, turns: f32) -> Vec3 {
    let a = std::f32::consts::TAU * turns * (p.z + 1.0) / 2.0;
    let (s, c) = a.sin_cos();
    Vec3::new(c * p.x - s * p.y, s * p.x + c * p.y, p.z)
}

#[test]
fn a_deforming_mesh_refits_until_the_tree_degrades_then_rebuilds() {
    use crate::kinds::tets::prepared::REFIT_DEGRADATION;
    let (mesh, scalars) = radial_mesh(10);
    let options = TetOptions {
        normals: Normals::Faceted,
        ..TetOptions::default()
    };
    let rest_cost = mesh.shared_bvh(options.build).area_cost();
    let q = TetQuery::single(0.7);
    let mut log = Vec::new();
    for turns in [0.05, 0.25, 1.0, 1.02] {
        let moved: Arc<[Vec3]> = mesh.vertices().iter().map(|p| twisted(*p, turns)).collect();
        let step = TetScene::new(mesh.clone(), scalars.clone())
            .expect("valid")
            .with_positions(moved)
            .expect("a twist inverts no tet");
        let refit = prepared(&step, options);
        let fresh = prepared(
            &step,
            TetOptions {
                time: TimeScheme::Rebuild,
                ..options
            },
        );
        // Whatever the tree, the same hits.
        assert_eq!(
            hits_single(&refit, &camera(), 32, 24, &q),
            hits_single(&fresh, &camera(), 32, 24, &q),
            "{turns} turns"
        );
        refit
            .bvh()
            .validate(refit.vertices())
            .expect("a sound tree");
        log.push((turns, refit.rebuilt(), refit.bvh().area_cost()));
        eprintln!(
            "{turns} turns: rebuilt {}, area cost {:.2} (rest {rest_cost:.2}, fresh {:.2})",
            refit.rebuilt(),
            refit.bvh().area_cost(),
            fresh.bvh().area_cost()
        );
    }
    // A small twist refits; a full turn swells the refitted boxes past the bound and
    // rebuilds; the next step, close to it, refits the rebuilt structure.
    assert!(!log[0].1 && !log[1].1, "{log:?}");
    assert!(log[2].1, "{log:?}");
    assert!(!log[3].1, "{log:?}");
    assert!(log[3].2 <= REFIT_DEGRADATION * log[2].2, "{log:?}");
}
