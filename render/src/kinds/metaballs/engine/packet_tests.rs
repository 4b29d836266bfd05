//! Packet against single-ray traversal on every metaball demo (the paper scenes among them):
//! the same hits, ray for ray, whatever the thread count.

use crate::camera::PrimaryRays;
use crate::kinds::contract::{settle, OcclusionHint};
use crate::kinds::dispatch::PreparedGeometry;
use crate::kinds::metaballs::counters::MetaballCounters;
use crate::kinds::metaballs::engine::PreparedMetaballs;
use crate::ray::Ray;
use crate::scene::PreparedScene;
use crate::scenes::DemoScene;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::{Arc, OnceLock};

pub(super) const WIDTH: u32 = 48;
pub(super) const HEIGHT: u32 = 40;
pub(super) const TILE: u32 = 16;
pub(super) const T_MAX: f32 = 1.0e4;

fn tiles() -> Vec<(u32, u32, u32, u32)> {
    (0..HEIGHT)
        .step_by(TILE as usize)
        .flat_map(|y| {
            (0..WIDTH)
                .step_by(TILE as usize)
                .map(move |x| (x, y, (x + TILE).min(WIDTH), (y + TILE).min(HEIGHT)))
        })
        .collect()
}

/// Asserts that a structure-of-arrays gather appended the balls the ball-by-ball gather did,
/// in order, every field (owner flag included) to the bit; returns how many.
pub(super) fn assert_same_balls(
    single: &[crate::kinds::metaballs::roots::RayBall<f32>],
    other: &[crate::kinds::metaballs::roots::RayBall<f32>],
    at: impl Fn() -> String,
) -> usize {
    assert_eq!(single.len(), other.len(), "{}", at());
    let bits = |b: &crate::kinds::metaballs::roots::RayBall<f32>| {
        (
            b.ball,
            b.owner,
            [b.t0, b.t1, b.a, b.tc, b.s_min, b.q].map(f32::to_bits),
        )
    };
    for (s, o) in single.iter().zip(other) {
        assert_eq!(bits(s), bits(o), "{}", at());
    }
    single.len()
}

/// Every metaball demo prepared with the defaults, once for the tests of this file.
pub(super) fn demos() -> &'static [(DemoScene, PreparedScene, Arc<PreparedMetaballs>)] {
    static DEMOS: OnceLock<Vec<(DemoScene, PreparedScene, Arc<PreparedMetaballs>)>> =
        OnceLock::new();
    DEMOS.get_or_init(|| {
        DemoScene::ALL
            .iter()
            .filter_map(|&demo| {
                let prepared = Arc::new(demo.state_at(1.0)).prepare();
                let m = match prepared.geometry() {
                    PreparedGeometry::Metaballs(m) => m.clone(),
                    PreparedGeometry::Tets(_) | PreparedGeometry::Surfels(_) => return None,
                };
                Some((demo, prepared, m))
            })
            .collect()
    })
}

#[test]
fn packets_match_single_rays_on_every_demo_at_1_2_and_8_threads() {
    let mut count = 0;
    for (demo, prepared, m) in demos() {
        let demo = *demo;
        count += 1;
        assert!(m.options().packets, "packets are the default");
        let rays = prepared.primary_rays(&demo.default_camera(), WIDTH, HEIGHT);
        let isovalue = demo.default_isovalue();
        let single: Vec<_> = tiles()
            .iter()
            .flat_map(|&(x0, y0, x1, y1)| (y0..y1).flat_map(move |y| (x0..x1).map(move |x| (x, y))))
            .map(|(x, y)| {
                let ray = rays.through_pixel(x, y);
                m.first_hit(&ray, 0.0, T_MAX, isovalue)
            })
            .collect();
        let hits = single.iter().filter(|h| h.is_some()).count();
        assert!(hits > 0, "{}: nothing hit", demo.id());
        for threads in [1, 2, 8] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("pool");
            let packet: Vec<_> = pool.install(|| {
                tiles()
                    .par_iter()
                    .map(|&rect| {
                        let mut c = MetaballCounters::default();
                        m.primary_tile_packet(&rays, rect, isovalue, T_MAX, &mut c)
                            .unwrap_or_else(|| panic!("{}: no packet", demo.id()))
                    })
                    .collect::<Vec<_>>()
                    .concat()
            });
            assert_eq!(packet.len(), single.len());
            for (k, ((_, p), s)) in packet.iter().zip(&single).enumerate() {
                match (p, s) {
                    (Some(p), Some(s)) => assert!(
                        p == s,
                        "{} ray {k}, {threads} threads: hit {p:?} against {s:?}",
                        demo.id(),
                    ),
                    (None, None) => {}
                    (p, s) => panic!(
                        "{} ray {k}, {threads} threads: packet {:?}, single {:?}",
                        demo.id(),
                        p.map(|h| h.t),
                        s.map(|h| h.t)
                    ),
                }
            }
        }
    }
    assert!(count >= 10, "only {count} metaball demos");
}

