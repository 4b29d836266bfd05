//! The radial falloffs a metaball set can use, all finite-support polynomials in `s = r²/R²`.
//!
//! How it works: every kernel here is a polynomial in `w = 1 - s` on `s ∈ [0, 1]` and zero
//! beyond, which is what lets the Bézier-clipping root finder (bezier-clipping-metaballs.txt
//! §3.2) express each ball's field along a ray exactly as a Bernstein polynomial:
//! - Wyvill's degree six (bezier-clipping-metaballs.txt eq. 4): `1 - 22/9 s + 17/9 s² - 4/9 s³
//!   = 5/9 w² + 4/9 w³`;
//! - Murakami's degree four (ibid. eq. 3, POV-Ray's blob): `(1 - s)² = w²`;
//! - the family `(1 - r²/R²)^α` of fitted-bvh-metaballs.txt §2.1: `w^α`, integer `α` in 1..=4;
//! - the tutorial's `g(r) = r⁴ - r² + 0.25` (metaballs-tutorial.txt §III) with its support
//!   `0.707` scaled to `R`, i.e. `r_tut² = s/2`: `s²/4 - s/2 + 1/4 = w²/4`.

use crate::kinds::metaballs::real::Real;

/// Highest power of `w` any kernel uses (`Power { alpha: 4 }`).
pub const MAX_W_DEGREE: usize = 4;

/// The radial falloff shared by every ball of a set.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// Wyvill, McPheeters and Wyvill's degree-six polynomial in `r/R`.
    Wyvill,
    /// Murakami's `(1 - r²/R²)²`, the same field as POV-Ray's blob.
    Quartic,
    /// `(1 - r²/R²)^alpha` (fitted-bvh-metaballs.txt §2.1), `alpha` in `1..=4`.
    Power { alpha: u8 },
    /// Geiss's `r⁴ - r² + 0.25` with its support stretched to the ball's radius.
    Tutorial,
}

impl Kernel {
    /// Every kernel, with each `Power` exponent, for tests and benchmarks.
    pub const ALL: [Kernel; 7] = [
        Kernel::Wyvill,
        Kernel::Quartic,
        Kernel::Power { alpha: 1 },
        Kernel::Power { alpha: 2 },
        Kernel::Power { alpha: 3 },
        Kernel::Power { alpha: 4 },
        Kernel::Tutorial,
    ];

    /// Whether the kernel's parameters are in range (`alpha` in `1..=4`).
    pub fn is_supported(self) -> bool {
        match self {
            Kernel::Power { alpha } => (1..=MAX_W_DEGREE as u8).contains(&alpha),
            _ => true,
        }
    }

    /// Coefficients `c_k` of `f = Σ c_k w^k`, `w = 1 - s`, `k = 0..=4`.
    pub fn w_coefficients(self) -> [f64; MAX_W_DEGREE + 1] {
        match self {
            Kernel::Wyvill => [0.0, 0.0, 5.0 / 9.0, 4.0 / 9.0, 0.0],
            Kernel::Quartic => [0.0, 0.0, 1.0, 0.0, 0.0],
            Kernel::Tutorial => [0.0, 0.0, 0.25, 0.0, 0.0],
            Kernel::Power { alpha } => {
                let mut c = [0.0; MAX_W_DEGREE + 1];
                c[(alpha as usize).clamp(1, MAX_W_DEGREE)] = 1.0;
                c
            }
        }
    }

    /// Highest power of `w` with a non-zero coefficient.
    pub fn w_degree(self) -> usize {
        let c = self.w_coefficients();
        (0..=MAX_W_DEGREE).rev().find(|&k| c[k] != 0.0).unwrap_or(0)
    }

    /// The kernel at `s = r² / R²`, for `s` in `[0, 1]`; zero beyond.
    #[inline]
    pub fn value(self, s: f32) -> f32 {
        if s >= 1.0 {
            return 0.0;
        }
        let w = 1.0 - s;
        match self {
            Kernel::Wyvill => w * w * (5.0 / 9.0 + w * (4.0 / 9.0)),
            Kernel::Quartic => w * w,
            Kernel::Tutorial => 0.25 * w * w,
            Kernel::Power { alpha } => match alpha {
                1 => w,
                2 => w * w,
                3 => w * w * w,
                _ => (w * w) * (w * w),
            },
        }
    }

    /// The kernel in double precision, for the reference root finder.
    pub fn value_f64(self, s: f64) -> f64 {
        if s >= 1.0 {
            return 0.0;
        }
        let w = 1.0 - s;
        let c = self.w_coefficients();
        c.iter().rev().fold(0.0, |acc, &ck| acc * w + ck)
    }

