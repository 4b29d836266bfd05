//! The demo scenes that show the effects: what they hold and how they are lit. Like every
//! demo, each is a pure function of time with fixed-seed randomness.
//! - Glass: three clusters of blobs over a checkered floor, one diffuse, one glass (refraction
//!   with Fresnel, fitted-bvh-metaballs.txt Fig. 8e), one mirror (Fig. 8a,b), under a sphere
//!   area light that casts soft shadows.
//! - Clouds: blobs rendered as an absorbing volume (bezier-clipping-metaballs.txt §5, Fig. 8)
//!   drifting over a floor, casting translucent shadows.
//! - Shells: one field shown as three nested isosurfaces, the outer one translucent, cut
//!   open by a clip box (tetrahedral-isosurface-ray-tracing.txt §7, Fig. 7).

use crate::camera::Camera;
use crate::effects::toggles::Effects;
use crate::geom::clip::ClipBox;
use crate::geom::rng::SplitMix64;
use crate::kinds::metaballs::kernel::Kernel;
use crate::kinds::metaballs::scene::{Metaball, MetaballScene};
use crate::shade::{Floor, Isosurface, Light, Lighting, Material, MaterialGroup, Volume};
use glam::Vec3;

fn wave(f: f32, time: f64, p: f32) -> f32 {
    ((f as f64) * time + p as f64).sin() as f32
}

fn look(eye: Vec3, target: Vec3) -> Camera {
    Camera {
        eye,
        target,
        up: Vec3::Y,
        fov_y_deg: 45.0,
    }
}

/// Balls per cluster of the Glass scene.
const GLASS_CLUSTER: usize = 8;
pub const GLASS_BALLS: usize = 3 * GLASS_CLUSTER;

pub fn glass(time: f64) -> MetaballScene {
    let mut rng = SplitMix64(0x06_1A55);
    let centres = [
        Vec3::new(-2.6, 0.0, 0.0),
        Vec3::new(0.0, 0.2, -0.4),
        Vec3::new(2.6, 0.0, 0.0),
    ];
    let colours = [
        Vec3::new(0.85, 0.35, 0.15),
        Vec3::new(0.9, 0.95, 1.0),
        Vec3::new(0.9, 0.9, 0.9),
    ];
    let balls = (0..GLASS_BALLS)
        .map(|i| {
            let cluster = i / GLASS_CLUSTER;
            let home = centres[cluster] + 0.6 * rng.in_unit_ball();
            let freq = rng.range(0.3, 0.7);
            let phase = rng.range(0.0, 6.3);
            let drift = 0.45
                * Vec3::new(
                    wave(freq, time, phase),
                    wave(freq * 1.3, time, phase + 1.0),
                    wave(freq * 0.7, time, phase + 2.0),
                );
            Metaball::sphere(home + drift, rng.range(0.8, 1.0), 1.0, colours[cluster])
        })
        .collect();
    MetaballScene {
        kernel: Kernel::Wyvill,
        balls,
        min_isovalue: 0.05,
    }
}

pub fn glass_lighting() -> Lighting {
    let cluster = GLASS_CLUSTER as u32;
    Lighting {
        lights: vec![
            Light::Sphere {
                center: Vec3::new(3.0, 6.5, 4.0),
                radius: 1.2,
                color: Vec3::new(1.0, 0.95, 0.88) * 70.0,
            },
            Light::Directional {
                to_light: Vec3::new(-0.5, 0.7, 0.4).normalize(),
                color: Vec3::new(0.55, 0.6, 0.75) * 0.25,
            },
        ],
        ambient: Vec3::splat(0.06),
        background_top: Vec3::new(0.20, 0.26, 0.38),
        background_bottom: Vec3::new(0.03, 0.03, 0.04),
        materials: vec![
            Material::default(),
            // Glass: mostly transmissive, bending, a sharp highlight.
            Material {
                diffuse: Vec3::splat(1.0),
                specular: 0.8,
                shininess: 200.0,
                opacity: 0.08,
                ior: 1.5,
                ..Material::default()
            },
            // Mirror.
            Material {
                diffuse: Vec3::splat(0.9),
                specular: 0.6,
                shininess: 120.0,
                reflectivity: 0.85,
                ..Material::default()
            },
            // Floor.
            Material {
                specular: 0.0,
                ..Material::default()
            },
        ],
        groups: vec![
            MaterialGroup {
                first: cluster,
                count: cluster,
                material: 1,
            },
            MaterialGroup {
                first: 2 * cluster,
                count: cluster,
                material: 2,
            },
        ],
        floor: Some(Floor {
            height: -1.7,
            material: 3,
            colors: [Vec3::splat(0.75), Vec3::splat(0.18)],
            checker: 1.0,
        }),
        occlusion_distance: 1.5,
        effects: Effects {
            shadows: true,
            soft_shadows: true,
            reflections: true,
            refraction: true,
            transparency: true,
            depth: 3,
            light_samples: 4,
            ..Effects::OFF
        },
        ..Lighting::default()
    }
}

