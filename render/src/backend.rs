//! The CPU backend: an image split into tiles, traced on a rayon pool.
//!
//! This is the one place in the engine that knows about threads. A render called from inside
//! the pool (as the server's render jobs are) runs its tiles on that same pool.

use crate::framebuffer::Framebuffer;
use crate::integrator::trace_primary;
use crate::scene::PreparedScene;
use crate::shade::linear_to_srgb8;
use crate::View;
use rayon::prelude::*;

/// Tile edge in pixels: small enough to balance two to sixty-four workers on one frame.
const TILE: u32 = 16;

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
            for y in y0..y1 {
                for x in x0..x1 {
                    let ray = rays.through_pixel(x, y);
                    let (color, t) = trace_primary(scene, &ray, view.isovalue);
                    rgb.extend([color.x, color.y, color.z].map(linear_to_srgb8));
                    depth.push(t * ray.dir.dot(forward));
                }
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
