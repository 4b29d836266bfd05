//! The CPU backend: an image split into tiles, traced on a rayon pool.
//!
//! This is the one place in the engine that knows about threads. A render called from inside
//! the pool (as the server's render jobs are) runs its tiles on that same pool.

use crate::effects::{Effects, EffectsPlan, RayCounts, RayKind};
use crate::framebuffer::Framebuffer;
use crate::geom::counters::RayTotals;
use crate::geom::rng::PixelRng;
use crate::integrator::{shade_primary, Tracer, T_MAX};
use crate::kinds::counters::SceneCounters;
use crate::scene::PreparedScene;
use crate::shade::linear_to_srgb8;
use crate::View;
use glam::Vec3;
use rayon::prelude::*;

/// Tile edge in pixels: small enough to balance two to sixty-four workers on one frame.
const TILE: u32 = 16;

/// The render backends, a closed set: the pass-level seam the server renders through. A new
/// backend (the wgpu one) is a new variant; each method dispatches here and nowhere else.
pub enum Backend {
    /// Tiles traced on a rayon pool of this machine's cores.
    Cpu(CpuBackend),
}

impl Backend {
    /// The CPU backend with `threads` workers (0: one per core).
    pub fn cpu(threads: usize) -> Result<Backend, PoolError> {
        Ok(Backend::Cpu(CpuBackend::new(threads)?))
    }

    /// The backend's name, for logs and metrics.
    pub fn name(&self) -> &'static str {
        match self {
            Backend::Cpu(_) => "cpu",
        }
    }

    /// Worker threads that trace on the CPU.
    pub fn threads(&self) -> usize {
        match self {
            Backend::Cpu(cpu) => cpu.threads(),
        }
    }

    /// Runs a render job (trace and encode of one frame) on the backend's workers without
    /// waiting for it.
    pub fn spawn(&self, job: impl FnOnce() + Send + 'static) {
        match self {
            Backend::Cpu(cpu) => cpu.spawn(job),
        }
    }

    /// Renders one frame with primary rays only, blocking the caller until it is done.
    pub fn render(&self, scene: &PreparedScene, view: &View) -> Framebuffer {
        match self {
            Backend::Cpu(cpu) => cpu.render(scene, view),
        }
    }

    /// See [`CpuBackend::render_effects`].
    pub fn render_effects(
        &self,
        scene: &PreparedScene,
        view: &View,
        effects: &Effects,
    ) -> (Framebuffer, FrameRays) {
        match self {
            Backend::Cpu(cpu) => cpu.render_effects(scene, view, effects),
        }
    }

    /// See [`CpuBackend::refine`].
    pub fn refine(
        &self,
        scene: &PreparedScene,
        view: &View,
        effects: &Effects,
        accumulator: &mut Accumulator,
    ) -> Framebuffer {
        match self {
            Backend::Cpu(cpu) => cpu.refine(scene, view, effects, accumulator),
        }
    }
}

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

    /// Renders one frame, blocking the caller until it is done.
    pub fn render(&self, scene: &PreparedScene, view: &View) -> Framebuffer {
        self.pool.install(|| render_tiles(scene, view))
    }
}

fn render_tiles(scene: &PreparedScene, view: &View) -> Framebuffer {
    let (width, height) = (view.width, view.height);
    let rays = view.camera.rays(width, height);
    let forward = rays.forward();
    let tiles_x = width.div_ceil(TILE);
    let tiles_y = height.div_ceil(TILE);
    let tiles: Vec<(u32, u32, Vec<u8>, Vec<f32>)> = (0..tiles_x * tiles_y)
        .into_par_iter()
        .map(|tile| {
            let x0 = (tile % tiles_x) * TILE;
            let y0 = (tile / tiles_x) * TILE;
            let (x1, y1) = ((x0 + TILE).min(width), (y0 + TILE).min(height));
            let n = ((x1 - x0) * (y1 - y0)) as usize;
            let mut rgb = Vec::with_capacity(n * 3);
            let mut depth = Vec::with_capacity(n);
            // Ray casting reports no counters (the frame's rays are its pixels).
            let mut counters = SceneCounters::default();
            for (ray, hit) in
                scene.primary_hits(&rays, (x0, y0, x1, y1), view.isovalue, T_MAX, &mut counters)
            {
                let (color, t) = shade_primary(scene, &ray, hit.as_ref());
                rgb.extend([color.x, color.y, color.z].map(linear_to_srgb8));
                depth.push(t * ray.dir.dot(forward));
            }
            (x0, y0, rgb, depth)
        })
        .collect();

    let mut fb = Framebuffer::new(width, height);
    for (x0, y0, rgb, depth) in tiles {
        let tile_w = (TILE.min(width - x0)) as usize;
        for (row, (rgb_row, depth_row)) in rgb
            .chunks_exact(tile_w * 3)
            .zip(depth.chunks_exact(tile_w))
            .enumerate()
        {
            let start = (y0 as usize + row) * width as usize + x0 as usize;
            fb.rgb[start * 3..(start + tile_w) * 3].copy_from_slice(rgb_row);
            fb.depth[start..start + tile_w].copy_from_slice(depth_row);
        }
    }
    fb
}

