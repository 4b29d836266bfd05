//! Hard shadow rays of a tile traced together: where a tile's camera rays spawn nothing but
//! hard shadow rays, a first shading pass records them ([`ShadowBatch::Record`]), they are
//! traced as packets towards each light ([`trace_shadows`], through
//! [`PreparedScene::any_hits_towards`]), and the second pass takes their answers in the
//! order it asks ([`ShadowBatch::Replay`]). The image is the pixel-by-pixel one (checked by
//! the CPU backend's `effects_frames_from_tile_hits_are_the_pixel_by_pixel_frames`).

use crate::kinds::counters::SceneCounters;
use crate::ray::{Ray, INSIDE_EPS};
use crate::scene::PreparedScene;
use glam::Vec3;

/// The shadow rays of a tile: recorded by a first shading pass, traced together (as packets
/// towards each light where the kind has them), answered in order by the second pass.
#[derive(Debug, Default)]
pub enum ShadowBatch {
    #[default]
    Off,
    Record(Vec<ShadowQuery>),
    /// The answers and the next one to give.
    Replay(Vec<(ShadowQuery, bool)>, usize),
}

/// One shadow ray over `[0, t_max]` towards `light` (a point, or `None`: directional).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowQuery {
    pub ray: Ray,
    pub t_max: f32,
    pub light: Option<Vec3>,
}

impl ShadowBatch {
    /// Whether shading is the first pass, which only notes the shadow rays.
    #[inline]
    pub fn is_recording(&self) -> bool {
        matches!(self, ShadowBatch::Record(_))
    }

    /// The answer for a shadow ray: `None` when no batch runs (trace it), "not blocked" while
    /// recording (it is noted), and the traced answer when replaying (an answer recorded for
    /// another ray, never the case by construction, is not used).
    pub fn answer(&mut self, query: ShadowQuery) -> Option<bool> {
        match self {
            ShadowBatch::Off => None,
            ShadowBatch::Record(queries) => {
                queries.push(query);
                Some(false)
            }
            ShadowBatch::Replay(answers, next) => {
                let answer = answers.get(*next).filter(|(q, _)| *q == query).map(|a| a.1);
                *next += 1;
                answer
            }
        }
    }
}

/// Whether each shadow ray is blocked by the isosurface at `isovalue`: rays towards one light
/// in packets of 64 (in the order given, so neighbouring pixels share a packet), each root
/// settled by [`settles`] as a single ray's is.
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
    let (mut rays, mut t_max) = (Vec::new(), Vec::new());
    for light in lights {
        let of_light: Vec<usize> = (0..queries.len())
            .filter(|&i| queries[i].light == light)
            .collect();
        for chunk in of_light.chunks(64) {
            rays.clear();
            t_max.clear();
            rays.extend(chunk.iter().map(|&i| queries[i].ray));
            t_max.extend(chunk.iter().map(|&i| queries[i].t_max));
            let found = scene.any_hits_towards(&rays, 0.0, &t_max, light, isovalue, counters);
            for (k, &i) in chunk.iter().enumerate() {
                let (ray, hi) = (&rays[k], t_max[k]);
                let root = match &found {
                    Some(found) => found[k],
                    None => scene.any_hit_counted(ray, 0.0, hi, isovalue, counters),
                };
                answers[i] = settles(scene, ray, (0.0, hi), isovalue, root, counters);
            }
        }
    }
    answers
}

/// Whether `[lo, hi]` of `ray` is blocked, given the any-hit query's `root` on it.
pub fn settles(
    scene: &PreparedScene,
    ray: &Ray,
    (lo, hi): (f32, f32),
    isovalue: f32,
    root: Option<f32>,
    counters: &mut SceneCounters,
) -> bool {
    match root {
        None => false,
        Some(t) if t > lo + INSIDE_EPS => true,
        // Starting inside the solid: its boundary blocks if the ray leaves it here.
        Some(_) => scene
            .exit_hit_counted(ray, lo, hi, isovalue, counters)
            .is_some(),
    }
}
