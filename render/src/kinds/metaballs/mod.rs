//! Metaballs: balls of finite support whose summed field defines the surface `F(p) = T`.
//!
//! How it works: each ball `i` has centre `p_i`, radius `R_i` and strength `q_i` (negative
//! carves) and contributes `q_i · f(s)` with `s = |p - p_i|² / R_i²` inside its support and
//! nothing outside (bezier-clipping-metaballs.txt §2, eq. 5). An ellipsoidal ball uses
//! `s = |M (p - p_i)|²`, `M` the inverse of its rotated, scaled frame (ibid. §3.3); its
//! `radius` is then the largest semi-axis, so the sphere of radius `R_i` still bounds it.
//! The modules:
//! - [`kernel`]: the falloffs `f` (Wyvill, degree four, `(1-s)^α`, the tutorial's), and
//!   `KernelPoly`, a kernel's coefficients in a root finder's precision.
//! - [`roots`]: the root finders along one ray (marching, projections + secant, Bézier
//!   clipping, sphere tracing), generic over `f32` and `f64`; `one_ball`, Bézier clipping's
//!   closed form for a section where one ball alone is active; [`lanes`], the isolated
//!   roots a primary packet sets aside, solved eight at a time.
//! - [`tree`]: the BVH with split metaballs and the Fitted BVH (fitted-bvh-metaballs.txt).
//! - [`engine`]: a state prepared for tracing: per-ball data, the acceleration structure, and
//!   the traversal modes (brute force, sorted active list, BVH, FBVH).
//! - [`reference`]: the `f64` reference hit used by tests.
//! - [`pdb`]: atoms of a PDB file as balls.

pub mod bezier;
pub mod counters;
pub mod engine;
mod events;
pub mod kernel;
pub mod kind;
pub mod lanes;
mod one_ball;
pub mod pdb;
pub mod real;
pub mod reference;
pub mod roots;
pub mod scene;
pub mod tree;

pub use counters::MetaballCounters;
/// The metaball kind's counters under their former name, for the other crates.
pub use counters::MetaballCounters as RayCounters;
pub use engine::{Accel, AccelKind, PrepareOptions, PreparedMetaballs};
pub use kernel::Kernel;
pub use roots::RootFinder;
pub use scene::{Metaball, MetaballError, MetaballScene, Shape};
pub use tree::{BuildOptions, TreeKind};
