//! Traversal of the bounding-sphere hierarchy (deforming-point-sampled-surfaces.txt §4.2,
//! §4.4): the nearest hit, optionally starting from the ray's cached sphere node (§4.2.2),
//! and any hit for shadow rays, which enters the already-updated child of a sphere first so
//! that the other is often neither updated nor traversed (§4.4 "Optimization for shadow
//! rays").
//!
//! The loop is generic over [`Spheres`]: the lazy view fills spheres on first touch, the
//! fixed view reads a refitted or rebuilt tree. Both are monomorphic; nothing allocates.

use crate::kinds::surfels::counters::SurfelCounters;
use crate::kinds::surfels::deform::{node_sphere, sphere_around};
use crate::kinds::surfels::intersect::{intersect_leaf, Leaf, LeafHit, Search, ANY, NEAREST};
use crate::kinds::surfels::prepared::{LazyNode, PreparedSurfels};
use crate::kinds::surfels::tree::{TreeNode, LEAF};
use crate::ray::Ray;
use glam::Vec3;

/// How much [`sphere_entry`] grows a sphere, relative to the distance from the ray's origin
/// to the sphere: several `f32` ulps, more than the rounding of the entry, of the ray's
/// offset from the centre and of a hit's own position, so a hit inside the sphere is never
/// taken for one outside it.
const SPHERE_SLACK: f32 = 1e-6;

/// Active rays from which a packet tests a sphere against all [`PACKET`] lanes at once
/// ([`Lanes::entries`]) rather than ray by ray.
const DENSE: u32 = 12;

/// Deep enough for any median-split tree of `u32` surfels (depth ≤ 33; two entries a level,
/// three in a packet's stack, which keeps a post-order marker under each expanded node's
/// children, one of which is popped at once).
pub const STACK: usize = 80;

/// Surfels below a node up to which its first sphere is the sphere around its children
/// rather than eq. 9's: at the bottom levels eq. 9 is 1.5–2.3 times the smallest sphere
/// (`isoray-bench surfels`'s tightness table, `surfel-impact`), the sphere around the
/// children 1.0–1.1 times, and a ray that enters the node fills its children anyway. On
/// `surfel-impact` (lazy, 512×384, shadows) 16 takes a ray from 65.2 to 61.2 sphere tests
/// and camera packets from 3.45 to 3.17 G instructions (callgrind); 4 and 8 save less, 32
/// no more.
const SMALL_SUBTREE: u32 = 16;

/// Where a traversal gets node spheres.
pub trait Spheres {
    /// Node `n`'s children (`[LEAF, surfel]` for a leaf).
    fn kids(&self, n: u32) -> [u32; 2];
    /// The sphere of node `n`, updating it if this view is lazy.
    fn sphere(&self, n: u32, c: &mut SurfelCounters) -> (Vec3, f32);
    /// Whether node `n` already has its sphere for this step.
    fn updated(&self, n: u32) -> bool;
    /// Told the spheres of both children of inner node `n` (whose sphere in use has
    /// `radius`): a lazy view tightens `n` to the sphere around them where that is smaller.
    fn tighten(&self, _n: u32, _radius: f32, _kids: [(Vec3, f32); 2]) {}
}

/// The model's hierarchy, updated on first touch.
pub struct LazyView<'a> {
    pub p: &'a PreparedSurfels,
    pub nodes: &'a [LazyNode],
}

impl Spheres for LazyView<'_> {
    #[inline]
    fn kids(&self, n: u32) -> [u32; 2] {
        self.nodes[n as usize].kids
    }

    #[inline(always)]
    fn sphere(&self, n: u32, c: &mut SurfelCounters) -> (Vec3, f32) {
        match self.nodes[n as usize].get() {
            Some(s) => s,
            None => self.fill(n, c),
        }
    }

    /// Eq. 11 once both children are updated (§4.4: "if a node is already visited before,
    /// update the radius using Equation 11"), and the sphere around both children where
    /// that is tighter: the single ray calls this right after it has updated and tested both
    /// children, a packet once the node's whole subtree is done (post-order), so that what
    /// its descendants learned reaches it within the packet; the node is written only when
    /// a sphere actually shrinks.
    #[inline]
    fn tighten(&self, n: u32, radius: f32, kids: [(Vec3, f32); 2]) {
        self.nodes[n as usize].tighten(radius, kids);
    }

    /// Whether `n`'s record holds a sphere (a leaf's is filled when a ray first touches it,
    /// so its surfel is deformed; reading the record, not the surfel, keeps this test on the
    /// tree's records, which the traversal reads next anyway).
    #[inline]
    fn updated(&self, n: u32) -> bool {
        self.nodes[n as usize].get().is_some()
    }
}

