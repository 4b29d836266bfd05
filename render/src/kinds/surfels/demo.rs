//! The demo scenes of deforming-point-sampled-surfaces.txt §5, driven by
//! [`crate::kinds::surfels::sim`]: 40 elastic balls thrown into a hollow cube (Fig. 9); a
//! large bumpy object (the paper's Armadillo scale, Table 1: 150k surfels, ~450 nodes) hit
//! by a cannonball (Fig. 6); three bouncing cubes whose faces meet at sharp edges through
//! clipping relations (Fig. 8). `detail` scales the surfel counts (1 = full size; tests use
//! small values).

use crate::camera::Camera;
use crate::kinds::surfels::model::{Surfel, SurfelError, SurfelModel, SurfelSet};
use crate::kinds::surfels::sample;
use crate::kinds::surfels::scene::{SurfelOptions, SurfelRuntime, SurfelScene};
use crate::kinds::surfels::sim::{Body, Simulation};
use glam::{Mat3, Vec3};
use std::sync::Arc;

/// The three demos.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SurfelDemoKind {
    Balls,
    Impact,
    Heads,
}

impl SurfelDemoKind {
    pub const ALL: [SurfelDemoKind; 3] = [
        SurfelDemoKind::Balls,
        SurfelDemoKind::Impact,
        SurfelDemoKind::Heads,
    ];

    pub fn name(self) -> &'static str {
        match self {
            SurfelDemoKind::Balls => "surfel-balls",
            SurfelDemoKind::Impact => "surfel-impact",
            SurfelDemoKind::Heads => "surfel-heads",
        }
    }
}

/// One simulated step: node displacements and Jacobians.
pub type Step = (Arc<[Vec3]>, Arc<[Mat3]>);

/// A demo: its object, the simulated steps and a camera that frames it.
pub struct SurfelDemo {
    pub model: Arc<SurfelModel>,
    pub steps: Vec<Step>,
    pub camera: Camera,
}

impl SurfelDemo {
    /// Step `k` (wrapping) as a scene.
    pub fn scene(
        &self,
        k: usize,
        options: SurfelOptions,
        runtime: Arc<SurfelRuntime>,
    ) -> SurfelScene {
        let (u, g) = &self.steps[k % self.steps.len()];
        SurfelScene {
            model: self.model.clone(),
            displacement: u.clone(),
            gradient: g.clone(),
            options,
            runtime,
        }
    }
}

/// Time step of the simulations, seconds (two substeps per frame at 30 fps).
const DT: f32 = 1.0 / 60.0;

struct Builder {
    surfels: Vec<Surfel>,
    nodes: Vec<Vec3>,
    node_body: Vec<u16>,
    bodies: Vec<Body>,
    clip: Vec<(u16, u16)>,
}

impl Builder {
    fn new() -> Builder {
        Builder {
            surfels: Vec::new(),
            nodes: Vec::new(),
            node_body: Vec::new(),
            bodies: Vec::new(),
            clip: Vec::new(),
        }
    }

    fn body(&mut self, surfels: Vec<Surfel>, nodes: Vec<Vec3>, radius: f32, stiffness: f32) {
        let b = self.bodies.len() as u16;
        let start = self.nodes.len();
        self.surfels.extend(surfels);
        self.node_body.extend(nodes.iter().map(|_| b));
        self.nodes.extend(nodes);
        self.bodies.push(Body {
            nodes: start..self.nodes.len(),
            radius,
            stiffness,
        });
    }

    fn finish(self, lo: Vec3, hi: Vec3) -> Result<(Arc<SurfelModel>, Simulation), SurfelError> {
        let sim = Simulation::new(self.nodes.clone(), self.bodies, lo, hi);
        let model = SurfelModel::new(
            SurfelSet {
                surfels: self.surfels,
                nodes: self.nodes,
                node_mass: Vec::new(),
                clip: self.clip,
                node_body: self.node_body,
                // Balls, a blob and cubes: every body a closed, outward surface.
                closed: true,
            },
            usize::MAX,
        )?;
        Ok((Arc::new(model), sim))
    }
}

/// Builds demo `kind` with `frames` simulated steps.
pub fn build(kind: SurfelDemoKind, detail: f32, frames: usize) -> Result<SurfelDemo, SurfelError> {
    let count = |n: f32| ((n * detail) as usize).max(64);
    let (model, mut sim, camera) = match kind {
        SurfelDemoKind::Balls => balls(count(6000.0))?,
        SurfelDemoKind::Impact => impact(count(150_000.0), count(3000.0))?,
        SurfelDemoKind::Heads => heads(((60.0 * detail.sqrt()) as usize).max(8))?,
    };
    let mut steps = Vec::with_capacity(frames);
    for _ in 0..frames {
        sim.step(DT);
        sim.step(DT);
        let (u, g) = sim.deformation();
        steps.push((u.into(), g.into()));
    }
    Ok(SurfelDemo {
        model,
        steps,
        camera,
    })
}

