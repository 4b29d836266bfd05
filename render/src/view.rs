//! What a session chooses about one frame, apart from the scene itself.

use crate::camera::Camera;

/// Everything a session chooses about one frame, apart from the scene itself.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    pub width: u32,
    pub height: u32,
    pub camera: Camera,
    /// The isovalue of the surface to show.
    pub isovalue: f32,
}
