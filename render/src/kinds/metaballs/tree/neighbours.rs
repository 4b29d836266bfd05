//! Algorithm 1's overlapping-sphere neighbour lists (CSR), from a uniform grid.

use crate::kinds::metaballs::tree::flat::TreeBall;
use glam::Vec3;
use rayon::prelude::*;

/// For every ball, the balls whose sphere overlaps its sphere, from a uniform grid of cell
/// size `2 R_max` (compressed rows, each sorted).
pub(super) fn neighbour_lists(balls: &[TreeBall], parallel: bool) -> (Vec<u32>, Vec<u32>) {
    let n = balls.len();
    if n == 0 {
        return (vec![0], Vec::new());
    }
    let r_max = balls.iter().fold(0.0f32, |m, b| m.max(b.radius));
    let cell = (2.0 * r_max).max(1e-6);
    let lo = balls
        .iter()
        .fold(Vec3::splat(f32::INFINITY), |m, b| m.min(b.center));
    let key = |p: Vec3| -> [i32; 3] {
        let c = ((p - lo) / cell).floor();
        [c.x as i32, c.y as i32, c.z as i32]
    };
    let hash = |k: [i32; 3]| -> u64 {
        (k[0] as u64 & 0x1F_FFFF)
            | ((k[1] as u64 & 0x1F_FFFF) << 21)
            | ((k[2] as u64 & 0x1F_FFFF) << 42)
    };
    let keyed_of = |(i, b): (usize, &TreeBall)| (hash(key(b.center)), i as u32);
    let keyed: Vec<(u64, u32)> = if parallel {
        let mut k: Vec<(u64, u32)> = balls.par_iter().enumerate().map(keyed_of).collect();
        k.par_sort_unstable();
        k
    } else {
        let mut k: Vec<(u64, u32)> = balls.iter().enumerate().map(keyed_of).collect();
        k.sort_unstable();
        k
    };
    let list_of = |(i, b): (usize, &TreeBall)| {
        let k = key(b.center);
        let mut out = Vec::new();
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let h = hash([k[0] + dx, k[1] + dy, k[2] + dz]);
                    let start = keyed.partition_point(|e| e.0 < h);
                    for &(kh, j) in &keyed[start..] {
                        if kh != h {
                            break;
                        }
                        let o = &balls[j as usize];
                        let reach = b.radius + o.radius;
                        if j as usize != i && (b.center - o.center).length_squared() < reach * reach
                        {
                            out.push(j);
                        }
                    }
                }
            }
        }
        out.sort_unstable();
        out
    };
    let lists: Vec<Vec<u32>> = if parallel {
        balls.par_iter().enumerate().map(list_of).collect()
    } else {
        balls.iter().enumerate().map(list_of).collect()
    };
    let mut start = Vec::with_capacity(n + 1);
    start.push(0u32);
    let mut flat = Vec::with_capacity(lists.iter().map(Vec::len).sum());
    for l in &lists {
        flat.extend_from_slice(l);
        start.push(flat.len() as u32);
    }
    (start, flat)
}
