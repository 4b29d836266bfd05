//! Marching tetrahedra and the ray–isopolygon test.
//!
//! How it works (tetrahedral-isosurface-ray-tracing.txt §4.1–4.3):
//! - Extraction (§4.1): each corner is above the isovalue or not, giving one of 16 cases;
//!   [`CASES`] stores, per case, how many polygon vertices there are and the tet edges they
//!   lie on, in cyclic order. Each vertex is interpolated along its edge, always from the
//!   corner with the lower *global* vertex index, so two tets sharing an edge compute the
//!   same point bit for bit.
//! - Intersection (§4.2): the paper projects the ray's hit on the polygon's plane to 2-D and
//!   tests it against each edge's half-plane. We do the same half-space test one dimension
//!   up: each edge and the ray origin span a plane with normal `m = (p_i - o) × (p_{i+1} - o)`,
//!   and the ray direction `d` passes inside the polygon exactly when every `m · d ≥ 0`
//!   (with the edges oriented as seen from `o`). Two reasons: the `m` depend only on the
//!   origin, so a packet of rays from one eye computes them once per polygon and then pays
//!   one dot product per edge and ray; and a shared edge gives its two polygons exactly
//!   negated `m` (each forms it about the edge's midpoint, [`edge_normal`]), so a ray on the
//!   edge is never lost between neighbouring tets (the surface is watertight).
//! - Frustum culling (§4.3): a ray through a tile is a positive combination of the tile's
//!   four corner rays, so when all four corners fail the same edge the whole packet misses,
//!   and when all four pass every edge the whole packet hits and only distances remain.

use glam::{Vec3, Vec4, Vec4Swizzles};

/// Tet edges as pairs of corners.
pub const EDGES: [(usize, usize); 6] = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)];

/// Per case (bit `i` set: corner `i` above the isovalue): the number of polygon vertices
/// (0, 3 or 4) and the edges (indices into [`EDGES`]) they lie on, in cyclic order.
pub const CASES: [(u8, [u8; 4]); 16] = [
    (0, [0; 4]),
    (3, [0, 1, 2, 0]),
    (3, [0, 3, 4, 0]),
    (4, [1, 2, 4, 3]),
    (3, [1, 3, 5, 0]),
    (4, [0, 2, 5, 3]),
    (4, [0, 4, 5, 1]),
    (3, [2, 4, 5, 0]),
    (3, [2, 4, 5, 0]),
    (4, [0, 1, 5, 4]),
    (4, [0, 3, 5, 2]),
    (3, [1, 3, 5, 0]),
    (4, [1, 3, 4, 2]),
    (3, [0, 3, 4, 0]),
    (3, [0, 1, 2, 0]),
    (0, [0; 4]),
];

/// The marching-tets case of a tet's four scalars against `isovalue`: bit `i` is set when
/// scalar `i` is above it. A polygon exists exactly when `min ≤ isovalue < max`.
#[inline]
pub fn case_of(scalars: [f32; 4], isovalue: f32) -> usize {
    (scalars[0] > isovalue) as usize
        | ((scalars[1] > isovalue) as usize) << 1
        | ((scalars[2] > isovalue) as usize) << 2
        | ((scalars[3] > isovalue) as usize) << 3
}

/// A tet's isopolygon: three or four vertices in cyclic order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Isopolygon {
    pub count: usize,
    pub points: [Vec3; 4],
}

/// The isopolygon of the tet with global vertex indices `ids` and corners `corners`
/// (`xyz` position, `w` scalar), or `None` when the isovalue misses the tet.
#[inline]
pub fn extract(ids: [u32; 4], corners: [Vec4; 4], isovalue: f32) -> Option<Isopolygon> {
    let (count, edges) = CASES[case_of(corners.map(|c| c.w), isovalue)];
    if count == 0 {
        return None;
    }
    let mut points = [Vec3::ZERO; 4];
    for (point, &edge) in points.iter_mut().zip(&edges[..count as usize]) {
        let (a, b) = EDGES[edge as usize];
        // From the lower global index, so a shared edge gives the same point in every tet.
        let (a, b) = if ids[a] < ids[b] { (a, b) } else { (b, a) };
        let (pa, pb) = (corners[a], corners[b]);
        let s = (isovalue - pa.w) / (pb.w - pa.w);
        *point = pa.xyz() + (pb.xyz() - pa.xyz()) * s;
    }
    Some(Isopolygon {
        count: count as usize,
        points,
    })
}

