//! The tet mesh (static connectivity and rest positions) and one step of it (scalars and,
//! for a deforming mesh, positions), checked when made.

use crate::kinds::tets::bvh::{BuildKind, Bvh};
use glam::Vec3;
use std::sync::{Arc, Mutex, OnceLock};

/// At most this many isosurfaces are traced at once (§7, "up to four different isosurfaces").
pub const MAX_ISOSURFACES: usize = 4;

/// A problem with tetrahedral data, naming the offending tet, vertex or value.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum TetError {
    #[error("tet {tet}: corner {corner} refers to vertex {vertex}, but there are only {vertex_count} vertices")]
    VertexOutOfRange {
        tet: usize,
        corner: usize,
        vertex: u64,
        vertex_count: usize,
    },
    #[error("tet {tet}: vertex {vertex} appears twice")]
    RepeatedVertex { tet: usize, vertex: u32 },
    #[error("tet {tet}: degenerate (volume {volume:e}, relative {relative:e}; the limit is {DEGENERATE_RELATIVE_VOLUME:e} of its longest edge cubed)")]
    Degenerate {
        tet: usize,
        volume: f64,
        relative: f64,
    },
    #[error("tet {tet}: inverted (signed volume {volume:e}; corners 0, 1, 2 must turn counter-clockwise seen from corner 3, as in VTK)")]
    Inverted { tet: usize, volume: f64 },
    #[error("vertex {vertex}: {field} is not finite")]
    NotFinite { vertex: usize, field: &'static str },
    #[error("{field} has {got} values, but the mesh has {expected} vertices")]
    WrongLength {
        field: &'static str,
        got: usize,
        expected: usize,
    },
    #[error("{count} tets exceed the limit of {limit}")]
    TooMany { count: usize, limit: usize },
    #[error("the mesh has {count} vertices; indices are 32-bit, so at most {max}")]
    TooManyVertices { count: usize, max: usize },
    #[error("{count} isovalues exceed the limit of {MAX_ISOSURFACES}")]
    TooManyIsovalues { count: usize },
    #[error("isovalue {index} is not finite")]
    IsovalueNotFinite { index: usize },
    #[error("the clip box has a NaN bound or lo > hi")]
    BadClipBox,
}

/// A tet whose volume is below this fraction of its longest edge cubed is degenerate. A
/// regular tet has `√2/12 ≈ 0.118`; a sliver from a decent mesher stays far above `1e-6`.
pub const DEGENERATE_RELATIVE_VOLUME: f64 = 1e-6;

/// Static connectivity and rest positions shared by every step of a scene.
pub struct TetMesh {
    vertices: Vec<Vec3>,
    tets: Vec<[u32; 4]>,
    /// Schema II (§6.2): one BVH per build kind, built on first use from the rest positions
    /// and refitted for each step.
    shared: [OnceLock<Arc<Bvh>>; 2],
    /// The tets around each vertex (for smoothed normals), built on first use.
    vertex_tets: OnceLock<VertexTets>,
    /// For a deforming mesh, per build kind: the tree whose structure steps refit, the last
    /// one rebuilt when a refit degraded too far (see `prepared::REFIT_DEGRADATION`).
    moving: [Mutex<Option<Topology>>; 2],
}

/// The structure a deforming mesh's steps refit, and its surface-area cost when it was
/// built ([`Bvh::area_cost`]).
#[derive(Clone, Debug)]
pub struct Topology {
    pub bvh: Arc<Bvh>,
    pub built_cost: f64,
}

/// The tets around each vertex, in increasing tet order: those of vertex `v` are
/// `tets[offsets[v]..offsets[v + 1]]`.
#[derive(Debug)]
pub struct VertexTets {
    pub offsets: Vec<usize>,
    pub tets: Vec<u32>,
}

impl std::fmt::Debug for TetMesh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TetMesh")
            .field("vertices", &self.vertices.len())
            .field("tets", &self.tets.len())
            .finish()
    }
}

impl PartialEq for TetMesh {
    fn eq(&self, other: &TetMesh) -> bool {
        self.vertices == other.vertices && self.tets == other.tets
    }
}