impl LazyView<'_> {
    /// Node `n`'s sphere on first touch (or while another thread writes it): eq. 4 and 9,
    /// a leaf's deformed surfel, or for a node over at most [`SMALL_SUBTREE`] surfels the
    /// sphere around its children, filled first (the same rule down to the leaves).
    #[cold]
    #[inline(never)]
    fn fill(&self, n: u32, c: &mut SurfelCounters) -> (Vec3, f32) {
        let node = &self.nodes[n as usize];
        if node.kids[0] == LEAF {
            // The leaf's sphere is copied into its record, so that later tests read the
            // tree's records only (the surfels lie in input order, not tree order).
            let mut fresh = false;
            let d = self.p.surfel(node.kids[1] as usize, &mut fresh);
            c.surfel_updates += fresh as u64;
            node.set(d.centre, d.leaf_radius);
            return (d.centre, d.leaf_radius);
        }
        c.node_updates += 1;
        let [a, b] = self.p.model.tree.leaf_range[n as usize];
        if b - a <= SMALL_SUBTREE {
            let kids = node.kids.map(|k| self.sphere(k, c));
            let (centre, radius) = sphere_around(kids[0], kids[1]);
            node.set(centre, radius);
            return (centre, radius);
        }
        let (centre, radius) = node_sphere(&self.p.model, &self.p.step, n as usize);
        node.set(centre, radius);
        (centre, radius)
    }
}

/// A tree whose spheres are all known.
pub struct FixedView<'a>(pub &'a [TreeNode]);

impl Spheres for FixedView<'_> {
    #[inline]
    fn kids(&self, n: u32) -> [u32; 2] {
        self.0[n as usize].kids
    }

    #[inline]
    fn sphere(&self, n: u32, _c: &mut SurfelCounters) -> (Vec3, f32) {
        let node = self.0[n as usize];
        (node.centre, node.radius)
    }

    #[inline]
    fn updated(&self, _n: u32) -> bool {
        true
    }
}

/// Where the ray (unit direction) enters the sphere within `[t_min, t_max]`, if it meets it
/// there; conservative under `f32` rounding: the sphere is grown by [`SPHERE_SLACK`] of its
/// distance, so a point inside it (a leaf's hit) is never reported beyond its entry.
///
/// The squared distance from the centre to the ray's line is `|oc − (oc·d) d|²`, not
/// `|oc|² − (oc·d)²` (Haines et al., "Precision Improvements for Ray/Sphere Intersection",
/// Ray Tracing Gems ch. 7): for a small sphere far from the ray's origin the latter is a
/// difference of two large numbers, off by `~|oc|²·ε`, and the entry it gives by up to
/// `ε|oc|²/r` (5·10⁻⁵ for a 0.01 sphere 3.6 away). Pruning by such an entry dropped leaves
/// whose hit lay nearer than the nearest hit found so far, so which hit a ray kept depended
/// on the order it met the leaves in, and that on the lazy spheres other threads had
/// tightened: one pixel of `surfel-impact` at t = 5.1 differed between runs at 8 threads.
#[inline]
pub fn sphere_entry(ray: &Ray, centre: Vec3, radius: f32, t_min: f32, t_max: f32) -> Option<f32> {
    let (met, entry) = entry_of(
        (ray.origin - centre).to_array(),
        ray.dir.to_array(),
        radius,
        t_min,
        t_max,
    );
    met.then_some(entry)
}

