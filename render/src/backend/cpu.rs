//! The CPU backend: an image split into tiles, traced on a rayon pool.
//!
//! This is the one place in the engine that knows about threads. A render called from inside
//! the pool (as the server's render jobs are) runs its tiles on that same pool. Both kinds of
//! frame (ray casting, and a pass of an effects plan) go through the one tile loop,
//! [`trace_tiles`].

use crate::backend::accumulator::{self, Accumulator, DeviceTimes, FrameRays, Pass, TracePasses};
use crate::camera::PrimaryRays;
use crate::effects::plan::EffectsPlan;
use crate::effects::toggles::Effects;
use crate::framebuffer::{Framebuffer, SurfaceBuffer};
use crate::geom::clip::ClipBox;
use crate::geom::rng::PixelRng;
use crate::integrator::{shade_primary, Tracer, T_MAX};
use crate::kinds::counters::SceneCounters;
use crate::scene::PreparedScene;
use crate::view::View;
use glam::Vec3;
use rayon::prelude::*;

/// Tile edge in pixels: small enough to balance two to sixty-four workers on one frame.
const TILE: u32 = 16;

/// Most render threads a pool is asked for: far beyond any machine's cores, and short of the
/// thousands of threads a mistyped count would start.
pub const MAX_THREADS: usize = 1024;

/// A pool of render workers.
pub struct CpuBackend {
    pool: rayon::ThreadPool,
}

/// Why the pool could not be made.
#[derive(Debug, thiserror::Error)]
#[error("could not start the render pool: {0}")]
pub struct PoolError(#[from] rayon::ThreadPoolBuildError);

impl CpuBackend {
    /// A pool of `threads` workers (0: one per core).
    pub fn new(threads: usize) -> Result<CpuBackend, PoolError> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("isoray-render-{i}"))
            .build()?;
        Ok(CpuBackend { pool })
    }

    pub fn threads(&self) -> usize {
        self.pool.current_num_threads()
    }

    /// Runs `job` on the pool without waiting for it (the server's entry point).
    pub fn spawn(&self, job: impl FnOnce() + Send + 'static) {
        self.pool.spawn(job);
    }

    /// Renders one frame with primary rays only, blocking the caller until it is done.
    pub fn render(&self, scene: &PreparedScene, view: &View) -> Framebuffer {
        self.render_primary(scene, view).0
    }

    /// The primary hits' distances and normals, blocking: the same hits
    /// [`CpuBackend::render`] shades.
    pub fn render_surface(&self, scene: &PreparedScene, view: &View) -> SurfaceBuffer {
        self.pool.install(|| surface_tiles(scene, view, None))
    }

    /// [`CpuBackend::render_surface`] under `effects`: of them only the clip box changes
    /// which surface a camera ray meets first (the image's, [`Tracer::surface_hit`]).
    pub fn render_surface_effects(
        &self,
        scene: &PreparedScene,
        view: &View,
        effects: &Effects,
    ) -> SurfaceBuffer {
        let clip = accumulator::plan_for(scene, effects).clip_box;
        self.pool.install(|| surface_tiles(scene, view, clip))
    }

    /// Renders one frame with `effects` (its first refinement pass), blocking. A plan with
    /// primary rays only renders exactly as [`CpuBackend::render`] does.
    pub fn render_effects(
        &self,
        scene: &PreparedScene,
        view: &View,
        effects: &Effects,
    ) -> (Framebuffer, FrameRays) {
        accumulator::render_effects(self, scene, view, effects)
    }

    /// Adds one refinement pass to `accumulator` and returns the image of the mean so far
    /// (see [`accumulator::refine`]).
    pub fn refine(
        &self,
        scene: &PreparedScene,
        view: &View,
        effects: &Effects,
        accumulator: &mut Accumulator,
    ) -> Framebuffer {
        accumulator::refine(self, scene, view, effects, accumulator)
    }

    /// Refines until `accumulator` converges (see [`accumulator::refine_until_converged`]).
    pub fn refine_until_converged(
        &self,
        scene: &PreparedScene,
        view: &View,
        effects: &Effects,
        accumulator: &mut Accumulator,
    ) -> Framebuffer {
        accumulator::refine_until_converged(self, scene, view, effects, accumulator).0
    }
}

