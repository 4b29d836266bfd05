//! Effects: what a session switches on ([`toggles`]), the ray kinds ([`rays`]) and the plan
//! of one frame ([`plan`]), which keeps only the rays some visible material needs.

pub mod plan;
pub mod rays;
pub mod toggles;

pub use plan::{available_effects, EffectsPlan};
pub use rays::{RayCounts, RayKind};
pub use toggles::{EffectKind, Effects, MAX_DEPTH, MAX_SAMPLES};
