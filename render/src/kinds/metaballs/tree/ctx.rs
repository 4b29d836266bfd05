//! What the build shares between its steps: the balls as it moves them, the build
//! context, and its limits.

use crate::geom::aabb::Aabb;
use crate::kinds::metaballs::kernel::Kernel;
use crate::kinds::metaballs::tree::flat::{BuildOptions, Node};
use glam::Vec3;
use std::sync::{Arc, Mutex, PoisonError};

/// A subtree built on one thread: node 0 is its root; child and ball indices are local.
pub(super) struct Chunk {
    pub(super) nodes: Vec<Node>,
    pub(super) balls: Vec<u32>,
}

/// The parallel top of the tree: joins of chunks, flattened once at the end.
pub(super) enum Built {
    Chunk(Chunk),
    Join(Aabb, Box<(Built, Built)>),
}

pub(super) const BLANK: Node = Node {
    bounds: Aabb::EMPTY,
    first: u32::MAX,
    count: 0,
    owned: 0,
};

/// A ball as the build moves it around: the owned balls of a node are a contiguous slice of
/// these, partitioned in place, so the passes over them read memory in order.
#[derive(Clone, Copy, Debug)]
pub(super) struct Prim {
    pub(super) center: Vec3,
    pub(super) radius: f32,
    pub(super) strength: f32,
    pub(super) id: u32,
}

/// A node's box, its `r_max` and the bounds of its owned balls' centres.
#[derive(Clone, Copy, Debug)]
pub(super) struct Geom {
    pub(super) bounds: Aabb,
    pub(super) r_max: f32,
    pub(super) centroids: (Vec3, Vec3),
}

/// A node's split balls and geometry.
pub(super) struct NodeInput {
    pub(super) split: Vec<u32>,
    pub(super) geom: Geom,
}

/// Bounds of the centres of `prims`.
pub(super) fn centroid_bounds(prims: &[Prim]) -> (Vec3, Vec3) {
    prims.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(p.center), hi.max(p.center)),
    )
}

pub(super) struct Ctx {
    pub(super) centers: Vec<Vec3>,
    pub(super) radii: Vec<f32>,
    pub(super) strengths: Vec<f32>,
    pub(super) kernel: Kernel,
    pub(super) opts: BuildOptions,
    /// Algorithm 1: overlapping-sphere neighbours (CSR).
    pub(super) neighbour_start: Vec<u32>,
    pub(super) neighbours: Vec<u32>,
    /// The largest positive strength of the whole set: a node's `q_max` is at most this.
    pub(super) q_max: f32,
    /// `sqrt(s*)` for `n = 0..S_TABLE` positive balls of strength `q_max`
    /// ([`root_s_star_table`]; empty when the build does not depend on the isovalue).
    pub(super) root_s_star: Arc<[f32]>,
    /// Whether the build may fork on rayon.
    pub(super) parallel: bool,
}

/// Node sizes whose `r_max` comes from a table rather than a bisection.
pub(super) const S_TABLE: usize = 4096;

/// `sqrt(s*)` for `n = 0..S_TABLE` positive balls of strength `q_max` at `isovalue`: the
/// table is [`S_TABLE`] 40-step bisections of the kernel, about 3 ms (more than the rest of a
/// 1,000-ball scene's build), and depends on nothing else, so it is computed once per
/// `(kernel, isovalue, q_max)` and shared: every state of an animated scene, and every
/// viewer's, asks for the same one. The last few tables are kept; each is a pure function of
/// its key, so which are kept changes no build.
pub(super) fn root_s_star_table(kernel: Kernel, isovalue: f32, q_max: f32) -> Arc<[f32]> {
    type Key = (Kernel, u32, u32);
    static TABLES: Mutex<Vec<(Key, Arc<[f32]>)>> = Mutex::new(Vec::new());
    const KEPT: usize = 8;
    let key = (kernel, isovalue.to_bits(), q_max.to_bits());
    let kept = |tables: &[(Key, Arc<[f32]>)]| {
        tables
            .iter()
            .find(|(k, _)| *k == key)
            .map(|(_, t)| t.clone())
    };
    if let Some(table) = kept(&TABLES.lock().unwrap_or_else(PoisonError::into_inner)) {
        return table;
    }
    // Computed with no lock held; a table another thread stored meanwhile is the same.
    let table: Arc<[f32]> = (0..S_TABLE)
        .map(|n| {
            kernel
                .s_at_value(isovalue / (n.max(1) as f32 * q_max))
                .sqrt()
        })
        .collect();
    let mut tables = TABLES.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some(stored) = kept(&tables) {
        return stored;
    }
    if tables.len() >= KEPT {
        tables.remove(0);
    }
    tables.push((key, table.clone()));
    table
}
/// Split-metaball discarding (§5.3.2) costs `split × (owned + split)` per leaf; larger
/// leaves (rare: the SAH splits them) keep their lists.
pub(super) const DISCARD_MAX_BALLS: usize = 96;

pub(super) const MAX_DEPTH: usize = 64;
/// Nodes owning this many balls or fewer stay leaves: splitting them changed render work by
/// about 2% (Pool, counted instructions) and cost a seventh of the build.
pub(super) const MIN_SPLIT_OWNED: usize = 2;
/// Most SAH bins per axis.
pub(super) const MAX_BINS: usize = 16;
/// Nodes with more owned balls than this build their children in parallel; smaller ones are
/// built sequentially into one chunk.
pub(super) const PARALLEL_BALLS: usize = 3072;