/// An isopolygon set up for rays from one origin: the oriented edge-plane normals, the
/// polygon's plane normal and `n · (p_0 - o)`.
#[derive(Clone, Copy, Debug)]
pub struct PolygonFromOrigin {
    count: usize,
    /// Enough edges are tested to close the polygon ([`closed`]); else it is never hit.
    closed: bool,
    edge_normals: [Vec3; 4],
    normal: Vec3,
    numerator: f32,
}

/// The verdict of the corner-ray frustum test on one polygon.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrustumTest {
    /// Every ray of the packet misses: skip the per-ray tests.
    Miss,
    /// Every ray of the packet passes every edge: only the distance remains.
    Hit,
    /// Test each ray.
    Partial,
}

/// `(16 ε)²` for `f32`'s `ε`: an edge plane's normal no longer than `16 ε |c|²`, with `c` the
/// edge's midpoint relative to the origin, has a direction that rounding sets ([`edge_normal`]).
const EDGE_NOISE: f32 = (16.0 * f32::EPSILON) * (16.0 * f32::EPSILON);

/// The normal of the plane through the ray origin `o` and the polygon edge from `p` to `q`,
/// given their offsets `rp = p − o` and `rq = q − o`: `(p − o) × (q − o)` in exact arithmetic,
/// formed as `c × (q − p)` about the edge's midpoint `c = (rp + rq) / 2`; or zero where the
/// edge is so short against its distance that rounding sets the normal's direction.
///
/// The form, for two reasons. Accuracy: `q − p` is the edge as the points give it (exact when
/// they are near each other), where `rp × rq` carries the rounding of both offsets at the
/// origin's distance: for an edge 5·10⁻⁵ long seen from 5.5 away the plane turned by about 1%
/// about the line of sight, and a sliver's two long edges both let through a ray well off the
/// polygon (the gyroid demo at 23.3 s, pixel (171, 85) at 320×240: a triangle of a tet with a
/// corner 2·10⁻⁴ below the isovalue was hit at 5.4757 where the surface is at 5.4948).
/// Watertightness: the polygon across a shared edge has the same points and offsets, bit for
/// bit ([`extract`]), in the other order, and forms `c × (p − q)` with the same `c` (addition
/// commutes): exactly the negated vector, so a ray on the edge is never lost between the two.
///
/// Short edges: a polygon vertex within rounding of the next (a tet corner within about 10⁻⁶
/// of the isovalue: two of the gyroid demo's quad's points 6·10⁻⁸ apart gave a plane that
/// rejected a ray through the middle of the quad and left a hole) has an edge whose direction
/// is the points' rounding. Such an edge cuts no real part of the polygon, so it is not tested
/// ([`is_noise`]); the polygon's other edges still close it when at least three are left (a
/// quad with one such edge is its triangle), and a polygon with fewer has no area and is
/// never hit ([`closed`]). The tet across the edge reaches the same verdict (the same `c` and
/// `|m|`), so no gap opens between the two.
#[inline]
pub fn edge_normal(p: Vec3, q: Vec3, rp: Vec3, rq: Vec3) -> Vec3 {
    let c = (rp + rq) * 0.5;
    let m = c.cross(q - p);
    if is_noise(c, m) {
        Vec3::ZERO
    } else {
        m
    }
}

/// The normal of a polygon's plane from its points (differences of the points themselves,
/// not of their offsets from an origin, [`edge_normal`]), oriented by their cyclic order.
#[inline]
fn plane_normal(poly: &Isopolygon) -> Vec3 {
    let p = &poly.points;
    if poly.count == 3 {
        (p[1] - p[0]).cross(p[2] - p[0])
    } else {
        (p[2] - p[0]).cross(p[3] - p[1])
    }
}

/// Whether an edge plane's normal `m`, formed about the edge's midpoint `c` (relative to the
/// origin), is no longer than `16 ε |c|²`: the edge's angular length is within rounding.
#[inline]
fn is_noise(c: Vec3, m: Vec3) -> bool {
    m.length_squared() <= EDGE_NOISE * (c.length_squared() * c.length_squared())
}

