//! Small shared pieces of the surfel kind: the compactly supported weight of eq. 2
//! (deforming-point-sampled-surfaces.txt), a 3×2 matrix's largest singular value, and
//! compressed rows.

use glam::Vec3;

/// The weight of eq. 2, `1 − 6r² + 8r³ − 3r⁴` for `r ≤ 1`, else 0.
#[inline]
pub fn weight(r: f32) -> f32 {
    if r >= 1.0 {
        0.0
    } else {
        let r2 = r * r;
        1.0 - 6.0 * r2 + 8.0 * r2 * r - 3.0 * r2 * r2
    }
}

/// Largest singular value of the 3×2 matrix `[a b]`.
#[inline]
pub fn sigma_max(a: Vec3, b: Vec3) -> f32 {
    let (p, q, r) = (a.length_squared(), a.dot(b), b.length_squared());
    let h = 0.5 * (p + r);
    let d = (0.25 * (p - r) * (p - r) + q * q).sqrt();
    (h + d).max(0.0).sqrt()
}

/// Compressed rows: row `i` is `items[start[i]..start[i + 1]]`.
#[derive(Clone, Debug)]
pub struct Rows<T> {
    pub start: Vec<u32>,
    pub items: Vec<T>,
}

impl<T> Default for Rows<T> {
    fn default() -> Self {
        Rows {
            start: vec![0],
            items: Vec::new(),
        }
    }
}

impl<T> Rows<T> {
    pub fn from_rows(rows: impl IntoIterator<Item = Vec<T>>) -> Rows<T> {
        let mut out = Rows {
            start: vec![0],
            items: Vec::new(),
        };
        for r in rows {
            out.items.extend(r);
            out.start.push(out.items.len() as u32);
        }
        out
    }

    #[inline]
    pub fn row(&self, i: usize) -> &[T] {
        &self.items[self.start[i] as usize..self.start[i + 1] as usize]
    }
}
