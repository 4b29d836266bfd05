//! The tet kind's side of the kind contract: the queries of [`PreparedKind`] answered by the
//! implicit min–max BVH of tetrahedral-isosurface-ray-tracing.txt, one isovalue at a time.

use crate::camera::PrimaryRays;
use crate::kinds::contract::PreparedKind;
use crate::kinds::counters::SceneCounters;
use crate::kinds::tets::counters::TetCounters;
use crate::kinds::tets::packet::{PacketScratch, RayPacket};
use crate::kinds::tets::prepared::PreparedTets;
use crate::kinds::tets::traverse::TetQuery;
use crate::ray::{Hit, Ray};

impl PreparedKind for PreparedTets {
    type Counters = TetCounters;

    #[inline]
    fn counters_in(all: &mut SceneCounters) -> &mut TetCounters {
        &mut all.tets
    }

    /// The BVH build (or refit) and the per-vertex shading data.
    fn build_ms(&self) -> f64 {
        PreparedTets::build_ms(self) + self.shading_ms()
    }

    /// The nearest crossing of one tet isosurface, as a shaded-ready hit.
    #[inline]
    fn first_hit(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut TetCounters,
    ) -> Option<Hit> {
        let q = TetQuery::single(isovalue);
        let hit = PreparedTets::first_hit(self, ray, t_min, t_max, &q, counters)?;
        Some(self.hit_record(ray, &hit, &q))
    }

    #[inline]
    fn any_hit(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut TetCounters,
    ) -> Option<f32> {
        let q = TetQuery::single(isovalue);
        PreparedTets::any_hit(self, ray, t_min, t_max, &q, counters).map(|h| h.t)
    }

    /// Every crossing of a tet isosurface is a surface (no root sits at the segment's start
    /// to mean "inside"), so the way out is the first crossing.
    #[inline]
    fn exit_hit(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalue: f32,
        counters: &mut TetCounters,
    ) -> Option<Hit> {
        <PreparedTets as PreparedKind>::first_hit(self, ray, t_min, t_max, isovalue, counters)
    }

    /// The tet paper renders isosurfaces only (§8.8): no density to absorb.
    fn optical_depth(&self, _ray: &Ray, _t_min: f32, _t_max: f32) -> f32 {
        0.0
    }

    /// Tets trace the tile as one packet (tetrahedral-isosurface-ray-tracing.txt §5.2).
    fn primary_tile(
        &self,
        rays: &PrimaryRays,
        rect: (u32, u32, u32, u32),
        isovalue: f32,
        t_max: f32,
        counters: &mut TetCounters,
    ) -> Vec<(Ray, Option<Hit>)> {
        let mut dirs = Vec::new();
        let packet = RayPacket::tile(rays, rect, &mut dirs);
        let mut hits = vec![None; packet.dirs.len()];
        let q = TetQuery::single(isovalue);
        let mut scratch = PacketScratch::default();
        self.first_hits_packet(&packet, 0.0, t_max, &q, &mut scratch, &mut hits, counters);
        packet
            .dirs
            .iter()
            .zip(hits)
            .map(|(&dir, hit)| {
                let ray = Ray {
                    origin: packet.origin,
                    dir,
                };
                (ray, hit.map(|h| self.hit_record(&ray, &h, &q)))
            })
            .collect()
    }
}
