//! The surfel demos of the demo list (deforming-point-sampled-surfaces.txt §5): each is
//! simulated once, on first use, for `FRAMES` frames at 30 fps, and played in a loop; every
//! step of one demo shares its object (the model built once) and its per-pixel sphere-node
//! cache. The sizes: the impact scene at the paper's Armadillo scale (153,000 surfels), the
//! ball pit and the clipped cubes smaller so they stay interactive on two cores.

use crate::camera::Camera;
use crate::kinds::surfels::demo::{self, SurfelDemo, SurfelDemoKind};
use crate::kinds::surfels::scene::{SurfelOptions, SurfelRuntime, SurfelScene};
use std::sync::{Arc, OnceLock};

/// Simulated frames per demo loop (8 s at 30 fps).
pub const FRAMES: usize = 240;
/// Frames per second of simulated time.
pub const FPS: f64 = 30.0;

/// The detail (scale of surfel counts) each demo is served at.
pub fn detail(kind: SurfelDemoKind) -> f32 {
    match kind {
        SurfelDemoKind::Balls => 0.1,
        SurfelDemoKind::Impact => 1.0,
        SurfelDemoKind::Heads => 0.05,
    }
}

/// Surfels in the served demo.
pub fn count(kind: SurfelDemoKind) -> usize {
    demo::surfel_count(kind, detail(kind))
}

struct Served {
    demo: SurfelDemo,
    runtime: Arc<SurfelRuntime>,
}

fn served(kind: SurfelDemoKind) -> &'static Served {
    static CELLS: [OnceLock<Served>; 3] = [OnceLock::new(), OnceLock::new(), OnceLock::new()];
    let slot = match kind {
        SurfelDemoKind::Balls => 0,
        SurfelDemoKind::Impact => 1,
        SurfelDemoKind::Heads => 2,
    };
    // Built with no lock held: the build forks on the pool (crate::once).
    crate::once::built(&CELLS[slot], || Served {
        // The demos are fixed, valid objects: a failure here is a bug in the generator.
        demo: demo::build(kind, detail(kind), FRAMES).expect("the surfel demos are valid"),
        runtime: Arc::new(SurfelRuntime::default()),
    })
}

/// The demo's step at `time` seconds (looping), built on first use.
pub fn state_at(kind: SurfelDemoKind, time: f64) -> SurfelScene {
    let s = served(kind);
    let frame = (time.max(0.0) * FPS).floor() as usize % FRAMES;
    s.demo
        .scene(frame, SurfelOptions::default(), Arc::clone(&s.runtime))
}

/// The demo's camera (no build needed).
pub fn camera(kind: SurfelDemoKind) -> Camera {
    let look = |eye: glam::Vec3, target: glam::Vec3| Camera {
        eye,
        target,
        up: glam::Vec3::Y,
        fov_y_deg: 45.0,
    };
    match kind {
        SurfelDemoKind::Balls => look(
            glam::Vec3::new(0.0, 1.2, 5.2),
            glam::Vec3::new(0.0, -0.3, 0.0),
        ),
        SurfelDemoKind::Impact => look(glam::Vec3::new(0.6, 0.8, 4.2), glam::Vec3::ZERO),
        SurfelDemoKind::Heads => look(
            glam::Vec3::new(0.0, 0.8, 5.0),
            glam::Vec3::new(0.0, -0.2, 0.0),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cameras_are_the_demos_own() {
        for kind in SurfelDemoKind::ALL {
            let built = demo::build(kind, 0.005, 1).expect("valid demo");
            assert_eq!(camera(kind), built.camera, "{kind:?}");
        }
    }
}
