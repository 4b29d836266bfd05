//! The pixels a driver cut short, traced again on the CPU.
//!
//! Mesa's software Vulkan driver (lavapipe, llvmpipe's code generator; the CI's GPU) counts
//! the loop iterations of each SIMD group of kernel invocations (8 pixels with AVX2) in one
//! budget of 65,535 that every loop of the kernel shares, and once it is spent ends every loop
//! after its current iteration without a word: a pixel loses the rays still waiting on its
//! stack and a root search stops early. The group's pixels share the budget, so a pixel's
//! image depended on its neighbours (issue 12: Glass through its layers, the tet gyroid's
//! occlusion through further isosurfaces). The kernel notices (`CUT` in common.wgsl: its
//! integrator loop only ends in an iteration of its own that finds the stack empty, which a
//! cut anywhere earlier prevents) and, when the frame asks (`flags::MARK_CUT`), writes
//! [`CUT_DEPTH`]; those pixels, a few percent of a
//! heavy frame on lavapipe and none on a hardware GPU, are traced here by the CPU's
//! integrator with the same ray and the same random stream.

use crate::backend::cpu::trace_pixel;
use crate::effects::plan::EffectsPlan;
use crate::integrator::Tracer;
use crate::scene::PreparedScene;
use crate::view::View;

/// The depth the kernel writes for a pixel it could not finish (`CUT` in common.wgsl).
pub const CUT_DEPTH: f32 = -2.0;

/// Traces every pixel of `pixels` (the kernel's output of refinement pass `pass` with `plan`)
/// marked [`CUT_DEPTH`] again on the CPU and writes its colour and depth in the kernel's
/// convention (`-1`: a miss). Returns how many there were.
pub fn retrace_cut(
    pixels: &mut [[f32; 4]],
    scene: &PreparedScene,
    view: &View,
    plan: &EffectsPlan,
    pass: u32,
) -> usize {
    let rays = scene.primary_rays(&view.camera, view.width, view.height);
    let forward = rays.forward();
    let mut tracer = Tracer::new(scene, plan, view.isovalue, rays.pixel_spread());
    let mut cut = 0;
    for (i, p) in pixels.iter_mut().enumerate() {
        if p[3] != CUT_DEPTH {
            continue;
        }
        cut += 1;
        let (x, y) = (i as u32 % view.width, i as u32 / view.width);
        let (c, depth) = trace_pixel(&mut tracer, &rays, forward, (x, y), pass);
        let depth = if depth.is_finite() { depth } else { -1.0 };
        *p = [c.x, c.y, c.z, depth];
    }
    cut
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::accumulator::{self, TracePasses};
    use crate::backend::cpu::CpuBackend;
    use crate::scenes::DemoScene;
    use std::sync::Arc;

    /// Marked pixels get the CPU backend's colour and depth of the same pass, in the kernel's
    /// convention; the others are left as they are.
    #[test]
    fn marked_pixels_get_the_cpu_backends_pixels() {
        let demo = DemoScene::Glass;
        let scene = Arc::new(demo.state_at(1.0)).prepare();
        let view = demo.default_view(24, 18);
        let plan = accumulator::plan_for(&scene, &scene.lighting().effects);
        let pass = 3;
        let cpu = CpuBackend::new(1)
            .expect("pool")
            .trace_pass(&scene, &view, &plan, pass);
        let untouched = [0.25, 0.5, 0.75, 1.5];
        let mut pixels: Vec<[f32; 4]> = (0..cpu.color.len())
            .map(|i| {
                if i % 5 == 2 {
                    [0.0, 0.0, 0.0, CUT_DEPTH]
                } else {
                    untouched
                }
            })
            .collect();
        let marked = pixels.iter().filter(|p| p[3] == CUT_DEPTH).count();
        assert_eq!(retrace_cut(&mut pixels, &scene, &view, &plan, pass), marked);
        let (mut hits, mut misses) = (0, 0);
        for (i, p) in pixels.iter().enumerate() {
            if i % 5 != 2 {
                assert_eq!(*p, untouched, "pixel {i} left alone");
                continue;
            }
            let c = cpu.color[i];
            assert_eq!([p[0], p[1], p[2]], [c.x, c.y, c.z], "pixel {i}'s colour");
            if cpu.depth[i].is_finite() {
                assert_eq!(p[3], cpu.depth[i], "pixel {i}'s depth");
                hits += 1;
            } else {
                assert_eq!(p[3], -1.0, "pixel {i} a miss");
                misses += 1;
            }
        }
        assert!(
            hits > 0 && misses > 0,
            "both kinds checked ({hits}, {misses})"
        );
    }
}