    /// `df/ds` at `s`, zero beyond the support.
    #[inline]
    pub fn derivative(self, s: f32) -> f32 {
        if s >= 1.0 {
            return 0.0;
        }
        let w = 1.0 - s;
        // df/ds = -df/dw.
        -match self {
            Kernel::Wyvill => w * (10.0 / 9.0 + w * (12.0 / 9.0)),
            Kernel::Quartic => 2.0 * w,
            Kernel::Tutorial => 0.5 * w,
            Kernel::Power { alpha } => match alpha {
                1 => 1.0,
                2 => 2.0 * w,
                3 => 3.0 * w * w,
                _ => 4.0 * w * w * w,
            },
        }
    }

    /// The kernel's value at the centre, its maximum.
    pub fn peak(self) -> f32 {
        self.value(0.0)
    }

    /// `max |df/dρ|` over `ρ = r/R ∈ [0, 1]`: the Lipschitz constant of one unit ball in
    /// units of `1/R`, used by sphere tracing. Sampled finely, with a 1% margin.
    pub fn max_slope(self) -> f32 {
        let steps = 4096;
        let mut max = 0.0f64;
        for i in 0..=steps {
            let rho = i as f64 / steps as f64;
            let s = rho * rho;
            let w = 1.0 - s;
            let c = self.w_coefficients();
            // df/dw, then df/dρ = df/dw · dw/dρ = -2ρ df/dw.
            let dfdw: f64 = (1..=MAX_W_DEGREE)
                .map(|k| k as f64 * c[k] * w.powi(k as i32 - 1))
                .sum();
            max = max.max((2.0 * rho * dfdw).abs());
        }
        (max * 1.01) as f32
    }

    /// The `s` in `[0, 1]` at which the kernel equals `value` (it decreases monotonically);
    /// 0 for values above the peak, 1 for values at or below zero.
    pub fn s_at_value(self, value: f32) -> f32 {
        if value <= 0.0 {
            return 1.0;
        }
        if value >= self.peak() {
            return 0.0;
        }
        let (mut lo, mut hi) = (0.0f64, 1.0f64);
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            if self.value_f64(mid) > value as f64 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        hi as f32
    }
}

/// A kernel as `Σ c_k w^k`, in the finder's precision.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KernelPoly<R> {
    pub c: [R; MAX_W_DEGREE + 1],
    pub degree: usize,
}

impl<R: Real> KernelPoly<R> {
    pub fn new(kernel: Kernel) -> Self {
        let c64 = kernel.w_coefficients();
        let mut c = [R::default(); MAX_W_DEGREE + 1];
        for (d, s) in c.iter_mut().zip(c64) {
            *d = R::of(s);
        }
        KernelPoly {
            c,
            degree: kernel.w_degree(),
        }
    }

    #[inline]
    pub fn at_w(&self, w: R) -> R {
        self.at_w_of::<0>(w)
    }

    /// [`KernelPoly::at_w`] with the degree `W` a constant the loop unrolls to (0: the
    /// kernel's own degree, read at run time); the same Horner steps either way.
    #[inline(always)]
    pub(crate) fn at_w_of<const W: usize>(&self, w: R) -> R {
        let degree = if W == 0 { self.degree } else { W };
        let mut acc = self.c[degree];
        let mut k = degree;
        while k > 0 {
            k -= 1;
            acc = acc * w + self.c[k];
        }
        acc
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wyvill_kernel_has_its_defining_values() {
        let k = Kernel::Wyvill;
        assert!((k.value(0.0) - 1.0).abs() < 1e-6);
        assert!(k.value(1.0).abs() < 1e-6);
        assert!((k.value(0.25) - 0.5).abs() < 1e-6, "f(R/2) = 1/2");
        assert!(
            k.derivative(1.0 - 1e-7).abs() < 1e-5,
            "flat at the support boundary"
        );
        // The w-form agrees with the seed's power form.
        for i in 0..=10 {
            let s = i as f32 / 10.0;
            let seed = 1.0 + s * (-22.0 / 9.0 + s * (17.0 / 9.0 - s * (4.0 / 9.0)));
            assert!((k.value(s) - seed).abs() < 1e-6);
        }
    }

    #[test]
    fn tutorial_kernel_is_geiss_polynomial_scaled_to_the_radius() {
        for i in 0..=10 {
            let s = i as f32 / 10.0;
            let r = (s / 2.0).sqrt(); // the tutorial's r, support 0.707
            let geiss = r.powi(4) - r * r + 0.25;
            assert!((Kernel::Tutorial.value(s) - geiss).abs() < 1e-6);
        }
    }

    #[test]
    fn derivatives_match_finite_differences_and_inverse_works() {
        for k in Kernel::ALL {
            for i in 1..10 {
                let s = i as f32 / 10.0;
                let fd = (k.value(s + 1e-3) - k.value(s - 1e-3)) / 2e-3;
                assert!((fd - k.derivative(s)).abs() < 1e-2, "{k:?} at {s}");
                let v = k.value(s);
                assert!((k.s_at_value(v) - s).abs() < 1e-4, "{k:?} inverse at {s}");
            }
            assert!(k.max_slope() > 0.0);
        }
    }
}
