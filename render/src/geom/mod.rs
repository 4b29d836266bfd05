//! Geometry every kind and the integrator share: boxes and the ray–box slab test, the clip
//! box, the random generators and the ray counters' common summary.

pub mod aabb;
pub mod clip;
pub mod counters;
pub mod rng;