// ---- Effects: frames traced by the effects plan, and progressive refinement. ----

/// One frame's rays, per ray kind, and the counters of their queries: the summary over
/// every primitive kind, and each kind's own.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameRays {
    pub rays: RayCounts,
    pub counters: RayTotals,
    pub kinds: SceneCounters,
}

impl CpuBackend {
    /// Renders one frame with `effects` (its first refinement pass), blocking. A plan with
    /// primary rays only renders exactly as [`CpuBackend::render`] does.
    pub fn render_effects(
        &self,
        scene: &PreparedScene,
        view: &View,
        effects: &Effects,
    ) -> (Framebuffer, FrameRays) {
        let plan = plan_for(scene, effects);
        if plan.is_primary_only() {
            let fb = self.render(scene, view);
            let mut rays = FrameRays::default();
            rays.rays
                .add_n(RayKind::Primary, view.width as u64 * view.height as u64);
            return (fb, rays);
        }
        let pass = self.pool.install(|| trace_pass(scene, view, &plan, 0));
        let mut fb = Framebuffer::new(view.width, view.height);
        for (i, c) in pass.color.iter().enumerate() {
            fb.rgb[i * 3..i * 3 + 3].copy_from_slice(&[c.x, c.y, c.z].map(linear_to_srgb8));
        }
        fb.depth = pass.depth;
        (fb, pass.rays)
    }

    /// Adds one refinement pass to `accumulator` (reset first if the frame it holds differs)
    /// and returns the image of the mean so far. Once converged it renders nothing and
    /// returns the same image again.
    pub fn refine(
        &self,
        scene: &PreparedScene,
        view: &View,
        effects: &Effects,
        accumulator: &mut Accumulator,
    ) -> Framebuffer {
        if accumulator.width != view.width || accumulator.height != view.height {
            accumulator.reset(view.width, view.height);
        }
        if !accumulator.converged {
            let plan = plan_for(scene, effects);
            if plan.is_primary_only() {
                // Ray casting has nothing to refine: one frame by the fast path is final.
                let fb = self.render(scene, view);
                accumulator.passes = 1;
                accumulator.converged = true;
                accumulator.last_delta = f32::INFINITY;
                accumulator.sum.clear();
                accumulator.fixed = Some(fb.clone());
                return fb;
            }
            let pass_index = accumulator.passes;
            let pass = self
                .pool
                .install(|| trace_pass(scene, view, &plan, pass_index));
            accumulator.add(pass, plan.is_stochastic());
        }
        accumulator.image()
    }
}

/// The plan of `effects` on `scene`.
pub fn plan_for(scene: &PreparedScene, effects: &Effects) -> EffectsPlan {
    let s = scene.scene();
    EffectsPlan::new(&s.lighting, s.primitive_count(), effects)
}

/// One pass: linear colour and depth per pixel, and its rays.
pub struct Pass {
    pub color: Vec<Vec3>,
    pub depth: Vec<f32>,
    pub rays: FrameRays,
}

fn trace_pass(scene: &PreparedScene, view: &View, plan: &EffectsPlan, pass: u32) -> Pass {
    let (width, height) = (view.width, view.height);
    let rays = view.camera.rays(width, height);
    let forward = rays.forward();
    let tiles_x = width.div_ceil(TILE);
    let tiles_y = height.div_ceil(TILE);
    type Tile = (u32, u32, Vec<Vec3>, Vec<f32>, FrameRays);
    let tiles: Vec<Tile> = (0..tiles_x * tiles_y)
        .into_par_iter()
        .map(|tile| {
            let x0 = (tile % tiles_x) * TILE;
            let y0 = (tile / tiles_x) * TILE;
            let (x1, y1) = ((x0 + TILE).min(width), (y0 + TILE).min(height));
            let n = ((x1 - x0) * (y1 - y0)) as usize;
            let mut color = Vec::with_capacity(n);
            let mut depth = Vec::with_capacity(n);
            let mut tracer = Tracer::new(scene, plan, view.isovalue);
            for y in y0..y1 {
                for x in x0..x1 {
                    let ray = rays.through_pixel(x, y);
                    let mut rng = PixelRng::new(x, y, pass);
                    let (c, t) = tracer.primary(&ray, &mut rng);
                    color.push(c);
                    depth.push(t * ray.dir.dot(forward));
                }
            }
            let rays = FrameRays {
                rays: tracer.counts,
                counters: tracer.counters.totals(),
                kinds: tracer.counters,
            };
            (x0, y0, color, depth, rays)
        })
        .collect();
    let n = width as usize * height as usize;
    let mut out = Pass {
        color: vec![Vec3::ZERO; n],
        depth: vec![f32::INFINITY; n],
        rays: FrameRays::default(),
    };
    for (x0, y0, color, depth, rays) in tiles {
        let tile_w = (TILE.min(width - x0)) as usize;
        for (row, (c_row, d_row)) in color
            .chunks_exact(tile_w)
            .zip(depth.chunks_exact(tile_w))
            .enumerate()
        {
            let start = (y0 as usize + row) * width as usize + x0 as usize;
            out.color[start..start + tile_w].copy_from_slice(c_row);
            out.depth[start..start + tile_w].copy_from_slice(d_row);
        }
        out.rays.rays.add(&rays.rays);
        out.rays.counters.add(&rays.counters);
        out.rays.kinds.add(&rays.kinds);
    }
    out
}

