//! The foundation's root finder: sorted sphere intervals, fixed-step marching, bisection.
//!
//! How it works (metaballs-tutorial.txt, "Here's how it works"): intersect the ray with every
//! ball's sphere of support, keep the intervals, merge overlapping ones into spans, and march
//! each span from near to far with a step of a quarter of the smallest radius active in it,
//! evaluating the field over the balls whose interval overlaps the span. The first sign change
//! of `F - T` is refined by bisection to a relative tolerance of 1e-6. Marching finds every
//! stretch where `F > T` that is longer than a step; thinner slivers (grazing rays, isovalues
//! just below a ball's peak) can be missed, which the interval root finders do not do.

use super::{sphere_interval, MetaballScene};
use crate::ray::{Hit, Ray};

/// Bisection steps after a sign change: halves a step of R/4 down to R/4·2⁻²⁴.
const BISECTION_STEPS: u32 = 24;

pub fn first_hit(
    scene: &MetaballScene,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    isovalue: f32,
) -> Option<Hit> {
    let mut intervals: Vec<(f32, f32, u32)> = scene
        .balls
        .iter()
        .enumerate()
        .filter_map(|(i, b)| {
            let (t0, t1) = sphere_interval(ray, b.center, b.radius)?;
            let (t0, t1) = (t0.max(t_min), t1.min(t_max));
            (t0 < t1).then_some((t0, t1, i as u32))
        })
        .collect();
    if intervals.is_empty() {
        return None;
    }
    intervals.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.2.cmp(&b.2)));

    let mut active: Vec<u32> = Vec::new();
    let mut i = 0;
    while i < intervals.len() {
        // Gather one span: a maximal run of overlapping intervals.
        let span_start = intervals[i].0;
        let mut span_end = intervals[i].1;
        let mut min_radius = f32::INFINITY;
        active.clear();
        while i < intervals.len() && intervals[i].0 <= span_end {
            span_end = span_end.max(intervals[i].1);
            let ball = intervals[i].2;
            min_radius = min_radius.min(scene.balls[ball as usize].radius);
            active.push(ball);
            i += 1;
        }
        if let Some(hit) = march_span(
            scene, ray, &active, span_start, span_end, min_radius, isovalue,
        ) {
            return Some(hit);
        }
    }
    None
}

fn march_span(
    scene: &MetaballScene,
    ray: &Ray,
    active: &[u32],
    start: f32,
    end: f32,
    min_radius: f32,
    isovalue: f32,
) -> Option<Hit> {
    let step = min_radius * 0.25;
    let g = |t: f32| scene.field_at(active, ray.at(t)) - isovalue;
    let mut t0 = start;
    let mut g0 = g(t0);
    while t0 < end {
        let t1 = (t0 + step).min(end);
        let g1 = g(t1);
        if g0 < 0.0 && g1 >= 0.0 {
            let (mut lo, mut hi) = (t0, t1);
            for _ in 0..BISECTION_STEPS {
                let mid = 0.5 * (lo + hi);
                if g(mid) < 0.0 {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let t = hi;
            let position = ray.at(t);
            let (normal, albedo) = scene.surface_at(active, position);
            return Some(Hit {
                t,
                position,
                normal,
                albedo,
            });
        }
        t0 = t1;
        g0 = g1;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::super::{Kernel, Metaball, MetaballScene};
    use crate::ray::Ray;
    use glam::Vec3;

    #[test]
    fn single_ball_hit_matches_the_analytic_radius() {
        // One Wyvill ball of radius 2 at T = 0.5 is a sphere of radius 1 (f(R/2) = 1/2).
        let scene = MetaballScene {
            kernel: Kernel::Wyvill,
            balls: vec![Metaball {
                center: Vec3::ZERO,
                radius: 2.0,
                strength: 1.0,
                color: Vec3::ONE,
            }],
        };
        let ray = Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z);
        let hit = scene
            .first_hit(&ray, 0.0, 100.0, 0.5)
            .expect("the ray hits the ball");
        assert!((hit.t - 4.0).abs() < 1e-4, "t = {}", hit.t);
        assert!((hit.normal - Vec3::Z).length() < 1e-4);
        let miss = Ray::new(Vec3::new(0.0, 1.5, 5.0), Vec3::NEG_Z);
        assert!(scene.first_hit(&miss, 0.0, 100.0, 0.5).is_none());
    }
}
