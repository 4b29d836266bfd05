//! Generated tet meshes and analytic fields: the demo scene, test meshes and the benchmark's
//! stand-ins for the paper's data sets. Everything is a pure function of its arguments and a
//! fixed seed.
//!
//! A mesh is a grid of cubes, each cut into the six tets of Kuhn's triangulation (all around
//! the cube's main diagonal, so neighbouring cubes share their face diagonals and the mesh is
//! conforming), keeping only cubes whose centre lies in a domain, with interior vertices
//! moved at random by a fraction of a cell so the tets are not all alike. A Kuhn tet's
//! corners lie at least 0.7 cell widths from the opposite faces, so a jitter of up to 0.3
//! cells never inverts one.

use crate::geom::clip::ClipBox;
use crate::geom::rng::SplitMix64;
use crate::kinds::tets::mesh::{TetMesh, TetScene};
use crate::shade::{Isosurface, Light, Lighting, Material};
use glam::{Quat, Vec3};
use rayon::prelude::*;
use std::sync::{Arc, OnceLock};

/// The six Kuhn tets of a cube whose corners are numbered by bits `x = 1, y = 2, z = 4`.
const KUHN: [[usize; 4]; 6] = [
    [0, 1, 3, 7],
    [0, 1, 5, 7],
    [0, 2, 3, 7],
    [0, 2, 6, 7],
    [0, 4, 5, 7],
    [0, 4, 6, 7],
];

/// A grid of `cells` cubes over `[lo, hi]`, keeping the cubes whose centre passes `keep`.
/// `jitter` (at most 0.3) moves each vertex not on the grid's outer faces by up to that many
/// cell widths.
pub fn grid_mesh(
    cells: [usize; 3],
    lo: Vec3,
    hi: Vec3,
    jitter: f32,
    seed: u64,
    keep: impl Fn(Vec3) -> bool + Sync,
) -> TetMesh {
    let grid = Grid::axis_aligned(cells, lo, hi);
    grid.mesh(jitter, seed, keep)
}

/// A grid of cubes of edge `cell` turned by `rotation`, covering the box `[lo, hi]`; the
/// cubes kept are those whose (turned) centre lies in the box and passes `keep`. Turned, no
/// axis-aligned plane runs between the tets, as in an unstructured mesh (an axis-aligned
/// grid lets an SAH build split along cube faces without overlap, which flatters it).
pub fn turned_mesh(
    lo: Vec3,
    hi: Vec3,
    cell: f32,
    rotation: Quat,
    jitter: f32,
    seed: u64,
    keep: impl Fn(Vec3) -> bool + Sync,
) -> TetMesh {
    Grid::turned(lo, hi, cell, rotation).mesh(jitter, seed, |c| {
        c.cmpge(lo).all() && c.cmple(hi).all() && keep(c)
    })
}

/// How many cubes [`turned_mesh`] would keep (to size a mesh before building it).
pub fn count_turned(
    lo: Vec3,
    hi: Vec3,
    cell: f32,
    rotation: Quat,
    keep: impl Fn(Vec3) -> bool + Sync,
) -> usize {
    Grid::turned(lo, hi, cell, rotation)
        .count(|c| c.cmpge(lo).all() && c.cmple(hi).all() && keep(c))
}

/// A (possibly turned) lattice of cubes: grid point `(i, j, k)` sits at
/// `origin + rotation · (step ⊙ (i, j, k))`.
struct Grid {
    cells: [usize; 3],
    origin: Vec3,
    step: Vec3,
    rotation: Quat,
}

impl Grid {
    fn axis_aligned(cells: [usize; 3], lo: Vec3, hi: Vec3) -> Grid {
        let cells = cells.map(|c| c.max(1));
        Grid {
            cells,
            origin: lo,
            step: (hi - lo) / Vec3::new(cells[0] as f32, cells[1] as f32, cells[2] as f32),
            rotation: Quat::IDENTITY,
        }
    }

