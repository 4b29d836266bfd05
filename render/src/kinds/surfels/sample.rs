//! Surfel objects generated for demos, tests and benchmarks: spheres, a bumpy blob and
//! cubes made of six clipped faces (deforming-point-sampled-surfaces.txt §4.3, Fig. 8), and
//! lattices of simulation nodes inside them.

use crate::kinds::surfels::model::Surfel;
use glam::Vec3;

/// Two unit tangents of a unit normal, so that `t1 × t2 = n`.
pub fn tangents(n: Vec3) -> (Vec3, Vec3) {
    let helper = if n.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
    let t1 = n.cross(helper).normalize();
    (t1, n.cross(t1))
}

/// `count` points spread evenly on the unit sphere (Fibonacci lattice).
pub fn fibonacci(count: usize) -> impl Iterator<Item = Vec3> {
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    (0..count).map(move |i| {
        let y = 1.0 - 2.0 * (i as f32 + 0.5) / count as f32;
        let r = (1.0 - y * y).max(0.0).sqrt();
        let phi = golden * i as f32;
        Vec3::new(r * phi.cos(), y, r * phi.sin())
    })
}

/// A sphere of `count` surfels whose discs overlap their neighbours'.
pub fn sphere(centre: Vec3, radius: f32, count: usize, colour: Vec3, group: u16) -> Vec<Surfel> {
    let spacing = radius * (4.0 * std::f32::consts::PI / count as f32).sqrt();
    fibonacci(count)
        .map(|n| {
            let (t1, t2) = tangents(n);
            Surfel {
                centre: centre + radius * n,
                t1,
                t2,
                normal: n,
                colour,
                radius: 0.9 * spacing,
                group,
            }
        })
        .collect()
}

/// The radius of the bumpy blob along unit direction `d`.
fn blob_radius(d: Vec3) -> f32 {
    1.0 + 0.12 * (3.0 * d.x).sin() * (4.0 * d.y).cos() + 0.08 * (5.0 * d.z + 1.0).sin()
}

/// A bumpy closed blob about `centre` (scale 1 × `size`) of `count` surfels: the large
/// object of the paper's Armadillo scale (Table 1) without shipping a scan. A surfel's
/// radius is the Fibonacci points' spacing on the unit sphere times how far the blob
/// stretches that sphere there (its radius and slope: 0.83–1.21 over the blob), so the discs
/// overlap alike on the bumps and in the hollows. One radius for all (1.045 spacings, the
/// same mean) left the stretched bumps covered so thinly that deformed steps of the impact
/// demo showed pinholes, 1–5 pixels in half the frames at 320×240 (the stability suite's
/// `the_surfel_demos_at_a_viewers_size`; docs/accuracy.md).
pub fn blob(centre: Vec3, size: f32, count: usize, colour: Vec3, group: u16) -> Vec<Surfel> {
    let spacing = size * (4.0 * std::f32::consts::PI / count as f32).sqrt();
    let at = |d: Vec3| centre + size * blob_radius(d) * d;
    fibonacci(count)
        .enumerate()
        .map(|(i, d)| {
            let (a, b) = tangents(d);
            let e = 1e-3;
            let t1 = at((d + e * a).normalize()) - at((d - e * a).normalize());
            let t2 = at((d + e * b).normalize()) - at((d - e * b).normalize());
            // How far the blob stretches the unit sphere here, along the farther axis.
            let stretch = t1.length().max(t2.length()) / (2.0 * e * size);
            let (t1, t2) = (t1.normalize(), t2.normalize());
            let n = t1.cross(t2).normalize();
            // A little colour variation so motion reads in the image.
            let shade = 0.85 + 0.15 * ((i % 7) as f32 / 6.0);
            Surfel {
                centre: at(d),
                t1,
                t2,
                normal: n,
                colour: colour * shade,
                radius: spacing * stretch,
                group,
            }
        })
        .collect()
}

/// A cube `[centre − half, centre + half]³` as six faces (groups `group0..group0 + 6`),
/// each sampled on a `per_side`² grid that runs two spacings past the edges, and the
/// clipping relations between adjacent faces that cut them back to sharp edges (§4.3).
pub fn cube(
    centre: Vec3,
    half: f32,
    per_side: usize,
    colours: [Vec3; 6],
    group0: u16,
) -> (Vec<Surfel>, Vec<(u16, u16)>) {
    let mut out = Vec::new();
    let spacing = 2.0 * half / per_side as f32;
    let axes = [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
    for (f, &n) in axes.iter().enumerate() {
        let (t1, t2) = tangents(n);
        for i in -2..per_side as i32 + 2 {
            for j in -2..per_side as i32 + 2 {
                let a = -half + (i as f32 + 0.5) * spacing;
                let b = -half + (j as f32 + 0.5) * spacing;
                out.push(Surfel {
                    centre: centre + half * n + a * t1 + b * t2,
                    t1,
                    t2,
                    normal: n,
                    colour: colours[f],
                    radius: 0.85 * spacing,
                    group: group0 + f as u16,
                });
            }
        }
    }
    let mut clip = Vec::new();
    for a in 0..6u16 {
        for b in 0..6u16 {
            // Faces on different axes are adjacent.
            if a / 2 != b / 2 {
                clip.push((group0 + a, group0 + b));
            }
        }
    }
    (out, clip)
}

/// Simulation nodes on a cubic lattice of `spacing` over `[lo, hi]`, kept where `inside`.
pub fn lattice(lo: Vec3, hi: Vec3, spacing: f32, inside: impl Fn(Vec3) -> bool) -> Vec<Vec3> {
    let n = ((hi - lo) / spacing)
        .ceil()
        .as_ivec3()
        .max(glam::IVec3::ONE);
    let mut out = Vec::new();
    for k in 0..=n.z {
        for j in 0..=n.y {
            for i in 0..=n.x {
                let p = lo + spacing * Vec3::new(i as f32, j as f32, k as f32);
                if inside(p) {
                    out.push(p);
                }
            }
        }
    }
    out
}

/// Whether `p` is inside the blob of [`blob`] (with a margin of `grow` sizes).
pub fn inside_blob(p: Vec3, centre: Vec3, size: f32, grow: f32) -> bool {
    let d = p - centre;
    let len = d.length();
    len < 1e-6 || len <= size * (blob_radius(d / len) + grow)
}
