//! Tet hard cases, against `tets::reference` (every tet by brute force in `f64`: the plane
//! of the linear field and barycentric coordinates; no marching-tets table, no BVH), and the
//! tet demos at a viewer's size, camera and shadow rays, against the same per-tet test behind
//! a uniform grid.

use super::{check_image, check_image_at, check_rays, shadow_rays, Answer, Case};
use glam::{DVec3, Vec3};
use isoray_render::integrator::trace_shadows;
use isoray_render::kinds::counters::SceneCounters;
use isoray_render::kinds::tets::generate::box_mesh;
use isoray_render::kinds::tets::reference::reference_hit;
use isoray_render::kinds::tets::{TetMesh, TetScene};
use isoray_render::scene::Geometry;
use isoray_render::scenes::DemoScene;
use isoray_render::shade::Lighting;
use isoray_render::{Camera, Ray, Scene};
use std::sync::Arc;

fn scene(mesh: TetMesh, field: impl Fn(Vec3) -> f32) -> Scene {
    let scalars: Arc<[f32]> = mesh.vertices().iter().map(|p| field(*p)).collect();
    let step = TetScene::new(Arc::new(mesh), scalars).expect("a valid step");
    Scene {
        geometry: Geometry::Tets(step),
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

/// The brute-force reference: the nearest crossing. Every crossing is robust for tets (the
/// engine is watertight on shared edges by construction, so a ray through an edge or a vertex
/// must still hit).
fn answer(case: &Case, ray: &Ray) -> Answer {
    let Geometry::Tets(step) = &case.scene.geometry else {
        unreachable!("a tet case");
    };
    let hit = reference_hit(
        step.positions(),
        step.scalars(),
        step.mesh().tets(),
        ray.origin.as_dvec3(),
        ray.dir.as_dvec3(),
        0.0,
        1.0e4,
        case.isovalue as f64,
    )
    .map(|(t, _)| t);
    Answer {
        low: hit,
        high: hit,
        robust: hit.is_some(),
        // The engine's normals are smooth (interpolated vertex gradients), the reference's
        // the tet's flat gradient: not the same definition, not compared.
        normal: None,
    }
}

fn image(case: Case) {
    check_image(&case, |ray| answer(&case, ray));
}

#[test]
fn isovalues_exactly_at_tet_vertex_values() {
    // Vertices on a 0.5 grid, a linear field: T = 0.5 passes exactly through vertices.
    image(Case {
        name: "isovalues_exactly_at_tet_vertex_values",
        scene: scene(
            box_mesh([4, 4, 4], Vec3::splat(-1.0), Vec3::splat(1.0), 0.0, 1),
            |p| p.x + p.y + p.z,
        ),
        camera: look([2.5, 1.5, 3.5], [0.0; 3]),
        isovalue: 0.5,
        bound: 1e-4,
        normal_deg: 0.0,
    });
}

#[test]
fn slivers_and_near_zero_volume_tets() {
    // Heavy jitter makes flat tets next to fat ones.
    image(Case {
        name: "slivers_and_near_zero_volume_tets",
        scene: scene(
            box_mesh([5, 5, 5], Vec3::splat(-1.0), Vec3::splat(1.0), 0.45, 7),
            |p| p.length_squared(),
        ),
        camera: look([1.5, 1.0, 3.0], [0.0; 3]),
        isovalue: 0.6,
        bound: 1e-4,
        normal_deg: 0.0,
    });
}

pub fn grid_case() -> (Case, Vec<Ray>) {
    let case = Case {
        name: "rays_along_axes_through_box_faces_edges_and_corners",
        scene: scene(
            box_mesh([4, 4, 4], Vec3::splat(-1.0), Vec3::splat(1.0), 0.0, 1),
            |p| p.length_squared(),
        ),
        camera: look([0.0, 0.0, 4.0], [0.0; 3]),
        isovalue: 0.6,
        bound: 1e-4,
        normal_deg: 0.0,
    };
    // Through vertices (both coordinates on the 0.5 grid), edges (one) and faces.
    let mut rays = Vec::new();
    for a in [-1.0f32, -0.5, -0.25, 0.0, 0.25, 0.5] {
        for b in [-0.5f32, 0.0, 0.3, 0.5] {
            rays.push(Ray::new(Vec3::new(a, b, 5.0), Vec3::NEG_Z));
            rays.push(Ray::new(Vec3::new(-5.0, a, b), Vec3::X));
            rays.push(Ray::new(Vec3::new(a, 5.0, b), Vec3::NEG_Y));
        }
    }
    (case, rays)
}

#[test]
fn rays_along_axes_through_box_faces_edges_and_corners() {
    let (case, rays) = grid_case();
    check_rays(&case, &rays, |ray| answer(&case, ray));
    image(case);
}

/// The gyroid demo at 23.3 s from its camera: a tet corner 4.8·10⁻⁷ above the isovalue made
/// two points of a quad 6·10⁻⁸ apart, whose edge plane rounding set; it rejected this ray
/// (pixel (109, 42) at 160×120), which showed the surface 0.05 behind. Found by checking the
/// tet demos at 160×120 against the reference (4 such pixels in the gyroid at 23.3 s, and a
/// false hit in the bucky ball at 0 s; none after the fix); the brute-force reference tests
/// every tet per ray, too slow for whole demo images here.
#[test]
fn a_tet_corner_within_rounding_of_the_isovalue_in_the_gyroid_demo() {
    let demo = DemoScene::TetGyroid;
    let case = Case {
        name: "a_tet_corner_within_rounding_of_the_isovalue_in_the_gyroid_demo",
        scene: demo.state_at(23.3),
        camera: demo.default_camera(),
        isovalue: demo.default_isovalue(),
        bound: 1e-3,
        normal_deg: 0.0,
    };
    let ray = Ray {
        origin: Vec3::new(3.0, 2.2, 5.2),
        dir: Vec3::new(-0.32548538, -0.23928557, -0.9147686),
    };
    check_rays(&case, &[ray], |ray| answer(&case, ray));
}

/// The brute-force reference made fast enough for whole demo images: the tets whose corner
/// values reach the isovalue are binned by their boxes (grown by a margin far above rounding)
/// into a uniform grid, a ray walks the grid's cells in order (Amanatides and Woo, in `f64`)
/// and [`reference_hit`] runs over each cell's tets until a hit lies within the cells walked.
/// Every tet the ray could hit within those cells is in one of them, so the answer is the
/// brute force's; the engine's BVH, packets and isopolygons are not used.
struct TetGrid<'a> {
    step: &'a TetScene,
    isovalue: f64,
    lo: DVec3,
    cell: DVec3,
    /// Cells along each axis.
    n: usize,
    cells: Vec<Vec<[u32; 4]>>,
}

impl TetGrid<'_> {
    fn new(case: &Case) -> TetGrid<'_> {
        let Geometry::Tets(step) = &case.scene.geometry else {
            unreachable!("a tet case");
        };
        let (positions, scalars) = (step.positions(), step.scalars());
        let iso = case.isovalue as f64;
        let active: Vec<[u32; 4]> = (step.mesh().tets().iter().copied())
            .filter(|ids| {
                let s = ids.map(|v| scalars[v as usize] as f64);
                let (min, max) = (
                    s.iter().copied().fold(f64::INFINITY, f64::min),
                    s.iter().copied().fold(f64::NEG_INFINITY, f64::max),
                );
                let slack = 1e-9 * (1.0 + iso.abs());
                min - slack <= iso && iso <= max + slack
            })
            .collect();
        let corners = |ids: &[u32; 4]| ids.map(|v| positions[v as usize].as_dvec3());
        let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        for p in active.iter().flat_map(corners) {
            (lo, hi) = (lo.min(p), hi.max(p));
        }
        let margin = 1e-6 * (hi - lo).max_element().max(1.0);
        (lo, hi) = (lo - margin, hi + margin);
        let n = ((active.len() as f64 / 2.0).cbrt().round() as usize).clamp(1, 96);
        let cell = (hi - lo) / n as f64;
        let mut cells = vec![Vec::new(); n * n * n];
        let index = |p: DVec3| {
            ((p - lo) / cell)
                .floor()
                .as_ivec3()
                .clamp(glam::IVec3::ZERO, glam::IVec3::splat(n as i32 - 1))
        };
        for ids in &active {
            let p = corners(ids);
            let (a, b) = p
                .iter()
                .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(a, b), q| {
                    (a.min(*q), b.max(*q))
                });
            let (a, b) = (index(a - margin), index(b + margin));
            for z in a.z..=b.z {
                for y in a.y..=b.y {
                    for x in a.x..=b.x {
                        cells[(z as usize * n + y as usize) * n + x as usize].push(*ids);
                    }
                }
            }
        }
        TetGrid {
            step,
            isovalue: iso,
            lo,
            cell,
            n,
            cells,
        }
    }

    /// The nearest hit's distance along `o + t d` (`d` normalised here), as [`reference_hit`]
    /// over every tet would give it.
    fn hit(&self, o: DVec3, dir: DVec3) -> Option<f64> {
        // `reference_hit` normalises `dir` itself, the same way.
        let d = dir.normalize();
        let (n, hi) = (self.n, self.lo + self.cell * self.n as f64);
        let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
        for i in 0..3 {
            if d[i] == 0.0 {
                if o[i] < self.lo[i] || o[i] > hi[i] {
                    return None;
                }
                continue;
            }
            let (a, b) = ((self.lo[i] - o[i]) / d[i], (hi[i] - o[i]) / d[i]);
            (t0, t1) = (t0.max(a.min(b)), t1.min(a.max(b)));
        }
        if t0 > t1 {
            return None;
        }
        let p = o + t0 * d;
        let mut at = [0usize; 3];
        let (mut next, mut delta, mut step) = ([f64::INFINITY; 3], [f64::INFINITY; 3], [0isize; 3]);
        for i in 0..3 {
            let c = ((p[i] - self.lo[i]) / self.cell[i]).floor();
            at[i] = (c.max(0.0) as usize).min(n - 1);
            if d[i] != 0.0 {
                step[i] = if d[i] > 0.0 { 1 } else { -1 };
                let far_side = if d[i] > 0.0 { 1.0 } else { 0.0 };
                let edge = self.lo[i] + (at[i] as f64 + far_side) * self.cell[i];
                next[i] = (edge - o[i]) / d[i];
                delta[i] = self.cell[i] / d[i].abs();
            }
        }
        let mut best: Option<f64> = None;
        loop {
            let cell = &self.cells[(at[2] * n + at[1]) * n + at[0]];
            let found = reference_hit(
                self.step.positions(),
                self.step.scalars(),
                cell,
                o,
                dir,
                0.0,
                1.0e4,
                self.isovalue,
            );
            if let Some((t, _)) = found {
                best = Some(best.map_or(t, |b: f64| b.min(t)));
            }
            let axis = (0..3)
                .min_by(|&a, &b| next[a].total_cmp(&next[b]))
                .unwrap_or(0);
            let exit = next[axis];
            if best.is_some_and(|b| b <= exit) || exit > t1 {
                return best;
            }
            let k = at[axis] as isize + step[axis];
            if k < 0 || k >= n as isize {
                return best;
            }
            at[axis] = k as usize;
            next[axis] += delta[axis];
        }
    }
}