/// [`sphere_entry`]'s arithmetic on plain lanes, shared by the single ray and
/// [`Lanes::entries`] (branch-free, so a loop of it vectorizes): whether the ray with origin
/// `oc` relative to the centre and direction `d` meets the sphere within `[t_min, t_max]`,
/// and its entry there.
#[inline(always)]
fn entry_of(oc: [f32; 3], d: [f32; 3], radius: f32, t_min: f32, t_max: f32) -> (bool, f32) {
    let b = d[0] * oc[0] + d[1] * oc[1] + d[2] * oc[2];
    let off = [oc[0] - b * d[0], oc[1] - b * d[1], oc[2] - b * d[2]];
    // `|b| + r` is at least `|oc|` for every ray that can meet the sphere.
    let r = radius + SPHERE_SLACK * (b.abs() + radius);
    let disc = r * r - (off[0] * off[0] + off[1] * off[1] + off[2] * off[2]);
    let sq = disc.sqrt();
    let (t0, t1) = (-b - sq, -b + sq);
    (
        !(disc < 0.0) && !(t1 < t_min) && !(t0 > t_max),
        t0.max(t_min),
    )
}

/// A cone from one apex around every ray of a packet that starts there (a camera packet):
/// a sphere outside it meets none of them, so a packet drops it with one test instead of a
/// test per ray. Conservative under rounding: the half-angle's cosine is rounded down and
/// its sine up, and a sphere is dropped only when it clears the cone by a relative margin
/// ten times [`SPHERE_SLACK`], so every sphere a ray's [`sphere_entry`] meets is kept.
#[derive(Clone, Copy, Debug)]
pub(super) struct Cone {
    apex: Vec3,
    axis: Vec3,
    cos: f32,
    sin: f32,
}

impl Cone {
    /// The cone around `rays` (unit directions), if they share an origin and fit in a cone
    /// narrower than a half space.
    pub(super) fn around(rays: &[Ray]) -> Option<Cone> {
        let apex = rays.first()?.origin;
        if rays.iter().any(|r| r.origin != apex) {
            return None;
        }
        let axis = rays
            .iter()
            .fold(Vec3::ZERO, |a, r| a + r.dir)
            .normalize_or_zero();
        let (mut cos, mut sin) = (1.0f32, 0.0f32);
        for r in rays {
            cos = cos.min(axis.dot(r.dir));
            sin = sin.max(axis.cross(r.dir).length());
        }
        (cos > 0.1 && axis != Vec3::ZERO).then_some(Cone {
            apex,
            axis,
            cos: cos * (1.0 - 1e-5) - 1e-6,
            sin: sin * (1.0 + 1e-5) + 1e-6,
        })
    }

    /// Whether the sphere lies outside the cone (then no ray of the packet meets it). Its
    /// distance from the cone is `|v| sin(φ − θ)` for a centre at angle `φ` off the axis
    /// (`φ − θ` up to 90°; beyond, the apex is nearer, farther than that): `e cos θ − d sin θ`
    /// with `d` and `e` the centre's offsets along and across the axis. A centre behind
    /// the apex is dropped only when the whole sphere is (the rays run forward of it).
    #[inline]
    pub(super) fn misses(&self, centre: Vec3, radius: f32) -> bool {
        let v = centre - self.apex;
        let d = v.dot(self.axis);
        let e = (v - d * self.axis).length();
        let r = radius + 10.0 * SPHERE_SLACK * (d.abs() + e + radius);
        if d < 0.0 {
            return d < -r;
        }
        e * self.cos - d * self.sin > r
    }
}

/// Lanes [`Lanes::entries`] skips together when none of them is active: a row of an 8×8
/// camera packet (two vector registers in the portable build).
const BLOCK: usize = 8;
const BLOCK_MASK: u64 = (1 << BLOCK) - 1;

/// A packet's rays as structure-of-arrays (lanes past the packet's rays are zero).
pub(super) struct Lanes {
    o: [[f32; PACKET]; 3],
    d: [[f32; PACKET]; 3],
}

impl Lanes {
    pub(super) fn new(rays: &[Ray]) -> Lanes {
        let mut l = Lanes {
            o: [[0.0; PACKET]; 3],
            d: [[0.0; PACKET]; 3],
        };
        for (i, r) in rays.iter().take(PACKET).enumerate() {
            for a in 0..3 {
                l.o[a][i] = r.origin[a];
                l.d[a][i] = r.dir[a];
            }
        }
        l
    }

