//! The packet paths' vector steps against their single-ray operations, to the bit: the
//! gathers of a leaf's balls across rays, the leaf search's bound and the slab tests in lanes,
//! and the shadow rays' and the tree's structure-of-arrays gathers.

use super::packet_tests::{assert_same_balls, demos, HEIGHT, TILE, T_MAX, WIDTH};
use crate::kinds::metaballs::engine::PreparedMetaballs;
use crate::ray::Ray;
use crate::scenes::DemoScene;
use glam::Vec3;
use std::sync::Arc;

/// Rays from `demo`'s camera through every `step`-th pixel of each row and column, each with
/// a range from `ranges` in turn (fractions of the distance from the eye to the target):
/// the eye, the rays, and `(ray, lo, hi)` for each.
#[allow(clippy::type_complexity)]
fn camera_grid(
    demo: DemoScene,
    prepared: &crate::scene::PreparedScene,
    step: usize,
    ranges: &[(f32, f32)],
) -> (Vec3, Vec<Ray>, Vec<(u32, f32, f32)>) {
    let rays = prepared.primary_rays(&demo.default_camera(), WIDTH, HEIGHT);
    let origin = rays.through_pixel(0, 0).origin;
    let reach = (demo.default_camera().target - origin).length();
    let (mut grid, mut crossing) = (Vec::new(), Vec::new());
    for y in (0..HEIGHT).step_by(step) {
        for x in (0..WIDTH).step_by(step) {
            let (lo, hi) = ranges[grid.len() % ranges.len()];
            crossing.push((grid.len() as u32, lo * reach, hi * reach));
            grid.push(rays.through_pixel(x, y));
        }
    }
    (origin, grid, crossing)
}

/// The structure-of-arrays gather of a packet leaf gives, for every ray from the shared
/// origin, the balls the single ray's gather gives, field for field to the bit: every demo's
/// spheres, rays from its camera through a grid over the image in groups of 1 to 8 lanes (the
/// lanes past a short group's last ray unused), each ray with a range of its own that cuts
/// some balls; all the balls at once and the first 84 in leaves of 1, 3 and 7.
#[test]
fn the_shared_origin_gather_is_the_single_rays_bit_for_bit() {
    use super::soa::{SharedOriginBalls, RAY_LANES};
    let (mut compared, mut in_small_leaves) = (0usize, 0usize);
    for (demo, prepared, m) in demos() {
        let all: Vec<u32> = (0..m.balls.len() as u32).collect();
        let (origin, grid, crossing) =
            camera_grid(*demo, prepared, 3, &[(0.0, 2.0), (0.8, 1.1), (0.0, 0.9)]);
        for (r, leaf) in [all.len(), 1, 3, 7].into_iter().enumerate() {
            // Leaves of few balls from the first 84 balls (enough of them, quick).
            let pool = if r == 0 {
                &all[..]
            } else {
                &all[..all.len().min(84)]
            };
            for balls in pool.chunks(leaf.max(1)) {
                let mut soa = SharedOriginBalls::default();
                if !soa.load(&m.balls, origin, balls) {
                    continue; // ellipsoids: the packet gathers as single rays do
                }
                let mut start = 0;
                for group in [RAY_LANES, 3, 1, RAY_LANES - 1].into_iter().cycle() {
                    let end = (start + group).min(crossing.len());
                    if start == end {
                        break;
                    }
                    soa.gather_rays(&crossing[start..end], &grid, None);
                    for (lane, &(i, lo, hi)) in crossing[start..end].iter().enumerate() {
                        let (mut single, mut shared) = (Vec::new(), Vec::new());
                        for &b in balls {
                            m.gather(&grid[i as usize], b, true, lo, hi, &mut single);
                        }
                        soa.lane_gathered(&m.balls, lane, &mut shared);
                        let at = || format!("{demo:?} ray {i} lane {lane}, leaves of {leaf}");
                        let n = assert_same_balls(&single, &shared, at);
                        compared += n;
                        in_small_leaves += if r > 0 { n } else { 0 };
                    }
                    start = end;
                }
            }
        }
    }
    assert!(compared > 1000, "{compared} gathered balls compared");
    assert!(
        in_small_leaves > 1000,
        "{in_small_leaves} gathered from leaves of few balls"
    );
}

