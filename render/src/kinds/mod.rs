//! The primitive kinds, one folder each, and the one place that dispatches over them.

pub mod contract;
pub mod counters;
pub mod dispatch;
pub mod metaballs;
pub mod surfels;
pub mod tets;