/// How far [`turned_answer`] turns a ray (radians): about 3.4 `f32` epsilons, above the
/// rounding of the engine's edge planes (`march.rs` `edge_normal`) and hit distances. Both demos
/// at 640×480 at 12 times each (the sweep this test was cut from) pass turned by `10⁻⁷` and
/// fail turned by `10⁻⁸` (two pixels: a silhouette and a grazing hit).
const TURN: f64 = 4e-7;

/// Unit `d` and `d` turned by [`TURN`] four ways (up, down, left and right of it).
fn turned(d: DVec3) -> [DVec3; 5] {
    let u = d.any_orthonormal_vector();
    let v = d.cross(u);
    [d, d + TURN * u, d - TURN * u, d + TURN * v, d - TURN * v]
}

/// The reference's answer for the ray and for the ray turned by [`TURN`] four ways (up, down,
/// left and right of it). Where they agree the answer is robust: the engine must hit there
/// (within the case's bound) or miss. Where they differ the ray passes within rounding of a
/// silhouette (the shared edge of two polygons that fold over each other as seen from the
/// eye, where a ray can cross the surface twice in a hair's breadth or pass it by) or meets a
/// polygon so obliquely that rounding moves the hit far along it: any of their hits, or
/// anything between, is right, and a miss too where one of them misses.
fn turned_answer(grid: &TetGrid, ray: &Ray) -> Answer {
    let o = ray.origin.as_dvec3();
    let hits = turned(ray.dir.as_dvec3().normalize()).map(|d| grid.hit(o, d));
    let found = hits.iter().flatten().copied();
    let (low, high) = (found.clone().reduce(f64::min), found.reduce(f64::max));
    Answer {
        low,
        high,
        robust: hits.iter().all(Option::is_some),
        normal: None,
    }
}

