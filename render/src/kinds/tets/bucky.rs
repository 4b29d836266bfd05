//! The deforming bucky ball demo (tetrahedral-isosurface-ray-tracing.txt Fig. 4, top: "an
//! artificially created deforming bucky ball that shows severe deformation of its 226K tets,
//! running at 50+ frames per second including shadows from a point light source").
//!
//! How it is made: a ball of radius 1.9 cut from a jittered Kuhn grid of 36³ cubes (about
//! 146,000 tets) carries a material field, the sum of a smooth bump `(1 - d²/R²)³` around each
//! of the 60 atoms of a C60 buckyball (bond length [`BOND`], `R` = one bond), sampled once at
//! the rest positions; at the isovalue 0.5 the surface is the ball-and-stick cage. Each step
//! moves every vertex by a smooth, severe deformation (a squash and stretch of ±35 % along
//! `y`, volume-preserving across it, a twist about `y` and a travelling bulge), so the cage
//! squashes, twists and ripples while its connectivity stays: a deforming mesh, refitted per
//! step (§6.2, [`crate::kinds::tets::prepared::REFIT_DEGRADATION`]). Lighting: one point
//! light with shadows on, over a floor that catches them.

use crate::effects::toggles::Effects;
use crate::kinds::tets::generate::{buckyball, grid_mesh, sample};
use crate::kinds::tets::mesh::{TetMesh, TetScene};
use crate::shade::{Floor, Light, Lighting, Material};
use glam::Vec3;
use rayon::prelude::*;
use std::sync::{Arc, OnceLock};

/// Bond length of the demo's cage (C60's edges, scaled).
pub const BOND: f32 = 0.55;

/// Radius of the meshed ball.
const RADIUS: f32 = 1.9;

/// Cube cells across the ball's diameter.
pub const BUCKY_CELLS: usize = 36;

/// The isovalue a viewer starts with: the cage.
pub const BUCKY_ISOVALUE: f32 = 0.5;

/// The rest mesh and its material field (built once).
fn rest() -> &'static (Arc<TetMesh>, Arc<[f32]>) {
    static REST: OnceLock<(Arc<TetMesh>, Arc<[f32]>)> = OnceLock::new();
    // Built with no lock held: the build forks on the pool (crate::once).
    crate::once::built(&REST, || {
        let mesh = Arc::new(grid_mesh(
            [BUCKY_CELLS; 3],
            Vec3::splat(-RADIUS),
            Vec3::splat(RADIUS),
            0.2,
            0xB0C4,
            |c| c.length() < RADIUS,
        ));
        // C60 with edge 2, scaled to the bond length.
        let atoms: Vec<Vec3> = buckyball().iter().map(|a| *a * (BOND / 2.0)).collect();
        let field = sample(mesh.vertices(), |p| {
            atoms
                .iter()
                .map(|a| {
                    let w = 1.0 - (p - *a).length_squared() / (BOND * BOND);
                    if w > 0.0 {
                        w * w * w
                    } else {
                        0.0
                    }
                })
                .sum()
        });
        (mesh, field)
    })
}

/// Where the rest point `p` is at `time` seconds.
pub fn deform(p: Vec3, time: f64) -> Vec3 {
    let t = time as f32;
    let stretch = 1.0 + 0.35 * (0.8 * t).sin();
    let across = 1.0 / stretch.sqrt();
    let q = Vec3::new(p.x * across, p.y * stretch, p.z * across);
    let (s, c) = (0.6 * (0.5 * t).sin() * q.y).sin_cos();
    let q = Vec3::new(c * q.x - s * q.z, q.y, s * q.x + c * q.z);
    let bulge = 1.0 + 0.08 * (2.0 * t + 3.0 * q.y).sin();
    Vec3::new(q.x * bulge, q.y, q.z * bulge)
}

/// The demo at `time`: the material field on the mesh moved by [`deform`].
pub fn bucky_state(time: f64) -> TetScene {
    let (mesh, field) = rest();
    let moved: Vec<Vec3> = mesh
        .vertices()
        .par_iter()
        .with_min_len(4096)
        .map(|&p| deform(p, time))
        .collect();
    TetScene::new(mesh.clone(), field.clone())
        .expect("the field is finite")
        .with_positions(moved.into())
        .expect("the deformation inverts no tet")
        .with_color_range(0.0, 1.2)
}

/// Tets of the demo mesh.
pub fn bucky_tet_count() -> usize {
    rest().0.tets().len()
}

/// One point light with shadows on, over a floor below the stretched cage.
pub fn bucky_lighting() -> Lighting {
    Lighting {
        lights: vec![Light::Point {
            position: Vec3::new(3.0, 6.0, 4.0),
            color: Vec3::splat(60.0),
        }],
        materials: vec![
            Material::default(),
            Material {
                diffuse: Vec3::splat(0.8),
                ..Material::default()
            },
        ],
        floor: Some(Floor {
            height: -2.7,
            material: 1,
            colors: [Vec3::splat(0.75), Vec3::splat(0.25)],
            checker: 0.8,
        }),
        effects: Effects {
            shadows: true,
            ..Effects::OFF
        },
        ..Lighting::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bucky_ball_deforms_without_inverting_and_shows_its_cage() {
        for time in [0.0, 1.9, 3.9, 6.0] {
            let step = bucky_state(time);
            assert!(step.deforms());
            let (lo, hi) = step.isovalue_range();
            assert!(lo < BUCKY_ISOVALUE && BUCKY_ISOVALUE < hi);
        }
        assert!(bucky_tet_count() > 140_000, "{}", bucky_tet_count());
        // Severe: the cage stretches and squashes by a third along y.
        let top = |t: f64| deform(Vec3::new(0.0, 1.0, 0.0), t).y;
        assert!(
            top(1.96) > 1.3 && top(5.9) < 0.7,
            "{} {}",
            top(1.96),
            top(5.9)
        );
    }
}
