//! Tetrahedral meshes with a scalar per vertex (tetrahedral-isosurface-ray-tracing.txt): the
//! static mesh, sent once (inline at creation or with `PUT /api/v1/scenes/{id}/mesh`) and
//! checked in full (every index in range, no repeated vertex, no degenerate or inverted tet,
//! finite positions; the first problem named by field, tet and corner, and for binary bodies
//! by byte offset); steps of one scalar per vertex; the histogram of those scalars.

pub mod histogram;
pub mod mesh;
pub mod mesh_body;
pub mod setup;
pub mod step;