    /// [`sphere_entry`] for the lanes at once, in one branch-free loop the compiler
    /// vectorizes, with lane `i`'s upper bound `t_max[i]`: `entry[i]` is its entry where the
    /// lane's bit is set in the answer. Blocks of [`BLOCK`] lanes none of which is `active`
    /// are skipped (no bit set, entries left as they were): on `surfel-impact` that takes
    /// camera packets from 3.17 to 3.03 G instructions and shadow packets from 1.53 to
    /// 1.41 G (callgrind). Both run [`entry_of`], so the entries are the same bits (checked
    /// by `lanes_give_sphere_entry_bit_for_bit`).
    #[inline]
    pub(super) fn entries(
        &self,
        centre: Vec3,
        radius: f32,
        t_min: f32,
        t_max: &[f32; PACKET],
        entry: &mut [f32; PACKET],
        active: u64,
    ) -> u64 {
        let mut mask = 0u64;
        for block in 0..PACKET / BLOCK {
            if (active >> (block * BLOCK)) & BLOCK_MASK == 0 {
                continue;
            }
            let mut met = [false; BLOCK];
            // Indexed, not `iter_mut`: this form is the one the compiler vectorizes
            // (callgrind: camera packets 3.03 G instructions against 4.14 G).
            #[allow(clippy::needless_range_loop)]
            for l in 0..BLOCK {
                let i = block * BLOCK + l;
                let oc = [
                    self.o[0][i] - centre.x,
                    self.o[1][i] - centre.y,
                    self.o[2][i] - centre.z,
                ];
                let d = [self.d[0][i], self.d[1][i], self.d[2][i]];
                (met[l], entry[i]) = entry_of(oc, d, radius, t_min, t_max[i]);
            }
            for (l, &m) in met.iter().enumerate() {
                mask |= (m as u64) << (block * BLOCK + l);
            }
        }
        mask
    }
}

/// The nearest hit in `[t_min, t_max]` as `search` asks ([`NEAREST`], or
/// [`NEAREST_LEAVING`](crate::kinds::surfels::intersect::NEAREST_LEAVING)); `hint` is the
/// ray's cached surfel, tested first.
pub fn first_hit<V: Spheres>(
    v: &V,
    p: &PreparedSurfels,
    ray: &Ray,
    (t_min, t_max): (f32, f32),
    (hint, search): (Option<u32>, Search),
    c: &mut SurfelCounters,
) -> Option<LeafHit> {
    let mut best: Option<LeafHit> = None;
    if let Some(s) = hint.filter(|&s| (s as usize) < p.surfels.len()) {
        best = intersect_leaf(p, ray, s as usize, t_min, t_max, search, c);
        c.cache_hits += best.is_some() as u64;
    }
    let mut stack = [(0u32, 0f32, 0f32); STACK];
    let mut top = 0;
    c.sphere_tests += 1;
    let (rc, rr) = v.sphere(0, c);
    if let Some(t) = sphere_entry(ray, rc, rr, t_min, t_max) {
        stack[0] = (0, t, rr);
        top = 1;
    }
    while top > 0 {
        top -= 1;
        let (n, entry, radius) = stack[top];
        let limit = LeafHit::limit(best, t_max);
        if entry > limit {
            continue;
        }
        let kids_of = v.kids(n);
        if kids_of[0] == LEAF {
            if Some(kids_of[1]) == hint {
                continue;
            }
            if let Some(h) = intersect_leaf(p, ray, kids_of[1] as usize, t_min, limit, search, c) {
                if best.is_none_or(|b| h.before(&b)) {
                    best = Some(h);
                }
            }
            continue;
        }
        let mut kids = [(0u32, f32::INFINITY, 0f32); 2];
        let mut spheres = [(Vec3::ZERO, 0f32); 2];
        let mut count = 0;
        for (slot, k) in kids_of.into_iter().enumerate() {
            c.sphere_tests += 1;
            let (kc, kr) = v.sphere(k, c);
            spheres[slot] = (kc, kr);
            if let Some(t) = sphere_entry(ray, kc, kr, t_min, limit) {
                kids[count] = (k, t, kr);
                count += 1;
            }
        }
        v.tighten(n, radius, spheres);
        if count == 2 && kids[1].1 > kids[0].1 {
            kids.swap(0, 1);
        }
        // Far first, so the near child is popped first.
        for &k in &kids[..count] {
            if top < STACK {
                stack[top] = k;
                top += 1;
            }
        }
    }
    best
}