/// Whether a polygon of `count` edges, `dropped` of them not tested ([`edge_normal`]), still
/// has edges that close it.
#[inline]
fn closed(count: usize, dropped: usize) -> bool {
    count >= dropped + 3
}

/// Corner rays must clear an edge plane by this fraction of `|m|` (directions are unit) for
/// the frustum verdicts, far above the rounding of one dot product (≈ 4·10⁻⁷), so a verdict
/// never disagrees with the per-ray test.
const FRUSTUM_MARGIN: f32 = 1e-5;

impl PolygonFromOrigin {
    #[inline]
    pub fn new(poly: &Isopolygon, origin: Vec3) -> PolygonFromOrigin {
        let n = poly.count;
        let rel = poly.points.map(|p| p - origin);
        let normal = plane_normal(poly);
        let numerator = normal.dot(rel[0]);
        // Seen from the origin's side of the plane the edges turn the other way.
        let sign = if numerator < 0.0 { -1.0 } else { 1.0 };
        let mut edge_normals = [Vec3::ZERO; 4];
        let mut dropped = 0;
        for i in 0..n {
            let j = if i + 1 == n { 0 } else { i + 1 };
            edge_normals[i] = edge_normal(poly.points[i], poly.points[j], rel[i], rel[j]) * sign;
            dropped += (edge_normals[i] == Vec3::ZERO) as usize;
        }
        PolygonFromOrigin {
            count: n,
            closed: closed(n, dropped),
            edge_normals,
            normal,
            numerator,
        }
    }

    /// Distance along `dir` (unit) from the origin to the polygon, if the ray passes inside.
    #[inline]
    pub fn intersect(&self, dir: Vec3) -> Option<f32> {
        if !self.closed {
            return None;
        }
        for m in &self.edge_normals[..self.count] {
            if m.dot(dir) < 0.0 {
                return None;
            }
        }
        self.distance(dir)
    }

    /// Distance to the polygon's plane along `dir` (for rays known to pass inside).
    #[inline]
    pub fn distance(&self, dir: Vec3) -> Option<f32> {
        let t = self.numerator / self.normal.dot(dir);
        t.is_finite().then_some(t)
    }

    /// §4.3: the four corner rays of a packet against every edge.
    #[inline]
    pub fn frustum(&self, corners: &[Vec3; 4]) -> FrustumTest {
        if !self.closed {
            return FrustumTest::Miss;
        }
        let mut all_inside = true;
        for m in &self.edge_normals[..self.count] {
            let margin = FRUSTUM_MARGIN * m.length();
            let mut all_outside = true;
            for c in corners {
                let v = m.dot(*c);
                all_outside &= v < -margin;
                all_inside &= v > margin;
            }
            if all_outside {
                return FrustumTest::Miss;
            }
        }
        if all_inside {
            FrustumTest::Hit
        } else {
            FrustumTest::Partial
        }
    }
}

/// One ray against an isopolygon: the distance if the ray passes inside within
/// `[t_min, t_max]`. The same arithmetic as [`PolygonFromOrigin`] (so the same answers, bit
/// for bit), ordered for one ray: the plane distance first, which rejects most polygons
/// (behind the origin or beyond the best hit so far) before any edge test, then the edges,
/// stopping at the first that fails. An edge's rounding test ([`edge_normal`]) is taken only
/// where the edge would reject the ray, and on every edge once all have passed (to count the
/// untested ones): the same verdicts as testing each edge first, without the test on the
/// edges of the many polygons whose plane a ray crosses outside the polygon.
#[inline]
pub fn intersect_one(
    poly: &Isopolygon,
    origin: Vec3,
    dir: Vec3,
    t_min: f32,
    t_max: f32,
) -> Option<f32> {
    let n = poly.count;
    let rel = poly.points.map(|p| p - origin);
    let normal = plane_normal(poly);
    let numerator = normal.dot(rel[0]);
    let t = numerator / normal.dot(dir);
    if !(t >= t_min && t <= t_max && t.is_finite()) {
        return None;
    }
    let sign = if numerator < 0.0 { -1.0 } else { 1.0 };
    let (mut cs, mut ms) = ([Vec3::ZERO; 4], [Vec3::ZERO; 4]);
    for i in 0..n {
        let j = if i + 1 == n { 0 } else { i + 1 };
        // `edge_normal` with its rounding test taken only where the edge would reject.
        cs[i] = (rel[i] + rel[j]) * 0.5;
        ms[i] = cs[i].cross(poly.points[j] - poly.points[i]) * sign;
        if ms[i].dot(dir) < 0.0 && !is_noise(cs[i], ms[i]) {
            return None;
        }
    }
    let dropped = (0..n).filter(|&i| is_noise(cs[i], ms[i])).count();
    closed(n, dropped).then_some(t)
}