impl TracePasses for CpuBackend {
    fn render_primary(&self, scene: &PreparedScene, view: &View) -> (Framebuffer, DeviceTimes) {
        (
            self.pool.install(|| render_tiles(scene, view)),
            DeviceTimes::default(),
        )
    }

    fn trace_pass(
        &self,
        scene: &PreparedScene,
        view: &View,
        plan: &EffectsPlan,
        pass: u32,
    ) -> Pass {
        self.pool
            .install(|| trace_pass(scene, view, plan, pass, true))
    }

    fn encode_srgb(&self, colors: &[Vec3], rgb: &mut [u8]) {
        // Blocks of pixels on the pool: a frame's conversion is no serial tail after its
        // parallel trace.
        const BLOCK: usize = 4096;
        self.pool.install(|| {
            rgb.par_chunks_mut(BLOCK * 3)
                .zip(colors.par_chunks(BLOCK))
                .for_each(|(out, block)| crate::srgb::encode8_pixels(block, out));
        });
    }
}

/// A tile's pixels `x0..x1 × y0..y1`.
type Rect = (u32, u32, u32, u32);

/// A traced tile: its corner, its pixels and depths row by row, and its summary.
type TracedTile<P, S> = (u32, u32, Vec<P>, Vec<f32>, S);

/// The one tile loop: splits a `width × height` image into tiles, traces them in parallel
/// with `trace` (which returns a tile's pixels row by row, `per_pixel` values each, its
/// depths, and a summary), writes every tile into `pixels` and `depth` at its place, and
/// hands each summary to `fold`, in tile order.
#[allow(clippy::too_many_arguments)]
fn trace_tiles<P: Copy + Send, S: Send>(
    width: u32,
    height: u32,
    per_pixel: usize,
    trace: impl Fn(Rect) -> (Vec<P>, Vec<f32>, S) + Sync + Send,
    pixels: &mut [P],
    depth: &mut [f32],
    mut fold: impl FnMut(S),
) {
    let tiles_x = width.div_ceil(TILE);
    let tiles_y = height.div_ceil(TILE);
    // Split down to single tiles: rayon's adaptive splitting otherwise stops after about
    // `log2(threads) + 1` halvings unless a piece is stolen, and runs a quarter of the image
    // (on two threads) in one sequential piece that no idle thread can take a tile from; a
    // scene whose work sits in that quarter then keeps the other thread idle (Tornado-128k's
    // ray cast at 1920×1080 ran 1.3 times faster on two threads than on one).
    let tiles: Vec<TracedTile<P, S>> = (0..tiles_x * tiles_y)
        .into_par_iter()
        .with_max_len(1)
        .map(|tile| {
            let x0 = (tile % tiles_x) * TILE;
            let y0 = (tile / tiles_x) * TILE;
            let (x1, y1) = ((x0 + TILE).min(width), (y0 + TILE).min(height));
            let (p, d, s) = trace((x0, y0, x1, y1));
            (x0, y0, p, d, s)
        })
        .collect();
    for (x0, y0, p, d, s) in tiles {
        let tile_w = (TILE.min(width - x0)) as usize;
        for (row, (p_row, d_row)) in p
            .chunks_exact(tile_w * per_pixel)
            .zip(d.chunks_exact(tile_w))
            .enumerate()
        {
            let start = (y0 as usize + row) * width as usize + x0 as usize;
            pixels[start * per_pixel..(start + tile_w) * per_pixel].copy_from_slice(p_row);
            depth[start..start + tile_w].copy_from_slice(d_row);
        }
        fold(s);
    }
}

