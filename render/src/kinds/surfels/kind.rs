//! The surfel kind's side of the kind contract: the queries of [`PreparedKind`] answered by
//! the lazily updated sphere hierarchy of deforming-point-sampled-surfaces.txt. Primary rays
//! go through the per-pixel sphere-node cache (§4.2.2) when the scene enables it.

use crate::camera::PrimaryRays;
use crate::kinds::contract::{settle, OcclusionHint, PreparedKind, RayStart};
use crate::kinds::counters::SceneCounters;
use crate::kinds::surfels::counters::SurfelCounters;
use crate::kinds::surfels::intersect::{LeafHit, Search, NEAREST, NEAREST_LEAVING, RESCUE};
use crate::kinds::surfels::prepared::{Accel, PreparedSurfels};
use crate::kinds::surfels::scene::SurfelRuntime;
use crate::kinds::surfels::traverse::{self, FixedView, LazyView};
use crate::ray::{Hit, Ray};

impl PreparedSurfels {
    /// The nearest hit, starting from `hint` (a cached surfel) if given.
    #[inline]
    pub fn nearest(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        hint: Option<u32>,
        c: &mut SurfelCounters,
    ) -> Option<LeafHit> {
        self.nearest_as(ray, (t_min, t_max), hint, NEAREST, c)
    }

    /// A camera ray's nearest hit: [`PreparedSurfels::nearest`] from `0`, and where that
    /// hit faces away from the ray (the ray seems to leave the object without having entered
    /// it: where the surface bends sharply or is met at a grazing angle the start gate can
    /// turn away every leaf of the front, and the back showed through as a dark crack), the
    /// crossing into the object before it, from a second search ([`RESCUE`]), if there is
    /// one. Both searches depend on the ray alone, so every traversal agrees.
    #[inline]
    pub fn camera_nearest(
        &self,
        ray: &Ray,
        t_max: f32,
        hint: Option<u32>,
        c: &mut SurfelCounters,
    ) -> Option<LeafHit> {
        let hit = self.nearest(ray, 0.0, t_max, hint, c);
        self.rescued(ray, hit, c)
    }

    /// [`PreparedSurfels::camera_nearest`]'s second search, for a first search's `hit`.
    #[inline]
    pub fn rescued(
        &self,
        ray: &Ray,
        hit: Option<LeafHit>,
        c: &mut SurfelCounters,
    ) -> Option<LeafHit> {
        match hit {
            Some(h) if h.normal.dot(ray.dir) > 0.0 => {
                c.rescues += 1;
                self.traverse(ray, (0.0, h.t), (None, RESCUE), c).or(hit)
            }
            _ => hit,
        }
    }

    /// [`PreparedSurfels::nearest`] as `search` asks.
    #[inline]
    pub fn nearest_as(
        &self,
        ray: &Ray,
        span: (f32, f32),
        hint: Option<u32>,
        search: Search,
        c: &mut SurfelCounters,
    ) -> Option<LeafHit> {
        c.rays += 1;
        let hit = self.traverse(ray, span, (hint, search), c);
        c.hits += hit.is_some() as u64;
        hit
    }

    /// [`PreparedKind::any_hit`] over `span`, counted; a ray [`RayStart::Leaving`] a surfel
    /// of a closed object skips the nodes of that surfel's body whose hits all face away from
    /// it ([`crate::kinds::surfels::cones`]).
    #[inline]
    pub fn any_hit_from(
        &self,
        ray: &Ray,
        span: (f32, f32),
        start: RayStart,
        c: &mut SurfelCounters,
    ) -> Option<f32> {
        c.rays += 1;
        let before = c.sphere_tests + c.surfel_tests;
        let outside = self.outside_of(start);
        let hit = match &self.accel {
            Accel::Lazy(nodes) => {
                let v = LazyView { p: self, nodes };
                traverse::any_hit(&v, self, ray, span, outside, c)
            }
            Accel::Fixed(nodes) => {
                traverse::any_hit(&FixedView(nodes), self, ray, span, outside, c)
            }
        };
        c.hits += hit.is_some() as u64;
        c.any_rays += 1;
        c.any_tests += c.sphere_tests + c.surfel_tests - before;
        hit
    }