/// The packet leaf's whole-stretch bound in lanes ([`super::soa::StretchBound`]) is for every
/// ray the bound the search of the ray's gathered balls starts with
/// (`roots::whole_stretch_bound`), to the bit, and says "cannot reach" exactly when it is
/// below the isovalue; the lanes count the ray's balls as its gather does:
/// every demo's spheres in leaves of 5, at the demo's isovalue, half and twice it, a quarter
/// of the balls carving (strength negated) or none, rays in groups of 1 to 8 lanes with
/// ranges that cut some balls or lie inside them.
#[test]
fn the_lanes_stretch_bound_decides_as_the_search() {
    use super::soa::{SharedOriginBalls, StretchBound, RAY_LANES};
    use crate::kinds::metaballs::roots::tests::whole_stretch_bound;
    let (mut yes, mut no, mut carving, mut covered) = (0usize, 0usize, 0usize, 0usize);
    for (demo, prepared, m) in demos() {
        // Short ranges too, which some balls cover whole (a carving ball counts only then).
        let ranges = [(0.0, 2.0), (0.8, 1.1), (0.97, 0.98), (1.0, 1.005)];
        let (origin, grid, crossing) = camera_grid(*demo, prepared, 2, &ranges);
        let all: Vec<u32> = (0..m.balls.len().min(200) as u32).collect();
        for carve in [false, true] {
            let mut records = m.balls.clone();
            for (i, ball) in records.iter_mut().enumerate() {
                if carve && i % 4 == 1 {
                    ball.strength = -ball.strength;
                }
            }
            for scale in [1.0, 0.5, 2.0] {
                let params = m.params(demo.default_isovalue() * scale);
                let bound = StretchBound::new(params.kernel, params.isovalue);
                for balls in all.chunks(5) {
                    let mut soa = SharedOriginBalls::default();
                    if !soa.load(&records, origin, balls) {
                        continue; // ellipsoids: the packet gathers as single rays do
                    }
                    for (g, rays) in crossing.chunks(RAY_LANES).enumerate() {
                        let rays = &rays[..rays.len().min([RAY_LANES, 3, 1, 7][g % 4])];
                        soa.gather_rays(rays, &grid, Some(&bound));
                        for (lane, &(i, lo, hi)) in rays.iter().enumerate() {
                            let mut single = Vec::new();
                            for &b in balls {
                                m.gather(&grid[i as usize], b, true, lo, hi, &mut single);
                            }
                            for b in single.iter_mut() {
                                b.q = records[b.ball as usize].strength;
                                carving += (b.q < 0.0) as usize;
                                covered += (b.q < 0.0 && b.t0 <= lo && hi <= b.t1) as usize;
                            }
                            let at = format!("{demo:?} ray {i} lane {lane}, T × {scale}");
                            assert_eq!(soa.lane_count(lane), single.len(), "{at}");
                            let sum = whole_stretch_bound(&params, &single, lo, hi);
                            assert_eq!(soa.lane_bound(lane), sum, "{at}");
                            let search = !(sum < params.isovalue);
                            assert_eq!(soa.may_reach(lane), search, "{at}");
                            if !single.is_empty() {
                                *(if search { &mut yes } else { &mut no }) += 1;
                            }
                        }
                    }
                }
            }
        }
    }
    assert!(yes > 1000 && no > 1000, "{yes} may reach, {no} may not");
    assert!(carving > 1000, "{carving} carving balls gathered");
    assert!(
        covered > 100,
        "{covered} carving balls cover their ray's range"
    );
}

