//! Deforming point-sampled surfaces (deforming-point-sampled-surfaces.txt): surfels embedded
//! in simulation nodes, a bounding-sphere hierarchy updated lazily while tracing, the MLS
//! ray–surface intersection, sphere-node caching and clipping.

#[cfg(test)]
mod clip_tests;
pub mod cones;
#[cfg(test)]
mod cones_tests;
pub mod counters;
pub mod deform;
pub mod demo;
pub mod input;
pub mod intersect;
pub mod kernel;
pub mod kind;
pub mod knn;
pub mod miniball;
pub mod model;
pub mod prepared;
pub mod reference;
pub mod rigid;
pub mod sample;
pub mod scene;
pub mod sim;
#[cfg(test)]
mod tests;
pub mod traverse;
#[cfg(test)]
mod traverse_tests;
pub mod tree;