/// Ray casting: each tile's primary hits found together (a kind may trace them as a packet)
/// and shaded, straight to sRGB.
fn render_tiles(scene: &PreparedScene, view: &View) -> Framebuffer {
    let (width, height) = (view.width, view.height);
    let rays = scene.primary_rays(&view.camera, width, height);
    let forward = rays.forward();
    let spread = rays.pixel_spread();
    let mut fb = Framebuffer::new(width, height);
    let trace = |rect: Rect| {
        let (x0, y0, x1, y1) = rect;
        let n = ((x1 - x0) * (y1 - y0)) as usize;
        let mut rgb = Vec::with_capacity(n * 3);
        let mut depth = Vec::with_capacity(n);
        // Ray casting reports no counters (the frame's rays are its pixels).
        let mut counters = SceneCounters::default();
        for (ray, hit) in scene.primary_hits(&rays, rect, view.isovalue, T_MAX, &mut counters) {
            let (color, t) = shade_primary(scene, &ray, hit.as_ref(), view.isovalue, spread);
            rgb.extend(crate::srgb::encode8_rgb(color.to_array()));
            depth.push(t * ray.dir.dot(forward));
        }
        (rgb, depth, ())
    };
    trace_tiles(width, height, 3, trace, &mut fb.rgb, &mut fb.depth, |()| {});
    fb
}

/// Each tile's primary hits, as distance and normal.
fn surface_tiles(scene: &PreparedScene, view: &View, clip: Option<ClipBox>) -> SurfaceBuffer {
    let (width, height) = (view.width, view.height);
    let rays = scene.primary_rays(&view.camera, width, height);
    let n = width as usize * height as usize;
    let mut values = vec![0.0f32; n * SurfaceBuffer::CHANNELS];
    let mut distances = vec![f32::INFINITY; n];
    let plan = EffectsPlan {
        clip_box: clip,
        ..EffectsPlan::PRIMARY_ONLY
    };
    let trace = |rect: Rect| {
        let (x0, y0, x1, y1) = rect;
        let n = ((x1 - x0) * (y1 - y0)) as usize;
        let mut out = Vec::with_capacity(n * SurfaceBuffer::CHANNELS);
        let mut t_out = Vec::with_capacity(n);
        let hits = match clip {
            None => {
                let mut counters = SceneCounters::default();
                scene.primary_hits(&rays, rect, view.isovalue, T_MAX, &mut counters)
            }
            Some(_) => {
                let mut tracer = Tracer::new(scene, &plan, view.isovalue, rays.pixel_spread());
                (y0..y1)
                    .flat_map(|y| (x0..x1).map(move |x| (x, y)))
                    .map(|(x, y)| {
                        let ray = rays.through_pixel(x, y);
                        (ray, tracer.surface_hit(&ray))
                    })
                    .collect()
            }
        };
        for (_, hit) in hits {
            let px = match hit {
                Some(h) => [h.t, h.normal.x, h.normal.y, h.normal.z],
                None => [f32::INFINITY, 0.0, 0.0, 0.0],
            };
            out.extend(px);
            t_out.push(px[0]);
        }
        (out, t_out, ())
    };
    trace_tiles(
        width,
        height,
        SurfaceBuffer::CHANNELS,
        trace,
        &mut values,
        &mut distances,
        |()| {},
    );
    SurfaceBuffer {
        width,
        height,
        values,
    }
}

/// Pixel `(x, y)` of pass `pass`: its primary ray followed by `tracer`, in linear colour, and
/// the hit's distance along the view axis `forward` (infinite for a miss). The one place a
/// pixel is traced on the CPU (the GPU backend's retrace of cut pixels calls it too).
pub(crate) fn trace_pixel(
    tracer: &mut Tracer,
    rays: &PrimaryRays,
    forward: Vec3,
    (x, y): (u32, u32),
    pass: u32,
) -> (Vec3, f32) {
    let ray = rays.through_pixel(x, y);
    let (c, t) = tracer.primary(&ray, &mut PixelRng::new(x, y, pass));
    (c, t * ray.dir.dot(forward))
}