/// The shadow packets' structure-of-arrays gather ([`super::soa::LeafSpheres`]) appends, for
/// rays with origins of their own, the balls the single ray's gather gives, field for field
/// to the bit: every demo's spheres, shadow rays from the surface points of a grid of camera
/// rays towards a point light, a range cutting some balls.
#[test]
fn the_shadow_rays_gather_is_the_single_rays_bit_for_bit() {
    use super::soa::LeafSpheres;
    let mut compared = 0usize;
    for (demo, prepared, m) in demos() {
        let all: Vec<u32> = (0..m.balls.len() as u32).collect();
        let mut soa = LeafSpheres::default();
        if !soa.load(&m.balls, &all) {
            continue; // ellipsoids: the packet gathers as single rays do
        }
        let camera = demo.default_camera();
        let light = camera.target + Vec3::new(3.0, 9.0, 2.0);
        let rays = prepared.primary_rays(&camera, WIDTH, HEIGHT);
        let far = 2.0 * (camera.target - camera.eye).length();
        for y in (0..HEIGHT).step_by(3) {
            for x in (0..WIDTH).step_by(3) {
                let camera_ray = rays.through_pixel(x, y);
                let Some(hit) = m.first_hit(&camera_ray, 0.0, far, demo.default_isovalue()) else {
                    continue;
                };
                let start = hit.position + hit.normal * 1e-3;
                let ray = Ray::new(start, (light - start).normalize());
                let (lo, hi) = (0.0, 0.5 * (light - start).length());
                let (mut single, mut packet) = (Vec::new(), Vec::new());
                for &b in &all {
                    m.gather(&ray, b, true, lo, hi, &mut single);
                }
                soa.gather(&m.balls, ray.origin, ray.dir, lo, hi, &mut packet);
                compared += assert_same_balls(&single, &packet, || format!("{demo:?} {x},{y}"));
            }
        }
    }
    assert!(compared > 1000, "{compared} gathered balls compared");
}

/// A single ray's leaf gather from the tree's structure-of-arrays
/// ([`super::soa::TreeSpheres`]) appends the balls, owner flags included, that gathering ball
/// by ball gives, field for field to the bit: every demo's Fitted BVH, and Blobs under the
/// BVH with split metaballs (whose leaves mark owners), rays from the camera through a grid,
/// every leaf each ray crosses, over its range and the first half of it, with both ways of
/// listing the balls met (for rays outside the solid and inside it).
#[test]
fn the_tree_leaf_gather_is_the_ball_by_ball_gather_bit_for_bit() {
    use super::Accel;
    use crate::kinds::metaballs::tree::BuildOptions;
    use crate::kinds::metaballs::{AccelKind, PrepareOptions};
    let mut states: Vec<(DemoScene, Arc<PreparedMetaballs>)> =
        demos().iter().map(|(d, _, m)| (*d, m.clone())).collect();
    let blobs = demos()
        .iter()
        .find(|(d, _, _)| *d == DemoScene::Blobs)
        .expect("blobs");
    let options = PrepareOptions::fitted(blobs.2.scene().min_isovalue)
        .with_accel(AccelKind::Tree(BuildOptions::bvh()));
    let bvh = PreparedMetaballs::new(blobs.2.scene().clone(), options);
    states.push((DemoScene::Blobs, Arc::new(bvh)));
    let (mut compared, mut owners, mut cut) = (0usize, [0usize; 2], 0usize);
    let prepared = &demos()[0].1;
    for (demo, m) in &states {
        let (Accel::Tree(tree), Some(soa)) = (&m.accel, &m.spheres) else {
            continue; // ellipsoids, or no tree: single rays gather ball by ball
        };
        let owners_only = tree.kind != crate::kinds::metaballs::tree::TreeKind::Fitted;
        let rays = prepared.primary_rays(&demo.default_camera(), WIDTH, HEIGHT);
        for y in (0..HEIGHT).step_by(4) {
            for x in (0..WIDTH).step_by(4) {
                let ray = rays.through_pixel(x, y);
                for node in tree.nodes.iter().filter(|n| n.is_leaf() && n.count > 0) {
                    let Some(range) = node.bounds.ray_range(ray.origin, ray.dir.recip(), 0.0, 1e4)
                    else {
                        continue;
                    };
                    let leaf = tree.leaf_balls(node);
                    // The leaf's range, and its first half (which cuts balls off), with the
                    // gather's listing for rays outside the solid and for rays inside it.
                    let half = (range.0, 0.5 * (range.0 + range.1));
                    for (range, crowded) in
                        [(range, false), (range, true), (half, false), (half, true)]
                    {
                        let (mut single, mut stored) = (Vec::new(), Vec::new());
                        for (k, &b) in leaf.iter().enumerate() {
                            let owner = !owners_only || k < node.owned as usize;
                            m.gather(&ray, b, owner, range.0, range.1, &mut single);
                        }
                        let first = node.first as usize;
                        let own = (node.owned as usize, owners_only);
                        let listed = (range, crowded);
                        soa.gather(&m.balls, leaf, first, own, &ray, listed, &mut stored);
                        let at = || format!("{demo:?} {x},{y} {range:?} crowded {crowded}");
                        let n = assert_same_balls(&single, &stored, at);
                        compared += n;
                        cut += (range == half && n < leaf.len()) as usize;
                        for s in &single {
                            owners[s.owner as usize] += 1;
                        }
                    }
                }
            }
        }
    }
    assert!(compared > 10_000, "{compared} gathered balls compared");
    assert!(cut > 1000, "only {cut} half ranges left balls out");
    assert!(
        owners[0] > 0 && owners[1] > 0,
        "owners and split balls both seen: {owners:?}"
    );
}