/// Rays of one packet of [`first_hits`] (a mask bit each).
pub const PACKET: usize = 64;

/// [`first_hits`]' entry distances, a row for each stack slot (20 KiB): kept by the caller
/// across the packets of a tile rather than zeroed for each packet (that memset was 6% of
/// the camera packets' instructions on `surfel-impact`). Stale lanes are never read: a
/// packet reads a lane of a row only where the row's mask has it, and writes it first.
pub type Entries = [[f32; PACKET]; STACK];

/// [`first_hit`] for up to [`PACKET`] rays on `[0, t_max]` together (coherent camera rays):
/// each node's sphere is read and updated once for the packet (and tightened once the
/// packet is done with its subtree), and each ray tests it only while it is active (it met
/// the parent and the parent's entry was not beyond its best hit's rank so far). `hints` holds
/// each ray's cached surfel (tested first, as the single ray does).
///
/// The answers are [`first_hit`]'s: a ray's answer is the first hit by [`LeafHit::before`]
/// (lowest rank, ties to the lower surfel) over the leaves it tests, a leaf's hit does not
/// depend on the order, and a ray drops a node only where the single ray would (entry
/// beyond its best rank so far, which only shrinks), so every leaf holding that hit is
/// tested by both.
pub fn first_hits<V: Spheres>(
    v: &V,
    p: &PreparedSurfels,
    rays: &[Ray],
    t_max: f32,
    hints: &[Option<u32>],
    (out, entries): (&mut [Option<LeafHit>], &mut Entries),
    c: &mut SurfelCounters,
) {
    let n = rays.len().min(PACKET).min(hints.len()).min(out.len());
    for i in 0..n {
        out[i] = None;
        if let Some(s) = hints[i].filter(|&s| (s as usize) < p.surfels.len()) {
            out[i] = intersect_leaf(p, &rays[i], s as usize, 0.0, t_max, NEAREST, c);
            c.cache_hits += out[i].is_some() as u64;
        }
    }
    let limit = |out: &[Option<LeafHit>], i: usize| LeafHit::limit(out[i], t_max);
    let lanes = Lanes::new(&rays[..n]);
    let cone = Cone::around(&rays[..n]);
    let mut lims = [t_max; PACKET];
    // Stack slot k: node, its radius, its rays and their entry distances.
    let mut stack = [(0u32, 0f32, 0u64); STACK];
    let (rc, rr) = v.sphere(0, c);
    c.sphere_tests += n as u64;
    let mut mask = 0u64;
    for i in 0..n {
        if let Some(t) = sphere_entry(&rays[i], rc, rr, 0.0, t_max) {
            entries[0][i] = t;
            mask |= 1 << i;
        }
    }
    stack[0] = (0, rr, mask);
    let mut top = (mask != 0) as usize;
    while top > 0 {
        top -= 1;
        let (node, radius, mut mask) = stack[top];
        if mask == 0 {
            // Post-order: the node's subtree is done; tighten it from its children now.
            let kids_of = v.kids(node);
            let spheres = kids_of.map(|k| v.sphere(k, c));
            v.tighten(node, radius, spheres);
            continue;
        }
        let entry = entries[top];
        for i in Bits(mask) {
            if entry[i] > limit(out, i) {
                mask &= !(1 << i);
            }
        }
        if mask == 0 {
            continue;
        }
        let kids_of = v.kids(node);
        if kids_of[0] == LEAF {
            let mut leaf = Leaf::new(p, kids_of[1] as usize, c);
            for i in Bits(mask) {
                if Some(kids_of[1]) == hints[i] {
                    continue;
                }
                let lim = limit(out, i);
                let h = leaf.hit(&rays[i], 0.0, lim, NEAREST, c);
                if let Some(h) = h {
                    if out[i].is_none_or(|b| h.before(&b)) {
                        out[i] = Some(h);
                    }
                }
            }
            continue;
        }
        let spheres = kids_of.map(|k| v.sphere(k, c));
        c.sphere_tests += 2 * mask.count_ones() as u64;
        if top + 3 > STACK {
            continue; // unreachable: two slots a level (see STACK)
        }
        // The node stays below its children as a post-order marker (no rays); the
        // children's entries go straight into the two slots above it.
        stack[top] = (node, radius, 0);
        let (below, above) = entries.split_at_mut(top + 2);
        let kid_entries = [&mut below[top + 1], &mut above[0]];
        let mut kid_masks = [0u64; 2];
        let mut nearer = [0u32; 2];
        if mask.count_ones() >= DENSE {
            for i in Bits(mask) {
                lims[i] = limit(out, i);
            }
            for (k, &(kc, kr)) in spheres.iter().enumerate() {
                if cone.is_some_and(|c| c.misses(kc, kr)) {
                    continue;
                }
                kid_masks[k] = lanes.entries(kc, kr, 0.0, &lims, kid_entries[k], mask) & mask;
            }
            for i in Bits(kid_masks[0] & kid_masks[1]) {
                nearer[(kid_entries[1][i] < kid_entries[0][i]) as usize] += 1;
            }
        } else {
            for i in Bits(mask) {
                let lim = limit(out, i);
                for (k, &(kc, kr)) in spheres.iter().enumerate() {
                    if let Some(t) = sphere_entry(&rays[i], kc, kr, 0.0, lim) {
                        kid_entries[k][i] = t;
                        kid_masks[k] |= 1 << i;
                    }
                }
                if kid_masks[0] & kid_masks[1] & (1 << i) != 0 {
                    nearer[(kid_entries[1][i] < kid_entries[0][i]) as usize] += 1;
                }
            }
        }
        top += 1;
        let kid = |k: usize| (kids_of[k], spheres[k].1, kid_masks[k]);
        match (kid_masks[0] != 0, kid_masks[1] != 0) {
            // The child nearer for most rays on top, so that it is popped first.
            (true, true) if nearer[1] > nearer[0] => {
                (stack[top], stack[top + 1]) = (kid(0), kid(1));
                top += 2;
            }
            (true, true) => {
                entries.swap(top, top + 1);
                (stack[top], stack[top + 1]) = (kid(1), kid(0));
                top += 2;
            }
            (true, false) => {
                stack[top] = kid(0);
                top += 1;
            }
            (false, true) => {
                entries.copy_within(top + 1..top + 2, top);
                stack[top] = kid(1);
                top += 1;
            }
            (false, false) => {}
        }
    }
}