pub fn glass_camera() -> Camera {
    look(Vec3::new(0.0, 2.6, 9.5), Vec3::new(0.0, -0.4, 0.0))
}

pub const CLOUD_BALLS: usize = 40;

pub fn clouds(time: f64) -> MetaballScene {
    let mut rng = SplitMix64(0xC10D);
    let balls = (0..CLOUD_BALLS)
        .map(|i| {
            let puff = (i % 4) as f32;
            let home = Vec3::new(-3.0 + 2.0 * puff, 1.2, -0.5 + 0.5 * puff)
                + Vec3::new(1.1, 0.45, 0.9) * rng.in_unit_ball();
            let drift = Vec3::new(0.4 * wave(0.15, time, puff), 0.0, 0.0);
            Metaball::sphere(home + drift, rng.range(0.9, 1.4), 1.0, Vec3::ONE)
        })
        .collect();
    MetaballScene {
        kernel: Kernel::Wyvill,
        balls,
        min_isovalue: 0.05,
    }
}

pub fn clouds_lighting() -> Lighting {
    Lighting {
        lights: vec![Light::Directional {
            to_light: Vec3::new(0.3, 0.9, 0.3).normalize(),
            color: Vec3::new(1.0, 0.97, 0.9),
        }],
        ambient: Vec3::new(0.18, 0.2, 0.25),
        background_top: Vec3::new(0.22, 0.40, 0.75),
        background_bottom: Vec3::new(0.65, 0.75, 0.9),
        materials: vec![Material {
            specular: 0.0,
            ..Material::default()
        }],
        floor: Some(Floor {
            height: -1.0,
            material: 0,
            colors: [Vec3::new(0.25, 0.45, 0.18), Vec3::new(0.2, 0.38, 0.14)],
            checker: 1.5,
        }),
        volume: Some(Volume {
            density: 1.5,
            color: Vec3::new(0.92, 0.92, 0.95),
        }),
        effects: Effects {
            shadows: true,
            transparency: true,
            ..Effects::OFF
        },
        ..Lighting::default()
    }
}

pub fn clouds_camera() -> Camera {
    look(Vec3::new(0.0, 1.0, 10.0), Vec3::new(0.0, 0.8, 0.0))
}

pub const SHELL_BALLS: usize = 24;

pub fn shells(time: f64) -> MetaballScene {
    let mut rng = SplitMix64(0x5E_11);
    let balls = (0..SHELL_BALLS)
        .map(|_| {
            let home = 1.3 * rng.in_unit_ball();
            let freq = rng.range(0.2, 0.5);
            let phase = rng.range(0.0, 6.3);
            let drift = 0.35
                * Vec3::new(
                    wave(freq, time, phase),
                    wave(freq, time, phase + 2.1),
                    wave(freq, time, phase + 4.2),
                );
            Metaball::sphere(
                home + drift,
                rng.range(1.0, 1.3),
                1.0,
                Vec3::new(0.95, 0.55, 0.2),
            )
        })
        .collect();
    MetaballScene {
        kernel: Kernel::Wyvill,
        balls,
        min_isovalue: 0.05,
    }
}

pub fn shells_lighting() -> Lighting {
    Lighting {
        lights: vec![Light::Point {
            position: Vec3::new(4.0, 6.0, 6.0),
            color: Vec3::splat(80.0),
        }],
        ambient: Vec3::splat(0.1),
        materials: vec![
            Material::default(),
            // The outer shell: translucent blue.
            Material {
                diffuse: Vec3::new(0.35, 0.55, 1.0),
                opacity: 0.3,
                specular: 0.5,
                ..Material::default()
            },
            // The core: deep red.
            Material {
                diffuse: Vec3::new(0.9, 0.1, 0.12),
                ..Material::default()
            },
        ],
        isosurfaces: vec![
            Isosurface {
                isovalue: 0.15,
                material: 1,
                color: None,
            },
            Isosurface {
                isovalue: 2.0,
                material: 2,
                color: None,
            },
        ],
        clip_box: Some(ClipBox {
            min: Vec3::new(0.0, -100.0, 0.0),
            max: Vec3::new(100.0, 0.3, 100.0),
        }),
        effects: Effects {
            shadows: true,
            transparency: true,
            clip_box: true,
            isosurfaces: true,
            layers: 4,
            ..Effects::OFF
        },
        ..Lighting::default()
    }
}

pub fn shells_camera() -> Camera {
    look(Vec3::new(5.5, 3.5, 7.0), Vec3::ZERO)
}
