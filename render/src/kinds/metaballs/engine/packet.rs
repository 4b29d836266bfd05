//! Packet traversal of the Fitted BVH: a tile of primary rays walks the tree once.
//!
//! How it works (tetrahedral-isosurface-ray-tracing.txt §5.2, after Wald et al.), for the
//! rays of a tile of a camera's pixel grid, which share the eye as origin:
//! 1. Frustum culling, sharpened to pixels: a node's box corners projected onto the image
//!    bound (widened by a pixel) the tile's pixels whose rays can meet it; a node covering
//!    none is skipped for the whole packet, and every later test looks only at the rays of
//!    that rectangle (the corner-ray test of §4.3 on sub-rectangles of the tile).
//! 2. First active ray: at an interior node the rays of the rectangle, from the packet's
//!    first active ray on, are tested in turn until one hits the node's box; the rays
//!    skipped cannot meet anything below it (every box lies inside its parent's), so the
//!    children inherit that index. The children are visited in the order the side of their
//!    separating plane the eye lies on gives (siblings of a Fitted BVH are split at a plane
//!    and the rays share an origin, so it is the order of every ray that crosses both).
//! 3. Leaves: the leaf's balls are culled once for the packet: a ball whose support sphere
//!    lies outside the pyramid of the rectangle's rays (widened by a pixel,
//!    [`crate::geom::tile::Frustum`]) is missed by every one of them, so no ray would gather it
//!    (a Fitted BVH leaf of Pool holds 33 balls of which a ray gathers 3). Then each ray of the
//!    rectangle not yet done, from the first active one on, gets its own slab test (eight rays
//!    at a time, [`TileInverses`]); those that cross the leaf gather its remaining balls eight
//!    rays at a time
//!    ([`SharedOriginBalls::gather_rays`]; the same balls in the same order, to the bit, as
//!    the single ray's gather on the same `[near, far]`), and in the same lanes the bound the
//!    leaf search starts with (the most the field can be over the ray's range,
//!    [`StretchBound`]): a ray whose bound is below the isovalue passes the leaf without
//!    its balls being read out of the lanes (57–74% of the leaf searches on the paper's
//!    scenes), as its search would have stopped there. Each other ray searches its balls with
//!    the single ray's leaf search. A ray is done at its first root, as a single ray is at
//!    the first leaf with a root.
//! 4. Roots in lanes: a search that ends on an isolated piece (one simple root, nearly every
//!    hit) is done there, since its first root lies in it, and the piece is set aside; after
//!    the walk the tile's pieces are solved eight at a time ([`lanes`]), every lane with the
//!    scalar search's operations in its order, so the roots are the same bit for bit.
//!
//! Why the hits equal the single ray's: the single-ray walk searches a leaf on its slab range
//! clamped to the ancestors' entries and to `[t_min, t_max]`; when every box lies inside its
//! parent's (checked once per build by `Tree::boxes_nest`) the slab entry only grows downwards, so
//! that range is the leaf's own slab range on `[t_min, t_max]`, which the packet computes per
//! ray; the leaf search is the same function. Where the condition fails (or the tree is not
//! a Fitted BVH, or the query needs the relaxed fallback tree) the tile falls back to single
//! rays, as it does with [`super::PrepareOptions::packets`] off.

use super::queries::search_gathered;
use super::slabs::TileInverses;
use super::soa::{SharedOriginBalls, StretchBound, RAY_LANES};
use super::{Accel, PreparedMetaballs, SCRATCH};
use crate::camera::PrimaryRays;
use crate::geom::aabb::Aabb;
use crate::geom::tile::TileGrid;
use crate::kinds::metaballs::counters::MetaballCounters;
use crate::kinds::metaballs::lanes::{self, Piece};
use crate::kinds::metaballs::roots::{
    self, FindParams, Found, RayBall, RootFinder, Scratch, ITERATION_CAP,
};
use crate::kinds::metaballs::tree::Tree;
use crate::ray::{Hit, Ray};
use glam::Vec3;
use std::cell::RefCell;

/// A packet's buffers, kept per thread so that a tile allocates only the list it returns.
#[derive(Default)]
struct TileBuffers {
    tile_rays: Vec<Ray>,
    inv: Vec<Vec3>,
    done: Vec<bool>,
    /// (node, first active ray) still to visit.
    stack: Vec<(u32, u32)>,
    /// A leaf's balls less those outside the cover's pyramid.
    culled: Vec<u32>,
    /// The rays of a leaf's cover that cross its box: (ray, near, far).
    crossing: Vec<(u32, f32, f32)>,
    /// The tile's `1/dir` for the leaves' slab tests in lanes.
    inverses: TileInverses,
    soa: SharedOriginBalls,
    aside: SetAside,
}

