//! Surfels from real data (deforming-point-sampled-surfaces.txt §3 takes its objects from
//! scans): an oriented point cloud becomes surfels with tangent axes from each normal and a
//! radius from the neighbours' spacing; a point cloud without normals gets them by principal
//! component analysis of its neighbourhoods; a triangle mesh is sampled into such a cloud
//! (area-weighted, deterministic); and a lattice of simulation nodes is laid around any of
//! them.
//!
//! How it works: neighbourhoods come from [`crate::kinds::surfels::knn::Grid`]. An estimated
//! normal is the eigenvector of the smallest eigenvalue of the neighbourhood's covariance
//! (nalgebra's symmetric eigensolver), oriented away from the cloud's centroid (right for
//! the closed, roughly star-shaped objects of the demos; a cloud that has normals keeps
//! them). A surfel's radius is the distance to its `RADIUS_NEIGHBOURS`-th nearest point, so
//! the discs overlap their neighbours' as the MLS intersection needs.

use crate::geom::rng::SplitMix64;
use crate::kinds::surfels::knn::Grid;
use crate::kinds::surfels::model::Surfel;
use crate::kinds::surfels::sample::tangents;
use glam::Vec3;
use rayon::prelude::*;

/// Neighbours whose farthest sets a surfel's radius.
pub const RADIUS_NEIGHBOURS: usize = 6;
/// Neighbours of a normal estimate.
pub const NORMAL_NEIGHBOURS: usize = 12;

/// Why input data cannot become surfels.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum InputError {
    #[error("the point cloud has no points")]
    NoPoints,
    #[error("the mesh has no faces")]
    NoFaces,
    #[error("face {face} names vertex {index}, but the mesh has {vertices} vertices")]
    BadIndex {
        face: usize,
        corner: usize,
        index: u64,
        vertices: usize,
    },
    #[error("{what} {index} is not finite")]
    NotFinite { what: &'static str, index: usize },
    #[error("{normals} normals for {points} points")]
    NormalCount { normals: usize, points: usize },
    #[error("every face of the mesh has zero area")]
    ZeroArea,
}

/// Surfels of colour `colour` (group 0) on `points`, with `normals` if the cloud has them
/// (a zero normal is estimated like a missing one).
pub fn from_points(
    points: &[Vec3],
    normals: Option<&[Vec3]>,
    colour: Vec3,
) -> Result<Vec<Surfel>, InputError> {
    if points.is_empty() {
        return Err(InputError::NoPoints);
    }
    if let Some(index) = points.iter().position(|p| !p.is_finite()) {
        return Err(InputError::NotFinite {
            what: "point",
            index,
        });
    }
    if let Some(n) = normals {
        if n.len() != points.len() {
            return Err(InputError::NormalCount {
                normals: n.len(),
                points: points.len(),
            });
        }
        if let Some(index) = n.iter().position(|v| !v.is_finite()) {
            return Err(InputError::NotFinite {
                what: "normal",
                index,
            });
        }
    }
    let grid = Grid::new(points);
    let centroid = points.iter().copied().sum::<Vec3>() / points.len() as f32;
    let (lo, hi) = points.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(a, b), p| (a.min(*p), b.max(*p)),
    );
    let min_radius = 1e-4 * (hi - lo).length().max(1e-6);
    let k = NORMAL_NEIGHBOURS.min(points.len() - 1);
    Ok((0..points.len())
        .into_par_iter()
        .map_init(Vec::new, |near, i| {
            let p = points[i];
            grid.nearest(p, k, Some(i as u32), near);
            let given = normals.map(|n| n[i]).filter(|n| n.length_squared() > 1e-20);
            let normal = match given {
                Some(n) => n.normalize(),
                None => {
                    let n = pca_normal(points, p, near);
                    if n.dot(p - centroid) < 0.0 {
                        -n
                    } else {
                        n
                    }
                }
            };
            let r = near
                .get(RADIUS_NEIGHBOURS.min(near.len()).saturating_sub(1))
                .map_or(min_radius, |n| n.1.sqrt())
                .max(min_radius);
            let (t1, t2) = tangents(normal);
            Surfel {
                centre: p,
                t1,
                t2,
                normal,
                colour,
                radius: r,
                group: 0,
            }
        })
        .collect())
}

/// The unit normal of the plane fitted to `p` and its neighbours `near`.
fn pca_normal(points: &[Vec3], p: Vec3, near: &[(u32, f32)]) -> Vec3 {
    let mut mean = p;
    for n in near {
        mean += points[n.0 as usize];
    }
    mean /= (near.len() + 1) as f32;
    let mut c = nalgebra::Matrix3::<f64>::zeros();
    for q in std::iter::once(p).chain(near.iter().map(|n| points[n.0 as usize])) {
        let d = q - mean;
        let d = nalgebra::Vector3::new(d.x as f64, d.y as f64, d.z as f64);
        c += d * d.transpose();
    }
    let eig = nalgebra::SymmetricEigen::new(c);
    let mut best = 0;
    for i in 1..3 {
        if eig.eigenvalues[i] < eig.eigenvalues[best] {
            best = i;
        }
    }
    let v = eig.eigenvectors.column(best);
    let n = Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32);
    if n.length_squared() > 1e-12 {
        n.normalize()
    } else {
        Vec3::Z
    }
}

