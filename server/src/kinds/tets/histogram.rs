//! A tetrahedral mesh's histogram: its scalar field is given at the mesh's vertices, so the
//! histogram bins those values (the point data histogram ParaView shows).

use crate::kinds::histogram::Histogram;

/// The scalars at the mesh's vertices, binned over `[lo, hi)`; `grid` is `[vertices, 1, 1]`.
pub fn vertex_histogram(scalars: &[f32], lo: f32, hi: f32, bins: usize) -> Histogram {
    let mut out = Histogram::empty(bins);
    out.grid = [u32::try_from(scalars.len()).unwrap_or(u32::MAX), 1, 1];
    out.evaluations = scalars.len() as u64;
    out.add(scalars.iter().copied(), lo, hi);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vertex_values_are_binned_with_the_outliers_counted() {
        let h = vertex_histogram(&[0.0, 0.1, 0.26, 0.5, 0.99, 1.0, -3.0], 0.0, 1.0, 4);
        assert_eq!(h.counts, vec![2, 1, 1, 1]);
        assert_eq!((h.below, h.above, h.samples), (1, 1, 7));
    }
}
