//! One prepared scene state and what it cost to make.

use isoray_render::PreparedScene;

/// One prepared state and what it cost.
#[derive(Clone)]
pub struct PreparedState {
    pub prepared: PreparedScene,
    /// Time to produce the scene state (simulation step or generator), microseconds.
    pub update_us: u32,
    /// Time to build the acceleration structure, microseconds.
    pub build_us: u32,
    /// The time of the state shown, when it is not simply the requested time: a stored
    /// scene's step (0 before its first step), or the demo state a live view shows (the
    /// newest built, up to a frame away from the view's clock).
    pub step_time: Option<f64>,
}

/// A duration in whole microseconds, saturating.
pub fn micros(d: std::time::Duration) -> u32 {
    u32::try_from(d.as_micros()).unwrap_or(u32::MAX)
}
