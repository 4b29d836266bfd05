//! The static part of a tet scene: its mesh (set once, then fixed) and the colour map's
//! range, the engine scene of one step on that mesh, and the checks of `tets` in a scene
//! description.

use crate::kinds::convert::finite;
use crate::kinds::error::KindError;
use crate::kinds::tets::mesh::mesh_from_spec;
use crate::kinds::tets::step::{positions_of, scalars_of, COLUMNS};
use isoray_protocol::api::TetSpec;
use isoray_render::kinds::tets::{TetMesh, TetScene};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};

/// The static part of a tet scene: its mesh once known, and the colour map's range.
#[derive(Clone, Debug, PartialEq)]
pub struct TetSetup {
    pub mesh: Arc<MeshSlot>,
    pub color_range: (f32, f32),
}

/// A scene's mesh: set once (at creation, on upload or when the store loads), then fixed.
#[derive(Default)]
pub struct MeshSlot {
    mesh: OnceLock<Arc<TetMesh>>,
    /// Serialises uploads, so exactly one writes the mesh file.
    upload: Mutex<()>,
}

impl std::fmt::Debug for MeshSlot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_tuple("MeshSlot").field(&self.mesh.get()).finish()
    }
}

impl PartialEq for MeshSlot {
    fn eq(&self, other: &MeshSlot) -> bool {
        self.mesh.get() == other.mesh.get()
    }
}

impl MeshSlot {
    pub fn get(&self) -> Option<&Arc<TetMesh>> {
        self.mesh.get()
    }

    /// Sets the mesh unless one is there already (then it is kept).
    pub fn set(&self, mesh: Arc<TetMesh>) {
        let _ = self.mesh.set(mesh);
    }

    /// Held while an upload decides whether to write the mesh, so exactly one does.
    pub fn lock_upload(&self) -> MutexGuard<'_, ()> {
        self.upload.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl TetSetup {
    /// The engine scene of one step: the mesh with `payload`'s `rows × 1` scalars (or
    /// `rows × 4`: scalars and this step's positions), or an empty scene before the mesh or
    /// the first step.
    pub fn scene(&self, step: Option<(u32, &[u8])>) -> TetScene {
        let built = self.mesh.get().and_then(|mesh| {
            let (columns, payload) = step?;
            let fits = COLUMNS.contains(&columns)
                && payload.len() == mesh.vertices().len() * 4 * columns as usize;
            if !fits {
                tracing::warn!(
                    columns,
                    bytes = payload.len(),
                    "a stored tet step does not match its mesh; showing nothing"
                );
                return None;
            }
            let scalars = scalars_of(payload, columns as usize);
            let scene = TetScene::new(Arc::clone(mesh), scalars.into()).ok()?;
            if columns == 1 {
                return Some(scene);
            }
            // Checked when pushed; a step that fails now (a store written by hand) shows
            // nothing rather than a mesh turned inside out.
            scene
                .with_positions(positions_of(payload).into())
                .map_err(|e| tracing::warn!(error = %e, "a stored tet step inverts its mesh"))
                .ok()
        });
        let scene = built.unwrap_or_else(empty_scene);
        scene.with_color_range(self.color_range.0, self.color_range.1)
    }

    /// Memory of a prepared step, roughly: 4-D vertices and gradients per vertex, BVH nodes
    /// (about one per six tets) per tet. (A deforming step's positions, 12 bytes a vertex,
    /// are within the margin.)
    pub fn prepared_bytes(&self) -> u64 {
        self.mesh.get().map_or(0, |m| {
            m.vertices().len() as u64 * 28 + m.tets().len() as u64 * 8
        })
    }
}

fn empty_scene() -> TetScene {
    let mesh = TetMesh::new(Vec::new(), Vec::new()).expect("an empty mesh is valid");
    TetScene::new(Arc::new(mesh), Vec::new().into()).expect("no vertices, no scalars")
}

/// The tet part of a scene description: the colour range (default: the isovalue slider's)
/// and the mesh, if it comes inline.
pub fn setup_from_spec(spec: &TetSpec, slider: (f32, f32)) -> Result<TetSetup, KindError> {
    let color_range = match spec.color_range {
        Some([lo, hi]) => {
            let (lo, hi) = (
                finite(lo, "tets.color_range[0]")?,
                finite(hi, "tets.color_range[1]")?,
            );
            if lo == hi {
                return Err(KindError::relational(
                    "invalid_value",
                    "tets.color_range must be two different values",
                )
                .field("tets.color_range"));
            }
            (lo, hi)
        }
        None => slider,
    };
    let mesh = MeshSlot::default();
    if let Some(data) = &spec.mesh {
        mesh.set(Arc::new(mesh_from_spec(data)?));
    }
    Ok(TetSetup {
        mesh: Arc::new(mesh),
        color_range,
    })
}
