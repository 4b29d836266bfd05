//! The tet kind on the GPU: not yet traced there (the upload says so and the frame goes to
//! the CPU).

use crate::backend::gpu::kind::KindUpload;
use crate::kinds::tets::prepared::PreparedTets;
use crate::view::View;
use std::sync::Arc;

/// Storage arrays of the tet kind's bind group.
pub const ARRAYS: usize = 0;

/// What the GPU needs of `prepared`, or why it cannot trace it.
pub fn upload<'a>(
    _prepared: &'a Arc<PreparedTets>,
    _view: &View,
) -> Result<KindUpload<'a>, String> {
    Err("tetrahedral meshes are traced on the CPU".into())
}