impl TetMesh {
    /// A mesh, checked: every index in range, no repeated vertex in a tet, finite positions,
    /// no degenerate or inverted tet. The first problem is named in the error.
    pub fn new(vertices: Vec<Vec3>, tets: Vec<[u32; 4]>) -> Result<TetMesh, TetError> {
        if vertices.len() > u32::MAX as usize {
            return Err(TetError::TooManyVertices {
                count: vertices.len(),
                max: u32::MAX as usize,
            });
        }
        check_positions(&vertices)?;
        check_connectivity(vertices.len(), tets.iter().map(|t| t.map(u64::from)))?;
        check_volumes(&vertices, &tets)?;
        Ok(TetMesh {
            vertices,
            tets,
            shared: [OnceLock::new(), OnceLock::new()],
            vertex_tets: OnceLock::new(),
            moving: [Mutex::new(None), Mutex::new(None)],
        })
    }

    /// [`TetMesh::new`] from raw 64-bit indices as a client sends them, so that an index
    /// beyond 32 bits is named rather than truncated.
    pub fn from_indices(vertices: Vec<Vec3>, tets: &[[u64; 4]]) -> Result<TetMesh, TetError> {
        if vertices.len() > u32::MAX as usize {
            return Err(TetError::TooManyVertices {
                count: vertices.len(),
                max: u32::MAX as usize,
            });
        }
        check_connectivity(vertices.len(), tets.iter().copied())?;
        // In range of a u32-sized vertex array, so the narrowing is exact.
        let tets = tets.iter().map(|t| t.map(|v| v as u32)).collect();
        TetMesh::new(vertices, tets)
    }

    pub fn vertices(&self) -> &[Vec3] {
        &self.vertices
    }

    pub fn tets(&self) -> &[[u32; 4]] {
        &self.tets
    }

    /// Axis-aligned bounds of the rest positions, or `None` without vertices.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        bounds_of(&self.vertices)
    }

    /// The shared BVH of `kind` over the rest positions (built on first call).
    pub fn shared_bvh(&self, kind: BuildKind) -> Arc<Bvh> {
        let slot = match kind {
            BuildKind::Bih => &self.shared[0],
            BuildKind::Sah => &self.shared[1],
        };
        // Built with no lock held: the build forks on the pool (crate::once).
        crate::once::built(slot, || {
            Arc::new(Bvh::build(&self.tets, &self.vertices, kind))
        })
        .clone()
    }

    /// The structure deforming steps of `kind` refit now: the shared BVH over the rest
    /// positions until a refit degraded and a step rebuilt it.
    pub fn moving_topology(&self, kind: BuildKind) -> Topology {
        let mut slot = self.moving_slot(kind);
        slot.get_or_insert_with(|| {
            let bvh = self.shared_bvh(kind);
            Topology {
                built_cost: bvh.area_cost(),
                bvh,
            }
        })
        .clone()
    }

    /// Makes `topology` (a tree just built for a deformed step) the one later steps refit.
    pub fn set_moving_topology(&self, kind: BuildKind, topology: Topology) {
        *self.moving_slot(kind) = Some(topology);
    }

    fn moving_slot(&self, kind: BuildKind) -> std::sync::MutexGuard<'_, Option<Topology>> {
        let slot = match kind {
            BuildKind::Bih => &self.moving[0],
            BuildKind::Sah => &self.moving[1],
        };
        slot.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The tets around each vertex (built on first call; the connectivity never changes).
    pub fn vertex_tets(&self) -> &VertexTets {
        self.vertex_tets.get_or_init(|| {
            let mut offsets = vec![0usize; self.vertices.len() + 1];
            for t in &self.tets {
                for &v in t {
                    offsets[v as usize + 1] += 1;
                }
            }
            for v in 0..self.vertices.len() {
                offsets[v + 1] += offsets[v];
            }
            let mut fill = offsets.clone();
            let mut tets = vec![0u32; offsets[self.vertices.len()]];
            for (i, t) in self.tets.iter().enumerate() {
                for &v in t {
                    tets[fill[v as usize]] = i as u32;
                    fill[v as usize] += 1;
                }
            }
            VertexTets { offsets, tets }
        })
    }

    /// Bytes of the raw input: positions, connectivity (what §8.7's "raw" column counts,
    /// without scalars).
    pub fn raw_bytes(&self) -> usize {
        self.vertices.len() * std::mem::size_of::<Vec3>()
            + self.tets.len() * std::mem::size_of::<[u32; 4]>()
    }
}