    /// [`traverse::first_hit`] over this frame's tree.
    #[inline]
    fn traverse(
        &self,
        ray: &Ray,
        span: (f32, f32),
        asked: (Option<u32>, Search),
        c: &mut SurfelCounters,
    ) -> Option<LeafHit> {
        match &self.accel {
            Accel::Lazy(nodes) => {
                let v = LazyView { p: self, nodes };
                traverse::first_hit(&v, self, ray, span, asked, c)
            }
            Accel::Fixed(nodes) => {
                traverse::first_hit(&FixedView(nodes), self, ray, span, asked, c)
            }
        }
    }

    #[inline]
    fn record(&self, h: LeafHit) -> Hit {
        Hit {
            t: h.t,
            position: h.position,
            normal: h.normal,
            albedo: h.colour(self),
            primitive: h.surfel,
        }
    }
}

impl PreparedKind for PreparedSurfels {
    type Counters = SurfelCounters;

    #[inline]
    fn counters_in(all: &mut SceneCounters) -> &mut SurfelCounters {
        &mut all.surfels
    }

    /// The rigid frame and, for eager or rebuild, the whole update.
    fn build_ms(&self) -> f64 {
        PreparedSurfels::build_ms(self)
    }

    #[inline]
    fn first_hit(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        _isovalue: f32,
        c: &mut SurfelCounters,
    ) -> Option<Hit> {
        // A camera ray of the effects integrator (no pixel here) starts at 0: it is searched
        // again where its hit faces away (`camera_nearest`), and with the cache on its last
        // nearest surfel is tested first (§4.2.2; the image is the same).
        if t_min != 0.0 {
            return self
                .nearest(ray, t_min, t_max, None, c)
                .map(|h| self.record(h));
        }
        if !self.options.cache {
            return self
                .camera_nearest(ray, t_max, None, c)
                .map(|h| self.record(h));
        }
        let key = SurfelRuntime::ray_key(ray);
        let hit = self.camera_nearest(ray, t_max, self.runtime.cached_ray(key), c);
        self.runtime.remember_ray(key, hit.map(|h| h.surfel));
        hit.map(|h| self.record(h))
    }

    /// A mirror ray from outside passes over a crossing out of the surface near its start
    /// (`intersect::OUTWARD`).
    #[inline]
    fn first_hit_leaving(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        _isovalue: f32,
        c: &mut SurfelCounters,
    ) -> Option<Hit> {
        self.nearest_as(ray, (t_min, t_max), None, NEAREST_LEAVING, c)
            .map(|h| self.record(h))
    }

    #[inline]
    fn any_hit(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        _isovalue: f32,
        c: &mut SurfelCounters,
    ) -> Option<f32> {
        self.any_hit_from(ray, (t_min, t_max), RayStart::Unknown, c)
    }

    /// [`PreparedKind::any_hit`], a ray from outside skipping what faces away from it.
    #[inline]
    fn occluded(
        &self,
        ray: &Ray,
        span: (f32, f32),
        isovalue: f32,
        start: RayStart,
        _hint: &mut OcclusionHint,
        c: &mut SurfelCounters,
    ) -> bool {
        let root = self.any_hit_from(ray, span, start, c);
        settle(self, ray, span, isovalue, root, c)
    }