/// Rays done with their search but for the root of the isolated piece their hit lies in
/// ([`lanes`]), the pieces, and each ray's gathered balls for its hit's normal.
#[derive(Default)]
struct SetAside {
    /// (ray, the search as it stood (its iterations leave out the piece's), its balls'
    /// range in `balls`).
    rays: Vec<(u32, Found<f32>, (u32, u32))>,
    pieces: Vec<Piece<f32>>,
    balls: Vec<u32>,
    solved: Vec<(Option<f32>, u32)>,
}

impl SetAside {
    fn clear(&mut self) {
        self.rays.clear();
        self.pieces.clear();
        self.balls.clear();
    }

    fn push(
        &mut self,
        ray: usize,
        found: Found<f32>,
        piece: Piece<f32>,
        gathered: &[RayBall<f32>],
    ) {
        let start = self.balls.len() as u32;
        self.balls.extend(gathered.iter().map(|b| b.ball));
        let range = (start, self.balls.len() as u32);
        self.rays.push((ray as u32, found, range));
        self.pieces.push(piece);
    }
}

/// What every ray of a packet searches with.
struct Walk<'a> {
    rays: &'a [Ray],
    params: FindParams<f32>,
    finder: RootFinder,
    /// Searches set their isolated pieces aside ([`PreparedMetaballs::sets_roots_aside`]).
    defer: bool,
    isovalue: f32,
    t_max: f32,
    /// The leaf search's whole-stretch bound, answered in the gather's lanes (where the finder
    /// starts with it).
    bound: Option<StretchBound>,
    /// `params` for the searches of rays the lanes' bound let through, which do not ask it
    /// again.
    lane_params: FindParams<f32>,
}

/// Where a packet's rays end: their hits, which are done, the pieces set aside.
struct Ends<'a> {
    out: &'a mut [(Ray, Option<Hit>)],
    done: &'a mut [bool],
    aside: &'a mut SetAside,
}

impl Ends<'_> {
    /// Ray `r`'s leaf search over the balls `gathered` found `found`: a root ends the ray.
    fn record(
        &mut self,
        m: &PreparedMetaballs,
        walk: &Walk,
        r: usize,
        found: Option<f32>,
        gathered: &[RayBall<f32>],
        counters: &mut MetaballCounters,
    ) {
        if let Some(mut t) = found {
            let ray = &walk.rays[r];
            if m.options.refine_f64 {
                t = m.refine_f64(ray, t, 0.0, walk.t_max, walk.isovalue, gathered);
            }
            counters.hits += 1;
            self.out[r].1 = Some(m.hit_at(ray, t, gathered));
            self.done[r] = true;
        }
    }
}

thread_local! {
    static TILE: RefCell<TileBuffers> = RefCell::new(TileBuffers::default());
}

/// Whether box `a` comes before box `b` along every ray from `origin` that crosses both: the
/// side of a separating plane (a Fitted BVH's siblings are split at one) the origin lies on;
/// without one (boxes that touch on every axis), the nearer centre.
#[inline]
fn nearer_first(a: &Aabb, b: &Aabb, origin: Vec3) -> bool {
    let (a_lo, a_hi, b_lo, b_hi) = (
        a.min.to_array(),
        a.max.to_array(),
        b.min.to_array(),
        b.max.to_array(),
    );
    let o = origin.to_array();
    for k in 0..3 {
        if a_hi[k] <= b_lo[k] {
            return o[k] <= a_hi[k];
        }
        if b_hi[k] <= a_lo[k] {
            return o[k] > b_hi[k];
        }
    }
    let centre = |b: &Aabb| ((b.min + b.max) * 0.5 - origin).length_squared();
    centre(a) <= centre(b)
}

impl PreparedMetaballs {
    /// Each primary ray through pixels `x0..x1 × y0..y1` of `rays` (row by row) and its first
    /// hit on `[0, t_max]`, the tile traced as one packet; `None` where packets do not apply
    /// (packets off, not a nested Fitted BVH, an isovalue below the build's floor), and the
    /// caller traces single rays. Hits equal [`PreparedMetaballs::first_hit_counted`]'s.
    pub fn primary_tile_packet(
        &self,
        rays: &PrimaryRays,
        (x0, y0, x1, y1): (u32, u32, u32, u32),
        isovalue: f32,
        t_max: f32,
        counters: &mut MetaballCounters,
    ) -> Option<Vec<(Ray, Option<Hit>)>> {
        if !self.options.packets || !self.nested || x1 <= x0 || y1 <= y0 {
            return None;
        }
        if !(isovalue > 0.0) || !isovalue.is_finite() || !(0.0 < t_max) {
            return None;
        }
        let accel = self.accel_for(isovalue);
        if !std::ptr::eq(accel, &self.accel) {
            return None; // the relaxed fallback tree, not checked for nesting
        }
        let tree = match accel {
            Accel::Tree(tree) => tree,
            Accel::BruteForce | Accel::ActiveList => return None,
        };
        let tile = TileGrid {
            rays: *rays,
            x0,
            y0,
            width: x1 - x0,
            height: y1 - y0,
        };
        TILE.with(|tile_cell| {
            let mut tile_guard = tile_cell.borrow_mut();
            self.primary_tile_packet_in(&mut tile_guard, tree, tile, isovalue, t_max, counters)
        })
    }

