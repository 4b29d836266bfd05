//! Tetrahedral meshes with a scalar field per vertex and time step, and their isosurfaces.
//!
//! How it works (tetrahedral-isosurface-ray-tracing.txt): the field is linear inside each tet,
//! so the isosurface inside one is a planar, convex *isopolygon* (a triangle or a quad) found
//! by marching tetrahedra (§4.1), which a ray intersects like a polygon (§4.2). An *implicit*
//! min–max BVH over the tets (§5) keeps, besides each node's box, the range of scalar values
//! below it, so one structure serves every isovalue and subtrees whose range misses all of a
//! query's isovalues are never entered. The modules:
//! - [`march`]: the 16 marching-tets cases, isopolygon extraction and the ray–isopolygon test
//!   (the same edge tests serve one ray and a whole packet with a common origin).
//! - [`bvh`]: the implicit BVH with 4-D `{x, y, z, v}` bounds, the BIH-style and the SAH
//!   builds (§5.1), and refitting (§6.2).
//! - [`traverse`]: single-ray first-hit and any-hit traversal with isorange culling, several
//!   isovalues at once and the clip box (§7).
//! - [`packet`]: packet traversal with first-active descent, interval-arithmetic frustum
//!   culling of nodes and corner-ray culling of isopolygons (§4.3, §5.2).
//! - [`prepared`]: one time step ready to trace: vertex data, the BVH (rebuilt per step or a
//!   shared one refitted, §6), smoothed normals.
//! - [`reference`]: the `f64` reference intersection used by tests.
//! - [`generate`]: deterministic generated meshes and analytic fields (demo and benchmarks);
//!   [`bucky`]: the deforming bucky ball demo (Fig. 4).
//!
//! The connectivity and rest positions ([`TetMesh`]) are static and shared, behind an `Arc`,
//! by every step; a step ([`TetScene`]) adds the per-vertex scalars and, for a deforming
//! mesh, per-vertex positions. Both are checked when made and immutable afterwards, so
//! everything downstream may index without checks.

pub mod bucky;
pub mod bvh;
pub mod counters;
pub mod generate;
pub mod kind;
pub mod march;
pub mod mesh;
pub mod packet;
pub mod prepared;
pub mod reference;
pub mod traverse;
mod walk;

#[cfg(test)]
mod scene_tests;

pub use crate::geom::clip::ClipBox;
pub use bvh::{BuildKind, Bvh, BvhStats};
pub use counters::TetCounters;
pub use mesh::{
    check_tet, colormap, signed_volume6, TetError, TetMesh, TetScene, VertexTets,
    DEGENERATE_RELATIVE_VOLUME, MAX_ISOSURFACES,
};
pub use packet::{PacketScratch, RayPacket};
pub use prepared::{Normals, PreparedTets, TetOptions, TimeScheme};
pub use traverse::{TetHit, TetQuery};