#[test]
fn packets_switched_off_leave_the_tile_to_single_rays() {
    let demo = DemoScene::Blobs;
    let scene = Arc::new(demo.state_at(0.0));
    let options = scene.geometry.default_metaball_options();
    let off = scene.prepare_with(crate::kinds::metaballs::engine::PrepareOptions {
        packets: false,
        ..options
    });
    let PreparedGeometry::Metaballs(m) = off.geometry() else {
        panic!("blobs is a metaball scene");
    };
    let rays = off.primary_rays(&demo.default_camera(), WIDTH, HEIGHT);
    let mut c = MetaballCounters::default();
    let tile = (0, 0, TILE, TILE);
    assert!(m
        .primary_tile_packet(&rays, tile, demo.default_isovalue(), T_MAX, &mut c)
        .is_none());
}

/// The lights of the shadow tests: a point light above and beside the eye of `rays`, and the
/// sun (a directional light) from the same side.
fn shadow_lights(rays: &PrimaryRays) -> [Option<Vec3>; 2] {
    let eye = rays.through_pixel(0, 0).origin;
    [
        Some(eye + Vec3::new(3.0, 5.0, 1.0) * (1.0 + eye.length() * 0.2)),
        None,
    ]
}

/// The shadow rays of a tile's primary hits (found as a packet) towards `light` (`None`: the
/// sun), each with its length.
fn tile_shadow_rays(
    m: &PreparedMetaballs,
    rays: &PrimaryRays,
    rect: (u32, u32, u32, u32),
    isovalue: f32,
    light: Option<Vec3>,
) -> (Vec<Ray>, Vec<f32>) {
    let sun = Vec3::new(0.4, 1.0, 0.3).normalize();
    let mut c = MetaballCounters::default();
    let hits = m
        .primary_tile_packet(rays, rect, isovalue, T_MAX, &mut c)
        .expect("a packet");
    hits.iter()
        .filter_map(|(_, h)| h.as_ref())
        .map(|h| {
            let origin = h.position + h.normal * 1e-3;
            match light {
                Some(light) => {
                    let to = light - origin;
                    (Ray::new(origin, to), to.length())
                }
                None => (Ray::new(origin, sun), T_MAX),
            }
        })
        .unzip()
}

/// Shadow rays from every primary hit towards one point light, and towards one directional
/// light: the packet's any-hit roots equal the single rays' (hit/miss identical, roots within
/// the tolerance).
#[test]
fn shadow_packets_match_single_rays_on_every_demo() {
    let mut shadowed = [0; 2];
    for (demo, prepared, m) in demos() {
        let demo = *demo;
        let rays = prepared.primary_rays(&demo.default_camera(), WIDTH, HEIGHT);
        let isovalue = demo.default_isovalue();
        let tolerance = m.options().tolerance;
        for (which, light) in shadow_lights(&rays).into_iter().enumerate() {
            for rect in tiles() {
                let mut c = MetaballCounters::default();
                let (shadow_rays, t_max) = tile_shadow_rays(m, &rays, rect, isovalue, light);
                if shadow_rays.is_empty() {
                    continue;
                }
                let packet = m
                    .any_hits_packet(&shadow_rays, 0.0, &t_max, light, isovalue, &mut c)
                    .expect("a shadow packet");
                for (k, (ray, &hi)) in shadow_rays.iter().zip(&t_max).enumerate() {
                    let single = m.any_hit_counted(ray, 0.0, hi, isovalue, &mut c);
                    match (packet[k], single) {
                        (Some(p), Some(s)) => {
                            shadowed[which] += 1;
                            assert!(
                                (p - s).abs() <= tolerance,
                                "{} shadow ray {k}: {p} against {s}",
                                demo.id()
                            );
                        }
                        (None, None) => {}
                        (p, s) => {
                            panic!("{} shadow ray {k}: packet {p:?}, single {s:?}", demo.id())
                        }
                    }
                }
            }
        }
    }
    assert!(
        shadowed.iter().all(|&s| s > 0),
        "no shadow ray was blocked: {shadowed:?}"
    );
}