    /// [`PreparedMetaballs::primary_tile_packet`] on `tile` with the thread's tile buffers.
    fn primary_tile_packet_in(
        &self,
        buffers: &mut TileBuffers,
        tree: &Tree,
        tile: TileGrid,
        isovalue: f32,
        t_max: f32,
        counters: &mut MetaballCounters,
    ) -> Option<Vec<(Ray, Option<Hit>)>> {
        let TileBuffers {
            tile_rays,
            inv,
            done,
            stack,
            culled,
            crossing,
            inverses,
            soa,
            aside,
        } = buffers;
        let rays = &tile.rays;
        let (x0, y0) = (tile.x0, tile.y0);
        rays.tile_rays((x0, y0, x0 + tile.width, y0 + tile.height), tile_rays, inv);
        inverses.load(inv);
        let n = tile_rays.len();
        let width = tile.width as usize;
        let origin = tile_rays[0].origin;
        if tile_rays.iter().any(|r| r.origin != origin) {
            return None;
        }
        // The tile's rays and hits, the hits filled in as rays finish.
        let mut out: Vec<(Ray, Option<Hit>)> = tile_rays.iter().map(|&ray| (ray, None)).collect();
        done.clear();
        done.resize(n, false);
        let params = self.params(isovalue);
        let bound = (self.options.finder.bounds_whole_stretch())
            .then(|| StretchBound::new(params.kernel, isovalue));
        let walk = Walk {
            rays: tile_rays,
            params,
            lane_params: FindParams {
                bounded: bound.is_some(),
                ..params
            },
            finder: self.options.finder,
            defer: self.sets_roots_aside(),
            isovalue,
            t_max,
            bound,
        };
        counters.rays += n as u64;
        let spheres = self.spheres_of(tree);
        SCRATCH.with(|cell| {
            let mut guard = cell.borrow_mut();
            let (gathered, scratch, _) = &mut *guard;
            stack.clear();
            stack.push((0, 0));
            while let Some((i, from)) = stack.pop() {
                let node = &tree.nodes[i as usize];
                if node.is_leaf() && node.count == 0 {
                    continue;
                }
                counters.node_traversals += 1;
                let cover = tile.cover_box(node.bounds.min, node.bounds.max);
                if node.is_leaf() {
                    // The leaf's balls less those outside the pyramid of the cover's rays.
                    let leaf = tree.leaf_balls(node);
                    let balls = match (tile.frustum(cover), spheres) {
                        (Some(frustum), Some(spheres)) => {
                            culled.clear();
                            spheres.cull(&frustum, leaf, node.first as usize, culled);
                            &culled[..]
                        }
                        (Some(frustum), None) => {
                            culled.clear();
                            culled.extend(leaf.iter().copied().filter(|&b| {
                                let ball = &self.balls[b as usize];
                                !frustum.excludes_sphere(ball.center, 1.0 / ball.inv_r)
                            }));
                            &culled[..]
                        }
                        (None, _) => leaf,
                    };
                    if balls.is_empty() {
                        continue;
                    }
                    // The cover's rays not done that cross the leaf's box, with their ranges.
                    let rays = (width, from as usize, n);
                    let b = &node.bounds;
                    inverses.crossing(cover, rays, done, b, origin, t_max, crossing);
                    if crossing.is_empty() {
                        continue;
                    }
                    let mut ends = Ends {
                        out: &mut out,
                        done: &mut done[..],
                        aside: &mut *aside,
                    };
                    if soa.load(&self.balls, origin, balls) {
                        let buffers = (&mut *gathered, &mut *scratch);
                        self.search_lanes(&walk, soa, crossing, buffers, &mut ends, counters);
                    } else {
                        for &(r, near, far) in crossing.iter() {
                            let ray = &tile_rays[r as usize];
                            let found = self.search_leaf(
                                balls,
                                balls.len(),
                                ray,
                                near,
                                far,
                                &walk.params,
                                walk.finder,
                                gathered,
                                scratch,
                                counters,
                            );
                            ends.record(self, &walk, r as usize, found, gathered, counters);
                        }
                    }
                    continue;
                }
                // The first active ray: the first of the cover, from the packet's, that is not
                // done and meets the box.
                let mut first = None;
                cover.visit(width, from as usize, n, |r| {
                    let hit =
                        !done[r] && node.bounds.ray_range(origin, inv[r], 0.0, t_max).is_some();
                    if hit {
                        first = Some(r);
                    }
                    hit
                });
                let Some(fa) = first else {
                    continue;
                };
                let c = node.first;
                let (a, b) = (&tree.nodes[c as usize], &tree.nodes[c as usize + 1]);
                let left_first = nearer_first(&a.bounds, &b.bounds, origin);
                let (near_child, far_child) = if left_first { (c, c + 1) } else { (c + 1, c) };
                stack.push((far_child, fa as u32));
                stack.push((near_child, fa as u32));
            }
        });
        self.settle_aside(aside, &mut out, isovalue, t_max, counters);
        Some(out)
    }

