//! Hard shadow rays of a tile traced together: where a tile's camera rays spawn nothing but
//! hard shadow rays, one shading pass takes every shadow ray as unblocked and notes it
//! ([`ShadowBatch::Record`]) along with the terms of each pixel's colour ([`Term`]); the
//! rays are traced as packets towards each light ([`trace_shadows`], through
//! [`PreparedScene::any_hits_towards`]), and a pixel with a blocked shadow ray has its
//! colour summed again from its terms without that light ([`resolve`]), in the order
//! shading sums them. The image is the pixel-by-pixel one (checked by the CPU backend's
//! `effects_frames_from_tile_hits_are_the_pixel_by_pixel_frames`).

use crate::kinds::contract::{OcclusionHint, RayStart};
use crate::kinds::counters::SceneCounters;
use crate::ray::Ray;
use crate::scene::PreparedScene;
use glam::Vec3;

/// The shadow rays of a tile, noted by its shading pass and traced together afterwards (as
/// packets towards each light where the kind has them).
#[derive(Debug, Default)]
pub enum ShadowBatch {
    #[default]
    Off,
    Record(Vec<ShadowQuery>),
}

/// One shadow ray over `[0, t_max]` towards `light` (a point, or `None`: directional), from
/// where `start` says.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowQuery {
    pub ray: Ray,
    pub t_max: f32,
    pub light: Option<Vec3>,
    pub start: RayStart,
}

impl ShadowBatch {
    /// Whether shading notes its shadow rays instead of tracing them.
    #[inline]
    pub fn is_recording(&self) -> bool {
        matches!(self, ShadowBatch::Record(_))
    }

    /// How many shadow rays have been noted.
    #[inline]
    pub fn noted(&self) -> usize {
        match self {
            ShadowBatch::Off => 0,
            ShadowBatch::Record(queries) => queries.len(),
        }
    }

    /// The answer for a shadow ray: `None` when no batch runs (trace it), "not blocked" while
    /// recording (it is noted, and [`resolve`] corrects the colour if it is blocked).
    pub fn answer(&mut self, query: ShadowQuery) -> Option<bool> {
        match self {
            ShadowBatch::Off => None,
            ShadowBatch::Record(queries) => {
                queries.push(query);
                Some(false)
            }
        }
    }
}

/// A term of a lit surface's colour while its shadow rays are noted, in the order shading
/// adds them: `emission + (ambient + light₁ + light₂ + …)`.
#[derive(Clone, Copy, Debug)]
pub enum Term {
    Emission(Vec3),
    Ambient(Vec3),
    /// A light's direct term as if unblocked, and the noted shadow ray it waits on (`None`:
    /// its visibility was known without one).
    Light(Option<usize>, Vec3),
}

/// Whether a pixel's colour needs [`resolve`]: one of its lights waits on a blocked ray.
pub fn any_blocked(terms: &[Term], blocked: &[bool]) -> bool {
    terms
        .iter()
        .any(|t| matches!(t, Term::Light(Some(q), _) if blocked[*q]))
}

/// A lit surface's colour from its `terms` with the `blocked` shadow rays' lights adding
/// nothing: the pixel-by-pixel shading's sums in its order (a blocked light's term is zero
/// there too, [`crate::shade::direct`] of visibility 0).
pub fn resolve(terms: &[Term], blocked: &[bool]) -> Vec3 {
    let (mut emission, mut local) = (Vec3::ZERO, Vec3::ZERO);
    for t in terms {
        match *t {
            Term::Emission(e) => emission = e,
            Term::Ambient(a) => local = a,
            Term::Light(q, value) => {
                local += if q.is_some_and(|q| blocked[q]) {
                    Vec3::ZERO
                } else {
                    value
                };
            }
        }
    }
    emission + local
}

/// Whether each shadow ray is blocked by the isosurface at `isovalue`: the rays towards one
/// light handed to the kind together with where each starts, in the order given (it packs
/// them, neighbouring pixels sharing a packet), each root settled as a single ray's is
/// ([`PreparedScene::settles`]); where the kind has no packet for them, ray by ray
/// ([`PreparedScene::occluded_counted`]). One hint serves the whole batch.
pub fn trace_shadows(
    scene: &PreparedScene,
    isovalue: f32,
    queries: &[ShadowQuery],
    counters: &mut SceneCounters,
) -> Vec<bool> {
    let mut answers = vec![false; queries.len()];
    let mut lights: Vec<Option<Vec3>> = Vec::new();
    for q in queries {
        if !lights.contains(&q.light) {
            lights.push(q.light);
        }
    }
    let (mut rays, mut t_max, mut starts) = (Vec::new(), Vec::new(), Vec::new());
    let mut hint = OcclusionHint::default();
    for light in lights {
        let of_light: Vec<usize> = (0..queries.len())
            .filter(|&i| queries[i].light == light)
            .collect();
        rays.clear();
        t_max.clear();
        starts.clear();
        rays.extend(of_light.iter().map(|&i| queries[i].ray));
        t_max.extend(of_light.iter().map(|&i| queries[i].t_max));
        starts.extend(of_light.iter().map(|&i| queries[i].start));
        let found = (scene).any_hits_towards(
            &rays, 0.0, &t_max, light, isovalue, &starts, &mut hint, counters,
        );
        for (k, &i) in of_light.iter().enumerate() {
            let (ray, span, start) = (&rays[k], (0.0, t_max[k]), starts[k]);
            answers[i] = match &found {
                Some(found) => scene.settles(ray, span, isovalue, found[k], counters),
                None => scene.occluded_counted(ray, span, isovalue, start, &mut hint, counters),
            };
        }
    }
    answers
}
