//! The surfel demos of the demo list (deforming-point-sampled-surfaces.txt §5): each is
//! simulated once, on first use, for `FRAMES` frames at 30 fps, and played in a loop; every
//! step of one demo shares its object (the model built once) and its per-pixel sphere-node
//! cache. The sizes: the impact scene at the paper's Armadillo scale (153,000 surfels), the
//! ball pit and the clipped cubes smaller so they stay interactive on two cores.

use crate::camera::Camera;
use crate::effects::Effects;
use crate::kinds::surfels::demo::{self, SurfelDemo, SurfelDemoKind};
use crate::kinds::surfels::scene::{SurfelOptions, SurfelRuntime, SurfelScene};
use crate::shade::{Floor, Lighting, Material};
use glam::Vec3;
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

/// The demo's lighting: the default light, and where the simulation has a floor the balls
/// land on or the cubes bounce off (the ball pit's box, the cubes' ground), a checker floor
/// there, so a viewer sees them land and (with shadows) their contact shadows. The impact
/// scene's object floats: no floor (its streaming figure with shadows is measured so).
pub fn lighting(kind: SurfelDemoKind) -> Lighting {
    let height = match kind {
        SurfelDemoKind::Balls => -1.5,
        SurfelDemoKind::Heads => -1.0,
        SurfelDemoKind::Impact => return Lighting::default(),
    };
    Lighting {
        materials: vec![
            Material::default(),
            Material {
                specular: 0.0,
                ..Material::default()
            },
        ],
        floor: Some(Floor {
            height,
            material: 1,
            colors: [Vec3::splat(0.55), Vec3::splat(0.3)],
            checker: 0.5,
        }),
        // Objects on a floor without their shadows look as if they float: hard shadows on
        // (about 1.4 times a ray-cast pass of the ball pit at 640×480).
        effects: Effects {
            shadows: true,
            ..Effects::OFF
        },
        ..Lighting::default()
    }
}

/// The demo's camera (no build needed).
pub fn camera(kind: SurfelDemoKind) -> Camera {
    let look = |eye: Vec3, target: Vec3| Camera {
        eye,
        target,
        up: Vec3::Y,
        fov_y_deg: 45.0,
    };
    match kind {
        SurfelDemoKind::Balls => look(Vec3::new(0.0, 1.2, 5.2), Vec3::new(0.0, -0.3, 0.0)),
        SurfelDemoKind::Impact => look(Vec3::new(0.6, 0.8, 4.2), Vec3::ZERO),
        SurfelDemoKind::Heads => look(Vec3::new(0.0, 0.8, 5.0), Vec3::new(0.0, -0.2, 0.0)),
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