/// The tet demos' frames the suite checks at a viewer's size.
const DEMO_FRAMES: [(DemoScene, f64); 4] = [
    (DemoScene::TetGyroid, 23.3),
    (DemoScene::TetGyroid, 6.0),
    (DemoScene::TetBucky, 0.0),
    (DemoScene::TetBucky, 2.5),
];

/// `demo` at `time` from its own camera, as served.
fn demo_case(demo: DemoScene, time: f64) -> Case {
    Case {
        name: demo.id(),
        scene: demo.state_at(time),
        camera: demo.default_camera(),
        isovalue: demo.default_isovalue(),
        // Beyond the turned answers' band: at most 1.7e-6 in the camera suite's frames,
        // 8.2e-6 in the sweep at 640×480.
        bound: 2e-5,
        normal_deg: 0.0,
    }
}

/// Both tet demos at a viewer's size against the reference ([`TetGrid`], [`turned_answer`]),
/// at times that include those of the defects found so far: the gyroid at 23.3 s had a ray
/// let through a sliver it passes 0.035 away (pixel (171, 85), edge planes formed from the
/// points' offsets from the eye) and, before that, a hole where a rounded edge plane rejected
/// a ray (the test above); the bucky ball at 0 s a false hit. Fails on the engine before the
/// edge planes were formed about the edge's midpoint.
#[test]
fn the_tet_demos_at_a_viewers_size() {
    for (demo, time) in DEMO_FRAMES {
        let case = demo_case(demo, time);
        eprintln!("{} at {time} s", demo.id());
        let grid = TetGrid::new(&case);
        // The grid only culls: on a sample of the image's rays (every 1201st, in pixel order)
        // its answer is the brute force's over every tet.
        let pixel = std::cell::Cell::new(0usize);
        check_image_at(&case, (320, 240), |ray| {
            if pixel.replace(pixel.get() + 1) % 1201 == 0 {
                let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
                let brute = reference_hit(
                    grid.step.positions(),
                    grid.step.scalars(),
                    grid.step.mesh().tets(),
                    o,
                    d,
                    0.0,
                    1.0e4,
                    case.isovalue as f64,
                );
                assert_eq!(grid.hit(o, d), brute.map(|(t, _)| t), "{ray:?}");
            }
            turned_answer(&grid, ray)
        });
    }
}

