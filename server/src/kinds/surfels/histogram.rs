//! A surfel step's histogram: surfels have no scalar field, so the values binned are the
//! simulation nodes' displacement lengths (what a step pushes).

use crate::kinds::histogram::Histogram;
use isoray_render::kinds::surfels::scene::SurfelScene;

pub fn displacement_histogram(scene: &SurfelScene, lo: f32, hi: f32, bins: usize) -> Histogram {
    let mut out = Histogram::empty(bins);
    let n = scene.displacement.len();
    out.grid = [u32::try_from(n).unwrap_or(u32::MAX), 1, 1];
    out.evaluations = n as u64;
    out.add(scene.displacement.iter().map(|u| u.length()), lo, hi);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat3, Vec3};
    use isoray_render::kinds::surfels::model::{SurfelModel, SurfelSet};
    use isoray_render::kinds::surfels::sample;
    use isoray_render::kinds::surfels::scene::{SurfelOptions, SurfelRuntime};
    use std::sync::Arc;

    #[test]
    fn bins_node_displacement_lengths() {
        let model = SurfelModel::new(
            SurfelSet {
                surfels: sample::sphere(Vec3::ZERO, 1.0, 100, Vec3::ONE, 0),
                nodes: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
                ..SurfelSet::default()
            },
            1000,
        )
        .expect("valid");
        let scene = SurfelScene::new(
            Arc::new(model),
            vec![Vec3::ZERO, Vec3::X * 0.5, Vec3::Y * 1.5].into(),
            vec![Mat3::ZERO; 3].into(),
            SurfelOptions::default(),
            Arc::new(SurfelRuntime::default()),
        )
        .expect("valid");
        let h = displacement_histogram(&scene, 0.0, 2.0, 4);
        assert_eq!(h.evaluations, 3);
        assert_eq!(h.counts, vec![1, 1, 0, 1]);
    }
}
