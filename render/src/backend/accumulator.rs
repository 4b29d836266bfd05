//! Above the backends: the frame logic every backend shares. A backend traces passes
//! ([`TracePasses`]); a frame with effects is its first pass, and progressive refinement
//! ([`Accumulator`]) the mean of its passes.

use crate::effects::plan::EffectsPlan;
use crate::effects::rays::{RayCounts, RayKind};
use crate::effects::toggles::Effects;
use crate::framebuffer::Framebuffer;
use crate::geom::counters::RayTotals;
use crate::kinds::counters::SceneCounters;
use crate::scene::PreparedScene;
use crate::view::View;
use glam::Vec3;

/// Time a device (the GPU) spent on passes, by stage, in microseconds; all zero for passes
/// traced on the CPU. `passes` counts the passes the device traced.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DeviceTimes {
    pub passes: u32,
    /// Writing the frame's uniform, the lighting arrays and (when the state changed) the
    /// kind's arrays into the device's buffers.
    pub upload_us: u64,
    /// From the dispatch to the kernel's end (the copy into the readback buffer included).
    pub trace_us: u64,
    /// Mapping the readback buffer and copying the pixels out.
    pub readback_us: u64,
}

impl DeviceTimes {
    pub fn add(&mut self, o: &DeviceTimes) {
        self.passes += o.passes;
        self.upload_us += o.upload_us;
        self.trace_us += o.trace_us;
        self.readback_us += o.readback_us;
    }
}

/// One frame's rays, per ray kind, and the counters of their queries: the summary over
/// every primitive kind, and each kind's own; and what a device spent on them.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameRays {
    pub rays: RayCounts,
    pub counters: RayTotals,
    pub kinds: SceneCounters,
    pub device: DeviceTimes,
}

impl FrameRays {
    pub fn add(&mut self, o: &FrameRays) {
        self.rays.add(&o.rays);
        self.counters.add(&o.counters);
        self.kinds.add(&o.kinds);
        self.device.add(&o.device);
    }
}

/// One pass: linear colour and depth per pixel, and its rays.
pub struct Pass {
    pub color: Vec<Vec3>,
    pub depth: Vec<f32>,
    pub rays: FrameRays,
}

/// What a backend does: the pass-level seam. Everything above it (effects frames,
/// refinement) is written once, in this file.
pub trait TracePasses {
    /// One frame of primary rays only (ray casting), blocking; with the device's stage times
    /// when a device traced it.
    fn render_primary(&self, scene: &PreparedScene, view: &View) -> (Framebuffer, DeviceTimes);
    /// One pass of `plan` (pass `pass` seeds the per-pixel random streams), blocking.
    fn trace_pass(&self, scene: &PreparedScene, view: &View, plan: &EffectsPlan, pass: u32)
        -> Pass;
    /// Linear colours to 8-bit sRGB, three bytes a colour into `rgb`, blocking; a backend
    /// with a pool of its own converts in parallel there.
    fn encode_srgb(&self, colors: &[Vec3], rgb: &mut [u8]) {
        crate::srgb::encode8_pixels(colors, rgb);
    }
}

/// The plan of `effects` on `scene`.
pub fn plan_for(scene: &PreparedScene, effects: &Effects) -> EffectsPlan {
    let s = scene.scene();
    EffectsPlan::new(scene.lighting_in_frame(), s.primitive_count(), effects)
}

/// Renders one frame with `effects` (its first refinement pass), blocking. A plan with
/// primary rays only renders exactly as [`TracePasses::render_primary`] does.
pub fn render_effects(
    backend: &impl TracePasses,
    scene: &PreparedScene,
    view: &View,
    effects: &Effects,
) -> (Framebuffer, FrameRays) {
    let plan = plan_for(scene, effects);
    if plan.is_primary_only() {
        let (fb, device) = backend.render_primary(scene, view);
        let mut rays = FrameRays {
            device,
            ..FrameRays::default()
        };
        rays.rays
            .add_n(RayKind::Primary, view.width as u64 * view.height as u64);
        return (fb, rays);
    }
    let pass = backend.trace_pass(scene, view, &plan, 0);
    let mut fb = Framebuffer::new(view.width, view.height);
    backend.encode_srgb(&pass.color, &mut fb.rgb);
    fb.depth = pass.depth;
    (fb, pass.rays)
}