    /// The rays `crossing` of a leaf whose balls `soa` holds: gathered eight at a time, and
    /// each whose field may reach the isovalue on its range searched over its balls.
    fn search_lanes(
        &self,
        walk: &Walk,
        soa: &mut SharedOriginBalls,
        crossing: &[(u32, f32, f32)],
        (gathered, scratch): (&mut Vec<RayBall<f32>>, &mut Scratch<f32>),
        ends: &mut Ends,
        counters: &mut MetaballCounters,
    ) {
        for rays in crossing.chunks(RAY_LANES) {
            soa.gather_rays(rays, walk.rays, walk.bound.as_ref());
            for (lane, &(r, near, far)) in rays.iter().enumerate() {
                if !soa.may_reach(lane) {
                    // The search would stop at its whole-stretch bound.
                    let balls = soa.lane_count(lane);
                    if balls > 0 {
                        roots::Found::default().counted(counters, balls);
                    }
                    continue;
                }
                gathered.clear();
                soa.lane_gathered(&self.balls, lane, gathered);
                let search = (r as usize, near, far);
                self.end_search(walk, search, gathered, scratch, ends, counters);
            }
        }
    }

    /// Ray `r`'s search of a leaf on `[near, far]` over `gathered`, the leaf's balls its
    /// support crosses there, the search's whole-stretch bound already answered in the lanes
    /// ([`Walk::lane_params`]): a root ends the ray, and so does an isolated piece set aside.
    fn end_search(
        &self,
        walk: &Walk,
        (r, near, far): (usize, f32, f32),
        gathered: &[RayBall<f32>],
        scratch: &mut Scratch<f32>,
        ends: &mut Ends,
        counters: &mut MetaballCounters,
    ) {
        let found = if !walk.defer || gathered.is_empty() {
            search_gathered(
                &walk.lane_params,
                walk.finder,
                near,
                far,
                gathered,
                scratch,
                counters,
            )
        } else {
            let (found, piece) = roots::find_first_deferring(
                walk.finder,
                &walk.lane_params,
                gathered,
                near,
                far,
                scratch,
            );
            if let Some(piece) = piece {
                ends.aside.push(r, found, piece, gathered);
                ends.done[r] = true;
                return;
            }
            found.counted(counters, gathered.len())
        };
        ends.record(self, walk, r, found, gathered, counters);
    }

    /// Whether a packet's Bézier searches set their isolated pieces aside, to be solved in
    /// lanes (not with the `f64` refinement, which refines each hit from its own search).
    fn sets_roots_aside(&self) -> bool {
        self.options.finder == RootFinder::BezierClipping && !self.options.refine_f64
    }

    /// The roots of the pieces `aside` holds, in lanes, and the hits of their rays; `aside`
    /// is left empty.
    fn settle_aside(
        &self,
        aside: &mut SetAside,
        out: &mut [(Ray, Option<Hit>)],
        isovalue: f32,
        t_max: f32,
        counters: &mut MetaballCounters,
    ) {
        lanes::solve(&aside.pieces, &mut aside.solved);
        let settled = aside.rays.iter().zip(&aside.pieces).zip(&aside.solved);
        for ((&(r, mut found, (start, end)), piece), &(t, iters)) in settled {
            let (ray, hit) = &mut out[r as usize];
            // As the section's search would have counted it, had it solved the piece itself.
            found.iterations += iters - piece.iters;
            found.capped |= iters >= ITERATION_CAP;
            found.hit_iterations = iters;
            found.t = t;
            let balls = &aside.balls[start as usize..end as usize];
            let Some(t) = found.counted(counters, balls.len()) else {
                // Past the iteration cap (in theory): the search would have gone on to later
                // sections and leaves, so the ray is traced again alone.
                *hit = self.first_hit_counted(ray, 0.0, t_max, isovalue, counters);
                continue;
            };
            counters.hits += 1;
            *hit = Some(self.hit_at_balls(ray, t, balls.iter().copied()));
        }
        aside.clear();
    }
}