/// One pass of an effects plan: every pixel's primary ray followed by the integrator, in
/// linear colour, with its rays counted.
///
/// With `tile_hits` (always, outside tests) and a plan whose camera rays take their first
/// hit from the kind's tile query ([`Tracer::takes_tile_hits`]), each tile's camera rays are
/// traced together first (as a packet where the kind has one); the image is the same.
fn trace_pass(
    scene: &PreparedScene,
    view: &View,
    plan: &EffectsPlan,
    pass: u32,
    tile_hits: bool,
) -> Pass {
    let (width, height) = (view.width, view.height);
    let rays = scene.primary_rays(&view.camera, width, height);
    let forward = rays.forward();
    let spread = rays.pixel_spread();
    let n = width as usize * height as usize;
    let mut out = Pass {
        color: vec![Vec3::ZERO; n],
        depth: vec![f32::INFINITY; n],
        rays: FrameRays::default(),
    };
    let trace = |(x0, y0, x1, y1): Rect| {
        let n = ((x1 - x0) * (y1 - y0)) as usize;
        let mut color = Vec::with_capacity(n);
        let mut depth = Vec::with_capacity(n);
        let mut tracer = Tracer::new(scene, plan, view.isovalue, spread);
        if tile_hits && tracer.takes_tile_hits() {
            // The tile's camera rays' first hits together (a packet where the kind has one),
            // then each pixel's integrator from its hit: the image of `trace_pixel`.
            let hits = scene.primary_hits(
                &rays,
                (x0, y0, x1, y1),
                view.isovalue,
                T_MAX,
                &mut tracer.counters,
            );
            let pixels: Vec<(u32, u32)> = (y0..y1)
                .flat_map(|y| (x0..x1).map(move |x| (x, y)))
                .collect();
            for ((c, t), (ray, _)) in tracer
                .primaries_from(&hits, &pixels, pass)
                .into_iter()
                .zip(&hits)
            {
                color.push(c);
                depth.push(t * ray.dir.dot(forward));
            }
        } else {
            for y in y0..y1 {
                for x in x0..x1 {
                    let (c, d) = trace_pixel(&mut tracer, &rays, forward, (x, y), pass);
                    color.push(c);
                    depth.push(d);
                }
            }
        }
        let rays = FrameRays {
            rays: tracer.counts,
            counters: tracer.counters.totals(),
            kinds: tracer.counters,
            device: DeviceTimes::default(),
        };
        (color, depth, rays)
    };
    let mut total = FrameRays::default();
    trace_tiles(
        width,
        height,
        1,
        trace,
        &mut out.color,
        &mut out.depth,
        |r| total.add(&r),
    );
    out.rays = total;
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenes::DemoScene;
    use crate::View;
    use std::sync::Arc;

    #[test]
    fn ray_casting_draws_the_floor_as_the_integrator_does() {
        // A floor is scene geometry, not an effect: ray casting alone (the fast path of
        // primary rays, which shades the floor itself) draws it, and gives the integrator's
        // image: the same hits, depths and colours.
        let backend = CpuBackend::new(2).expect("pool");
        for demo in [DemoScene::Glass, DemoScene::Clouds, DemoScene::SurfelBalls] {
            let scene = Arc::new(demo.state_at(1.0)).prepare();
            assert!(
                scene.lighting_in_frame().floor.is_some(),
                "{demo:?} has a floor"
            );
            let view = demo.default_view(96, 72);
            assert!(accumulator::plan_for(&scene, &Effects::OFF).is_primary_only());
            let fast = backend.render_effects(&scene, &view, &Effects::OFF).0;
            let pass = backend.trace_pass(&scene, &view, &EffectsPlan::PRIMARY_ONLY, 0);
            let mut rgb = vec![0; fast.rgb.len()];
            backend.encode_srgb(&pass.color, &mut rgb);
            let floor = scene.lighting_in_frame().floor.expect("floor");
            let rays = scene.primary_rays(&view.camera, view.width, view.height);
            let mut floor_pixels = 0;
            for (i, (a, b)) in fast.depth.iter().zip(&pass.depth).enumerate() {
                let (x, y) = (i as u32 % view.width, i as u32 / view.width);
                assert_eq!(
                    a.is_finite(),
                    b.is_finite(),
                    "{demo:?} pixel ({x}, {y}): hit or miss"
                );
                if a.is_finite() {
                    assert_eq!(a, b, "{demo:?} ({x}, {y}): depth");
                    let ray = rays.through_pixel(x, y);
                    let at = ray.origin + ray.dir * (a / ray.dir.dot(rays.forward()));
                    floor_pixels += usize::from((at.y - floor.height).abs() < 1e-3);
                }
            }
            assert!(
                floor_pixels > 500,
                "{demo:?}: {floor_pixels} pixels on the floor"
            );
            assert!(fast.rgb == rgb, "{demo:?}: the colours differ");
        }
    }

    /// No thread holds a run of tiles that another thread could trace: while the first tile
    /// is held up, the other worker traces every other tile. Rayon's default splitting left
    /// a quarter of the image (tiles 1 to 3 of 16 here) queued behind the first tile on its
    /// thread, and this test then fails at its guard.
    #[test]
    fn a_tile_held_up_keeps_no_other_tile_waiting() {
        use std::sync::{Condvar, Mutex};
        use std::time::Duration;
        let (width, height) = (4 * TILE, 4 * TILE);
        let tiles = (width / TILE * (height / TILE)) as usize;
        let per_tile = (TILE * TILE) as usize;
        let traced = (Mutex::new(0usize), Condvar::new());
        let trace = |rect: Rect| {
            let (lock, changed) = &traced;
            let mut count = lock.lock().expect("count");
            if rect.0 == 0 && rect.1 == 0 {
                // A guard against a hang, not a timing: the other worker needs no more than
                // the time to trace 15 empty tiles.
                let (count, waited) = changed
                    .wait_timeout_while(count, Duration::from_secs(120), |c| *c < tiles - 1)
                    .expect("count");
                assert!(
                    !waited.timed_out(),
                    "{} of {} other tiles traced while the first was held up",
                    *count,
                    tiles - 1
                );
            } else {
                *count += 1;
                changed.notify_all();
            }
            (vec![0u8; per_tile], vec![0.0f32; per_tile], ())
        };
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .expect("pool");
        let (mut pixels, mut depth) = (vec![1u8; tiles * per_tile], vec![1.0f32; tiles * per_tile]);
        pool.install(|| trace_tiles(width, height, 1, trace, &mut pixels, &mut depth, |()| {}));
        assert!(pixels.iter().all(|&p| p == 0), "every tile written");
    }

    #[test]
    fn render_is_deterministic_across_thread_counts() {
        let demo = DemoScene::Blobs;
        let scene = Arc::new(demo.state_at(1.25)).prepare();
        let view = View {
            width: 37,
            height: 23,
            camera: demo.default_camera(),
            isovalue: 0.5,
        };
        let one = CpuBackend::new(1).expect("pool").render(&scene, &view);
        let two = CpuBackend::new(2).expect("pool").render(&scene, &view);
        assert_eq!(one, two);
        assert!(one.hit_count() > 0, "the default camera sees the blobs");
        assert!(one.hit_count() < 37 * 23, "and some background");
    }

    /// Every kind (metaball, tet and surfel packets): camera rays' first hits taken from the
    /// tile query, and with hard shadows alone the shadow rays traced together, give the
    /// image of asking pixel by pixel, bit for bit (with reflections and occlusion the shadow
    /// rays stay single); a clip box or a volume keeps the pixel-by-pixel path.
    #[test]
    fn effects_frames_from_tile_hits_are_the_pixel_by_pixel_frames() {
        let shadows = Effects {
            shadows: true,
            ..Effects::OFF
        };
        let more = Effects {
            reflections: true,
            ambient_occlusion: true,
            ao_samples: 2,
            ..shadows
        };
        let demos = [
            DemoScene::Blobs,
            DemoScene::Pool,
            DemoScene::Molecule,
            DemoScene::TetBucky,
            DemoScene::Glass,
            DemoScene::SurfelHeads,
            DemoScene::SurfelBalls,
        ];
        let (mut tiles_used, mut batched) = (0, 0);
        for demo in demos {
            let scene = Arc::new(demo.state_at(0.5)).prepare();
            let view = demo.default_view(40, 28);
            for effects in [shadows, more] {
                let plan = accumulator::plan_for(&scene, &effects);
                let tracer = Tracer::new(&scene, &plan, view.isovalue, 0.0);
                tiles_used += tracer.takes_tile_hits() as usize;
                batched += tracer.batches_shadows() as usize;
                let tiles = trace_pass(&scene, &view, &plan, 0, true);
                let pixels = trace_pass(&scene, &view, &plan, 0, false);
                assert!(
                    tiles.depth.iter().any(|d| d.is_finite()),
                    "{demo:?}: nothing hit"
                );
                assert_eq!(tiles.color, pixels.color, "{demo:?} {effects:?}: colours");
                let bits = |d: &[f32]| d.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&tiles.depth), bits(&pixels.depth), "{demo:?}: depths");
                assert_eq!(tiles.rays.rays, pixels.rays.rays, "{demo:?}: rays per kind");
            }
        }
        assert_eq!(tiles_used, 2 * demos.len(), "every demo took the tile path");
        assert_eq!(batched, demos.len(), "hard shadows alone were batched");
    }

    /// Metaball frames with every effect whose rays walk the Fitted BVH one by one (shadows,
    /// soft shadows, reflections, refraction, transparency, occlusion) are the same bit for bit
    /// whether single rays walk it four boxes at a time or node by node.
    #[test]
    fn the_wide_walk_renders_the_binary_walks_frames() {
        let all = Effects {
            clip_box: false,
            isosurfaces: false,
            ao_samples: 2,
            light_samples: 2,
            ..Effects::ALL
        };
        let hard = Effects {
            shadows: true,
            transparency: true,
            ..Effects::OFF
        };
        let mut compared = 0;
        for demo in [
            DemoScene::Blobs,
            DemoScene::Pool,
            DemoScene::Molecule,
            DemoScene::Glass,
        ] {
            let state = Arc::new(demo.state_at(0.5));
            let options = state.geometry.default_metaball_options();
            let binary = crate::kinds::metaballs::engine::PrepareOptions {
                wide: false,
                ..options
            };
            let (wide, node_by_node) = (Arc::clone(&state).prepare(), state.prepare_with(binary));
            let view = demo.default_view(48, 32);
            for effects in [hard, all] {
                let plan = accumulator::plan_for(&wide, &effects);
                let a = trace_pass(&wide, &view, &plan, 0, true);
                let b = trace_pass(&node_by_node, &view, &plan, 0, true);
                assert_eq!(a.color, b.color, "{demo:?} {effects:?}: colours");
                let bits = |d: &[f32]| d.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&a.depth), bits(&b.depth), "{demo:?}: depths");
                compared += a.depth.iter().filter(|d| d.is_finite()).count();
            }
        }
        assert!(compared > 2000, "only {compared} pixels hit");
    }
}

