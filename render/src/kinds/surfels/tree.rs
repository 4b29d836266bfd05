//! The bounding-sphere hierarchy of deforming-point-sampled-surfaces.txt §4.1.1, built once
//! on the undeformed object (and, for the rebuild baseline, on each deformed step).
//!
//! How it works: top-down, each node's surfels split at the median along the longest axis of
//! their centres' bounding box, down to one surfel per leaf, except that surfels of several
//! bodies are split between whole bodies first ([`split`]), so that each body's subtree moves
//! with the body's rigid frame; a node's sphere is the smallest sphere around its surfel
//! centres ([`miniball`]) grown by the largest leaf radius below it, so it holds every surfel
//! disc, not only the centres. Nodes are stored in preorder, which
//! the median split makes computable in advance (a node of `n` surfels spans `2n − 1` slots,
//! its left child starts right after it), so subtrees build in parallel into disjoint slices
//! and the tree is the same on any number of threads.
//!
//! For the lazy update each inner node keeps the simulation nodes of its surfels with the
//! precomputed terms of eq. 9 ([`SimTerm`]): `A_j = max_s a_sj`, `B_j = max_s ‖b_sj‖` (plus
//! `ρ_max · A_j`, the bound on how much the leaf radii below can grow), and the weights of
//! eq. 3 for the centre.

use crate::kinds::surfels::kernel::{weight, Rows};
use crate::kinds::surfels::miniball::miniball;
use glam::Vec3;

/// `kids[0]` of a leaf.
pub const LEAF: u32 = u32::MAX;

/// Subtrees with fewer surfels are built on the calling thread.
const PARALLEL_MIN: usize = 2048;

/// One sphere of the hierarchy. A leaf has `kids = [LEAF, surfel]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TreeNode {
    pub centre: Vec3,
    pub radius: f32,
    pub kids: [u32; 2],
}

impl TreeNode {
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.kids[0] == LEAF
    }
}

/// A simulation node's terms in an inner sphere's eq. 9 and eq. 3.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimTerm {
    pub node: u32,
    /// Normalised weight of eq. 3 for the sphere's centre.
    pub wc: f32,
    /// `A_j`.
    pub a: f32,
    /// `B_j + ρ_max · A_j`.
    pub b: f32,
}

/// A node whose surfels hang on nodes of several bodies.
pub const MIXED: u16 = u16::MAX;

/// The hierarchy: nodes in preorder (root 0), per-node eq. 9 terms, tree levels, and the
/// body of each inner node's simulation nodes ([`MIXED`] if several).
#[derive(Clone, Debug, Default)]
pub struct SphereTree {
    pub nodes: Vec<TreeNode>,
    pub terms: Rows<SimTerm>,
    pub level: Vec<u8>,
    pub body: Vec<u16>,
    /// The surfels in the order the preorder meets their leaves.
    pub leaves: Vec<u32>,
    /// Per node, the range of [`SphereTree::leaves`] below it (a subtree's leaves are
    /// contiguous in preorder).
    pub leaf_range: Vec<[u32; 2]>,
}

/// The embedding the eq. 9 terms come from: per-surfel `(node, weight)` rows, the rest
/// node positions and each node's body.
pub type Embedding<'a> = (&'a Rows<(u32, f32)>, &'a [Vec3], &'a [u16]);

struct Input<'a> {
    centres: &'a [Vec3],
    leaf_radius: &'a [f32],
    /// Each surfel's body (empty: one body).
    body: &'a [u16],
}

impl SphereTree {
    /// Builds the hierarchy over surfel `centres` with leaf radii; with an embedding, also
    /// the eq. 9 terms of every inner node.
    pub fn build(centres: &[Vec3], leaf_radius: &[f32], embed: Option<Embedding>) -> SphereTree {
        let n = centres.len();
        if n == 0 {
            return SphereTree::default();
        }
        let body = embed.map(surfel_bodies).unwrap_or_default();
        let input = Input {
            centres,
            leaf_radius,
            body: &body,
        };
        let mut ids: Vec<u32> = (0..n as u32).collect();
        let blank = TreeNode {
            centre: Vec3::ZERO,
            radius: 0.0,
            kids: [LEAF, 0],
        };
        let mut nodes = vec![blank; 2 * n - 1];
        let mut level = vec![0u8; 2 * n - 1];
        build_range(&input, &mut ids, &mut nodes, &mut level, 0, 0);
        let terms = match embed {
            Some(e) => {
                let mut lists = vec![Vec::new(); nodes.len()];
                terms_range(&nodes, &mut lists, 0, e, leaf_radius);
                Rows::from_rows(lists)
            }
            None => Rows::from_rows(nodes.iter().map(|_| Vec::new())),
        };
        let body = match embed {
            Some((_, _, node_body)) => (0..nodes.len())
                .map(|i| {
                    let mut it = terms.row(i).iter().map(|t| node_body[t.node as usize]);
                    let first = it.next().unwrap_or(0);
                    if it.all(|b| b == first) {
                        first
                    } else {
                        MIXED
                    }
                })
                .collect(),
            None => vec![0; nodes.len()],
        };
        let (leaves, leaf_range) = leaf_ranges(&nodes);
        SphereTree {
            nodes,
            terms,
            level,
            body,
            leaves,
            leaf_range,
        }
    }