/// One time step of a tet scene: the shared mesh, this step's scalars (and positions, for a
/// deforming mesh) and how isovalues map to colour. Further isosurfaces and the clip box are
/// the scene's effects (`Lighting`), common to every primitive kind; [`TetQuery`] carries
/// them into one traversal.
#[derive(Clone, Debug, PartialEq)]
pub struct TetScene {
    mesh: Arc<TetMesh>,
    scalars: Arc<[f32]>,
    positions: Option<Arc<[Vec3]>>,
    color_range: (f32, f32),
}

impl TetScene {
    /// A step with per-vertex `scalars` over `mesh` (finite, one per vertex). Isovalues are
    /// coloured over the scalars' range until [`TetScene::with_color_range`] says otherwise.
    pub fn new(mesh: Arc<TetMesh>, scalars: Arc<[f32]>) -> Result<TetScene, TetError> {
        if scalars.len() != mesh.vertices.len() {
            return Err(TetError::WrongLength {
                field: "scalars",
                got: scalars.len(),
                expected: mesh.vertices.len(),
            });
        }
        if let Some(vertex) = scalars.iter().position(|s| !s.is_finite()) {
            return Err(TetError::NotFinite {
                vertex,
                field: "scalar",
            });
        }
        let color_range = scalar_range(&scalars).unwrap_or((0.0, 1.0));
        Ok(TetScene {
            mesh,
            scalars,
            positions: None,
            color_range,
        })
    }

    /// This step's vertex positions, for a mesh that deforms (§6: connectivity stays, vertices
    /// move). Checked like the rest positions: finite, no tet degenerate or inverted.
    pub fn with_positions(mut self, positions: Arc<[Vec3]>) -> Result<TetScene, TetError> {
        if positions.len() != self.mesh.vertices.len() {
            return Err(TetError::WrongLength {
                field: "positions",
                got: positions.len(),
                expected: self.mesh.vertices.len(),
            });
        }
        check_positions(&positions)?;
        check_volumes(&positions, &self.mesh.tets)?;
        self.positions = Some(positions);
        Ok(self)
    }

    /// The scalar values mapped to the two ends of the colour map (any finite pair).
    pub fn with_color_range(mut self, lo: f32, hi: f32) -> TetScene {
        if lo.is_finite() && hi.is_finite() && lo != hi {
            self.color_range = (lo, hi);
        }
        self
    }

    pub fn mesh(&self) -> &Arc<TetMesh> {
        &self.mesh
    }

    /// The scalar values mapped to the two ends of the colour map ([`TetScene::color_of`]).
    pub fn color_range(&self) -> (f32, f32) {
        self.color_range
    }

    pub fn scalars(&self) -> &[f32] {
        &self.scalars
    }

    /// This step's vertex positions (the rest positions unless the mesh deforms).
    pub fn positions(&self) -> &[Vec3] {
        self.positions.as_deref().unwrap_or(&self.mesh.vertices)
    }

    /// Whether this step moves the vertices away from the rest positions.
    pub fn deforms(&self) -> bool {
        self.positions.is_some()
    }

    pub fn tet_count(&self) -> usize {
        self.mesh.tets.len()
    }

    /// Checks the engine's size limit (everything else was checked when the parts were made).
    pub fn validate(&self, limit: usize) -> Result<(), TetError> {
        if self.mesh.tets.len() > limit {
            return Err(TetError::TooMany {
                count: self.mesh.tets.len(),
                limit,
            });
        }
        Ok(())
    }

    /// Axis-aligned bounds of this step's vertices (its own positions for a deforming mesh,
    /// else the rest positions), or `None` without vertices.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        match &self.positions {
            Some(p) => bounds_of(p),
            None => self.mesh.bounds(),
        }
    }

    /// Isovalues with a non-empty surface: strictly inside the scalars' range.
    pub fn isovalue_range(&self) -> (f32, f32) {
        scalar_range(&self.scalars).unwrap_or((0.0, 0.0))
    }

    /// Linear-light colour of the isosurface at `isovalue`.
    pub fn color_of(&self, isovalue: f32) -> Vec3 {
        let (lo, hi) = self.color_range;
        colormap((isovalue - lo) / (hi - lo))
    }
}