/// `count` points on a triangle mesh, area-weighted, with their faces' normals (right-handed
/// winding: `(b − a) × (c − a)` points out). Deterministic for a given `seed`.
pub fn sample_mesh(
    vertices: &[Vec3],
    triangles: &[[u64; 3]],
    count: usize,
    seed: u64,
) -> Result<(Vec<Vec3>, Vec<Vec3>), InputError> {
    if triangles.is_empty() {
        return Err(InputError::NoFaces);
    }
    if let Some(index) = vertices.iter().position(|p| !p.is_finite()) {
        return Err(InputError::NotFinite {
            what: "vertex",
            index,
        });
    }
    for (face, t) in triangles.iter().enumerate() {
        for (corner, &index) in t.iter().enumerate() {
            if index >= vertices.len() as u64 {
                return Err(InputError::BadIndex {
                    face,
                    corner,
                    index,
                    vertices: vertices.len(),
                });
            }
        }
    }
    let corners = |t: &[u64; 3]| t.map(|i| vertices[i as usize]);
    let mut cdf = Vec::with_capacity(triangles.len());
    let mut total = 0.0f64;
    for t in triangles {
        let [a, b, c] = corners(t);
        total += 0.5 * (b - a).cross(c - a).length() as f64;
        cdf.push(total);
    }
    if !(total > 0.0) {
        return Err(InputError::ZeroArea);
    }
    let mut rng = SplitMix64(seed);
    let mut points = Vec::with_capacity(count);
    let mut normals = Vec::with_capacity(count);
    for _ in 0..count.max(1) {
        let x = rng.next_f32() as f64 * total;
        let f = cdf.partition_point(|&c| c <= x).min(triangles.len() - 1);
        let [a, b, c] = corners(&triangles[f]);
        let (r1, r2) = (rng.next_f32().sqrt(), rng.next_f32());
        points.push(a * (1.0 - r1) + b * (r1 * (1.0 - r2)) + c * (r1 * r2));
        normals.push((b - a).cross(c - a).normalize_or_zero());
    }
    Ok((points, normals))
}

/// Simulation nodes for an object on `points`: a cubic lattice over its bounds with about
/// `target` cells, kept where a point of the object is within one lattice spacing.
pub fn nodes_for(points: &[Vec3], target: usize) -> Vec<Vec3> {
    let (lo, hi) = points.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(a, b), p| (a.min(*p), b.max(*p)),
    );
    if points.is_empty() {
        return Vec::new();
    }
    let ext = (hi - lo).max(Vec3::splat(1e-3 * (hi - lo).max_element().max(1e-6)));
    let spacing = (ext.x * ext.y * ext.z / target.max(1) as f32).cbrt();
    let grid = Grid::new(points);
    crate::kinds::surfels::sample::lattice(lo, hi, spacing, |q| {
        let mut near = Vec::with_capacity(1);
        grid.nearest(q, 1, None, &mut near);
        near.first().is_some_and(|n| n.1.sqrt() <= spacing)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinds::surfels::sample::fibonacci;

    #[test]
    fn estimated_normals_of_a_sphere_point_outwards_and_radii_overlap() {
        let points: Vec<Vec3> = fibonacci(2000).map(|p| p * 2.0).collect();
        let surfels = from_points(&points, None, Vec3::ONE).expect("valid");
        for s in &surfels {
            let radial = s.centre.normalize();
            assert!(
                s.normal.dot(radial) > 0.99,
                "{:?} at {:?}",
                s.normal,
                s.centre
            );
            assert!(s.t1.cross(s.t2).dot(s.normal) > 0.99);
        }
        // Spacing of 2000 points on a sphere of radius 2: sqrt(4π·4/2000) ≈ 0.16.
        let mean = surfels.iter().map(|s| s.radius).sum::<f32>() / surfels.len() as f32;
        assert!((0.12..0.4).contains(&mean), "mean radius {mean}");
    }

    #[test]
    fn meshes_are_sampled_on_their_faces_and_bad_ones_refused() {
        // A tetrahedron, faces wound outwards.
        let v = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let faces = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        let (p, n) = sample_mesh(&v, &faces, 500, 7).expect("valid");
        let centroid = Vec3::splat(0.25);
        for (p, n) in p.iter().zip(&n) {
            assert!(
                p.min_element() >= -1e-5 && p.element_sum() <= 1.0 + 1e-5,
                "{p:?}"
            );
            assert!(n.dot(*p - centroid) > 0.0, "outward normal");
        }
        assert_eq!(sample_mesh(&v, &[], 10, 1), Err(InputError::NoFaces));
        assert!(matches!(
            sample_mesh(&v, &[[0, 1, 9]], 10, 1),
            Err(InputError::BadIndex {
                face: 0,
                corner: 2,
                index: 9,
                ..
            })
        ));
        assert_eq!(
            sample_mesh(&v, &[[0, 1, 1]], 10, 1),
            Err(InputError::ZeroArea)
        );
        let nodes = nodes_for(&p, 64);
        assert!(nodes.len() >= 8, "{} nodes", nodes.len());
    }
}