/// Both tet demos' hard shadow rays ([`shadow_rays`]: from the isosurface and the floor where
/// it faces the light), answered as the renderer answers them (`integrator::trace_shadows`)
/// and by the reference: blocked where the ray and the ray turned by [`TURN`] four ways all
/// hit the surface before the light, let through where none does; anything else goes (the
/// ray passes within rounding of a silhouette).
#[test]
fn the_tet_demos_shadow_rays() {
    let (mut must_block, mut must_pass) = (0, 0);
    for (demo, time) in DEMO_FRAMES {
        let case = demo_case(demo, time);
        let grid = TetGrid::new(&case);
        let prepared = Arc::new(case.scene.clone()).prepare();
        let frame = *prepared.frame();
        let shadows = shadow_rays(&prepared, &case.camera, (320, 240), case.isovalue);
        let queries: Vec<_> = shadows.iter().map(|s| s.query).collect();
        let blocked = trace_shadows(
            &prepared,
            case.isovalue,
            &queries,
            &mut SceneCounters::default(),
        );
        let mut wrong = Vec::new();
        let (mut block, mut pass, mut floor) = (0, 0, 0);
        for (shadow, &got) in shadows.iter().zip(&blocked) {
            let q = &shadow.query;
            let (o, d) = (frame.world_from_local(q.ray.origin), q.ray.dir.as_dvec3());
            let hits = turned(d).map(|d| grid.hit(o, d).is_some_and(|t| t <= q.t_max as f64));
            floor += shadow.on_floor as usize;
            let answer = if hits.iter().all(|&h| h) {
                block += 1;
                Some(true)
            } else if hits.iter().all(|&h| !h) {
                pass += 1;
                Some(false)
            } else {
                None
            };
            if answer.is_some_and(|a| a != got) {
                wrong.push(format!(
                    "pixel {:?} (floor: {}, cos {:.3}) {q:?}: renderer {got}",
                    shadow.pixel, shadow.on_floor, shadow.cos
                ));
            }
        }
        eprintln!(
            "{} at {time} s: {} shadow rays ({floor} from the floor), {block} to block, {pass} to pass, {} wrong",
            demo.id(),
            shadows.len(),
            wrong.len()
        );
        assert!(wrong.is_empty(), "{} at {time} s: {wrong:#?}", demo.id());
        (must_block, must_pass) = (must_block + block, must_pass + pass);
    }
    assert!(
        must_block > 1000 && must_pass > 10_000,
        "{must_block} to block, {must_pass} to pass"
    );
}