/// A cool-to-warm colour map in linear light, `x` in `[0, 1]` (clamped; NaN gives the cool end).
pub fn colormap(x: f32) -> Vec3 {
    const STOPS: [Vec3; 5] = [
        Vec3::new(0.05, 0.18, 0.60),
        Vec3::new(0.10, 0.50, 0.75),
        Vec3::new(0.60, 0.60, 0.55),
        Vec3::new(0.85, 0.40, 0.12),
        Vec3::new(0.70, 0.06, 0.06),
    ];
    let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
    let f = x * (STOPS.len() - 1) as f32;
    let i = (f as usize).min(STOPS.len() - 2);
    STOPS[i].lerp(STOPS[i + 1], f - i as f32)
}

fn scalar_range(scalars: &[f32]) -> Option<(f32, f32)> {
    let mut it = scalars.iter().copied();
    let first = it.next()?;
    Some(it.fold((first, first), |(lo, hi), s| (lo.min(s), hi.max(s))))
}

fn bounds_of(points: &[Vec3]) -> Option<(Vec3, Vec3)> {
    let mut it = points.iter().copied();
    let first = it.next()?;
    Some(it.fold((first, first), |(lo, hi), p| (lo.min(p), hi.max(p))))
}

fn check_positions(positions: &[Vec3]) -> Result<(), TetError> {
    match positions.iter().position(|p| !p.is_finite()) {
        Some(vertex) => Err(TetError::NotFinite {
            vertex,
            field: "position",
        }),
        None => Ok(()),
    }
}

fn check_connectivity(
    vertex_count: usize,
    tets: impl Iterator<Item = [u64; 4]>,
) -> Result<(), TetError> {
    for (tet, corners) in tets.enumerate() {
        for (corner, &vertex) in corners.iter().enumerate() {
            if vertex >= vertex_count as u64 {
                return Err(TetError::VertexOutOfRange {
                    tet,
                    corner,
                    vertex,
                    vertex_count,
                });
            }
            if corners[..corner].contains(&vertex) {
                return Err(TetError::RepeatedVertex {
                    tet,
                    vertex: vertex as u32,
                });
            }
        }
    }
    Ok(())
}

/// Six times the signed volume of a tet, in `f64`: positive when
/// `((p1 - p0) × (p2 - p0)) · (p3 - p0) > 0`, VTK's convention for its tetra (corners 0, 1, 2
/// turn counter-clockwise seen from corner 3).
pub fn signed_volume6(p: [Vec3; 4]) -> f64 {
    let [a, b, c, d] = p.map(|v| v.as_dvec3());
    (b - a).cross(c - a).dot(d - a)
}

fn check_volumes(positions: &[Vec3], tets: &[[u32; 4]]) -> Result<(), TetError> {
    for (tet, t) in tets.iter().enumerate() {
        check_tet(tet, t.map(|i| positions[i as usize]))?;
    }
    Ok(())
}