/// Progressive refinement of one still view: the sum of every pass so far, per pixel.
///
/// Each pass draws new samples for soft shadows and occlusion (the per-pixel streams are
/// seeded by the pass number), and the image shown is the mean. The refinement converges when
/// the mean changes by less than [`Accumulator::threshold`] per pixel and channel on average
/// from one pass to the next, or after [`Accumulator::max_passes`]; a plan with nothing
/// random converges after its first pass.
#[derive(Clone, Debug)]
pub struct Accumulator {
    width: u32,
    height: u32,
    sum: Vec<Vec3>,
    depth: Vec<f32>,
    /// The final image of a plan with nothing to accumulate.
    fixed: Option<Framebuffer>,
    passes: u32,
    converged: bool,
    /// Mean absolute change of the linear mean from the previous pass (`INFINITY` before 2).
    last_delta: f32,
    /// Convergence: mean per-channel change of the linear mean below this.
    pub threshold: f32,
    pub max_passes: u32,
}

impl Default for Accumulator {
    fn default() -> Accumulator {
        Accumulator::new(DEFAULT_MAX_PASSES)
    }
}

/// Passes after which refinement stops even if it has not met its threshold.
pub const DEFAULT_MAX_PASSES: u32 = 64;
/// A mean change of 1e-4 in linear light is a twentieth of one 8-bit sRGB step at mid-grey.
pub const DEFAULT_THRESHOLD: f32 = 1.0e-4;

impl Accumulator {
    pub fn new(max_passes: u32) -> Accumulator {
        Accumulator {
            width: 0,
            height: 0,
            sum: Vec::new(),
            depth: Vec::new(),
            fixed: None,
            passes: 0,
            converged: false,
            last_delta: f32::INFINITY,
            threshold: DEFAULT_THRESHOLD,
            max_passes: max_passes.max(1),
        }
    }

    /// Forgets every pass (the view, scene or effects changed).
    pub fn reset(&mut self, width: u32, height: u32) {
        self.width = width;
        self.height = height;
        self.sum.clear();
        self.depth.clear();
        self.fixed = None;
        self.passes = 0;
        self.converged = false;
        self.last_delta = f32::INFINITY;
    }

    pub fn passes(&self) -> u32 {
        self.passes
    }

    pub fn converged(&self) -> bool {
        self.converged
    }

    /// Mean absolute per-channel change of the mean image made by the last pass.
    pub fn last_delta(&self) -> f32 {
        self.last_delta
    }

    fn add(&mut self, pass: Pass, stochastic: bool) {
        if self.passes == 0 {
            self.sum = pass.color;
            self.depth = pass.depth;
        } else {
            let k = self.passes as f32;
            let mut change = 0.0f64;
            for (s, c) in self.sum.iter_mut().zip(&pass.color) {
                // |(S + c)/(k + 1) - S/k| = |c - S/k| / (k + 1)
                let d = (*c - *s / k).abs() / (k + 1.0);
                change += (d.x + d.y + d.z) as f64;
                *s += *c;
            }
            self.last_delta = (change / (3.0 * self.sum.len().max(1) as f64)) as f32;
        }
        self.passes += 1;
        self.converged = !stochastic
            || self.passes >= self.max_passes
            || (self.passes >= 2 && self.last_delta < self.threshold);
    }

    /// The mean of the passes so far, as an sRGB frame.
    pub fn image(&self) -> Framebuffer {
        if let Some(fb) = &self.fixed {
            return fb.clone();
        }
        let mut fb = Framebuffer::new(self.width, self.height);
        if self.passes == 0 {
            return fb;
        }
        let inv = 1.0 / self.passes as f32;
        for (i, s) in self.sum.iter().enumerate() {
            let c = *s * inv;
            fb.rgb[i * 3..i * 3 + 3].copy_from_slice(&[c.x, c.y, c.z].map(linear_to_srgb8));
        }
        fb.depth.clone_from(&self.depth);
        fb
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenes::DemoScene;
    use crate::View;
    use std::sync::Arc;

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
}

#[cfg(test)]
mod effects_tests {
    use super::*;
    use crate::effects::{Effects, RayKind};
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
        let mut image = backend.refine(&scene, &v, &effects, &mut acc);
        while !acc.converged() {
            image = backend.refine(&scene, &v, &effects, &mut acc);
        }
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