/// Adds one refinement pass to `accumulator` (reset first if the frame it holds differs)
/// and returns the image of the mean so far. Once converged it renders nothing and returns
/// the same image again. [`Accumulator::last_device`] says what a device spent on the pass.
pub fn refine(
    backend: &impl TracePasses,
    scene: &PreparedScene,
    view: &View,
    effects: &Effects,
    accumulator: &mut Accumulator,
) -> Framebuffer {
    if accumulator.width != view.width || accumulator.height != view.height {
        accumulator.reset(view.width, view.height);
    }
    accumulator.last_device = DeviceTimes::default();
    if !accumulator.converged {
        let plan = plan_for(scene, effects);
        let antialiased = accumulator.antialias > 1;
        if plan.is_primary_only() && !antialiased {
            // Ray casting has nothing to refine: one frame by the fast path is final.
            let (fb, device) = backend.render_primary(scene, view);
            accumulator.last_device = device;
            accumulator.passes = 1;
            accumulator.converged = true;
            accumulator.last_delta = f32::INFINITY;
            accumulator.sum.clear();
            accumulator.fixed = Some(fb.clone());
            return fb;
        }
        let pass_index = accumulator.passes;
        // Antialiasing: every pass after the first sees the view from a sub-pixel offset.
        let jittered;
        let traced = if antialiased && pass_index > 0 {
            let camera = view
                .camera
                .jittered(subpixel_offset(pass_index), view.height);
            jittered = View { camera, ..*view };
            &jittered
        } else {
            view
        };
        let pass = backend.trace_pass(scene, traced, &plan, pass_index);
        accumulator.last_device = pass.rays.device;
        accumulator.add(pass, plan.is_stochastic());
    }
    accumulator.image()
}

/// [`refine`] until `accumulator` converges: the image of the mean of its passes, and what a
/// device spent on them all.
pub fn refine_until_converged(
    backend: &impl TracePasses,
    scene: &PreparedScene,
    view: &View,
    effects: &Effects,
    accumulator: &mut Accumulator,
) -> (Framebuffer, DeviceTimes) {
    let mut device = DeviceTimes::default();
    loop {
        let fb = refine(backend, scene, view, effects, accumulator);
        device.add(&accumulator.last_device);
        if accumulator.converged {
            return (fb, device);
        }
    }
}

/// The offset in pixels, each coordinate in `[-0.5, 0.5)`, from which antialiasing pass
/// `pass` sees the view: the pixel's centre for pass 0, then the 2-D Halton sequence (bases 2
/// and 3), which covers the pixel evenly at every count.
pub fn subpixel_offset(pass: u32) -> (f32, f32) {
    if pass == 0 {
        return (0.0, 0.0);
    }
    let radical_inverse = |mut n: u32, base: u32| {
        let (mut value, mut scale) = (0.0f32, 1.0f32);
        while n > 0 {
            scale /= base as f32;
            value += (n % base) as f32 * scale;
            n /= base;
        }
        value
    };
    (
        radical_inverse(pass, 2) - 0.5,
        radical_inverse(pass, 3) - 0.5,
    )
}

/// Progressive refinement of one still view: the sum of every pass so far, per pixel.
///
/// Each pass draws new samples for soft shadows and occlusion (the per-pixel streams are
/// seeded by the pass number), and, with [`Accumulator::antialias`], sees the view from a new
/// sub-pixel offset, so that edges and fine detail average over the pixel's area; the image
/// shown is the mean (its depths are the first pass's, at the pixels' centres). The
/// refinement converges when the mean changes by less than [`Accumulator::threshold`] per
/// pixel and channel on average from one pass to the next and the antialiasing positions are
/// done, or after [`Accumulator::max_passes`]; without antialiasing a plan with nothing random
/// converges after its first pass.
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
    /// What a device spent on the last call of [`refine`] (zero when the CPU traced it or
    /// nothing was traced).
    last_device: DeviceTimes,
    /// Convergence: mean per-channel change of the linear mean below this.
    pub threshold: f32,
    pub max_passes: u32,
    /// Sub-pixel positions ([`subpixel_offset`]) a still view averages before it may
    /// converge (0 or 1: the pixels' centres only, and a plan with nothing random is final
    /// after one pass).
    pub antialias: u32,
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
            last_device: DeviceTimes::default(),
            threshold: DEFAULT_THRESHOLD,
            max_passes: max_passes.max(1),
            antialias: 0,
        }
    }

    /// Exactly `passes` passes, each from its own sub-pixel position, whatever the change
    /// between them (a one-shot image's average).
    pub fn fixed_passes(passes: u32) -> Accumulator {
        let mut accumulator = Accumulator::new(passes);
        accumulator.antialias = passes;
        accumulator.threshold = 0.0;
        accumulator
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

    /// What a device spent on the last call of [`refine`].
    pub fn last_device(&self) -> DeviceTimes {
        self.last_device
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
        let settled = !stochastic || (self.passes >= 2 && self.last_delta < self.threshold);
        self.converged =
            self.passes >= self.max_passes || (self.passes >= self.antialias && settled);
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
            fb.rgb[i * 3..i * 3 + 3].copy_from_slice(&crate::srgb::encode8_rgb(c.to_array()));
        }
        fb.depth.clone_from(&self.depth);
        fb
    }
}
