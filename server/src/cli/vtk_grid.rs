//! A VTK unstructured grid as the readers give it (`vtk_xml` for `.vtu`, `vtk_legacy` for
//! `.vtk`), and its tetrahedra: what `isoray push` sends as a tet scene's mesh and steps.
//!
//! How it works: tetrahedra pass through; hexahedra (and voxels), wedges and pyramids are
//! split into tets, and the quadratic versions of all four keep their corner nodes (a linear
//! approximation). Cells of lower dimension (vertices, lines, triangles, quads: a mesher's
//! boundary) are skipped and counted. The split is a cone from the cell's lowest-numbered
//! vertex over the faces that do not hold it, each quad face cut along the diagonal through
//! its own lowest-numbered vertex. A face two cells share is then cut the same way from both
//! sides (a face holding the cone's apex is cut through the apex, which is its lowest
//! vertex too), so the tets of neighbouring cells meet face to face and the isosurface has no
//! cracks. A hexahedron becomes 6 tets, a wedge 3, a pyramid 2.
//!
//! Cell data becomes point data when that is what the file has: each vertex gets the mean of
//! the values of the cells around it (as ParaView's Cell Data to Point Data filter does).

/// The scalar array a reader picked: of the points or of the cells.
#[derive(Clone, Debug, PartialEq)]
pub enum Picked {
    Point(String),
    Cell(String),
}

impl Picked {
    pub fn name(&self) -> &str {
        match self {
            Picked::Point(n) | Picked::Cell(n) => n,
        }
    }
}

/// The scalar array to push: `wanted` among the point arrays, then the cell arrays; without
/// a name, the first one-component point array, else the first one-component cell array.
/// Arrays are `(name, components)`.
pub fn pick_array(
    point: &[(String, usize)],
    cell: &[(String, usize)],
    wanted: Option<&str>,
) -> Result<Picked, String> {
    let one = |(name, comps): &(String, usize)| -> Result<String, String> {
        if *comps == 1 {
            Ok(name.clone())
        } else {
            Err(format!("array {name:?} has {comps} components, not 1"))
        }
    };
    let found = match wanted {
        Some(w) => match point.iter().find(|(n, _)| n == w) {
            Some(a) => Some(Picked::Point(one(a)?)),
            None => match cell.iter().find(|(n, _)| n == w) {
                Some(a) => Some(Picked::Cell(one(a)?)),
                None => None,
            },
        },
        None => point
            .iter()
            .find(|(_, c)| *c == 1)
            .map(|(n, _)| Picked::Point(n.clone()))
            .or_else(|| {
                cell.iter()
                    .find(|(_, c)| *c == 1)
                    .map(|(n, _)| Picked::Cell(n.clone()))
            }),
    };
    found.ok_or_else(|| {
        let (p, c) = (names(point), names(cell));
        match wanted {
            Some(name) => format!(
                "no point or cell array named {name:?} (point arrays {p:?}, cell arrays {c:?})"
            ),
            None => format!(
                "no one-component point or cell array to push (point arrays {p:?}, cell arrays {c:?})"
            ),
        }
    })
}

fn names(arrays: &[(String, usize)]) -> Vec<&str> {
    arrays.iter().map(|(n, _)| n.as_str()).collect()
}

/// A grid as read, pieces joined.
#[derive(Debug, Default)]
pub struct Grid {
    pub points: Vec<[f64; 3]>,
    pub connectivity: Vec<u64>,
    /// Where each cell's corners end in `connectivity`.
    pub offsets: Vec<u64>,
    pub types: Vec<u8>,
    pub picked: Option<Picked>,
    /// One value per point, or per cell (`picked`).
    pub scalars: Vec<f64>,
}

fn whole(v: f64, what: &str, below: u64) -> Result<u64, String> {
    if v >= 0.0 && v.fract() == 0.0 && v < below as f64 {
        Ok(v as u64)
    } else {
        Err(format!("{what} is {v}, not a whole number below {below}"))
    }
}

