//! The surfel kind on the server (deforming-point-sampled-surfaces.txt): the undeformed
//! object checked and precomputed at creation (`setup`), its steps' layout (`step`: node
//! positions) and its histogram (node displacement lengths).

pub mod histogram;
pub mod setup;
pub mod step;