/// A tile's shadow rays asked in order with one hint, as a tile's tracer asks them, get the
/// full query's answer ray by ray ([`settle`] of the any-hit root, no hint) on every demo,
/// towards a point and a directional light; the hinted leaf alone (no node of the tree
/// popped) answers some of the blocked ones, on most demos.
#[test]
fn occlusion_with_the_hint_answers_as_the_full_query_on_every_demo() {
    let (mut blocked, mut from_hint, mut with_hinted) = (0usize, 0usize, 0usize);
    let (mut witnessed, mut with_witnessed) = (0usize, 0usize);
    for (demo, prepared, m) in demos() {
        let rays = prepared.primary_rays(&demo.default_camera(), WIDTH, HEIGHT);
        let isovalue = demo.default_isovalue();
        let (mut demo_blocked, mut demo_hinted, mut demo_witnessed) = (0, 0, 0);
        for light in shadow_lights(&rays) {
            for rect in tiles() {
                let (shadow_rays, t_max) = tile_shadow_rays(m, &rays, rect, isovalue, light);
                let mut hint = OcclusionHint::default();
                for (k, (ray, &hi)) in shadow_rays.iter().zip(&t_max).enumerate() {
                    let mut c = MetaballCounters::default();
                    let got = m.occluded_counted(ray, (0.0, hi), isovalue, &mut hint, &mut c);
                    let mut full = MetaballCounters::default();
                    let root = m.any_hit_counted(ray, 0.0, hi, isovalue, &mut full);
                    let want = settle(m.as_ref(), ray, (0.0, hi), isovalue, root, &mut full);
                    assert_eq!(got, want, "{} {rect:?} shadow ray {k}", demo.id());
                    demo_blocked += want as usize;
                    demo_hinted += (got && c.node_traversals == 0) as usize;
                    // A witness answers without searching a leaf.
                    demo_witnessed += (got && c.node_traversals == 0 && c.leaf_tests == 0) as usize;
                }
            }
        }
        // At 48×40 the paper scenes' neighbouring rays mostly meet different leaves (a few
        // hinted answers on Scattered-30k, none on Tornado-128k); small scenes share many.
        with_hinted += (demo_hinted > 0) as usize;
        with_witnessed += (demo_witnessed > 0) as usize;
        blocked += demo_blocked;
        from_hint += demo_hinted;
        witnessed += demo_witnessed;
    }
    assert!(
        from_hint > 0 && from_hint < blocked && with_hinted * 2 > demos().len(),
        "{from_hint} of {blocked} blocked rays answered by the hint, on {with_hinted} demos"
    );
    assert!(
        witnessed > 0 && with_witnessed * 2 > demos().len(),
        "{witnessed} of {blocked} blocked rays answered by a witness, on {with_witnessed} demos"
    );
}

/// A tile's shadow rays handed to the kind together, as the renderer's shadow batch hands
/// them (packets of 64 with one hint, whose witnesses the earlier packets' roots leave):
/// every answer, settled, is the full query's, on every demo towards a point and a
/// directional light, and witnesses answered rays of later packets (their points differ from
/// the plain packet's roots; at 48×40 few tiles hold more than one packet).
#[test]
fn hinted_shadow_packets_settle_as_the_full_query_on_every_demo() {
    use crate::kinds::contract::PreparedKind;
    let (mut packed, mut witnessed, mut with_witnessed) = (0usize, 0usize, 0usize);
    for (demo, prepared, m) in demos() {
        let rays = prepared.primary_rays(&demo.default_camera(), WIDTH, HEIGHT);
        let isovalue = demo.default_isovalue();
        let mut demo_witnessed = 0;
        for light in shadow_lights(&rays) {
            for rect in tiles() {
                let (shadow_rays, t_max) = tile_shadow_rays(m, &rays, rect, isovalue, light);
                let mut hint = OcclusionHint::default();
                let mut c = MetaballCounters::default();
                let ask = (&shadow_rays[..], 0.0, &t_max[..], light, isovalue);
                let Some(found) =
                    m.any_hits_towards(ask.0, 0.0, ask.2, ask.3, ask.4, &[], &mut hint, &mut c)
                else {
                    continue;
                };
                let plain = m
                    .any_hits_packet(ask.0, 0.0, ask.2, ask.3, ask.4, &mut c)
                    .expect("a packet where the kind packs them");
                for (k, (ray, &hi)) in shadow_rays.iter().zip(&t_max).enumerate() {
                    let span = (0.0, hi);
                    let got = settle(m.as_ref(), ray, span, isovalue, found[k], &mut c);
                    let root = m.any_hit_counted(ray, 0.0, hi, isovalue, &mut c);
                    let want = settle(m.as_ref(), ray, span, isovalue, root, &mut c);
                    assert_eq!(got, want, "{} {rect:?} shadow ray {k}", demo.id());
                    packed += 1;
                    demo_witnessed += (found[k] != plain[k]) as usize;
                }
            }
        }
        with_witnessed += (demo_witnessed > 0) as usize;
        witnessed += demo_witnessed;
    }
    assert!(
        witnessed > 0 && witnessed < packed,
        "{witnessed} of {packed} packed rays answered by a witness, on {with_witnessed} demos"
    );
}