impl Grid {
    /// Adds one piece: `coords` (3 per point), `offsets` (end of each cell in
    /// `connectivity`, piece-local), cell `types`, and the scalars of `picked`.
    pub fn append(
        &mut self,
        coords: &[f64],
        connectivity: &[f64],
        offsets: &[f64],
        types: &[f64],
        picked: Picked,
        scalars: Vec<f64>,
    ) -> Result<(), String> {
        if let Some(before) = &self.picked {
            if *before != picked {
                return Err(format!(
                    "the scalar array is {picked:?} here, {before:?} in the first piece"
                ));
            }
        }
        let base = self.points.len() as u64;
        let count = coords.len() / 3;
        let corner_base = self.connectivity.len() as u64;
        for (c, &id) in connectivity.iter().enumerate() {
            let id = whole(id, &format!("connectivity[{c}]"), count as u64)
                .map_err(|e| format!("{e} (the piece has {count} points)"))?;
            self.connectivity.push(base + id);
        }
        let mut last = 0;
        for (c, &end) in offsets.iter().enumerate() {
            let end = whole(end, &format!("offsets[{c}]"), connectivity.len() as u64 + 1)?;
            if end < last {
                return Err(format!(
                    "offsets[{c}] = {end} is below offsets[{}]",
                    c.max(1) - 1
                ));
            }
            last = end;
            self.offsets.push(corner_base + end);
        }
        for (c, &t) in types.iter().enumerate() {
            self.types
                .push(whole(t, &format!("types[{c}]"), 256)? as u8);
        }
        self.points
            .extend(coords.chunks_exact(3).map(|p| [p[0], p[1], p[2]]));
        self.picked = Some(picked);
        self.scalars.extend(scalars);
        Ok(())
    }

    /// The grid's tets: cells split, cell data moved to the points, tets oriented as the
    /// server wants them (positive volume).
    pub fn into_tets(self) -> Result<TetGrid, String> {
        let mut tets: Vec<[u64; 4]> = Vec::with_capacity(self.types.len());
        let mut split = [0usize; 3];
        let mut skipped = 0usize;
        let mut flipped = 0usize;
        let mut start = 0usize;
        let on_cells = matches!(self.picked, Some(Picked::Cell(_)));
        let mut sums = vec![(0.0f64, 0u32); if on_cells { self.points.len() } else { 0 }];
        for (c, (&end, &kind)) in self.offsets.iter().zip(&self.types).enumerate() {
            let ids = &self.connectivity[start..end as usize];
            start = end as usize;
            let shape = match Shape::of(kind) {
                Some(Some(shape)) => shape,
                Some(None) => {
                    skipped += 1;
                    continue;
                }
                None => {
                    return Err(format!(
                        "cell {c} is VTK cell type {kind}; isoray reads tetrahedra (10), voxels \
                         (11), hexahedra (12), wedges (13), pyramids (14) and their quadratic \
                         forms, and skips cells of lower dimension"
                    ))
                }
            };
            let corners = shape.corners();
            if ids.len() < corners {
                return Err(format!(
                    "cell {c} (VTK type {kind}) lists {} points, not {corners}",
                    ids.len()
                ));
            }
            let ids = shape.linear(kind, &ids[..corners]);
            let first = tets.len();
            match shape {
                Shape::Tet => tets.push([ids[0], ids[1], ids[2], ids[3]]),
                Shape::Hex => cone(&ids, &HEX_FACES, &mut tets),
                Shape::Wedge => cone(&ids, &WEDGE_FACES, &mut tets),
                Shape::Pyramid => cone(&ids, &PYRAMID_FACES, &mut tets),
            }
            match shape {
                Shape::Tet => {}
                Shape::Hex => split[0] += 1,
                Shape::Wedge => split[1] += 1,
                Shape::Pyramid => split[2] += 1,
            }
            for tet in &mut tets[first..] {
                if volume6(&self.points, tet) < 0.0 {
                    tet.swap(1, 2);
                    if shape == Shape::Tet {
                        flipped += 1;
                    }
                }
            }
            if on_cells {
                let v = self.scalars.get(c).copied().unwrap_or(0.0);
                for &id in &ids {
                    let s = &mut sums[id as usize];
                    s.0 += v;
                    s.1 += 1;
                }
            }
        }
        if tets.is_empty() {
            return Err("no three-dimensional cells".into());
        }
        let scalars = if on_cells {
            sums.iter()
                .map(|&(s, n)| if n == 0 { 0.0 } else { s / f64::from(n) })
                .collect()
        } else {
            self.scalars
        };
        Ok(TetGrid {
            points: self.points,
            cells: tets,
            scalars,
            picked: self.picked.unwrap_or(Picked::Point(String::new())),
            split,
            skipped,
            flipped,
        })
    }
}