    pub fn levels(&self) -> usize {
        self.level
            .iter()
            .map(|&l| l as usize + 1)
            .max()
            .unwrap_or(0)
    }
}

/// The surfels in preorder leaf order, and each node's range of that order.
fn leaf_ranges(nodes: &[TreeNode]) -> (Vec<u32>, Vec<[u32; 2]>) {
    let mut leaves = Vec::with_capacity(nodes.len() / 2 + 1);
    let mut range = vec![[0u32; 2]; nodes.len()];
    for (i, n) in nodes.iter().enumerate() {
        if n.is_leaf() {
            range[i] = [leaves.len() as u32, leaves.len() as u32 + 1];
            leaves.push(n.kids[1]);
        }
    }
    // Preorder: children come after their parent, so reverse order is bottom-up.
    for i in (0..nodes.len()).rev() {
        if !nodes[i].is_leaf() {
            let [a, b] = nodes[i].kids.map(|k| range[k as usize]);
            range[i] = [a[0].min(b[0]), a[1].max(b[1])];
        }
    }
    (leaves, range)
}

/// Builds the subtree of `ids` into `out` (its `2n − 1` preorder slots), `base` being the
/// index of `out[0]` in the whole tree.
fn build_range(
    input: &Input,
    ids: &mut [u32],
    out: &mut [TreeNode],
    level: &mut [u8],
    base: u32,
    depth: u8,
) {
    level[0] = depth;
    if ids.len() == 1 {
        let s = ids[0] as usize;
        out[0] = TreeNode {
            centre: input.centres[s],
            radius: input.leaf_radius[s],
            kids: [LEAF, s as u32],
        };
        return;
    }
    let pts: Vec<Vec3> = ids.iter().map(|&i| input.centres[i as usize]).collect();
    let ball = miniball(&pts);
    let rho = ids
        .iter()
        .map(|&i| input.leaf_radius[i as usize])
        .fold(0.0f32, f32::max);
    let half = split(input.centres, input.body, ids);
    let left_len = 2 * half - 1;
    out[0] = TreeNode {
        centre: ball.centre.as_vec3(),
        // Rounded up so the f32 sphere still holds every centre.
        radius: (ball.radius * (1.0 + 1e-6)) as f32 + rho,
        kids: [base + 1, base + 1 + left_len as u32],
    };
    let (ids_l, ids_r) = ids.split_at_mut(half);
    let (out_l, out_r) = out[1..].split_at_mut(left_len);
    let (lev_l, lev_r) = level[1..].split_at_mut(left_len);
    let next = depth.saturating_add(1);
    if ids_l.len() + ids_r.len() >= PARALLEL_MIN {
        rayon::join(
            || build_range(input, ids_l, out_l, lev_l, base + 1, next),
            || build_range(input, ids_r, out_r, lev_r, base + 1 + left_len as u32, next),
        );
    } else {
        build_range(input, ids_l, out_l, lev_l, base + 1, next);
        build_range(input, ids_r, out_r, lev_r, base + 1 + left_len as u32, next);
    }
}

/// Each surfel's body: the body of the node with the largest weight in its embedding.
pub fn surfel_bodies((rows, _, node_body): Embedding) -> Vec<u16> {
    (0..rows.start.len() - 1)
        .map(|s| {
            let heaviest = rows.row(s).iter().max_by(|a, b| a.1.total_cmp(&b.1));
            heaviest.map_or(0, |&(j, _)| node_body[j as usize])
        })
        .collect()
}

/// The longest axis of the box around `ids`' centres.
fn longest_axis(centres: &[Vec3], ids: &[u32]) -> usize {
    let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
    for &i in ids {
        lo = lo.min(centres[i as usize]);
        hi = hi.max(centres[i as usize]);
    }
    let ext = hi - lo;
    if ext.x >= ext.y && ext.x >= ext.z {
        0
    } else if ext.y >= ext.z {
        1
    } else {
        2
    }
}