#[cfg(test)]
mod effects_tests {
    use super::*;
    use crate::effects::{Effects, RayCounts, RayKind};
    use crate::scenes::DemoScene;
    use crate::shade::Lighting;
    use crate::{Scene, View};
    use std::sync::Arc;

    fn view(demo: DemoScene) -> View {
        View {
            width: 40,
            height: 30,
            camera: demo.default_camera(),
            isovalue: 0.5,
        }
    }

    /// Renders `scene` with `a` and with `b` and asserts equal ray counts per kind and
    /// identical images; returns the counts.
    fn same_rays(scene: &PreparedScene, v: &View, a: Effects, b: Effects) -> RayCounts {
        let backend = CpuBackend::new(2).expect("pool");
        let (fa, ra) = backend.render_effects(scene, v, &a);
        let (fb, rb) = backend.render_effects(scene, v, &b);
        for kind in RayKind::ALL {
            assert_eq!(
                ra.rays.get(kind),
                rb.rays.get(kind),
                "{} rays differ between {a:?} and {b:?}",
                kind.name()
            );
        }
        assert_eq!(fa, fb, "the images differ");
        ra.rays
    }

    #[test]
    fn effects_no_material_can_use_trace_no_rays() {
        // Blobs: one directional light, one opaque, non-reflective material.
        let demo = DemoScene::Blobs;
        let scene = Arc::new(demo.state_at(1.0)).prepare();
        let v = view(demo);
        let pixels = (v.width * v.height) as u64;
        let off = Effects::OFF;
        let rays = same_rays(
            &scene,
            &v,
            off,
            Effects {
                reflections: true,
                depth: 3,
                refraction: true,
                transparency: true,
                soft_shadows: true,
                clip_box: true,
                isosurfaces: true,
                ..off
            },
        );
        assert_eq!(rays.get(RayKind::Primary), pixels);
        assert_eq!(rays.total(), pixels, "ray casting alone");

        // With shadows on (so the full integrator runs), unusable effects still add nothing.
        let shadows = Effects {
            shadows: true,
            ..off
        };
        let rays = same_rays(
            &scene,
            &v,
            shadows,
            Effects {
                reflections: true,
                refraction: true,
                transparency: true,
                depth: 3,
                ..shadows
            },
        );
        assert!(rays.get(RayKind::Shadow) > 0, "the light casts shadows");
        assert_eq!(rays.get(RayKind::Reflection), 0);
        assert_eq!(rays.get(RayKind::Refraction), 0);
        assert_eq!(rays.get(RayKind::Transparency), 0);

        // No light: shadows switched on trace nothing.
        let dark = Scene {
            lighting: Lighting {
                lights: Vec::new(),
                ..Lighting::default()
            },
            ..demo.state_at(1.0)
        };
        let dark = Arc::new(dark).prepare();
        let rays = same_rays(&dark, &v, off, shadows);
        assert_eq!(rays.total(), pixels);
    }

