//! The metaball kind's side of the kind contract: the queries of [`PreparedKind`] answered by
//! the prepared Fitted BVH (or the structure the options chose) and the root finders.

use crate::camera::PrimaryRays;
use crate::kinds::contract::{OcclusionHint, PreparedKind, RayStart};
use crate::kinds::counters::SceneCounters;
use crate::kinds::metaballs::counters::MetaballCounters;
use crate::kinds::metaballs::engine::{PreparedMetaballs, FIRST_SHADOW_PACKET};
use crate::ray::{Hit, Ray};

impl PreparedKind for PreparedMetaballs {
    type Counters = MetaballCounters;

    #[inline]
    fn counters_in(all: &mut SceneCounters) -> &mut MetaballCounters {
        &mut all.metaballs
    }

    fn build_ms(&self) -> f64 {
        PreparedMetaballs::build_ms(self)
    }

    #[inline]
    fn first_hit(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut MetaballCounters,
    ) -> Option<Hit> {
        self.first_hit_counted(ray, t_min, t_max, isovalue, counters)
    }

    #[inline]
    fn any_hit(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut MetaballCounters,
    ) -> Option<f32> {
        self.any_hit_counted(ray, t_min, t_max, isovalue, counters)
    }

    #[inline]
    fn occluded(
        &self,
        ray: &Ray,
        span: (f32, f32),
        isovalue: f32,
        _start: RayStart,
        hint: &mut OcclusionHint,
        counters: &mut MetaballCounters,
    ) -> bool {
        self.occluded_counted(ray, span, isovalue, hint, counters)
    }

    /// The Fitted BVH's shadow packets towards a point or a directional light, where the rays
    /// (a tile's, for one light) are coherent enough to gain from packets
    /// ([`PreparedMetaballs::shadow_packet_pays`]); otherwise none, and the caller traces them
    /// one by one. Two packets, in the order given: the first [`FIRST_SHADOW_PACKET`] rays,
    /// whose roots leave witnesses in `hint`, then the rest, answered first by those
    /// witnesses ([`PreparedMetaballs::any_hits_packet_hinted`]: any_hit's own roots, or a
    /// point inside the solid for a witnessed ray).
    fn any_hits_towards(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: &[f32],
        light: Option<glam::Vec3>,
        isovalue: f32,
        _starts: &[RayStart],
        hint: &mut OcclusionHint,
        counters: &mut MetaballCounters,
    ) -> Option<Vec<Option<f32>>> {
        if t_max.len() != rays.len() || !self.shadow_packet_pays(rays, t_min) {
            return None;
        }
        let mut found = Vec::with_capacity(rays.len());
        let first = rays.len().min(FIRST_SHADOW_PACKET);
        let packets = [(0, first), (first, rays.len())];
        for (from, to) in packets.into_iter().filter(|(from, to)| from < to) {
            let packet = (&rays[from..to], t_min, &t_max[from..to], light);
            found.extend(self.any_hits_packet_hinted(packet, isovalue, hint, counters)?);
        }
        Some(found)
    }

    #[inline]
    fn exit_hit(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut MetaballCounters,
    ) -> Option<Hit> {
        self.exit_hit_counted(ray, t_min, t_max, isovalue, counters)
    }

    #[inline]
    fn crossings(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        inside: bool,
        max: usize,
        out: &mut Vec<Hit>,
        counters: &mut MetaballCounters,
    ) {
        self.crossings_counted(ray, t_min, t_max, isovalue, inside, max, out, counters)
    }

    #[inline]
    fn crossing_count(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        inside: bool,
        max: usize,
        counters: &mut MetaballCounters,
    ) -> usize {
        self.crossing_count_counted(ray, t_min, t_max, isovalue, inside, max, counters)
    }

    #[inline]
    fn optical_depth(&self, ray: &Ray, t_min: f32, t_max: f32) -> f32 {
        PreparedMetaballs::optical_depth(self, ray, t_min, t_max)
    }

    /// Metaballs trace a tile as one packet through the Fitted BVH
    /// ([`PreparedMetaballs::primary_tile_packet`]), or ray by ray where packets do not apply
    /// or are switched off.
    fn primary_tile(
        &self,
        rays: &PrimaryRays,
        (x0, y0, x1, y1): (u32, u32, u32, u32),
        isovalue: f32,
        t_max: f32,
        counters: &mut MetaballCounters,
    ) -> Vec<(Ray, Option<Hit>)> {
        let rect = (x0, y0, x1, y1);
        if let Some(hits) = self.primary_tile_packet(rays, rect, isovalue, t_max, counters) {
            return hits;
        }
        let (eye, width) = (rays.eye(), (x1 - x0) as usize);
        let mut tile_rays = Vec::with_capacity(width * (y1 - y0) as usize);
        for y in y0..y1 {
            rays.row_directions(y, x0, width, |_, dir, _| {
                tile_rays.push(Ray { origin: eye, dir })
            });
        }
        tile_rays
            .into_iter()
            .map(|ray| {
                let hit = self.first_hit_counted(&ray, 0.0, t_max, isovalue, counters);
                (ray, hit)
            })
            .collect()
    }
}