/// [`any_hit`] for up to [`PACKET`] rays (shadow rays of neighbouring pixels) together: each
/// node's sphere is read and updated once for the packet and tested by the rays still
/// searching that met its parent; a ray stops at its first hit. `out[i]` is `Some` exactly
/// when [`any_hit`] finds a hit for ray `i` (both search until a hit or the whole tree:
/// every sphere bounds its surfels), though it may be another hit. A ray that starts
/// outside a body (`outside[i]`, [`PreparedSurfels::outside_of`]) skips that body's nodes
/// whose hits all face away from it, as [`any_hit`]'s does.
#[allow(clippy::too_many_arguments)]
pub fn any_hits<V: Spheres>(
    v: &V,
    p: &PreparedSurfels,
    rays: &[Ray],
    t_min: f32,
    t_max: &[f32],
    outside: &[Option<u16>],
    out: &mut [Option<f32>],
    c: &mut SurfelCounters,
) {
    let cull = p.cull.is_some() && outside.iter().any(Option::is_some);
    let n = rays.len().min(PACKET).min(t_max.len()).min(out.len());
    out[..n].fill(None);
    let lanes = Lanes::new(&rays[..n]);
    let mut lims = [0f32; PACKET];
    lims[..n].copy_from_slice(&t_max[..n]);
    let mut scratch = [0f32; PACKET];
    let mut stack = [(0u32, 0u64); STACK];
    stack[0] = (
        0,
        if n == PACKET {
            u64::MAX
        } else {
            (1u64 << n) - 1
        },
    );
    let mut top = (n > 0) as usize;
    let mut done = 0u64;
    while top > 0 {
        top -= 1;
        let (node, mask) = stack[top];
        let mut mask = mask & !done;
        if cull && mask != 0 {
            if let Some((axis, sin, body)) = p.cone(node) {
                for i in Bits(mask) {
                    if outside.get(i) == Some(&Some(body)) && axis.dot(rays[i].dir) > sin {
                        mask &= !(1 << i);
                    }
                }
            }
        }
        if mask == 0 {
            continue;
        }
        let (sc, sr) = v.sphere(node, c);
        c.sphere_tests += mask.count_ones() as u64;
        let mut inside = 0u64;
        if mask.count_ones() >= DENSE {
            inside = lanes.entries(sc, sr, t_min, &lims, &mut scratch, mask) & mask;
        } else {
            for i in Bits(mask) {
                if sphere_entry(&rays[i], sc, sr, t_min, t_max[i]).is_some() {
                    inside |= 1 << i;
                }
            }
        }
        if inside == 0 {
            continue;
        }
        let [a, b] = v.kids(node);
        if a == LEAF {
            let mut leaf = Leaf::new(p, b as usize, c);
            for i in Bits(inside) {
                if let Some(h) = leaf.hit(&rays[i], t_min, t_max[i], ANY, c) {
                    out[i] = Some(h.t);
                    done |= 1 << i;
                }
            }
            continue;
        }
        let (first, second) = updated_first(v, a, b);
        if top + 2 <= STACK {
            stack[top] = (second, inside);
            stack[top + 1] = (first, inside);
            top += 2;
        }
    }
}

