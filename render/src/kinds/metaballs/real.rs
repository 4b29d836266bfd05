//! The scalar arithmetic the root finders need, for `f32` (rendering) and `f64` (the
//! reference).

use std::fmt::Debug;
use std::ops::{Add, Div, Mul, Neg, Sub};

/// The scalar arithmetic the finders need, for `f32` and `f64`.
pub trait Real:
    Copy
    + Debug
    + Default
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    fn of(v: f64) -> Self;
    fn to_f64(self) -> f64;
    fn sqrt(self) -> Self;
    fn abs(self) -> Self;
    fn min(self, o: Self) -> Self;
    fn max(self, o: Self) -> Self;
    /// The type's machine epsilon (the gap above 1).
    const EPSILON: Self;
    /// A key whose order is `(self, code)`'s: the numeric order of `self` (not NaN; `-0` and
    /// `+0` equal), then `code`. One integer comparison instead of a float comparison and a
    /// tie-break, for sorting a root search's entry/exit events.
    type EventKey: Ord + Copy + Debug + Default;
    fn event_key(self, code: u32) -> Self::EventKey;
    /// A key above the key of every value but NaN with a code below `u32::MAX`: "no event".
    const NO_EVENT: Self::EventKey;
    /// The value (`-0` read as `+0`) and code of an [`Real::event_key`].
    fn of_event_key(key: Self::EventKey) -> (Self, u32);
}

macro_rules! real {
    ($t:ty, $bits:ty, $key:ty) => {
        impl Real for $t {
            type EventKey = $key;
            const EPSILON: $t = <$t>::EPSILON;
            const NO_EVENT: $key = <$key>::MAX;
            #[inline(always)]
            fn event_key(self, code: u32) -> $key {
                const SIGN: $bits = 1 << (<$bits>::BITS - 1);
                // `+ 0.0` turns -0 into +0; negatives' bits flip, positives' gain the sign bit,
                // so that unsigned order is numeric order.
                let bits = (self + 0.0).to_bits();
                let ordered = if bits & SIGN != 0 { !bits } else { bits | SIGN };
                ((ordered as $key) << 32) | code as $key
            }
            #[inline(always)]
            fn of_event_key(key: $key) -> ($t, u32) {
                const SIGN: $bits = 1 << (<$bits>::BITS - 1);
                let ordered = (key >> 32) as $bits;
                let bits = if ordered & SIGN != 0 {
                    ordered & !SIGN
                } else {
                    !ordered
                };
                (<$t>::from_bits(bits), key as u32)
            }
            #[inline]
            fn of(v: f64) -> Self {
                v as $t
            }
            #[inline]
            fn to_f64(self) -> f64 {
                self as f64
            }
            #[inline]
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            #[inline]
            fn abs(self) -> Self {
                <$t>::abs(self)
            }
            #[inline]
            fn min(self, o: Self) -> Self {
                <$t>::min(self, o)
            }
            #[inline]
            fn max(self, o: Self) -> Self {
                <$t>::max(self, o)
            }
        }
    };
}
real!(f32, u32, u64);
real!(f64, u64, u128);

#[cfg(test)]
mod tests {
    use super::Real;
    use proptest::prelude::*;
    use std::cmp::Ordering;

    /// The order the root search sorted its events by before the keys.
    fn by_value_then_code<R: Real>(x: &(R, u32), y: &(R, u32)) -> Ordering {
        x.0.partial_cmp(&y.0)
            .unwrap_or(Ordering::Equal)
            .then(x.1.cmp(&y.1))
    }

    fn value() -> impl Strategy<Value = f64> {
        prop_oneof![
            Just(0.0),
            Just(-0.0),
            Just(f64::INFINITY),
            Just(f64::NEG_INFINITY),
            Just(f64::MIN_POSITIVE),
            -1e3f64..1e3,
            any::<f64>().prop_filter("not NaN", |v| !v.is_nan()),
        ]
    }

    proptest! {
        #[test]
        fn event_keys_order_pairs_as_value_then_code(
            pairs in prop::collection::vec((value(), 0u32..8), 0..40)
        ) {
            let doubles: Vec<(f64, u32)> = pairs.clone();
            let singles: Vec<(f32, u32)> = pairs.iter().map(|&(v, c)| (v as f32, c)).collect();
            for a in &doubles {
                for b in &doubles {
                    prop_assert_eq!(a.0.event_key(a.1).cmp(&b.0.event_key(b.1)), by_value_then_code(a, b));
                }
            }
            for &(v, c) in &doubles {
                prop_assert_eq!(f64::of_event_key(v.event_key(c)), (v + 0.0, c));
            }
            for &(v, c) in &singles {
                prop_assert_eq!(f32::of_event_key(v.event_key(c)), (v + 0.0, c));
            }
            for a in &singles {
                for b in &singles {
                    prop_assert_eq!(a.0.event_key(a.1).cmp(&b.0.event_key(b.1)), by_value_then_code(a, b));
                }
            }
        }
    }

    #[test]
    fn no_event_is_above_every_key_of_a_value() {
        assert!(f32::INFINITY.event_key(u32::MAX - 1) < f32::NO_EVENT);
        assert!(f64::INFINITY.event_key(u32::MAX - 1) < f64::NO_EVENT);
        assert!(f32::MAX.event_key(u32::MAX - 1) < f32::NO_EVENT);
    }
}