/// The leaves' slab tests in lanes ([`super::slabs::TileInverses`]) list the rays, and their
/// ranges, that the slab test ray by ray does: every demo's tree nodes (up to 400 a demo) and
/// boxes about the eye (faces through it, which give a NaN slab where a direction component
/// is zero, and boxes holding it) against every tile of its camera and of cameras looking
/// down the z and x axes (rays with zero direction components among them), with every third ray done
/// or none, from the first ray or the tile's middle.
#[test]
fn the_leaves_slab_tests_in_lanes_are_the_single_rays() {
    use super::Accel;
    use crate::geom::aabb::Aabb;
    use crate::geom::tile::TileGrid;
    let (mut listed, mut infinite) = (0usize, 0usize);
    for (demo, prepared, m) in demos() {
        let Accel::Tree(tree) = &m.accel else {
            continue;
        };
        let step = (tree.nodes.len() / 400).max(1);
        let nodes: Vec<Aabb> = tree.nodes.iter().step_by(step).map(|n| n.bounds).collect();
        let camera = demo.default_camera();
        let down = |axis: Vec3| crate::camera::Camera {
            target: camera.eye - axis * (camera.target - camera.eye).length(),
            up: Vec3::Y,
            ..camera
        };
        let cameras = [
            (camera, (WIDTH, HEIGHT)),
            (down(Vec3::Z), (33, 33)),
            (down(Vec3::X), (33, 33)),
        ];
        for (cam, (w, h)) in cameras {
            let rays = prepared.primary_rays(&cam, w, h);
            let mut boxes = nodes.clone();
            boxes.extend(boxes_about(rays.through_pixel(0, 0).origin));
            for y0 in (0..h).step_by(TILE as usize) {
                for x0 in (0..w).step_by(TILE as usize) {
                    let (width, height) = (TILE.min(w - x0), TILE.min(h - y0));
                    let tile = TileGrid {
                        rays,
                        x0,
                        y0,
                        width,
                        height,
                    };
                    let (l, i) = slabs_in_lanes_against_one_by_one(&tile, &boxes);
                    (listed, infinite) = (listed + l, infinite + i);
                }
            }
        }
    }
    assert!(listed > 10_000, "{listed} rays listed");
    assert!(infinite > 0, "no ray with a zero direction component");
}

/// Boxes about `eye`: on each axis the low or the high face through it, the eye inside, or the
/// box beside it.
fn boxes_about(eye: Vec3) -> Vec<crate::geom::aabb::Aabb> {
    let mut boxes = Vec::new();
    for d in [0.5f32, 4.0] {
        for k in 0..64u32 {
            let (mut lo, mut hi) = (Vec3::ZERO, Vec3::ZERO);
            for axis in 0..3 {
                (lo[axis], hi[axis]) = match (k >> (2 * axis)) & 3 {
                    0 => (-d, d),
                    1 => (0.0, d),
                    2 => (-d, 0.0),
                    _ => (-3.0 * d, -d),
                };
            }
            boxes.push(crate::geom::aabb::Aabb {
                min: eye + lo,
                max: eye + hi,
            });
        }
    }
    boxes
}

