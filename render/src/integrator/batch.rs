//! Hard shadow rays of a tile traced together: where a tile's camera rays spawn nothing but
//! hard shadow rays, a first shading pass records them, they are traced as packets towards
//! each light ([`PreparedScene::any_hits_towards`]), and the second pass takes their answers
//! in the order it asks. The image is the pixel-by-pixel one (checked by the CPU backend's
//! `effects_frames_from_tile_hits_are_the_pixel_by_pixel_frames`).

use super::Tracer;
use crate::geom::rng::PixelRng;
use crate::ray::{Hit, Ray};
#[cfg(doc)]
use crate::scene::PreparedScene;
use glam::Vec3;

/// The shadow rays of a tile: recorded by a first shading pass, traced together (as packets
/// towards each light where the kind has them), answered in order by the second pass.
#[derive(Debug, Default)]
pub(super) enum ShadowBatch {
    #[default]
    Off,
    Record(Vec<ShadowQuery>),
    /// The answers and the next one to give.
    Replay(Vec<(ShadowQuery, bool)>, usize),
}

/// One shadow ray over `[0, t_max]` towards `light`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct ShadowQuery {
    ray: Ray,
    t_max: f32,
    light: Option<Vec3>,
}

impl Tracer<'_> {
    /// Whether a tile's camera rays spawn nothing but hard shadow rays towards the lights (no
    /// reflection, refraction, layers, occlusion, soft shadows, further isosurfaces, volume
    /// or clip box), so that [`Tracer::primaries_from`] can trace those together.
    pub fn batches_shadows(&self) -> bool {
        let p = self.plan;
        self.takes_tile_hits()
            && p.shadows
            && !p.soft_shadows
            && p.reflection_depth == 0
            && p.refraction_depth == 0
            && p.layers == 0
            && p.ao_samples == 0
            && (!p.isosurfaces || self.lighting.isosurfaces.is_empty())
    }

    /// [`Tracer::primary_from`] for each camera ray of a tile (`hits` from the kind's tile
    /// query, `pixels` their pixels) in order. Where the camera rays spawn only hard shadow
    /// rays, a first shading pass records those, they are traced together (packets towards
    /// each light, [`PreparedScene::any_hits_towards`]), and the second pass takes their
    /// answers in the order it asks; the image is [`Tracer::primary`]'s.
    pub fn primaries_from(
        &mut self,
        hits: &[(Ray, Option<Hit>)],
        pixels: &[(u32, u32)],
        pass: u32,
    ) -> Vec<(Vec3, f32)> {
        if self.batches_shadows() {
            let counts = self.counts;
            self.batch = ShadowBatch::Record(Vec::new());
            for (&(ray, hit), &(x, y)) in hits.iter().zip(pixels) {
                self.primary_from(&ray, hit, &mut PixelRng::new(x, y, pass));
            }
            // The recording pass traced nothing (its shadow rays were only noted).
            self.counts = counts;
            if let ShadowBatch::Record(queries) = std::mem::take(&mut self.batch) {
                let answers = self.trace_shadows(&queries);
                self.batch = ShadowBatch::Replay(queries.into_iter().zip(answers).collect(), 0);
            }
        }
        let out = (hits.iter().zip(pixels))
            .map(|(&(ray, hit), &(x, y))| {
                self.primary_from(&ray, hit, &mut PixelRng::new(x, y, pass))
            })
            .collect();
        self.batch = ShadowBatch::Off;
        out
    }

    /// Whether each recorded shadow ray is blocked: rays towards one light in packets of 64
    /// (in the order recorded, so neighbouring pixels share a packet), each answer settled as
    /// [`Tracer::blocked`] settles a single ray's.
    fn trace_shadows(&mut self, queries: &[ShadowQuery]) -> Vec<bool> {
        let mut answers = vec![false; queries.len()];
        let mut lights: Vec<Option<Vec3>> = Vec::new();
        for q in queries {
            if !lights.contains(&q.light) {
                lights.push(q.light);
            }
        }
        let (mut rays, mut t_max, mut index) = (Vec::new(), Vec::new(), Vec::new());
        for light in lights {
            let of_light = (queries.iter().enumerate()).filter(|(_, q)| q.light == light);
            let all: Vec<usize> = of_light.map(|(i, _)| i).collect();
            for chunk in all.chunks(64) {
                rays.clear();
                t_max.clear();
                index.clear();
                for &i in chunk {
                    rays.push(queries[i].ray);
                    t_max.push(queries[i].t_max);
                    index.push(i);
                }
                let iso = self.isovalue;
                let found = (self.scene).any_hits_towards(
                    &rays,
                    0.0,
                    &t_max,
                    light,
                    iso,
                    &mut self.counters,
                );
                for (k, &i) in index.iter().enumerate() {
                    let (ray, hi) = (queries[i].ray, queries[i].t_max);
                    let root = match &found {
                        Some(found) => found[k],
                        None => {
                            (self.scene).any_hit_counted(&ray, 0.0, hi, iso, &mut self.counters)
                        }
                    };
                    answers[i] = self.settles(&ray, 0.0, hi, iso, root);
                }
            }
        }
        answers
    }

    /// The batch's answer for a shadow ray (recording: noted, and "not blocked" for now).
    pub(super) fn batched(&mut self, ray: &Ray, t_max: f32) -> Option<bool> {
        let query = ShadowQuery {
            ray: *ray,
            t_max,
            light: self.shadow_light,
        };
        match &mut self.batch {
            ShadowBatch::Off => None,
            ShadowBatch::Record(queries) => {
                queries.push(query);
                Some(false)
            }
            // An answer for another ray (never, by construction) is not used.
            ShadowBatch::Replay(answers, next) => {
                let answer = answers.get(*next).filter(|(q, _)| *q == query).map(|a| a.1);
                *next += 1;
                answer
            }
        }
    }
}