/// A hint left by one state is not used by another (its leaf is of another tree): the answer
/// is the full query's and the tree is walked.
#[test]
fn a_hint_from_another_state_is_not_used() {
    let (demo, prepared, m) = &demos()[0];
    let demo = *demo;
    // The same demo prepared again (a later time): another state, with a tree of its own.
    let other = match Arc::new(demo.state_at(2.0)).prepare().geometry() {
        PreparedGeometry::Metaballs(m) => m.clone(),
        _ => unreachable!("{} is a metaball demo", demo.id()),
    };
    let rays = prepared.primary_rays(&demo.default_camera(), WIDTH, HEIGHT);
    let isovalue = demo.default_isovalue();
    let [light, _] = shadow_lights(&rays);
    let mut hint = OcclusionHint::default();
    let mut c = MetaballCounters::default();
    let mut asked = 0;
    for rect in tiles() {
        let (shadow_rays, t_max) = tile_shadow_rays(m, &rays, rect, isovalue, light);
        for (ray, &hi) in shadow_rays.iter().zip(&t_max) {
            if m.occluded_counted(ray, (0.0, hi), isovalue, &mut hint, &mut c) {
                let mut walked = MetaballCounters::default();
                let got = other.occluded_counted(ray, (0.0, hi), isovalue, &mut hint, &mut walked);
                let mut full = MetaballCounters::default();
                let root = other.any_hit_counted(ray, 0.0, hi, isovalue, &mut full);
                assert_eq!(
                    got,
                    settle(other.as_ref(), ray, (0.0, hi), isovalue, root, &mut full)
                );
                assert!(
                    walked.node_traversals > 0,
                    "the other state's tree was walked"
                );
                asked += 1;
            }
        }
    }
    assert!(asked > 0, "no shadow ray of {} was blocked", demo.id());
}

/// Shadow rays whose start points spread over more than 8 mean ball radii are not traced as a
/// packet (the kind answers `None` and the caller traces them one by one); within it they are.
#[test]
fn spread_out_shadow_rays_fall_back_to_single_rays() {
    use crate::kinds::contract::PreparedKind;
    let (demo, _, m) = demos()
        .iter()
        .find(|(d, _, _)| *d == DemoScene::Pool)
        .expect("the pool demo");
    let r = m.mean_radius;
    assert!(r > 0.0);
    let light = Vec3::new(0.0, 50.0, 0.0);
    let from = |spread: f32| -> (Vec<Ray>, Vec<f32>) {
        [Vec3::ZERO, Vec3::new(spread, 0.0, 0.0) * r]
            .iter()
            .map(|&o| (Ray::new(o, light - o), (light - o).length()))
            .unzip()
    };
    let isovalue = demo.default_isovalue();
    let mut c = MetaballCounters::default();
    let (near, near_max) = from(7.9);
    assert!(m.shadow_packet_pays(&near, 0.0));
    let mut hint = OcclusionHint::default();
    let packet = m.any_hits_towards(
        &near,
        0.0,
        &near_max,
        Some(light),
        isovalue,
        &[],
        &mut hint,
        &mut c,
    );
    assert!(packet.is_some(), "a coherent pair is a packet");
    let (far, far_max) = from(8.1);
    assert!(!m.shadow_packet_pays(&far, 0.0));
    let packet = m.any_hits_towards(
        &far,
        0.0,
        &far_max,
        Some(light),
        isovalue,
        &[],
        &mut hint,
        &mut c,
    );
    assert!(packet.is_none(), "a spread pair is traced ray by ray");
}