/// Children `a` and `b` in the order an any-hit search tries them: §4.4, if only one child
/// is updated, it is tried first.
#[inline]
fn updated_first<V: Spheres>(v: &V, a: u32, b: u32) -> (u32, u32) {
    if !v.updated(a) && v.updated(b) {
        (b, a)
    } else {
        (a, b)
    }
}

/// The set bits of a mask, lowest first.
struct Bits(u64);

impl Iterator for Bits {
    type Item = usize;
    #[inline]
    fn next(&mut self) -> Option<usize> {
        if self.0 == 0 {
            return None;
        }
        let i = self.0.trailing_zeros() as usize;
        self.0 &= self.0 - 1;
        Some(i)
    }
}

/// Some hit in `[t_min, t_max]`, the first found. A ray that starts `outside` a closed body
/// ([`PreparedSurfels::outside_of`]) skips that body's nodes whose hits all face away from
/// it: its first crossing of the body, if any, faces it ([`crate::kinds::surfels::cones`]).
pub fn any_hit<V: Spheres>(
    v: &V,
    p: &PreparedSurfels,
    ray: &Ray,
    (t_min, t_max): (f32, f32),
    outside: Option<u16>,
    c: &mut SurfelCounters,
) -> Option<f32> {
    let cull = outside.is_some() && p.cull.is_some();
    let mut stack = [0u32; STACK];
    stack[0] = 0;
    let mut top = 1;
    while top > 0 {
        top -= 1;
        let n = stack[top];
        if cull
            && p.cone(n)
                .is_some_and(|(axis, sin, body)| Some(body) == outside && axis.dot(ray.dir) > sin)
        {
            continue;
        }
        c.sphere_tests += 1;
        let (sc, sr) = v.sphere(n, c);
        if sphere_entry(ray, sc, sr, t_min, t_max).is_none() {
            continue;
        }
        let [a, b] = v.kids(n);
        if a == LEAF {
            if let Some(h) = intersect_leaf(p, ray, b as usize, t_min, t_max, ANY, c) {
                return Some(h.t);
            }
            continue;
        }
        let (first, second) = updated_first(v, a, b);
        if top + 2 <= STACK {
            stack[top] = second;
            stack[top + 1] = first;
            top += 2;
        }
    }
    None
}
