//! The seam between the kind-independent kernel (`common.wgsl`: camera, integrator, shading)
//! and each kind's part (`metaballs.wgsl`, `tets.wgsl`, `surfels.wgsl`): the kernel of a kind
//! is the common source followed by the kind's, and the kind's data is bind group 1 — a
//! uniform at binding 0 and [`GpuKind::arrays`] storage arrays at bindings `1..=N`.
//!
//! A kind's WGSL defines `kind_first_hit`, `kind_exit_hit`, `kind_any_hit` and
//! `kind_optical_depth`, the GPU twins of [`crate::kinds::contract::PreparedKind`]'s queries
//! (`kind_first_hit`'s last argument, `leaving`, chooses `first_hit_leaving`); the common
//! integrator calls nothing else of it.

use std::any::Any;
use std::sync::Arc;

/// The kinds the GPU traces, one pipeline each.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GpuKind {
    Metaballs,
    Tets,
    Surfels,
}

impl GpuKind {
    pub const ALL: [GpuKind; 3] = [GpuKind::Metaballs, GpuKind::Tets, GpuKind::Surfels];

    /// The kind's part of the kernel.
    pub fn source(self) -> &'static str {
        match self {
            GpuKind::Metaballs => concat!(
                include_str!("metaballs.wgsl"),
                "\n",
                include_str!("metaball_finders.wgsl")
            ),
            GpuKind::Tets => include_str!("tets.wgsl"),
            GpuKind::Surfels => include_str!("surfels.wgsl"),
        }
    }

    /// Storage arrays of the kind's bind group (bindings `1..=N`).
    pub fn arrays(self) -> usize {
        match self {
            GpuKind::Metaballs => 3,
            GpuKind::Tets => crate::backend::gpu::tets_layout::ARRAYS,
            // surfels.rs ARRAYS (a test checks they agree; kind.rs imports no kind module).
            GpuKind::Surfels => 4,
        }
    }

    /// The whole kernel of the kind: the common part, then the kind's.
    pub fn kernel(self) -> String {
        format!("{}\n{}", include_str!("common.wgsl"), self.source())
    }

    pub fn name(self) -> &'static str {
        match self {
            GpuKind::Metaballs => "metaballs",
            GpuKind::Tets => "tets",
            GpuKind::Surfels => "surfels",
        }
    }
}

/// One state of a kind, ready to go to the GPU.
pub struct KindUpload<'a> {
    pub kind: GpuKind,
    /// Equal keys mean the arrays already on the GPU are this state's (the address of the
    /// prepared state, and anything else the arrays depend on): they are built and uploaded
    /// only when the key changes.
    pub key: (usize, u64),
    /// The state the key names, kept alive while its arrays are on the GPU: a freed state's
    /// address could come back as another state's, and its key with it.
    pub hold: Arc<dyn Any + Send + Sync>,
    /// The kind's uniform (group 1, binding 0): a `#[repr(C)]` Pod struct's bytes, a multiple
    /// of 16 bytes.
    pub params: Vec<u8>,
    /// The storage arrays (group 1, bindings `1..=N`), each non-empty.
    pub arrays: Box<dyn FnOnce() -> Vec<Vec<u8>> + 'a>,
}