fn balls(per_ball: usize) -> Result<(Arc<SurfelModel>, Simulation, Camera), SurfelError> {
    let r = 0.25;
    let mut b = Builder::new();
    let palette = [
        Vec3::new(0.8, 0.2, 0.15),
        Vec3::new(0.2, 0.6, 0.25),
        Vec3::new(0.2, 0.35, 0.85),
        Vec3::new(0.85, 0.7, 0.15),
    ];
    let mut starts = Vec::new();
    for i in 0..40 {
        // Rest shapes apart on a wide grid; start positions packed in the cube's top half.
        let rest = Vec3::new((i % 8) as f32, 0.0, (i / 8) as f32) * 1.0;
        let start = Vec3::new(
            -1.05 + 0.6 * (i % 5) as f32,
            0.2 + 0.55 * (i / 20) as f32,
            -1.05 + 0.6 * ((i / 5) % 4) as f32,
        );
        starts.push(start - rest);
        let nodes = sample::lattice(rest - Vec3::splat(r), rest + Vec3::splat(r), r / 2.2, |p| {
            (p - rest).length() <= 0.95 * r
        });
        b.body(
            sample::sphere(rest, r, per_ball, palette[i % 4], 0),
            nodes,
            r,
            0.35,
        );
    }
    let (model, mut sim) = b.finish(Vec3::splat(-1.5), Vec3::splat(1.5))?;
    for (i, off) in starts.iter().enumerate() {
        sim.place(i, *off);
        let spin = ((i * 7) % 11) as f32 / 11.0 - 0.5;
        sim.throw(i, Vec3::new(3.0 * spin, -1.0, 2.0 * (0.5 - spin)));
    }
    let camera = Camera {
        eye: Vec3::new(0.0, 1.2, 5.2),
        target: Vec3::new(0.0, -0.3, 0.0),
        up: Vec3::Y,
        fov_y_deg: 45.0,
    };
    Ok((model, sim, camera))
}

fn impact(
    blob_surfels: usize,
    ball_surfels: usize,
) -> Result<(Arc<SurfelModel>, Simulation, Camera), SurfelError> {
    let mut b = Builder::new();
    let size = 1.0;
    let centre = Vec3::ZERO;
    let nodes = sample::lattice(Vec3::splat(-1.3), Vec3::splat(1.3), 0.21, |p| {
        sample::inside_blob(p, centre, size, -0.05)
    });
    b.body(
        sample::blob(centre, size, blob_surfels, Vec3::new(0.75, 0.62, 0.45), 0),
        nodes,
        1.15,
        0.12,
    );
    let ball_rest = Vec3::new(4.0, 0.0, 0.0);
    let r = 0.3;
    let nodes = sample::lattice(
        ball_rest - Vec3::splat(r),
        ball_rest + Vec3::splat(r),
        0.14,
        |p| (p - ball_rest).length() <= 0.9 * r,
    );
    b.body(
        sample::sphere(ball_rest, r, ball_surfels, Vec3::splat(0.25), 1),
        nodes,
        r,
        1.0,
    );
    // Walls close enough that the knocked blob bounces back into view within the loop.
    let (model, mut sim) = b.finish(Vec3::new(-2.6, -1.3, -2.6), Vec3::new(2.8, 2.2, 2.6))?;
    sim.place(1, Vec3::new(-1.6, 0.35, 0.1));
    sim.throw(1, Vec3::new(-7.0, 0.5, 0.0));
    sim.gravity = Vec3::ZERO;
    let camera = Camera {
        eye: Vec3::new(0.6, 0.8, 4.2),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 45.0,
    };
    Ok((model, sim, camera))
}

fn heads(per_side: usize) -> Result<(Arc<SurfelModel>, Simulation, Camera), SurfelError> {
    let mut b = Builder::new();
    let half = 0.4;
    let mut starts = Vec::new();
    for i in 0..3u16 {
        let rest = Vec3::new(3.0 * i as f32, 0.0, 0.0);
        let tint = [
            Vec3::new(0.8, 0.3, 0.2),
            Vec3::new(0.3, 0.7, 0.3),
            Vec3::new(0.3, 0.4, 0.85),
        ][i as usize];
        let colours = [0.6, 0.7, 0.8, 0.9, 1.0, 0.75].map(|s| tint * s);
        let (surfels, clip) = sample::cube(rest, half, per_side, colours, 6 * i);
        let nodes = sample::lattice(
            rest - Vec3::splat(half),
            rest + Vec3::splat(half),
            0.2,
            |_| true,
        );
        b.clip.extend(clip);
        b.body(surfels, nodes, half * 1.2, 0.3);
        starts.push(Vec3::new(-1.4 + 1.4 * i as f32, 0.4 + 0.5 * i as f32, 0.0) - rest);
    }
    let (model, mut sim) = b.finish(Vec3::new(-2.5, -1.0, -2.5), Vec3::splat(2.5))?;
    for (i, off) in starts.iter().enumerate() {
        sim.place(i, *off);
        sim.throw(i, Vec3::new(0.3 * (1.0 - i as f32), 0.0, 0.2));
    }
    let camera = Camera {
        eye: Vec3::new(0.0, 0.8, 5.0),
        target: Vec3::new(0.0, -0.2, 0.0),
        up: Vec3::Y,
        fov_y_deg: 45.0,
    };
    Ok((model, sim, camera))
}

/// Surfels of demo `kind` at `detail`, without building it (the demo list shows the count
/// before anyone watches; [`build`] makes exactly this many).
pub fn surfel_count(kind: SurfelDemoKind, detail: f32) -> usize {
    let count = |n: f32| ((n * detail) as usize).max(64);
    match kind {
        SurfelDemoKind::Balls => 40 * count(6000.0),
        SurfelDemoKind::Impact => count(150_000.0) + count(3000.0),
        SurfelDemoKind::Heads => {
            let per_side = ((60.0 * detail.sqrt()) as usize).max(8);
            3 * 6 * (per_side + 4) * (per_side + 4)
        }
    }
}

#[cfg(test)]
mod count_tests {
    use super::*;

    #[test]
    fn surfel_count_is_what_build_makes() {
        for kind in SurfelDemoKind::ALL {
            for detail in [0.005, 0.02] {
                let demo = build(kind, detail, 1).expect("valid demo");
                assert_eq!(
                    demo.model.len(),
                    surfel_count(kind, detail),
                    "{kind:?} {detail}"
                );
            }
        }
    }
}
