//! Traversal of the bounding-sphere hierarchy (deforming-point-sampled-surfaces.txt §4.2,
//! §4.4): the nearest hit, optionally starting from the ray's cached sphere node (§4.2.2),
//! and any hit for shadow rays, which enters the already-updated child of a sphere first so
//! that the other is often neither updated nor traversed (§4.4 "Optimization for shadow
//! rays").
//!
//! The loop is generic over [`Spheres`]: the lazy view fills spheres on first touch, the
//! fixed view reads a refitted or rebuilt tree. Both are monomorphic; nothing allocates.

use crate::kinds::surfels::counters::SurfelCounters;
use crate::kinds::surfels::deform::{node_sphere, radius_from_children};
use crate::kinds::surfels::intersect::{intersect_leaf, LeafHit};
use crate::kinds::surfels::prepared::{PreparedSurfels, UNSET};
use crate::kinds::surfels::tree::TreeNode;
use crate::ray::Ray;
use glam::Vec3;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::OnceLock;

/// Deep enough for any median-split tree of `u32` surfels (depth ≤ 33, two entries a level).
const STACK: usize = 80;

/// Where a traversal gets node spheres.
pub trait Spheres {
    fn node(&self, n: u32) -> TreeNode;
    /// The sphere of node `n`, updating it if this view is lazy.
    fn sphere(&self, n: u32, c: &mut SurfelCounters) -> (Vec3, f32);
    /// Whether node `n` already has its sphere for this step.
    fn updated(&self, n: u32) -> bool;
}

/// The model's hierarchy, updated on first touch.
pub struct LazyView<'a> {
    pub p: &'a PreparedSurfels,
    pub nodes: &'a [OnceLock<(Vec3, f32)>],
    pub refined: &'a [AtomicU32],
}

impl LazyView<'_> {
    /// The sphere in use for node `n` if it has one, without updating anything.
    #[inline]
    fn peek(&self, n: u32) -> Option<(Vec3, f32)> {
        let node = self.p.model.tree.nodes[n as usize];
        if node.is_leaf() {
            return self.p.surfels[node.kids[1] as usize]
                .get()
                .map(|d| (d.centre, d.leaf_radius));
        }
        let (c, r) = *self.nodes[n as usize].get()?;
        let rf = self.refined[n as usize].load(Ordering::Relaxed);
        Some((c, if rf == UNSET { r } else { f32::from_bits(rf) }))
    }
}

impl Spheres for LazyView<'_> {
    #[inline]
    fn node(&self, n: u32) -> TreeNode {
        self.p.model.tree.nodes[n as usize]
    }

    #[inline]
    fn sphere(&self, n: u32, c: &mut SurfelCounters) -> (Vec3, f32) {
        let node = self.p.model.tree.nodes[n as usize];
        if node.is_leaf() {
            let mut fresh = false;
            let d = self.p.surfel(node.kids[1] as usize, &mut fresh);
            c.surfel_updates += fresh as u64;
            return (d.centre, d.leaf_radius);
        }
        let (centre, r9) = *self.nodes[n as usize].get_or_init(|| {
            c.node_updates += 1;
            node_sphere(&self.p.model, &self.p.step, n as usize)
        });
        // Eq. 11 whenever both children are updated (§4.4: "if a node is already visited
        // before, update the radius using Equation 11"); radii only ever shrink, and a
        // positive f32's bits order like the value, so `fetch_min` keeps the tightest.
        let rf = self.refined[n as usize].load(Ordering::Relaxed);
        let mut r = if rf == UNSET { r9 } else { f32::from_bits(rf) };
        if let (Some(a), Some(b)) = (self.peek(node.kids[0]), self.peek(node.kids[1])) {
            let r11 = radius_from_children(centre, [a, b]);
            if r11 < r {
                r = r11;
                self.refined[n as usize].fetch_min(r.to_bits(), Ordering::Relaxed);
            }
        }
        (centre, r)
    }

    #[inline]
    fn updated(&self, n: u32) -> bool {
        let node = self.p.model.tree.nodes[n as usize];
        if node.is_leaf() {
            self.p.surfels[node.kids[1] as usize].get().is_some()
        } else {
            self.nodes[n as usize].get().is_some()
        }
    }
}

