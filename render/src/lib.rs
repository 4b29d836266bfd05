//! isoray's engine: scenes of implicit surfaces, their acceleration structures and
//! intersectors, shading, and the CPU backend that traces tiles on a rayon pool.
//!
//! Architecture invariant: this crate knows nothing about tokio, sockets, JSON or files. It
//! takes plain values (a [`Scene`], a [`View`]) and returns pixels. It is deterministic: the
//! same scene, view and settings give the same [`Framebuffer`], whatever the thread count.
//!
//! The seams, from the outside in:
//! - [`Backend`] (a closed enum; today its one variant is [`CpuBackend`], which owns the worker
//!   pool) turns a [`PreparedScene`] and a [`View`] into a [`Framebuffer`], a pass at a time
//!   (`backend` is the one place that knows about threads).
//! - [`integrator`] follows a camera ray, asks the scene for the first hit and shades it.
//! - [`PreparedScene`] is a scene plus its acceleration structure, built once per state and
//!   shared by every view of that state; it answers "first hit along this ray segment".
//! - [`Scene`] holds one of the closed set of primitive kinds (`kinds::dispatch::Geometry`:
//!   metaballs and tetrahedral meshes), each in its own folder under `kinds/` behind one
//!   contract (`kinds::contract::PreparedKind`).

// `!(a < b)` is the engine's NaN-rejecting comparison: it is true when either side is NaN,
// which `a >= b` is not. The lint would have us lose that.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod backend;
pub mod camera;
pub mod colormap;
pub mod cpu;
mod demo_effects;
mod demo_surfels;
pub mod effects;
pub mod framebuffer;
pub mod geom;
pub mod integrator;
pub mod kinds;
pub mod once;
pub mod ray;
pub mod sampling;
pub mod scene;
pub mod scenes;
pub mod shade;
pub mod srgb;
pub mod view;

pub use backend::{Accumulator, Backend, CpuBackend, DeviceTimes, FrameRays};
pub use camera::Camera;
pub use effects::{EffectKind, Effects, EffectsPlan, RayCounts, RayKind};
pub use framebuffer::{Framebuffer, SurfaceBuffer};
pub use ray::{Hit, Ray};
pub use scene::{PreparedScene, Scene, SceneError};
pub use shade::Lighting;
pub use view::View;