    #[test]
    fn effects_a_material_uses_trace_their_rays() {
        let demo = DemoScene::Glass;
        let scene = Arc::new(demo.state_at(1.0)).prepare();
        let v = view(demo);
        let backend = CpuBackend::new(2).expect("pool");
        let on = Effects {
            depth: 1,
            ..scene.scene().lighting.effects
        };
        let (_, rays) = backend.render_effects(&scene, &v, &on);
        for kind in [RayKind::Shadow, RayKind::Reflection, RayKind::Refraction] {
            assert!(rays.rays.get(kind) > 0, "{} rays", kind.name());
        }
        let deeper = Effects { depth: 3, ..on };
        let (_, deep) = backend.render_effects(&scene, &v, &deeper);
        assert!(deep.rays.get(RayKind::Reflection) > rays.rays.get(RayKind::Reflection));
    }

    fn soft_shadow_view() -> (PreparedScene, View, Effects) {
        let demo = DemoScene::Glass;
        let scene = Arc::new(demo.state_at(1.0)).prepare();
        let effects = Effects {
            shadows: true,
            soft_shadows: true,
            light_samples: 2,
            ..Effects::OFF
        };
        (scene, view(demo), effects)
    }

    #[test]
    fn refinement_of_soft_shadows_converges() {
        let (scene, v, effects) = soft_shadow_view();
        let backend = CpuBackend::new(2).expect("pool");
        let mut acc = Accumulator::new(40);
        acc.threshold = 0.0;
        let mut deltas = Vec::new();
        loop {
            backend.refine(&scene, &v, &effects, &mut acc);
            if acc.passes() >= 2 {
                deltas.push(acc.last_delta());
            }
            if acc.converged() {
                break;
            }
        }
        assert_eq!(acc.passes(), 40);
        // The change from one pass to the next falls monotonically on average: its means over
        // blocks of eight passes strictly decrease (it goes as 1/k for a running mean).
        let blocks: Vec<f32> = deltas
            .chunks(8)
            .map(|c| c.iter().sum::<f32>() / c.len() as f32)
            .collect();
        assert!(
            blocks.windows(2).all(|w| w[1] < w[0]),
            "block means {blocks:?}"
        );
        assert!(blocks[0] > 0.0, "soft shadows are sampled");
        assert!(
            blocks[blocks.len() - 1] < blocks[0] / 4.0,
            "block means {blocks:?}"
        );
    }

    #[test]
    fn refinement_stops_once_converged() {
        let (scene, v, effects) = soft_shadow_view();
        let backend = CpuBackend::new(2).expect("pool");
        let mut acc = Accumulator::new(2000);
        let image = backend.refine_until_converged(&scene, &v, &effects, &mut acc);
        let passes = acc.passes();
        assert!(
            (2..2000).contains(&passes),
            "converged by its threshold after {passes} passes"
        );
        assert!(acc.last_delta() < acc.threshold);
        // Converged: further calls render nothing and return the same image.
        let again = backend.refine(&scene, &v, &effects, &mut acc);
        assert_eq!(acc.passes(), passes);
        assert_eq!(again, image);
        // Without anything random in the plan, one pass is final.
        let hard = Effects {
            soft_shadows: false,
            ..effects
        };
        let mut acc = Accumulator::new(2000);
        backend.refine(&scene, &v, &hard, &mut acc);
        assert!(acc.converged() && acc.passes() == 1);
    }
}
