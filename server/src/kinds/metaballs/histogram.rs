//! The histogram of a metaball field, for the isovalue slider's background.
//!
//! How it works: a regular grid over the scene's bounds, at most [`MAX_GRID`] points per
//! axis; every metaball adds `q · f(s)` to the grid points inside its support (a splat, so
//! the cost is the balls' support volume in cells, not balls × points). Points that no
//! support reaches are left out: they are empty space, not field. The grid shrinks when the
//! splat would cost more than [`MAX_SPLAT_CELLS`].

use crate::kinds::histogram::Histogram;
use glam::Vec3;
use isoray_render::kinds::metaballs::MetaballScene;

/// Grid points along the longest side of the scene's bounds.
pub const MAX_GRID: u32 = 64;
/// Largest number of (ball, grid point) pairs one histogram evaluates.
pub const MAX_SPLAT_CELLS: f64 = 5.0e7;

/// The field's values at the grid points inside any support, binned over `[lo, hi)`.
pub fn field_histogram(scene: &MetaballScene, lo: f32, hi: f32, bins: usize) -> Histogram {
    let mut out = Histogram::empty(bins);
    let Some((min, max)) = scene.bounds() else {
        return out;
    };
    let extent = (max - min).max(Vec3::splat(1e-6));
    let mut cell = extent.max_element() / MAX_GRID as f32;
    // Splat cost: each ball touches about (2R / cell)³ grid points.
    let cost = |cell: f32| -> f64 {
        scene
            .balls
            .iter()
            .map(|b| (2.0 * f64::from(b.radius) / f64::from(cell) + 1.0).powi(3))
            .sum()
    };
    let estimate = cost(cell);
    if estimate > MAX_SPLAT_CELLS {
        cell *= (estimate / MAX_SPLAT_CELLS).cbrt() as f32;
        while cost(cell) > MAX_SPLAT_CELLS {
            cell *= 1.1;
        }
    }
    let dims = (extent / cell)
        .ceil()
        .max(Vec3::ONE)
        .as_uvec3()
        .min(glam::UVec3::splat(MAX_GRID));
    out.grid = dims.to_array();
    let (nx, ny, nz) = (dims.x as usize, dims.y as usize, dims.z as usize);
    // Grid point (i, j, k) sits at the centre of its cell.
    let point = |i: usize, j: usize, k: usize| {
        min + Vec3::new(i as f32 + 0.5, j as f32 + 0.5, k as f32 + 0.5) * cell
    };
    let mut field = vec![0f32; nx * ny * nz];
    let mut inside = vec![false; nx * ny * nz];
    let index_range = |c: f32, r: f32, lo: f32, n: usize| {
        let first = (((c - r - lo) / cell) - 0.5).floor().max(0.0) as usize;
        let last = ((((c + r - lo) / cell) - 0.5).ceil().max(0.0) as usize).min(n - 1);
        first..=last
    };
    for ball in &scene.balls {
        let (c, r) = (ball.center, ball.radius);
        for k in index_range(c.z, r, min.z, nz) {
            for j in index_range(c.y, r, min.y, ny) {
                for i in index_range(c.x, r, min.x, nx) {
                    out.evaluations += 1;
                    let s = ball.s_at(point(i, j, k));
                    if s < 1.0 {
                        let at = (k * ny + j) * nx + i;
                        field[at] += ball.strength * scene.kernel.value(s);
                        inside[at] = true;
                    }
                }
            }
        }
    }
    let values = field
        .iter()
        .zip(&inside)
        .filter(|(_, &i)| i)
        .map(|(&v, _)| v);
    out.add(values, lo, hi);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use isoray_render::kinds::metaballs::{Kernel, Metaball};

    /// One ball: the grid points where the field is at least `t` fill the sphere of radius
    /// `R · sqrt(s(t))`, so their count is that sphere's volume in cells.
    #[test]
    fn one_ball_matches_the_sphere_volumes() {
        let radius = 2.0;
        let scene = MetaballScene::new(
            Kernel::Wyvill,
            vec![Metaball::sphere(Vec3::ZERO, radius, 1.0, Vec3::ONE)],
        );
        let bins = 100;
        let h = field_histogram(&scene, 0.0, 1.0, bins);
        assert_eq!(h.grid, [MAX_GRID; 3]);
        let cell = 2.0 * radius as f64 / MAX_GRID as f64;
        let ball_cells = |r: f64| 4.0 / 3.0 * std::f64::consts::PI * r.powi(3) / cell.powi(3);
        let total = ball_cells(radius as f64);
        assert!(
            (h.samples as f64 - total).abs() < 0.02 * total,
            "{} samples inside the support, expected about {total:.0}",
            h.samples
        );
        for t in [0.1f32, 0.3, 0.5, 0.8] {
            let at_least: u64 = h.counts[(t * bins as f32).round() as usize..].iter().sum();
            let r_t = radius as f64 * f64::from(Kernel::Wyvill.s_at_value(t)).sqrt();
            let expected = ball_cells(r_t);
            assert!(
                (at_least as f64 - expected).abs() < 0.03 * expected + 50.0,
                "field ≥ {t}: {at_least} points, expected about {expected:.0}"
            );
        }
        assert_eq!(h.samples, h.below + h.above + h.counts.iter().sum::<u64>());
    }

    #[test]
    fn overlapping_balls_add_and_empty_scenes_are_empty() {
        let two = MetaballScene::new(
            Kernel::Wyvill,
            vec![
                Metaball::sphere(Vec3::ZERO, 1.0, 1.0, Vec3::ONE),
                Metaball::sphere(Vec3::ZERO, 1.0, 1.0, Vec3::ONE),
            ],
        );
        let h = field_histogram(&two, 0.0, 2.0, 2);
        // Doubled strength: values above 1 exist (near the centre), none at or above 2.
        assert!(h.counts[1] > 0 && h.above == 0, "{h:?}");
        let empty = MetaballScene::new(Kernel::Wyvill, Vec::new());
        let h = field_histogram(&empty, 0.0, 1.0, 8);
        assert_eq!((h.samples, h.counts), (0, vec![0; 8]));
    }

    #[test]
    fn many_large_balls_shrink_the_grid_to_the_budget() {
        let balls = (0..20_000)
            .map(|i| Metaball::sphere(Vec3::new(i as f32 * 1e-4, 0.0, 0.0), 1.0, 1.0, Vec3::ONE))
            .collect();
        let h = field_histogram(&MetaballScene::new(Kernel::Wyvill, balls), 0.0, 1.0, 4);
        let points: u32 = h.grid.iter().product();
        assert!(points < MAX_GRID.pow(3), "grid {:?}", h.grid);
        assert!(
            h.evaluations as f64 <= MAX_SPLAT_CELLS && h.evaluations > 1_000_000,
            "{} evaluations on grid {:?}",
            h.evaluations,
            h.grid
        );
    }
}