    /// Packets of up to 64 rays ([`traverse::any_hits`]) whatever the light: `Some` exactly
    /// where [`PreparedKind::occluded`] finds a hit (perhaps another one: a sheet's way out
    /// is any later hit, so the integrator decides the same).
    fn any_hits_towards(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: &[f32],
        _light: Option<glam::Vec3>,
        _isovalue: f32,
        starts: &[RayStart],
        _hint: &mut OcclusionHint,
        c: &mut SurfelCounters,
    ) -> Option<Vec<Option<f32>>> {
        if t_max.len() != rays.len() {
            return None;
        }
        let mut out = vec![None; rays.len()];
        let mut outside: Vec<Option<u16>> = starts.iter().map(|&s| self.outside_of(s)).collect();
        outside.resize(rays.len(), None);
        let before = c.sphere_tests + c.surfel_tests;
        for (k, chunk) in rays.chunks(traverse::PACKET).enumerate() {
            let at = k * traverse::PACKET;
            let (hi, found) = (&t_max[at..], &mut out[at..at + chunk.len()]);
            let outside = &outside[at..at + chunk.len()];
            match &self.accel {
                Accel::Lazy(nodes) => {
                    let v = LazyView { p: self, nodes };
                    traverse::any_hits(&v, self, chunk, t_min, hi, outside, found, c);
                }
                Accel::Fixed(nodes) => {
                    let v = FixedView(nodes);
                    traverse::any_hits(&v, self, chunk, t_min, hi, outside, found, c);
                }
            }
        }
        let n = rays.len() as u64;
        c.rays += n;
        c.hits += out.iter().filter(|h| h.is_some()).count() as u64;
        c.any_rays += n;
        c.any_tests += c.sphere_tests + c.surfel_tests - before;
        Some(out)
    }

    /// A surfel surface is a sheet: the way out of a closed object is its next crossing.
    #[inline]
    fn exit_hit(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        c: &mut SurfelCounters,
    ) -> Option<Hit> {
        let _ = isovalue;
        self.nearest(ray, t_min, t_max, None, c)
            .map(|h| self.record(h))
    }

    /// Surfels have no density.
    fn optical_depth(&self, _ray: &Ray, _t_min: f32, _t_max: f32) -> f32 {
        0.0
    }

    /// In 8×8 packets ([`traverse::first_hits`]), a ray whose hit faces away searched again
    /// on its own ([`PreparedSurfels::rescued`]); with the cache on, each pixel's last
    /// nearest surfel is tested first and this frame's is remembered (the image is the same
    /// either way, and the same as ray by ray).
    fn primary_tile(
        &self,
        rays: &PrimaryRays,
        rect: (u32, u32, u32, u32),
        _isovalue: f32,
        t_max: f32,
        c: &mut SurfelCounters,
    ) -> Vec<(Ray, Option<Hit>)> {
        const SIDE: u32 = 8;
        let (x0, y0, x1, y1) = rect;
        let width = (x1 - x0) as usize;
        let mut out = vec![(Ray::new(rays.eye(), glam::Vec3::Z), None); width * (y1 - y0) as usize];
        let cache = self.options.cache;
        let (mut packet, mut hints, mut pixels) = (Vec::new(), Vec::new(), Vec::new());
        let mut hits = [None; traverse::PACKET];
        let mut entries: Box<traverse::Entries> =
            Box::new([[0.0; traverse::PACKET]; traverse::STACK]);
        let eye = rays.eye();
        for by in (y0..y1).step_by(SIDE as usize) {
            for bx in (x0..x1).step_by(SIDE as usize) {
                packet.clear();
                hints.clear();
                pixels.clear();
                let bx1 = (bx + SIDE).min(x1);
                for y in by..(by + SIDE).min(y1) {
                    rays.row_directions(y, bx, (bx1 - bx) as usize, |_, dir, _| {
                        packet.push(Ray { origin: eye, dir })
                    });
                    for x in bx..bx1 {
                        hints.push(if cache {
                            self.runtime.cached(x, y)
                        } else {
                            None
                        });
                        pixels.push((x, y));
                    }
                }
                c.rays += packet.len() as u64;
                let found = (&mut hits[..], &mut *entries);
                match &self.accel {
                    Accel::Lazy(nodes) => {
                        let v = LazyView { p: self, nodes };
                        traverse::first_hits(&v, self, &packet, t_max, &hints, found, c);
                    }
                    Accel::Fixed(nodes) => {
                        let v = FixedView(nodes);
                        traverse::first_hits(&v, self, &packet, t_max, &hints, found, c);
                    }
                }
                for (k, &(x, y)) in pixels.iter().enumerate() {
                    let hit = self.rescued(&packet[k], hits[k], c);
                    c.hits += hit.is_some() as u64;
                    if cache {
                        self.runtime.remember(x, y, hit.map(|h| h.surfel));
                    }
                    let at = (y - y0) as usize * width + (x - x0) as usize;
                    out[at] = (packet[k], hit.map(|h| self.record(h)));
                }
            }
        }
        out
    }
}