/// The check every tet gets when a mesh is made or a step moves it: not degenerate (volume
/// above [`DEGENERATE_RELATIVE_VOLUME`] of its longest edge cubed) and not inverted; `tet`
/// names it in the error.
pub fn check_tet(tet: usize, p: [Vec3; 4]) -> Result<(), TetError> {
    let volume6 = signed_volume6(p);
    let d = p.map(|v| v.as_dvec3());
    let mut longest2 = 0.0f64;
    for i in 0..4 {
        for j in i + 1..4 {
            longest2 = longest2.max((d[i] - d[j]).length_squared());
        }
    }
    let relative = volume6.abs() / 6.0 / (longest2 * longest2.sqrt());
    if !(relative > DEGENERATE_RELATIVE_VOLUME) {
        return Err(TetError::Degenerate {
            tet,
            volume: volume6 / 6.0,
            relative,
        });
    }
    if volume6 < 0.0 {
        return Err(TetError::Inverted {
            tet,
            volume: volume6 / 6.0,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::clip::ClipBox;
    use crate::kinds::tets::traverse::TetQuery;

    fn unit_tet() -> Vec<Vec3> {
        vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z]
    }

    #[test]
    fn vtk_orientation_is_positive() {
        assert!(signed_volume6([Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z]) > 0.0);
        assert!(signed_volume6([Vec3::ZERO, Vec3::Y, Vec3::X, Vec3::Z]) < 0.0);
        assert!(TetMesh::new(unit_tet(), vec![[0, 1, 2, 3]]).is_ok());
    }

    #[test]
    fn bad_meshes_are_named() {
        let mut v = unit_tet();
        v.push(Vec3::ONE);
        assert_eq!(
            TetMesh::new(v.clone(), vec![[0, 1, 2, 3], [1, 2, 3, 9]]).expect_err("rejected"),
            TetError::VertexOutOfRange {
                tet: 1,
                corner: 3,
                vertex: 9,
                vertex_count: 5
            }
        );
        let msg = TetMesh::new(v.clone(), vec![[0, 1, 2, 3], [1, 2, 3, 9]])
            .expect_err("rejected")
            .to_string();
        assert!(msg.contains("tet 1") && msg.contains("vertex 9"), "{msg}");
        assert_eq!(
            TetMesh::from_indices(v.clone(), &[[0, 1, 2, 3], [0, 1, 2, 1 << 40]])
                .expect_err("rejected"),
            TetError::VertexOutOfRange {
                tet: 1,
                corner: 3,
                vertex: 1 << 40,
                vertex_count: 5
            }
        );
        assert_eq!(
            TetMesh::new(v.clone(), vec![[0, 2, 2, 3]]).expect_err("rejected"),
            TetError::RepeatedVertex { tet: 0, vertex: 2 }
        );
        assert!(matches!(
            TetMesh::new(v.clone(), vec![[0, 1, 2, 3], [0, 2, 1, 3]]).expect_err("rejected"),
            TetError::Inverted { tet: 1, .. }
        ));
        // Four coplanar points.
        let flat = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, 1e-9)];
        assert!(matches!(
            TetMesh::new(flat, vec![[0, 1, 2, 3]]).expect_err("rejected"),
            TetError::Degenerate { tet: 0, .. }
        ));
        v[3].z = f32::NAN;
        assert_eq!(
            TetMesh::new(v, vec![[0, 1, 2, 3]]).expect_err("rejected"),
            TetError::NotFinite {
                vertex: 3,
                field: "position"
            }
        );
    }

    #[test]
    fn bad_steps_are_named() {
        let mesh = Arc::new(TetMesh::new(unit_tet(), vec![[0, 1, 2, 3]]).expect("valid"));
        assert_eq!(
            TetScene::new(mesh.clone(), vec![0.0; 3].into()).expect_err("rejected"),
            TetError::WrongLength {
                field: "scalars",
                got: 3,
                expected: 4
            }
        );
        assert_eq!(
            TetScene::new(mesh.clone(), vec![0.0, 1.0, f32::NAN, 0.0].into())
                .expect_err("rejected"),
            TetError::NotFinite {
                vertex: 2,
                field: "scalar"
            }
        );
        let step = TetScene::new(mesh.clone(), vec![0.0, 1.0, 2.0, 3.0].into()).expect("valid");
        assert_eq!(step.isovalue_range(), (0.0, 3.0));
        let inverted: Arc<[Vec3]> = vec![Vec3::ZERO, Vec3::Y, Vec3::X, Vec3::Z].into();
        assert!(matches!(
            step.clone().with_positions(inverted).expect_err("rejected"),
            TetError::Inverted { tet: 0, .. }
        ));
        assert_eq!(
            TetQuery::new(&[0.5, 1.0, 1.5, 2.0, 2.5], None).expect_err("rejected"),
            TetError::TooManyIsovalues { count: 5 }
        );
        assert_eq!(
            TetQuery::new(&[0.5, f32::INFINITY], None).expect_err("rejected"),
            TetError::IsovalueNotFinite { index: 1 }
        );
        assert_eq!(
            ClipBox::new(Vec3::ONE, Vec3::ZERO).expect_err("rejected"),
            TetError::BadClipBox
        );
        assert_eq!(
            step.validate(0).expect_err("rejected"),
            TetError::TooMany { count: 1, limit: 0 }
        );
    }
}