/// The (constant) gradient of the linear field over a tet, and six times its signed volume.
#[inline]
pub fn gradient(corners: [Vec4; 4]) -> (Vec3, f32) {
    let p0 = corners[0].xyz();
    let e1 = corners[1].xyz() - p0;
    let e2 = corners[2].xyz() - p0;
    let e3 = corners[3].xyz() - p0;
    let c23 = e2.cross(e3);
    let c31 = e3.cross(e1);
    let c12 = e1.cross(e2);
    let det = e1.dot(c23);
    let s0 = corners[0].w;
    let g =
        (c23 * (corners[1].w - s0) + c31 * (corners[2].w - s0) + c12 * (corners[3].w - s0)) / det;
    (g, det)
}

/// Barycentric coordinates of `p` in the tet, clamped to the tet and renormalised.
#[inline]
pub fn barycentric(corners: [Vec4; 4], p: Vec3) -> [f32; 4] {
    let [a, b, c, d] = corners.map(|v| v.xyz());
    let vol = |p0: Vec3, p1: Vec3, p2: Vec3, p3: Vec3| (p1 - p0).cross(p2 - p0).dot(p3 - p0);
    let total = vol(a, b, c, d);
    let l = [
        vol(p, b, c, d) / total,
        vol(a, p, c, d) / total,
        vol(a, b, p, d) / total,
        vol(a, b, c, p) / total,
    ]
    .map(|x| if x.is_finite() { x.max(0.0) } else { 0.0 });
    let sum: f32 = l.iter().sum();
    if sum > 0.0 {
        l.map(|x| x / sum)
    } else {
        [0.25; 4]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::rng::SplitMix64;

    #[test]
    fn the_case_table_is_marching_tets() {
        for (case, &(count, edges)) in CASES.iter().enumerate() {
            let above = |c: usize| case & (1 << c) != 0;
            let crossing: Vec<usize> = (0..6)
                .filter(|&e| above(EDGES[e].0) != above(EDGES[e].1))
                .collect();
            assert_eq!(count as usize, crossing.len(), "case {case}");
            let listed: Vec<usize> = edges[..count as usize]
                .iter()
                .map(|&e| e as usize)
                .collect();
            let mut sorted = listed.clone();
            sorted.sort_unstable();
            assert_eq!(sorted, crossing, "case {case}: every crossing edge once");
            // Consecutive polygon vertices lie on a common face: their edges span 3 corners.
            for i in 0..listed.len() {
                let (a, b) = EDGES[listed[i]];
                let (c, d) = EDGES[listed[(i + 1) % listed.len()]];
                let mut corners = vec![a, b, c, d];
                corners.sort_unstable();
                corners.dedup();
                assert_eq!(corners.len(), 3, "case {case}: edge {i} crosses a face");
            }
        }
    }

    fn random_tet(rng: &mut SplitMix64) -> [Vec4; 4] {
        [0; 4].map(|_| {
            Vec4::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            )
        })
    }

    #[test]
    fn isopolygons_are_planar_convex_and_on_the_isosurface() {
        let mut rng = SplitMix64(7);
        let mut seen = [0usize; 5];
        for _ in 0..2000 {
            let corners = random_tet(&mut rng);
            let iso = rng.range(-0.8, 0.8);
            let Some(poly) = extract([0, 1, 2, 3], corners, iso) else {
                continue;
            };
            seen[poly.count] += 1;
            let (g, det) = gradient(corners);
            if det.abs() < 1e-3 {
                continue;
            }
            let p = &poly.points[..poly.count];
            for q in p {
                // The linear field is the isovalue at every polygon vertex.
                let f = corners[0].w + g.dot(*q - corners[0].xyz());
                assert!((f - iso).abs() < 1e-3 * (1.0 + g.length()), "{f} vs {iso}");
            }
            // Convex: every turn has the same sense about the gradient.
            let turns: Vec<f32> = (0..p.len())
                .map(|i| {
                    let a = p[(i + 1) % p.len()] - p[i];
                    let b = p[(i + 2) % p.len()] - p[(i + 1) % p.len()];
                    a.cross(b).dot(g)
                })
                .collect();
            let scale: f32 = turns.iter().map(|t| t.abs()).fold(0.0, f32::max);
            assert!(
                turns.iter().all(|&t| t >= -1e-4 * scale)
                    || turns.iter().all(|&t| t <= 1e-4 * scale),
                "{turns:?}"
            );
        }
        assert!(
            seen[3] > 100 && seen[4] > 100,
            "both shapes tested: {seen:?}"
        );
    }

    #[test]
    fn ray_isopolygon_test_matches_the_plane_and_inside_test() {
        let mut rng = SplitMix64(11);
        let mut hits = 0;
        for _ in 0..4000 {
            let corners = random_tet(&mut rng);
            let Some(poly) = extract([0, 1, 2, 3], corners, 0.0) else {
                continue;
            };
            let origin = 3.0 * rng.in_unit_ball() + Vec3::new(0.0, 0.0, 3.0);
            let target = 0.6 * rng.in_unit_ball();
            let dir = (target - origin).normalize();
            let got = PolygonFromOrigin::new(&poly, origin).intersect(dir);
            // Independent answer in f64: the plane of the linear field, then barycentric
            // coordinates of the hit within the tet.
            let c = corners.map(|v| v.as_dvec4());
            let p0 = c[0].truncate();
            let e = [1, 2, 3].map(|i| c[i].truncate() - p0);
            let det = e[0].dot(e[1].cross(e[2]));
            if det.abs() < 1e-3 {
                continue;
            }
            let g = (e[1].cross(e[2]) * (c[1].w - c[0].w)
                + e[2].cross(e[0]) * (c[2].w - c[0].w)
                + e[0].cross(e[1]) * (c[3].w - c[0].w))
                / det;
            let (o, d) = (origin.as_dvec3(), dir.as_dvec3());
            let t = -(c[0].w + g.dot(o - p0)) / g.dot(d);
            let h = o + d * t;
            let vol = |a: glam::DVec3, b: glam::DVec3, cc: glam::DVec3, dd: glam::DVec3| {
                (b - a).cross(cc - a).dot(dd - a)
            };
            let [a, b, cc, dd] = c.map(|v| v.truncate());
            let l = [
                vol(h, b, cc, dd),
                vol(a, h, cc, dd),
                vol(a, b, h, dd),
                vol(a, b, cc, h),
            ]
            .map(|x| x / vol(a, b, cc, dd));
            let margin = l.iter().copied().fold(f64::INFINITY, f64::min);
            let inside = t > 0.0 && margin >= 0.0;
            match got {
                Some(tf) => {
                    if margin > -1e-4 {
                        hits += 1;
                        assert!((tf as f64 - t).abs() < 1e-4, "t {tf} vs {t}");
                    } else {
                        panic!("hit outside the tet: margin {margin}");
                    }
                }
                None => assert!(!(inside && margin > 1e-4), "missed, margin {margin}"),
            }
        }
        assert!(hits > 200, "{hits} hits tested");
    }

    #[test]
    fn the_single_ray_test_is_the_packet_test() {
        let mut rng = SplitMix64(21);
        let mut hits = 0;
        for _ in 0..4000 {
            let corners = random_tet(&mut rng);
            let Some(poly) = extract([0, 1, 2, 3], corners, 0.0) else {
                continue;
            };
            let origin = 3.0 * rng.in_unit_ball();
            let dir = (0.6 * rng.in_unit_ball() - origin).normalize();
            let (t_min, t_max) = (rng.range(0.0, 1.0), rng.range(1.0, 6.0));
            let packet = PolygonFromOrigin::new(&poly, origin)
                .intersect(dir)
                .filter(|&t| t >= t_min && t <= t_max);
            assert_eq!(intersect_one(&poly, origin, dir, t_min, t_max), packet);
            hits += packet.is_some() as usize;
        }
        assert!(hits > 200, "{hits}");
    }

    /// Tets with a corner within rounding of the isovalue, so that polygon points nearly
    /// coincide and edges go untested ([`edge_normal`]): the single-ray test, which takes the
    /// rounding test only where an edge would reject, still agrees with the packet test.
    #[test]
    fn the_single_ray_test_is_the_packet_test_on_edges_within_rounding() {
        let mut rng = SplitMix64(22);
        let (mut hits, mut untested) = (0, 0);
        for k in 0..8000 {
            let mut corners = random_tet(&mut rng);
            corners[k % 4].w = rng.range(-1e-7, 1e-7);
            let Some(poly) = extract([0, 1, 2, 3], corners, 0.0) else {
                continue;
            };
            let origin = 3.0 * rng.in_unit_ball();
            // Aim at the polygon's first point, nudged, so that many rays pass near the
            // short edges.
            let aim = poly.points[0] + 1e-3 * rng.in_unit_ball();
            let dir = (aim - origin).normalize();
            let n = poly.count;
            untested += (0..n)
                .filter(|&i| {
                    let (p, q) = (poly.points[i], poly.points[(i + 1) % n]);
                    edge_normal(p, q, p - origin, q - origin) == Vec3::ZERO
                })
                .count();
            let packet = PolygonFromOrigin::new(&poly, origin).intersect(dir);
            assert_eq!(intersect_one(&poly, origin, dir, 0.0, 100.0), packet);
            hits += packet.is_some() as usize;
        }
        assert!(
            hits > 500 && untested > 500,
            "{hits} hits, {untested} edges untested"
        );
    }

    #[test]
    fn frustum_verdicts_agree_with_every_ray() {
        let mut rng = SplitMix64(5);
        let (mut misses, mut full) = (0, 0);
        for _ in 0..3000 {
            let corners = random_tet(&mut rng);
            let Some(poly) = extract([0, 1, 2, 3], corners, 0.0) else {
                continue;
            };
            let origin = Vec3::new(0.0, 0.0, 4.0);
            let centre = 0.8 * rng.in_unit_ball();
            let half = rng.range(0.01, 0.4);
            let grid = |u: f32, v: f32| {
                (centre + Vec3::new(half * (2.0 * u - 1.0), half * (2.0 * v - 1.0), 0.0) - origin)
                    .normalize()
            };
            let tile = [
                grid(0.0, 0.0),
                grid(1.0, 0.0),
                grid(0.0, 1.0),
                grid(1.0, 1.0),
            ];
            let prep = PolygonFromOrigin::new(&poly, origin);
            let verdict = prep.frustum(&tile);
            for i in 0..=8 {
                for j in 0..=8 {
                    let d = grid(i as f32 / 8.0, j as f32 / 8.0);
                    let hit = prep.intersect(d).is_some_and(|t| t > 0.0);
                    match verdict {
                        FrustumTest::Miss => assert!(!hit),
                        FrustumTest::Hit => assert!(hit),
                        FrustumTest::Partial => {}
                    }
                }
            }
            misses += (verdict == FrustumTest::Miss) as usize;
            full += (verdict == FrustumTest::Hit) as usize;
        }
        assert!(
            misses > 100 && full > 20,
            "misses {misses}, full hits {full}"
        );
    }

    /// The gyroid demo's quad at 23.3 s whose two points 6·10⁻⁸ apart (a corner 4.8·10⁻⁷ above
    /// the isovalue 0) made an edge plane of rounding noise: the ray through the quad's middle
    /// was rejected, on packets and single rays alike, and the pixel showed the surface 0.05
    /// behind (the `f64` reference: a hit at 5.553579).
    #[test]
    fn an_edge_shorter_than_rounding_does_not_reject_rays() {
        let poly = Isopolygon {
            count: 4,
            points: [
                Vec3::new(1.1568439, 0.87873393, 0.12209125),
                Vec3::new(1.1460956, 0.86916745, 0.13050857),
                Vec3::new(1.2558117, 0.86912805, 0.10804941),
                Vec3::new(1.2558117, 0.8691281, 0.10804935),
            ],
        };
        let (origin, dir) = (
            Vec3::new(3.0, 2.2, 5.2),
            Vec3::new(-0.32548538, -0.23928557, -0.9147686),
        );
        let packet = PolygonFromOrigin::new(&poly, origin).intersect(dir);
        let single = intersect_one(&poly, origin, dir, 0.0, 100.0);
        assert_eq!(packet, single);
        let t = single.expect("the ray passes through the quad");
        assert!((t - 5.553579).abs() < 1e-4, "t = {t}");
        // The same edge seen from the tet across it (reversed) is dropped there too.
        let p = poly.points;
        assert_eq!(
            edge_normal(p[3], p[2], p[3] - origin, p[2] - origin),
            Vec3::ZERO
        );
        assert_ne!(
            edge_normal(p[0], p[1], p[0] - origin, p[1] - origin),
            Vec3::ZERO
        );
    }

    /// The gyroid demo's sliver at 23.3 s (a triangle 5·10⁻⁵ across, 5.5 from the eye) and the
    /// ray of pixel (171, 85) at 320×240, which passes it 0.035 away: in `f64` two edges
    /// reject the ray (sines −1.4·10⁻³ and −1.7·10⁻³ of their planes). Edge planes formed as
    /// `(p − o) × (q − o)` in `f32` turned enough to pass it, and the pixel showed the
    /// triangle 0.019 in front of the surface.
    #[test]
    fn a_sliver_far_from_the_eye_does_not_let_rays_by_its_side_through() {
        let poly = Isopolygon {
            count: 3,
            points: [
                Vec3::new(0.49970424, 0.86407244, 0.48051217),
                Vec3::new(0.49968326, 0.8641145, 0.48056495),
                Vec3::new(0.4997129, 0.8640804, 0.4805548),
                Vec3::ZERO,
            ],
        };
        let origin = Vec3::new(3.0, 2.2, 5.2);
        let dir = Vec3::new(-0.4542334, -0.24435239, -0.8567168);
        assert_eq!(intersect_one(&poly, origin, dir, 0.0, 100.0), None);
        assert_eq!(PolygonFromOrigin::new(&poly, origin).intersect(dir), None);
        // A ray through the triangle's centroid still hits it.
        let centroid = (poly.points[0] + poly.points[1] + poly.points[2]) / 3.0;
        let through = (centroid - origin).normalize();
        assert!(intersect_one(&poly, origin, through, 0.0, 100.0).is_some());
    }

    /// The polygon across a shared edge walks it the other way: its edge normal is exactly
    /// the negated one, for edges of every length at every distance.
    #[test]
    fn an_edge_walked_both_ways_gives_exactly_negated_normals() {
        let mut rng = SplitMix64(23);
        for k in 0..20_000 {
            let origin = 4.0 * rng.in_unit_ball();
            let p = rng.in_unit_ball();
            let q = p + 10f32.powi(-(k % 7)) * rng.in_unit_ball();
            let (rp, rq) = (p - origin, q - origin);
            assert_eq!(
                edge_normal(p, q, rp, rq),
                -edge_normal(q, p, rq, rp),
                "{p} {q}"
            );
        }
    }

    #[test]
    fn shared_edges_are_watertight() {
        // Two tets sharing face (1, 2, 3); a ray through the shared isopolygon edge must hit
        // one of them whatever the rounding.
        let p = [
            Vec4::new(0.0, 0.0, 0.0, -1.0),
            Vec4::new(1.0, 0.0, 0.0, 1.0),
            Vec4::new(0.0, 1.0, 0.0, -1.0),
            Vec4::new(0.0, 0.0, 1.0, 1.0),
            Vec4::new(1.0, 1.0, 1.0, -1.0),
        ];
        let tet_a = [0u32, 1, 2, 3];
        let tet_b = [4u32, 3, 2, 1];
        let pa = extract(tet_a, tet_a.map(|i| p[i as usize]), 0.1).expect("crosses");
        let pb = extract(tet_b, tet_b.map(|i| p[i as usize]), 0.1).expect("crosses");
        let origin = Vec3::new(0.3, 0.4, 3.0);
        let (a, b) = (
            PolygonFromOrigin::new(&pa, origin),
            PolygonFromOrigin::new(&pb, origin),
        );
        let mut rng = SplitMix64(3);
        let shared: Vec<Vec3> = pa.points[..pa.count]
            .iter()
            .copied()
            .filter(|q| pb.points[..pb.count].contains(q))
            .collect();
        assert_eq!(shared.len(), 2, "the polygons share an edge bit for bit");
        for _ in 0..2000 {
            let s = rng.next_f32();
            let target = shared[0].lerp(shared[1], s);
            let dir = (target - origin).normalize();
            assert!(
                a.intersect(dir).is_some() || b.intersect(dir).is_some(),
                "a ray through the shared edge at {s} fell through"
            );
        }
    }
}
