//! Progressive refinement of a resting view, for one session.
//!
//! While the view and the scene time stay the same, each still frame the session asks for is
//! one more pass accumulated by the engine ([`isoray_render::Accumulator`]): soft shadows and
//! ambient occlusion get more samples per pixel with every frame, and the first
//! `--antialias-passes` see the view from sub-pixel offsets (antialiasing). Once the engine says the
//! accumulation converged, [`Refinement::converged`] tells the session to stop rendering until
//! something changes; any change (a new settings version, time or size) starts over.
//!
//! The session's render loop holds one `Refinement` and consults it in two places only: to
//! decide whether a still view wants another frame, and to render that frame (on the render
//! pool; the lock is never held on the async runtime across an await).

use isoray_render::{Accumulator, Backend, DeviceTimes, Effects, Framebuffer, PreparedScene, View};
use std::sync::Mutex;

/// What a refinement accumulates: settings version, scene time (bits), width, height.
pub type RefineKey = (u64, u64, u32, u32);

/// One session's accumulation.
pub struct Refinement {
    state: Mutex<(Option<RefineKey>, Accumulator)>,
}

impl Refinement {
    /// Refinement that stops after at most `max_passes` passes, averaging `antialias`
    /// sub-pixel positions ([`Accumulator::antialias`]).
    pub fn new(max_passes: u32, antialias: u32) -> Refinement {
        let mut accumulator = Accumulator::new(max_passes);
        accumulator.antialias = antialias;
        Refinement {
            state: Mutex::new((None, accumulator)),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, (Option<RefineKey>, Accumulator)> {
        // Plain values only: a panicked render cannot leave them inconsistent.
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Whether the view `key` needs no more passes.
    pub fn converged(&self, key: RefineKey) -> bool {
        let state = self.lock();
        state.0 == Some(key) && state.1.converged()
    }

    /// Passes accumulated for the current view.
    pub fn passes(&self) -> u32 {
        self.lock().1.passes()
    }

    /// Adds the next pass for view `key` (starting over if the view changed) and returns the
    /// image of the mean, with what a device spent on the pass. Blocking: call it on the
    /// render pool.
    pub fn next_pass(
        &self,
        backend: &Backend,
        scene: &PreparedScene,
        view: &View,
        effects: &Effects,
        key: RefineKey,
    ) -> (Framebuffer, DeviceTimes) {
        let mut state = self.lock();
        if state.0 != Some(key) {
            state.0 = Some(key);
            state.1.reset(view.width, view.height);
        }
        let fb = backend.refine(scene, view, effects, &mut state.1);
        (fb, state.1.last_device())
    }
}