/// Asserts that `tile`'s slab tests in lanes list the rays ray by ray does for each of
/// `boxes`; returns how many rays were listed and how many of the tile's rays have a zero
/// direction component.
fn slabs_in_lanes_against_one_by_one(
    tile: &crate::geom::tile::TileGrid,
    boxes: &[crate::geom::aabb::Aabb],
) -> (usize, usize) {
    use super::slabs::{crossing_one_by_one, TileInverses};
    let (x1, y1) = (tile.x0 + tile.width, tile.y0 + tile.height);
    let (mut tile_rays, mut inv) = (Vec::new(), Vec::new());
    tile.rays
        .tile_rays((tile.x0, tile.y0, x1, y1), &mut tile_rays, &mut inv);
    let origin = tile_rays[0].origin;
    let mut inverses = TileInverses::default();
    inverses.load(&inv);
    let n = inv.len();
    let mut listed = 0;
    for b in boxes {
        let cover = tile.cover_box(b.min, b.max);
        for (thirds, from) in [(false, 0), (true, 0), (false, n / 2), (true, n / 2)] {
            let done: Vec<bool> = (0..n).map(|r| thirds && r % 3 == 1).collect();
            let rays = (tile.width as usize, from, n);
            let mut lanes = Vec::new();
            inverses.crossing(cover, rays, &done, b, origin, T_MAX, &mut lanes);
            let one = crossing_one_by_one(cover, rays, &done, &inv, b, origin, T_MAX);
            assert_eq!(lanes, one, "tile ({}, {}), box {b:?}", tile.x0, tile.y0);
            listed += one.len();
        }
    }
    (listed, inv.iter().filter(|v| !v.is_finite()).count())
}

/// The packet leaves' frustum culling in lanes ([`super::soa::TreeSpheres::cull`]) keeps the
/// balls [`crate::geom::tile::Frustum::excludes_sphere`] keeps, ball by ball: every demo of
/// spheres, every leaf of its tree, against the pyramid of every tile's cover of the leaf.
#[test]
fn the_leaves_culling_in_lanes_keeps_the_balls_one_by_one_does() {
    use super::Accel;
    use crate::geom::tile::TileGrid;
    let (mut kept, mut dropped) = (0usize, 0usize);
    for (demo, prepared, m) in demos() {
        let (Accel::Tree(tree), Some(spheres)) = (&m.accel, &m.spheres) else {
            continue;
        };
        let rays = prepared.primary_rays(&demo.default_camera(), WIDTH, HEIGHT);
        for y0 in (0..HEIGHT).step_by(TILE as usize) {
            for x0 in (0..WIDTH).step_by(TILE as usize) {
                let (width, height) = (TILE.min(WIDTH - x0), TILE.min(HEIGHT - y0));
                let tile = TileGrid {
                    rays,
                    x0,
                    y0,
                    width,
                    height,
                };
                for node in tree.nodes.iter().filter(|n| n.is_leaf() && n.count > 0) {
                    let cover = tile.cover_box(node.bounds.min, node.bounds.max);
                    let Some(frustum) = tile.frustum(cover) else {
                        continue;
                    };
                    let leaf = tree.leaf_balls(node);
                    let mut lanes = Vec::new();
                    spheres.cull(&frustum, leaf, node.first as usize, &mut lanes);
                    let one: Vec<u32> = leaf
                        .iter()
                        .copied()
                        .filter(|&b| {
                            let ball = &m.balls[b as usize];
                            !frustum.excludes_sphere(ball.center, 1.0 / ball.inv_r)
                        })
                        .collect();
                    assert_eq!(lanes, one, "tile ({x0}, {y0})");
                    (kept, dropped) = (kept + one.len(), dropped + leaf.len() - one.len());
                }
            }
        }
    }
    assert!(
        kept > 10_000 && dropped > 10_000,
        "{kept} kept, {dropped} dropped"
    );
}