/// A grid as tets, ready to push.
#[derive(Debug, PartialEq)]
pub struct TetGrid {
    pub points: Vec<[f64; 3]>,
    pub cells: Vec<[u64; 4]>,
    /// One per point (cell data already averaged onto the points).
    pub scalars: Vec<f64>,
    pub picked: Picked,
    /// Hexahedra, wedges and pyramids split.
    pub split: [usize; 3],
    /// Cells of lower dimension skipped.
    pub skipped: usize,
    /// Tets whose corners 1 and 2 were swapped to turn them the server's way.
    pub flipped: usize,
}

impl TetGrid {
    /// A line saying what was converted, if anything was.
    pub fn notes(&self) -> Vec<String> {
        let mut out = Vec::new();
        let [h, w, p] = self.split;
        if h + w + p > 0 {
            out.push(format!(
                "split {h} hexahedra, {w} wedges and {p} pyramids into tets ({} tets in all)",
                self.cells.len()
            ));
        }
        if self.skipped > 0 {
            out.push(format!("skipped {} cells of lower dimension", self.skipped));
        }
        if self.flipped > 0 {
            out.push(format!(
                "{} tets turned the other way from VTK's convention; corners 1 and 2 swapped",
                self.flipped
            ));
        }
        if let Picked::Cell(name) = &self.picked {
            out.push(format!(
                "cell array {name:?} moved to the points (each the mean of its cells)"
            ));
        }
        out
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Shape {
    Tet,
    Hex,
    Wedge,
    Pyramid,
}

/// Faces by local corner, VTK's order (hexahedron 0-3 bottom, 4-7 top; wedge triangles
/// 0-2 and 3-5; pyramid base 0-3, apex 4).
const HEX_FACES: [&[usize]; 6] = [
    &[0, 3, 2, 1],
    &[4, 5, 6, 7],
    &[0, 1, 5, 4],
    &[1, 2, 6, 5],
    &[2, 3, 7, 6],
    &[3, 0, 4, 7],
];
const WEDGE_FACES: [&[usize]; 5] = [
    &[0, 1, 2],
    &[3, 4, 5],
    &[0, 1, 4, 3],
    &[1, 2, 5, 4],
    &[2, 0, 3, 5],
];
const PYRAMID_FACES: [&[usize]; 5] = [
    &[0, 1, 2, 3],
    &[0, 1, 4],
    &[1, 2, 4],
    &[2, 3, 4],
    &[3, 0, 4],
];

impl Shape {
    /// `Some(Some(shape))` for a volume cell, `Some(None)` for one of lower dimension to
    /// skip, `None` for one isoray does not read.
    fn of(vtk_type: u8) -> Option<Option<Shape>> {
        Some(match vtk_type {
            10 | 24 => Some(Shape::Tet),
            11 | 12 | 25 | 29 => Some(Shape::Hex),
            13 | 26 | 32 => Some(Shape::Wedge),
            14 | 27 => Some(Shape::Pyramid),
            1..=9 | 21 | 22 | 23 | 28 | 30 => None,
            _ => return None,
        })
    }

    fn corners(self) -> usize {
        match self {
            Shape::Tet => 4,
            Shape::Hex => 8,
            Shape::Wedge => 6,
            Shape::Pyramid => 5,
        }
    }

    /// The corner ids in the linear cell's order (a voxel's, VTK type 11, are reordered to
    /// a hexahedron's).
    fn linear(self, vtk_type: u8, ids: &[u64]) -> Vec<u64> {
        if vtk_type == 11 {
            [0, 1, 3, 2, 4, 5, 7, 6].map(|i| ids[i]).to_vec()
        } else {
            ids.to_vec()
        }
    }
}

/// The cone from the cell's lowest vertex over the faces without it.
fn cone(ids: &[u64], faces: &[&[usize]], out: &mut Vec<[u64; 4]>) {
    let apex = (0..ids.len()).min_by_key(|&i| ids[i]).unwrap_or(0);
    for face in faces {
        if face.contains(&apex) {
            continue;
        }
        let q: Vec<u64> = face.iter().map(|&i| ids[i]).collect();
        if q.len() == 3 {
            out.push([ids[apex], q[0], q[1], q[2]]);
        } else {
            let m = (0..4).min_by_key(|&i| q[i]).unwrap_or(0);
            let at = |k: usize| q[(m + k) % 4];
            out.push([ids[apex], at(0), at(1), at(2)]);
            out.push([ids[apex], at(0), at(2), at(3)]);
        }
    }
}

/// Six times the signed volume of a tet, VTK's sign. Corners missing from `points` count
/// as the origin (`append` has checked them).
pub fn volume6(points: &[[f64; 3]], cell: &[u64; 4]) -> f64 {
    let p = cell.map(|i| points.get(i as usize).copied().unwrap_or([0.0; 3]));
    let d = |a: [f64; 3], b: [f64; 3]| [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let (a, b, c) = (d(p[0], p[1]), d(p[0], p[2]), d(p[0], p[3]));
    a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
        + a[2] * (b[0] * c[1] - b[1] * c[0])
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    /// A grid of `types` over `points`, one point array.
    fn grid(points: Vec<[f64; 3]>, cells: &[(u8, Vec<u64>)]) -> Grid {
        let coords: Vec<f64> = points.iter().flatten().copied().collect();
        let mut connectivity = Vec::new();
        let mut offsets = Vec::new();
        for (_, ids) in cells {
            connectivity.extend(ids.iter().map(|&i| i as f64));
            offsets.push(connectivity.len() as f64);
        }
        let types: Vec<f64> = cells.iter().map(|(t, _)| f64::from(*t)).collect();
        let mut g = Grid::default();
        let n = points.len();
        g.append(
            &coords,
            &connectivity,
            &offsets,
            &types,
            Picked::Cell("c".into()),
            (0..cells.len()).map(|c| c as f64).collect(),
        )
        .expect("a good grid");
        assert_eq!(g.points.len(), n);
        g
    }

    fn cube(x0: f64) -> Vec<[f64; 3]> {
        let mut p = Vec::new();
        for z in [0.0, 1.0] {
            for (x, y) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
                p.push([x0 + x, y, z]);
            }
        }
        p
    }

    /// The faces of every tet, sorted, with how many tets hold each: an inner face twice.
    fn faces(tets: &[[u64; 4]]) -> HashMap<[u64; 3], usize> {
        let mut out = HashMap::new();
        for t in tets {
            for skip in 0..4 {
                let mut f: Vec<u64> = (0..4).filter(|&i| i != skip).map(|i| t[i]).collect();
                f.sort_unstable();
                *out.entry([f[0], f[1], f[2]]).or_insert(0) += 1;
            }
        }
        out
    }

    #[test]
    fn cells_split_into_positive_tets_that_fill_them_and_meet_face_to_face() {
        // Two hexahedra sharing the face x = 1, numbered so that the shared face's lowest
        // vertex differs from both cells' lowest: the split must still agree there.
        let mut points = cube(0.0);
        points.extend(cube(1.0));
        // The second cube's face x = 1 is points 1, 2, 5, 6 of the first (its own copies
        // 8, 11, 12, 15 are unused).
        let second = vec![1, 9, 10, 2, 5, 13, 14, 6];
        let g = grid(points, &[(12, vec![7, 6, 5, 4, 3, 2, 1, 0]), (12, second)]);
        let t = g.into_tets().expect("tets");
        assert_eq!(t.cells.len(), 12);
        let total: f64 = t.cells.iter().map(|c| volume6(&t.points, c) / 6.0).sum();
        assert!((total - 2.0).abs() < 1e-12, "{total}");
        assert!(t.cells.iter().all(|c| volume6(&t.points, c) > 0.0));
        // Every face is on the boundary (once) or shared by exactly two tets; the shared
        // square x = 1 is two triangles seen from both sides.
        let f = faces(&t.cells);
        assert!(f.values().all(|&n| n <= 2));
        let boundary = f.values().filter(|&&n| n == 1).count();
        assert_eq!(boundary, 2 * 10, "10 outer squares, two triangles each");
        // Cell data on the points: vertex 0 only in cell 0 (value 0), vertex 1 in both.
        assert_eq!(t.scalars[0], 0.0);
        assert_eq!(t.scalars[1], 0.5);
        assert_eq!(t.scalars[9], 1.0);
        assert_eq!(t.split, [2, 0, 0]);

        let wedge = grid(
            vec![
                [0., 0., 0.],
                [1., 0., 0.],
                [0., 1., 0.],
                [0., 0., 1.],
                [1., 0., 1.],
                [0., 1., 1.],
            ],
            &[(13, vec![0, 1, 2, 3, 4, 5]), (5, vec![0, 1, 2])],
        )
        .into_tets()
        .expect("tets");
        assert_eq!((wedge.cells.len(), wedge.skipped), (3, 1));
        let v: f64 = wedge.cells.iter().map(|c| volume6(&wedge.points, c)).sum();
        assert!((v / 6.0 - 0.5).abs() < 1e-12);

        let pyramid = grid(
            // The apex is the lowest-numbered vertex: the cone is then over the base.
            vec![
                [0.5, 0.5, 1.],
                [0., 0., 0.],
                [1., 0., 0.],
                [1., 1., 0.],
                [0., 1., 0.],
            ],
            &[(14, vec![1, 2, 3, 4, 0])],
        );
        let e = grid(pyramid.points.clone(), &[(42, vec![0, 1, 2, 3])])
            .into_tets()
            .expect_err("a polyhedron");
        assert!(e.contains("cell 0") && e.contains("42"), "{e}");
        let pyramid = pyramid.into_tets().expect("tets");
        assert_eq!(pyramid.cells.len(), 2);
        let v: f64 = pyramid
            .cells
            .iter()
            .map(|c| volume6(&pyramid.points, c))
            .sum();
        assert!((v / 6.0 - 1.0 / 3.0).abs() < 1e-12);
    }

    #[test]
    fn bad_connectivity_and_array_choices_are_named() {
        let mut g = Grid::default();
        let e = g
            .append(
                &[0.0; 12],
                &[0.0, 1.0, 2.0, 7.0],
                &[4.0],
                &[10.0],
                Picked::Point("p".into()),
                vec![0.0; 4],
            )
            .expect_err("point 7 of 4");
        assert!(e.contains("connectivity[3]") && e.contains('7'), "{e}");
        let arrays = |n: &[(&str, usize)]| -> Vec<(String, usize)> {
            n.iter().map(|(a, c)| (a.to_string(), *c)).collect()
        };
        let p = arrays(&[("v", 3), ("p", 1)]);
        let c = arrays(&[("rho", 1)]);
        assert_eq!(pick_array(&p, &c, None), Ok(Picked::Point("p".into())));
        assert_eq!(
            pick_array(&p, &c, Some("rho")),
            Ok(Picked::Cell("rho".into()))
        );
        assert_eq!(pick_array(&[], &c, None), Ok(Picked::Cell("rho".into())));
        let e = pick_array(&p, &c, Some("v")).expect_err("3 components");
        assert!(e.contains("\"v\"") && e.contains('3'), "{e}");
        let e = pick_array(&p, &c, Some("q")).expect_err("none");
        assert!(e.contains("\"q\"") && e.contains("rho"), "{e}");
    }
}