/// A tree whose spheres are all known.
pub struct FixedView<'a>(pub &'a [TreeNode]);

impl Spheres for FixedView<'_> {
    #[inline]
    fn node(&self, n: u32) -> TreeNode {
        self.0[n as usize]
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

/// Where the ray enters the sphere within `[t_min, t_max]`, if it meets it there.
#[inline]
pub fn sphere_entry(ray: &Ray, centre: Vec3, radius: f32, t_min: f32, t_max: f32) -> Option<f32> {
    let oc = ray.origin - centre;
    let b = ray.dir.dot(oc);
    let cc = oc.length_squared() - radius * radius;
    let disc = b * b - cc;
    if disc < 0.0 {
        return None;
    }
    let sq = disc.sqrt();
    let (t0, t1) = (-b - sq, -b + sq);
    if t1 < t_min || t0 > t_max {
        return None;
    }
    Some(t0.max(t_min))
}

/// The nearest hit in `[t_min, t_max]`; `hint` is the ray's cached surfel, tested first.
pub fn first_hit<V: Spheres>(
    v: &V,
    p: &PreparedSurfels,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    hint: Option<u32>,
    c: &mut SurfelCounters,
) -> Option<LeafHit> {
    let mut best: Option<LeafHit> = None;
    if let Some(s) = hint.filter(|&s| (s as usize) < p.surfels.len()) {
        best = intersect_leaf(p, ray, s as usize, t_min, t_max, c);
        c.cache_hits += best.is_some() as u64;
    }
    let mut stack = [(0u32, 0f32); STACK];
    let mut top = 0;
    c.sphere_tests += 1;
    let (rc, rr) = v.sphere(0, c);
    if let Some(t) = sphere_entry(ray, rc, rr, t_min, t_max) {
        stack[0] = (0, t);
        top = 1;
    }
    while top > 0 {
        top -= 1;
        let (n, entry) = stack[top];
        let limit = best.map_or(t_max, |b| b.t);
        if entry > limit {
            continue;
        }
        let node = v.node(n);
        if node.is_leaf() {
            if Some(node.kids[1]) == hint {
                continue;
            }
            if let Some(h) = intersect_leaf(p, ray, node.kids[1] as usize, t_min, limit, c) {
                if best.is_none_or(|b| h.before(&b)) {
                    best = Some(h);
                }
            }
            continue;
        }
        let mut kids = [(0u32, f32::INFINITY); 2];
        let mut count = 0;
        for k in node.kids {
            c.sphere_tests += 1;
            let (kc, kr) = v.sphere(k, c);
            if let Some(t) = sphere_entry(ray, kc, kr, t_min, limit) {
                kids[count] = (k, t);
                count += 1;
            }
        }
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

/// Some hit in `[t_min, t_max]`, the first found.
pub fn any_hit<V: Spheres>(
    v: &V,
    p: &PreparedSurfels,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    c: &mut SurfelCounters,
) -> Option<f32> {
    let mut stack = [0u32; STACK];
    stack[0] = 0;
    let mut top = 1;
    while top > 0 {
        top -= 1;
        let n = stack[top];
        c.sphere_tests += 1;
        let (sc, sr) = v.sphere(n, c);
        if sphere_entry(ray, sc, sr, t_min, t_max).is_none() {
            continue;
        }
        let node = v.node(n);
        if node.is_leaf() {
            if let Some(h) = intersect_leaf(p, ray, node.kids[1] as usize, t_min, t_max, c) {
                return Some(h.t);
            }
            continue;
        }
        // §4.4: if only one child is updated, it goes on top (is tried first).
        let [a, b] = node.kids;
        let (first, second) = if !v.updated(a) && v.updated(b) {
            (b, a)
        } else {
            (a, b)
        };
        if top + 2 <= STACK {
            stack[top] = second;
            stack[top + 1] = first;
            top += 2;
        }
    }
    None
}
