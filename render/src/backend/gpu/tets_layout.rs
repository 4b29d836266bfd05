//! The tet kernel's data as `#[repr(C)]` plain-old-data structs (twins of `TetParams` and
//! `TetNode` in `tets.wgsl`; `tets.rs` checks their layout against naga) and its limits. A
//! module of its own, importing nothing of the seam, so that `kind.rs` reads [`ARRAYS`]
//! without an import cycle through `tets.rs`.

use bytemuck::{Pod, Zeroable};

/// Storage arrays of the kind (bindings 1..=5 of group 1).
pub const ARRAYS: usize = 5;

/// Deepest tree the kernel's traversal stack holds (`TET_STACK_SIZE` - 1 in the shader): a
/// depth-first walk that pushes both children keeps at most one entry per level.
pub const MAX_DEPTH: usize = 63;

/// The kind's uniform (`TetParams` in the shader).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuTetParams {
    pub node_count: u32,
    /// 1: interpolate the per-vertex gradients; 0: the hit tet's own.
    pub smooth_normals: u32,
    /// The scalars mapped to the two ends of the colour map.
    pub color_lo: f32,
    pub color_hi: f32,
}

/// One BVH node (`TetNode` in the shader): 4-D bounds `{x, y, z, v}`, then two children at
/// `first` (`count == 0`) or `count` tets at `first` in leaf order.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuTetNode {
    pub lo: [f32; 4],
    pub hi: [f32; 4],
    pub first: u32,
    pub count: u32,
    pub _pad0: u32,
    pub _pad1: u32,
}
