//! Built-in, deterministic, animated scenes: a pure function of time, no files, no randomness
//! beyond a fixed-seed generator, so every run and every thread count sees the same states.

use crate::camera::Camera;
use crate::metaball::{Kernel, Metaball, MetaballScene};
use crate::scene::{Geometry, Scene};
use crate::shade::Lighting;
use glam::Vec3;

/// The demo scenes the server offers without any pushed data.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DemoScene {
    /// Forty-eight Wyvill blobs drifting on Lissajous paths and merging.
    Blobs,
}

impl DemoScene {
    pub const ALL: [DemoScene; 1] = [DemoScene::Blobs];

    /// Stable identifier used in URLs.
    pub fn id(self) -> &'static str {
        match self {
            DemoScene::Blobs => "blobs",
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            DemoScene::Blobs => "Blobs",
        }
    }

    pub fn description(self) -> &'static str {
        match self {
            DemoScene::Blobs => "48 metaballs (Wyvill kernel) on Lissajous paths",
        }
    }

    /// A camera that frames the scene.
    pub fn default_camera(self) -> Camera {
        match self {
            DemoScene::Blobs => Camera {
                eye: Vec3::new(0.0, 1.5, 7.5),
                target: Vec3::ZERO,
                up: Vec3::Y,
                fov_y_deg: 45.0,
            },
        }
    }

    /// The isovalue a viewer starts with, and a useful slider range.
    pub fn default_isovalue(self) -> f32 {
        0.5
    }

    pub fn isovalue_slider(self) -> (f32, f32) {
        (0.05, 1.5)
    }

    /// The scene at `time` seconds.
    pub fn state_at(self, time: f64) -> Scene {
        match self {
            DemoScene::Blobs => blobs(48, time),
        }
    }
}

/// A small fixed-seed generator (SplitMix64) so scenes never depend on a platform RNG.
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next_f32()
    }
}

const PALETTE: [Vec3; 6] = [
    Vec3::new(0.80, 0.18, 0.12),
    Vec3::new(0.95, 0.55, 0.10),
    Vec3::new(0.20, 0.55, 0.85),
    Vec3::new(0.25, 0.70, 0.35),
    Vec3::new(0.65, 0.30, 0.80),
    Vec3::new(0.85, 0.80, 0.70),
];

fn blobs(count: usize, time: f64) -> Scene {
    let mut rng = SplitMix64(0x0015_03A7);
    let balls = (0..count)
        .map(|i| {
            let freq = Vec3::new(
                rng.range(0.2, 0.6),
                rng.range(0.2, 0.6),
                rng.range(0.2, 0.6),
            );
            let phase = Vec3::new(
                rng.range(0.0, 6.3),
                rng.range(0.0, 6.3),
                rng.range(0.0, 6.3),
            );
            let amp = Vec3::new(2.2, 1.4, 1.6);
            let radius = rng.range(0.7, 1.1);
            // Angles in f64 so that long-running servers keep smooth motion.
            let angle = |f: f32, p: f32| ((f as f64) * time + p as f64).sin() as f32;
            Metaball {
                center: amp
                    * Vec3::new(
                        angle(freq.x, phase.x),
                        angle(freq.y, phase.y),
                        angle(freq.z, phase.z),
                    ),
                radius,
                strength: 1.0,
                color: PALETTE[i % PALETTE.len()],
            }
        })
        .collect();
    Scene {
        geometry: Geometry::Metaballs(MetaballScene {
            kernel: Kernel::Wyvill,
            balls,
        }),
        lighting: Lighting::default(),
    }
}
