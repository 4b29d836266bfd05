//! The scenes a server holds — built-in animated demos and pushed scenes from the store — and
//! the caches of prepared states, so every session watching the same state shares one
//! acceleration structure.
//!
//! A demo is a pure function of time, cached per scene for the last few times. Its states are
//! built on a build pool of their own, apart from the render pool, and live views are
//! pipelined as in fitted-bvh-metaballs.txt Fig. 7: a live request takes the newest state
//! already built and starts building the state at the current time, so the build of state
//! k+1 overlaps the rendering of state k (see [`DemoPipeline`]). A pinned time gets exactly
//! that state. A stored scene is a sequence of pushed steps: a live viewer sees the newest
//! step, a viewer who pins a time sees the step with the largest time not after it. Prepared
//! stored steps share one cache bounded in bytes across all scenes (`--cache-bytes`), least
//! recently used first out.
//!
//! The files: `registry` (every scene by id), `entry` (one scene: a demo or a stored scene,
//! and how a view gets its prepared state), `demo` (the demo pipeline and its build pool),
//! `cache` (prepared stored steps, bounded in bytes), `prepared` (a prepared state and what
//! it cost).

pub mod cache;
pub mod demo;
pub mod entry;
pub mod prepared;
pub mod registry;