    fn turned(lo: Vec3, hi: Vec3, cell: f32, rotation: Quat) -> Grid {
        // The box's corners in the grid's frame bound the cubes needed.
        let back = rotation.inverse();
        let (mut glo, mut ghi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for c in 0..8 {
            let corner = Vec3::new(
                if c & 1 != 0 { hi.x } else { lo.x },
                if c & 2 != 0 { hi.y } else { lo.y },
                if c & 4 != 0 { hi.z } else { lo.z },
            );
            let g = back * corner;
            glo = glo.min(g);
            ghi = ghi.max(g);
        }
        let cells = ((ghi - glo) / cell).ceil().max(Vec3::ONE);
        Grid {
            cells: [cells.x as usize, cells.y as usize, cells.z as usize],
            origin: rotation * glo,
            step: Vec3::splat(cell),
            rotation,
        }
    }

    fn point(&self, g: Vec3) -> Vec3 {
        self.origin + self.rotation * (self.step * g)
    }

    fn centre(&self, x: usize, y: usize, z: usize) -> Vec3 {
        self.point(Vec3::new(x as f32 + 0.5, y as f32 + 0.5, z as f32 + 0.5))
    }

    /// Kept cubes, plane by plane in parallel, in a fixed order.
    fn kept(&self, keep: impl Fn(Vec3) -> bool + Sync) -> Vec<Vec<[usize; 3]>> {
        let [nx, ny, nz] = self.cells;
        (0..nz)
            .into_par_iter()
            .map(|z| {
                let mut row = Vec::new();
                for y in 0..ny {
                    for x in 0..nx {
                        if keep(self.centre(x, y, z)) {
                            row.push([x, y, z]);
                        }
                    }
                }
                row
            })
            .collect()
    }

    fn count(&self, keep: impl Fn(Vec3) -> bool + Sync) -> usize {
        self.kept(keep).iter().map(Vec::len).sum()
    }

    fn mesh(&self, jitter: f32, seed: u64, keep: impl Fn(Vec3) -> bool + Sync) -> TetMesh {
        let [nx, ny, nz] = self.cells;
        let vertex_id = |x: usize, y: usize, z: usize| (z * (ny + 1) + y) * (nx + 1) + x;
        let kept = self.kept(keep);
        let mut used = vec![u32::MAX; (nx + 1) * (ny + 1) * (nz + 1)];
        let mut tets = Vec::new();
        let mut vertices = Vec::new();
        let mut rng = SplitMix64(seed);
        let jitter = jitter.clamp(0.0, 0.3);
        for [x, y, z] in kept.into_iter().flatten() {
            let corner_ids = [0usize, 1, 2, 3, 4, 5, 6, 7]
                .map(|c| vertex_id(x + (c & 1), y + ((c >> 1) & 1), z + ((c >> 2) & 1)));
            let mut local = [0u32; 8];
            for (c, &g) in corner_ids.iter().enumerate() {
                if used[g] == u32::MAX {
                    used[g] = vertices.len() as u32;
                    let (gx, gy, gz) = (
                        g % (nx + 1),
                        (g / (nx + 1)) % (ny + 1),
                        g / ((nx + 1) * (ny + 1)),
                    );
                    let mut p = self.point(Vec3::new(gx as f32, gy as f32, gz as f32));
                    let interior = gx > 0 && gx < nx && gy > 0 && gy < ny && gz > 0 && gz < nz;
                    if interior && jitter > 0.0 {
                        p += rng.in_unit_ball() * self.step.min_element() * jitter;
                    }
                    vertices.push(p);
                }
                local[c] = used[g];
            }
            for k in KUHN {
                // Three of the six turn the other way; swap two corners to make every tet
                // positive in VTK's sense (a rotation keeps the sign).
                let t = k.map(|c| local[c]);
                let rest = k.map(|c| {
                    Vec3::new((c & 1) as f32, ((c >> 1) & 1) as f32, ((c >> 2) & 1) as f32)
                });
                if crate::kinds::tets::mesh::signed_volume6(rest) < 0.0 {
                    tets.push([t[0], t[2], t[1], t[3]]);
                } else {
                    tets.push(t);
                }
            }
        }
        TetMesh::new(vertices, tets).expect("a Kuhn grid with jitter ≤ 0.3 cells is valid")
    }
}

/// [`grid_mesh`] keeping every cube.
pub fn box_mesh(cells: [usize; 3], lo: Vec3, hi: Vec3, jitter: f32, seed: u64) -> TetMesh {
    grid_mesh(cells, lo, hi, jitter, seed, |_| true)
}

/// How many cubes of a grid `cells` over `[lo, hi]` pass `keep` (to size a mesh).
pub fn count_cells(
    cells: [usize; 3],
    lo: Vec3,
    hi: Vec3,
    keep: impl Fn(Vec3) -> bool + Sync,
) -> usize {
    Grid::axis_aligned(cells, lo, hi).count(keep)
}

/// `f` at every point, in parallel.
pub fn sample(points: &[Vec3], f: impl Fn(Vec3) -> f32 + Sync) -> Arc<[f32]> {
    points
        .par_iter()
        .with_min_len(4096)
        .map(|&p| f(p))
        .collect::<Vec<f32>>()
        .into()
}

/// The 60 atoms of a C60 buckyball (truncated icosahedron, edge 2): the even permutations of
/// `(0, ±1, ±3φ)`, `(±1, ±(2+φ), ±2φ)` and `(±φ, ±2, ±(2φ+1))`.
pub fn buckyball() -> Vec<Vec3> {
    let phi = (1.0 + 5.0f32.sqrt()) / 2.0;
    let bases = [
        Vec3::new(0.0, 1.0, 3.0 * phi),
        Vec3::new(1.0, 2.0 + phi, 2.0 * phi),
        Vec3::new(phi, 2.0, 2.0 * phi + 1.0),
    ];
    let mut out: Vec<Vec3> = Vec::new();
    for b in bases {
        for signs in 0..8 {
            let s = Vec3::new(
                if signs & 1 != 0 { -1.0 } else { 1.0 },
                if signs & 2 != 0 { -1.0 } else { 1.0 },
                if signs & 4 != 0 { -1.0 } else { 1.0 },
            );
            let v = b * s;
            for p in [v, Vec3::new(v.y, v.z, v.x), Vec3::new(v.z, v.x, v.y)] {
                if !out.iter().any(|q| (*q - p).length_squared() < 1e-6) {
                    out.push(p);
                }
            }
        }
    }
    out
}

/// The demo's field: a gyroid whose phase drifts and whose cells breathe, fading towards the
/// ball's rim, `time` in seconds.
pub fn gyroid(p: Vec3, time: f64) -> f32 {
    let k = 2.0 * std::f32::consts::PI / 1.6;
    let phase = (0.35 * time) as f32;
    let q = p * k + Vec3::splat(phase);
    let g = q.x.sin() * q.y.cos() + q.y.sin() * q.z.cos() + q.z.sin() * q.x.cos();
    let breathe = 0.25 * ((0.9 * time) as f32 + 1.5 * p.y).sin();
    g + breathe - 0.6 * p.length_squared()
}

/// Cube cells across the demo ball's diameter.
pub const DEMO_CELLS: usize = 32;

/// The demo mesh: a ball of radius 2 cut from a jittered Kuhn grid (built once).
pub fn demo_mesh() -> Arc<TetMesh> {
    static MESH: OnceLock<Arc<TetMesh>> = OnceLock::new();
    // Built with no lock held: the build forks on the pool (crate::once).
    crate::once::built(&MESH, || {
        Arc::new(grid_mesh(
            [DEMO_CELLS; 3],
            Vec3::splat(-2.0),
            Vec3::splat(2.0),
            0.2,
            0x7E75,
            |c| c.length() < 2.0,
        ))
    })
    .clone()
}

/// The demo's lighting, with what tetrahedral-isosurface-ray-tracing.txt §7 shows (Fig. 7):
/// a point light for shadows, a second, transparent isosurface around the first, and a clip
/// box that cuts one octant away. A viewer starts with these effects off and switches them
/// on.
pub fn demo_lighting() -> Lighting {
    Lighting {
        lights: vec![Light::Point {
            position: Vec3::new(4.0, 6.0, 5.0),
            color: Vec3::splat(70.0),
        }],
        materials: vec![
            Material::default(),
            Material {
                diffuse: Vec3::new(0.75, 0.85, 1.0),
                opacity: 0.35,
                ..Material::default()
            },
        ],
        isosurfaces: vec![Isosurface {
            isovalue: DEMO_OUTER_ISOVALUE,
            material: 1,
            color: None,
        }],
        clip_box: Some(ClipBox {
            min: Vec3::ZERO,
            max: Vec3::splat(3.0),
        }),
        ..Lighting::default()
    }
}

/// The demo's second isosurface (the viewer's slider starts at 0).
pub const DEMO_OUTER_ISOVALUE: f32 = -0.9;

/// The demo at `time`: the gyroid sampled on [`demo_mesh`], coloured over a fixed range.
pub fn demo_state(time: f64) -> TetScene {
    let mesh = demo_mesh();
    let scalars = sample(mesh.vertices(), |p| gyroid(p, time));
    TetScene::new(mesh, scalars)
        .expect("the gyroid is finite on every vertex")
        .with_color_range(-1.5, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buckyball_has_sixty_atoms_at_unit_bond_spacing() {
        let atoms = buckyball();
        assert_eq!(atoms.len(), 60);
        // Every atom has exactly three neighbours at distance 2 (the edge length).
        for a in &atoms {
            let near = atoms
                .iter()
                .filter(|b| ((**b - *a).length() - 2.0).abs() < 1e-4)
                .count();
            assert_eq!(near, 3);
        }
    }

    #[test]
    fn grids_are_valid_and_conforming() {
        let mesh = grid_mesh(
            [5, 4, 3],
            Vec3::ZERO,
            Vec3::new(5.0, 4.0, 3.0),
            0.3,
            9,
            |_| true,
        );
        assert_eq!(mesh.tets().len(), 6 * 5 * 4 * 3);
        assert_eq!(mesh.vertices().len(), 6 * 5 * 4);
        // Conforming: every interior triangle is shared by exactly two tets, boundary ones by one.
        let mut faces = std::collections::HashMap::new();
        for t in mesh.tets() {
            for skip in 0..4 {
                let mut f: Vec<u32> = (0..4).filter(|&i| i != skip).map(|i| t[i]).collect();
                f.sort_unstable();
                *faces.entry(f).or_insert(0) += 1;
            }
        }
        let boundary = faces.values().filter(|&&n| n == 1).count();
        assert!(faces.values().all(|&n| n == 1 || n == 2));
        // Two triangles per cube face on the outside: 2·(5·4 + 4·3 + 5·3)·2.
        assert_eq!(boundary, 2 * 2 * (5 * 4 + 4 * 3 + 5 * 3));
        let ball = grid_mesh([8; 3], Vec3::splat(-1.0), Vec3::splat(1.0), 0.0, 1, |c| {
            c.length() < 1.0
        });
        assert_eq!(
            ball.tets().len(),
            6 * count_cells([8; 3], Vec3::splat(-1.0), Vec3::splat(1.0), |c| c.length()
                < 1.0)
        );
    }

    #[test]
    fn the_demo_is_deterministic_and_animated() {
        let a = demo_state(1.0);
        assert_eq!(a, demo_state(1.0));
        assert_ne!(a.scalars(), demo_state(2.0).scalars());
        let (lo, hi) = a.isovalue_range();
        assert!(lo < 0.0 && hi > 0.0, "the default isovalue 0 has a surface");
    }
}