/// Splits `ids` in two, the first part first; returns its length. Surfels of several bodies
/// are split between bodies, never through one, so that each body has subtrees of its own
/// that its rigid motion carries whole (40 balls thrown apart otherwise leave spheres
/// spanning two balls); the bodies in order of their centroids along the longest axis, cut
/// where the counts come nearest to halves. Surfels of one body split at the median along
/// the longest axis (ties by id).
fn split(centres: &[Vec3], body: &[u16], ids: &mut [u32]) -> usize {
    let axis = longest_axis(centres, ids);
    let body_of = |i: u32| body.get(i as usize).copied().unwrap_or(0);
    let first = body_of(ids[0]);
    if ids.iter().any(|&i| body_of(i) != first) {
        // (body, centroid along the axis, count), ordered by centroid then body.
        let mut bodies: Vec<(u16, f64, usize)> = Vec::new();
        ids.sort_unstable_by_key(|&i| (body_of(i), i));
        for &i in ids.iter() {
            let (b, x) = (body_of(i), centres[i as usize][axis] as f64);
            match bodies.last_mut() {
                Some(last) if last.0 == b => (last.1, last.2) = (last.1 + x, last.2 + 1),
                _ => bodies.push((b, x, 1)),
            }
        }
        for b in &mut bodies {
            b.1 /= b.2 as f64;
        }
        bodies.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        let mut rank = std::collections::HashMap::new();
        let (mut best, mut below, half) = ((usize::MAX, 0), 0, ids.len() / 2);
        for (k, b) in bodies.iter().enumerate() {
            rank.insert(b.0, k);
            below += b.2;
            if k + 1 < bodies.len() && below.abs_diff(half) < best.0 {
                best = (below.abs_diff(half), below);
            }
        }
        ids.sort_unstable_by_key(|&i| (rank[&body_of(i)], i));
        return best.1;
    }
    let half = ids.len() / 2;
    ids.select_nth_unstable_by(half, |&a, &b| {
        centres[a as usize][axis]
            .total_cmp(&centres[b as usize][axis])
            .then(a.cmp(&b))
    });
    half
}

/// The order in which [`SphereTree::build`]'s leaves would meet `centres` of surfels in
/// bodies `body` (its splits without its spheres): the model stores its surfels in this
/// order, so that the surfels under one sphere lie together in memory.
pub fn leaf_order(centres: &[Vec3], body: &[u16]) -> Vec<u32> {
    fn halves(centres: &[Vec3], body: &[u16], ids: &mut [u32]) {
        if ids.len() < 2 {
            return;
        }
        let half = split(centres, body, ids);
        let (l, r) = ids.split_at_mut(half);
        if l.len() + r.len() >= PARALLEL_MIN {
            rayon::join(|| halves(centres, body, l), || halves(centres, body, r));
        } else {
            halves(centres, body, l);
            halves(centres, body, r);
        }
    }
    let mut ids: Vec<u32> = (0..centres.len() as u32).collect();
    halves(centres, body, &mut ids);
    ids
}

/// `(node, max a, max ‖b‖)` over the surfels below, sorted by node.
type Bounds = Vec<(u32, f32, f32)>;

/// Fills the eq. 9 terms of every inner node of the subtree at `lists[0]` (preorder, like
/// `nodes`); returns the subtree's merged bounds and largest leaf radius.
fn terms_range(
    nodes: &[TreeNode],
    lists: &mut [Vec<SimTerm>],
    base: usize,
    embed: Embedding,
    leaf_radius: &[f32],
) -> (Bounds, f32) {
    let node = nodes[base];
    let (rows, sim, _) = embed;
    if node.is_leaf() {
        let s = node.kids[1] as usize;
        let x = node.centre;
        let mut b: Bounds = rows
            .row(s)
            .iter()
            .map(|&(j, w)| (j, w, w * (x - sim[j as usize]).length()))
            .collect();
        b.sort_by_key(|t| t.0);
        return (b, leaf_radius[s]);
    }
    let left_len = node.kids[1] as usize - node.kids[0] as usize;
    let (_, rest) = lists.split_at_mut(1);
    let (l_lists, r_lists) = rest.split_at_mut(left_len);
    let (l_base, r_base) = (node.kids[0] as usize, node.kids[1] as usize);
    let big = left_len >= PARALLEL_MIN;
    let ((bl, rl), (br, rr)) = if big {
        rayon::join(
            || terms_range(nodes, l_lists, l_base, embed, leaf_radius),
            || terms_range(nodes, r_lists, r_base, embed, leaf_radius),
        )
    } else {
        (
            terms_range(nodes, l_lists, l_base, embed, leaf_radius),
            terms_range(nodes, r_lists, r_base, embed, leaf_radius),
        )
    };
    let merged = merge(&bl, &br);
    let rho = rl.max(rr);
    let far = merged
        .iter()
        .map(|t| (node.centre - sim[t.0 as usize]).length())
        .fold(0.0f32, f32::max);
    let h = 1.5 * far + 1e-6;
    let raw: Vec<f32> = merged
        .iter()
        .map(|t| weight((node.centre - sim[t.0 as usize]).length() / h))
        .collect();
    let sum: f32 = raw.iter().sum();
    lists[0] = merged
        .iter()
        .zip(&raw)
        .map(|(t, w)| SimTerm {
            node: t.0,
            wc: w / sum,
            a: t.1,
            b: t.2 + rho * t.1,
        })
        .collect();
    (merged, rho)
}

fn merge(a: &Bounds, b: &Bounds) -> Bounds {
    let mut out = Vec::with_capacity(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() || j < b.len() {
        if j == b.len() || (i < a.len() && a[i].0 < b[j].0) {
            out.push(a[i]);
            i += 1;
        } else if i == a.len() || b[j].0 < a[i].0 {
            out.push(b[j]);
            j += 1;
        } else {
            out.push((a[i].0, a[i].1.max(b[j].1), a[i].2.max(b[j].2)));
            i += 1;
            j += 1;
        }
    }
    out
}
