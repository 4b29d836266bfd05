//! Geometry every kind and the integrator share: boxes and the ray–box slab test, the clip
//! box, the local frame a far scene is traced in, the random generators, the ray counters' common summary, a tile's pixel cover for packets,
//! and mirror and Snell directions.

pub mod aabb;
pub mod clip;
pub mod counters;
pub mod frame;
pub mod optics;
pub mod rng;
pub mod tile;
