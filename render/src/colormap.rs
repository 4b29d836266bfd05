//! Colour maps of a scalar value, as ParaView and VisIt offer them: a session may colour each
//! isosurface by its value through a chosen map over a chosen range (tetrahedral scenes colour
//! their isosurfaces by isovalue already, through the fixed map of
//! [`crate::kinds::tets::mesh::colormap`]; a [`ColorMap`] in [`crate::shade::Lighting`]
//! replaces it for that session only, and no map leaves every image as it was).
//!
//! How it works: each map is a list of evenly spaced sRGB stops (8-bit, as published for
//! matplotlib's viridis and inferno, Moreland's cool-warm, and a grey ramp), interpolated
//! linearly in sRGB, then converted to linear light for shading, so a lit surface shows the
//! colour the legend draws with the same stops.

use glam::Vec3;

/// The maps on offer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColorMapKind {
    Viridis,
    Inferno,
    CoolWarm,
    Grey,
}

impl ColorMapKind {
    /// Every map, in the order clients list them.
    pub const ALL: [ColorMapKind; 4] = [
        ColorMapKind::Viridis,
        ColorMapKind::Inferno,
        ColorMapKind::CoolWarm,
        ColorMapKind::Grey,
    ];

    /// The map's name on the wire.
    pub fn name(self) -> &'static str {
        match self {
            ColorMapKind::Viridis => "viridis",
            ColorMapKind::Inferno => "inferno",
            ColorMapKind::CoolWarm => "cool_warm",
            ColorMapKind::Grey => "grey",
        }
    }

    /// The map called `name`.
    pub fn from_name(name: &str) -> Option<ColorMapKind> {
        ColorMapKind::ALL.into_iter().find(|k| k.name() == name)
    }

    /// Evenly spaced sRGB stops from the low end to the high end.
    pub fn stops(self) -> &'static [[u8; 3]] {
        match self {
            ColorMapKind::Viridis => &[
                [0x44, 0x01, 0x54],
                [0x48, 0x28, 0x78],
                [0x3e, 0x49, 0x89],
                [0x31, 0x68, 0x8e],
                [0x26, 0x82, 0x8e],
                [0x1f, 0x9e, 0x89],
                [0x35, 0xb7, 0x79],
                [0x6e, 0xce, 0x58],
                [0xb5, 0xde, 0x2b],
                [0xfd, 0xe7, 0x25],
            ],
            ColorMapKind::Inferno => &[
                [0x00, 0x00, 0x04],
                [0x1b, 0x0c, 0x41],
                [0x4a, 0x0c, 0x6b],
                [0x78, 0x1c, 0x6d],
                [0xa5, 0x2c, 0x60],
                [0xcf, 0x44, 0x46],
                [0xed, 0x69, 0x25],
                [0xfb, 0x9b, 0x06],
                [0xf7, 0xd1, 0x3d],
                [0xfc, 0xff, 0xa4],
            ],
            ColorMapKind::CoolWarm => &[
                [0x3b, 0x4c, 0xc0],
                [0x67, 0x88, 0xee],
                [0x9a, 0xbb, 0xff],
                [0xc9, 0xd7, 0xf0],
                [0xed, 0xd1, 0xc2],
                [0xf7, 0xa8, 0x89],
                [0xe2, 0x69, 0x52],
                [0xb4, 0x04, 0x26],
            ],
            ColorMapKind::Grey => &[[0x00, 0x00, 0x00], [0xff, 0xff, 0xff]],
        }
    }
}

/// A map and the value range it spans: values below `lo` take the first stop, above `hi`
/// the last.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ColorMap {
    pub kind: ColorMapKind,
    pub lo: f32,
    pub hi: f32,
}

impl ColorMap {
    /// The linear-light albedo of `value` (NaN takes the low end).
    pub fn albedo(&self, value: f32) -> Vec3 {
        let stops = self.kind.stops();
        let span = self.hi - self.lo;
        let x = if span > 0.0 {
            (value - self.lo) / span
        } else {
            0.0
        };
        let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
        let f = x * (stops.len() - 1) as f32;
        let i = (f as usize).min(stops.len() - 2);
        let w = f - i as f32;
        let channel = |c: usize| {
            let srgb = stops[i][c] as f32 * (1.0 - w) + stops[i + 1][c] as f32 * w;
            srgb_code_to_linear(srgb)
        };
        Vec3::new(channel(0), channel(1), channel(2))
    }
}

/// An sRGB code in `[0, 255]`, not necessarily whole, to linear light (IEC 61966-2-1);
/// `shade::srgb8_to_linear` is this for whole codes.
pub fn srgb_code_to_linear(v: f32) -> f32 {
    let s = v / 255.0;
    if s <= 0.040_45 {
        s / 12.92
    } else {
        ((s + 0.055) / 1.055).powf(2.4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shade::srgb8_to_linear;

    #[test]
    fn ends_are_the_first_and_last_stops_and_names_round_trip() {
        for kind in ColorMapKind::ALL {
            assert_eq!(ColorMapKind::from_name(kind.name()), Some(kind));
            let map = ColorMap {
                kind,
                lo: -2.0,
                hi: 6.0,
            };
            let first = kind.stops()[0].map(srgb8_to_linear);
            let last = kind.stops()[kind.stops().len() - 1].map(srgb8_to_linear);
            assert_eq!(map.albedo(-2.0).to_array(), first);
            assert_eq!(map.albedo(-5.0).to_array(), first, "clamped below");
            assert_eq!(map.albedo(f32::NAN).to_array(), first);
            assert!((map.albedo(6.0) - Vec3::from(last)).abs().max_element() < 1e-6);
            assert_eq!(map.albedo(60.0), map.albedo(6.0), "clamped above");
        }
        assert_eq!(ColorMapKind::from_name("jet"), None);
    }

    #[test]
    fn grey_rises_with_the_value() {
        let map = ColorMap {
            kind: ColorMapKind::Grey,
            lo: 0.0,
            hi: 1.0,
        };
        let mut last = -1.0;
        for i in 0..=20 {
            let a = map.albedo(i as f32 / 20.0);
            assert!(a.x > last && a.x == a.y && a.y == a.z);
            last = a.x;
        }
        // Half way in sRGB is code 127.5: between codes 127 and 128 in linear light.
        let mid = map.albedo(0.5).x;
        assert!(mid > srgb8_to_linear(127) && mid < srgb8_to_linear(128));
    }
}
