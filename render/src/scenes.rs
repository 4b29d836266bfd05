//! Built-in, deterministic, animated scenes: a pure function of time, no randomness beyond a
//! fixed-seed generator, so every run and every thread count sees the same states. The one
//! file read is the Molecule demo's real structure, 1TII from Debian's `pymol-data`
//! ([`PYMOL_MOLECULE`]), read once when installed; without it that demo is synthetic.
//!
//! Besides the small `Blobs` demo, these are the test scenes of fitted-bvh-metaballs.txt §6
//! (Table 1, Fig. 8) with the paper's ball counts, rebuilt as generators: Scattered (30,000
//! and 100,000 balls in a cube, each bobbing), Tornado (4,000 and 128,000 balls swirling up a
//! widening funnel), Molecule (1TII, 5,469 atoms without waters, from `pymol-data`; else 5,440
//! atoms of a synthetic folded chain; element radii and CPK colours, slowly turning and
//! vibrating) and Pool (10,000 balls of a dense fluid slab under
//! travelling waves). All use Wyvill's kernel at `T = 0.5`.

use crate::camera::Camera;
use crate::demo_effects;
use crate::demo_surfels;
pub use crate::geom::rng::SplitMix64;
use crate::kinds::metaballs::kernel::Kernel;
use crate::kinds::metaballs::pdb::{read_models, Element, MoleculeOptions, Row};
use crate::kinds::metaballs::scene::{Metaball, MetaballScene};
use crate::kinds::surfels::demo::SurfelDemoKind;
use crate::scene::{Geometry, Scene};
use crate::shade::Lighting;
use crate::view::View;
use glam::{Quat, Vec3};
use std::path::Path;
use std::sync::OnceLock;

/// The demo scenes the server offers without any pushed data.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DemoScene {
    /// Forty-eight Wyvill blobs drifting on Lissajous paths and merging.
    Blobs,
    /// fitted-bvh-metaballs.txt "Scattered metaballs", 30,000 balls.
    Scattered30k,
    /// The same, 100,000 balls.
    Scattered100k,
    /// The Scattered generator with 1,000 balls: the streaming benchmarks' interactive scene.
    Scattered1k,
    /// fitted-bvh-metaballs.txt "Tornado", 4,000 balls.
    Tornado4k,
    /// The same, 128,000 balls.
    Tornado128k,
    /// fitted-bvh-metaballs.txt "Molecule", 5,440 atoms.
    Molecule,
    /// fitted-bvh-metaballs.txt "Pool", 10,000 balls.
    Pool,
    /// A tet mesh with a time-varying gyroid field (tetrahedral-isosurface-ray-tracing.txt).
    TetGyroid,
    /// The deforming bucky ball of tetrahedral-isosurface-ray-tracing.txt Fig. 4, shadows on.
    TetBucky,
    // The effects demos (see `demo_effects`).
    /// Diffuse, glass and mirror blobs over a floor under a sphere area light.
    Glass,
    /// Blobs as an absorbing volume (bezier-clipping-metaballs.txt §5).
    Clouds,
    /// Nested isosurfaces cut by a clip box (tetrahedral-isosurface-ray-tracing.txt §7).
    Shells,
    // The surfel demos (deforming-point-sampled-surfaces.txt §5; see `demo_surfels`).
    /// 40 elastic balls thrown into a hollow cube.
    SurfelBalls,
    /// A 150,000-surfel bumpy object hit by a ball (the paper's Armadillo scale).
    SurfelImpact,
    /// Three bouncing cubes whose faces meet at sharp, clipped edges.
    SurfelHeads,
}

impl DemoScene {
    pub const ALL: [DemoScene; 16] = [
        DemoScene::Blobs,
        DemoScene::Scattered1k,
        DemoScene::Scattered30k,
        DemoScene::Scattered100k,
        DemoScene::Tornado4k,
        DemoScene::Tornado128k,
        DemoScene::Molecule,
        DemoScene::Pool,
        DemoScene::TetGyroid,
        DemoScene::TetBucky,
        DemoScene::Glass,
        DemoScene::Clouds,
        DemoScene::Shells,
        DemoScene::SurfelBalls,
        DemoScene::SurfelImpact,
        DemoScene::SurfelHeads,
    ];

    /// The surfel demos.
    pub const SURFELS: [DemoScene; 3] = [
        DemoScene::SurfelBalls,
        DemoScene::SurfelImpact,
        DemoScene::SurfelHeads,
    ];

    /// The scenes made to show the effects.
    pub const EFFECTS: [DemoScene; 3] = [DemoScene::Glass, DemoScene::Clouds, DemoScene::Shells];

    /// The scenes of the Fitted BVH paper's Table 1.
    pub const PAPER: [DemoScene; 6] = [
        DemoScene::Scattered30k,
        DemoScene::Scattered100k,
        DemoScene::Tornado4k,
        DemoScene::Tornado128k,
        DemoScene::Molecule,
        DemoScene::Pool,
    ];

    /// Stable identifier used in URLs.
    pub fn id(self) -> &'static str {
        match self {
            DemoScene::Blobs => "blobs",
            DemoScene::Scattered30k => "scattered-30k",
            DemoScene::Scattered100k => "scattered-100k",
            DemoScene::Scattered1k => "scattered-1k",
            DemoScene::Tornado4k => "tornado-4k",
            DemoScene::Tornado128k => "tornado-128k",
            DemoScene::Molecule => "molecule",
            DemoScene::Pool => "pool",
            DemoScene::TetGyroid => "tets-gyroid",
            DemoScene::TetBucky => "tets-bucky",
            DemoScene::Glass => "glass",
            DemoScene::Clouds => "clouds",
            DemoScene::Shells => "shells",
            DemoScene::SurfelBalls => "surfel-balls",
            DemoScene::SurfelImpact => "surfel-impact",
            DemoScene::SurfelHeads => "surfel-heads",
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            DemoScene::Blobs => "Blobs",
            DemoScene::Scattered30k => "Scattered 30k",
            DemoScene::Scattered100k => "Scattered 100k",
            DemoScene::Scattered1k => "Scattered 1k",
            DemoScene::Tornado4k => "Tornado 4k",
            DemoScene::Tornado128k => "Tornado 128k",
            DemoScene::Molecule => "Molecule",
            DemoScene::Pool => "Pool",
            DemoScene::TetGyroid => "Gyroid (tets)",
            DemoScene::TetBucky => "Deforming bucky ball (tets)",
            DemoScene::Glass => "Glass and mirrors",
            DemoScene::Clouds => "Clouds",
            DemoScene::Shells => "Shells",
            DemoScene::SurfelBalls => "Ball pit (surfels)",
            DemoScene::SurfelImpact => "Impact (surfels)",
            DemoScene::SurfelHeads => "Clipped cubes (surfels)",
        }
    }

    pub fn description(self) -> &'static str {
        match self {
            DemoScene::Blobs => "48 metaballs (Wyvill kernel) on Lissajous paths",
            DemoScene::Scattered30k => "30,000 scattered metaballs (Fitted BVH paper, Table 1)",
            DemoScene::Scattered100k => "100,000 scattered metaballs (Fitted BVH paper, Table 1)",
            DemoScene::Scattered1k => {
                "1,000 scattered, bobbing metaballs (streaming benchmark scene)"
            }
            DemoScene::Tornado4k => "4,000 metaballs in a tornado (Fitted BVH paper, Table 1)",
            DemoScene::Tornado128k => "128,000 metaballs in a tornado (Fitted BVH paper, Table 1)",
            DemoScene::Molecule => match real_molecule() {
                Some(_) => {
                    "the 1TII molecule from the PDB (pymol-data), CPK colours (Fitted BVH paper, Table 1)"
                }
                None => "5,440-atom synthetic molecule, CPK colours (Fitted BVH paper, Table 1)",
            },
            DemoScene::Pool => "10,000 metaballs of a fluid pool (Fitted BVH paper, Table 1)",
            DemoScene::TetGyroid => "time-varying gyroid field on a ball of 103,000 tets",
            DemoScene::TetBucky => {
                "a C60 cage on 146,000 tets whose vertices move every step, with shadows"
            }
            DemoScene::Glass => {
                "diffuse, glass and mirror blobs over a floor, lit by a sphere area light"
            }
            DemoScene::Clouds => "metaballs rendered as an absorbing volume over a floor",
            DemoScene::Shells => "three nested isosurfaces of one field, cut open by a clip box",
            DemoScene::SurfelBalls => {
                "40 elastic surfel balls thrown into a hollow cube (shape matching)"
            }
            DemoScene::SurfelImpact => {
                "a 153,000-surfel bumpy object on ~450 simulation nodes, hit by a ball"
            }
            DemoScene::SurfelHeads => {
                "three bouncing cubes of clipped surfel faces with sharp edges"
            }
        }
    }

    /// Number of primitives (balls, or tets) in every state.
    pub fn ball_count(self) -> usize {
        match self {
            DemoScene::Blobs => 48,
            DemoScene::Scattered30k => 30_000,
            DemoScene::Scattered100k => 100_000,
            DemoScene::Scattered1k => 1_000,
            DemoScene::Tornado4k => 4_000,
            DemoScene::Tornado128k => 128_000,
            DemoScene::Molecule => real_molecule().map_or(SYNTHETIC_MOLECULE_ATOMS, <[Row]>::len),
            DemoScene::Pool => 10_000,
            DemoScene::TetGyroid => crate::kinds::tets::generate::demo_mesh().tets().len(),
            DemoScene::TetBucky => crate::kinds::tets::bucky::bucky_tet_count(),
            DemoScene::Glass => demo_effects::GLASS_BALLS,
            DemoScene::Clouds => demo_effects::CLOUD_BALLS,
            DemoScene::Shells => demo_effects::SHELL_BALLS,
            DemoScene::SurfelBalls => demo_surfels::count(SurfelDemoKind::Balls),
            DemoScene::SurfelImpact => demo_surfels::count(SurfelDemoKind::Impact),
            DemoScene::SurfelHeads => demo_surfels::count(SurfelDemoKind::Heads),
        }
    }

    /// A camera that frames the scene.
    pub fn default_camera(self) -> Camera {
        let look = |eye: Vec3, target: Vec3, fov_y_deg: f32| Camera {
            eye,
            target,
            up: Vec3::Y,
            fov_y_deg,
        };
        match self {
            DemoScene::Blobs => look(Vec3::new(0.0, 1.5, 7.5), Vec3::ZERO, 45.0),
            DemoScene::Scattered30k | DemoScene::Scattered100k | DemoScene::Scattered1k => {
                let half = 0.5 * scattered_side(self.ball_count());
                look(Vec3::new(0.4, 0.5, 2.6) * half * 1.25, Vec3::ZERO, 45.0)
            }
            DemoScene::Tornado4k | DemoScene::Tornado128k => {
                look(Vec3::new(0.0, 12.0, 42.0), Vec3::new(0.0, 10.0, 0.0), 45.0)
            }
            DemoScene::Molecule => {
                // 95 for the synthetic globule (reach 38), the same framing for 1TII.
                let d = 2.5 * molecule_reach();
                look(Vec3::new(0.0, 0.105 * d, d), Vec3::ZERO, 45.0)
            }
            DemoScene::Pool => look(Vec3::new(0.0, 14.0, 26.0), Vec3::new(0.0, 1.0, 0.0), 50.0),
            DemoScene::TetGyroid => look(Vec3::new(3.0, 2.2, 5.2), Vec3::ZERO, 40.0),
            DemoScene::TetBucky => look(Vec3::new(3.2, 2.4, 6.4), Vec3::new(0.0, -0.4, 0.0), 40.0),
            DemoScene::Glass => demo_effects::glass_camera(),
            DemoScene::Clouds => demo_effects::clouds_camera(),
            DemoScene::Shells => demo_effects::shells_camera(),
            DemoScene::SurfelBalls => demo_surfels::camera(SurfelDemoKind::Balls),
            DemoScene::SurfelImpact => demo_surfels::camera(SurfelDemoKind::Impact),
            DemoScene::SurfelHeads => demo_surfels::camera(SurfelDemoKind::Heads),
        }
    }

    /// A `width` × `height` view from [`DemoScene::default_camera`] at
    /// [`DemoScene::default_isovalue`]: what a viewer first sees.
    pub fn default_view(self, width: u32, height: u32) -> View {
        View {
            width,
            height,
            camera: self.default_camera(),
            isovalue: self.default_isovalue(),
        }
    }

    /// The isovalue a viewer starts with, and a useful slider range.
    pub fn default_isovalue(self) -> f32 {
        match self {
            DemoScene::TetGyroid => 0.0,
            _ => 0.5,
        }
    }

    pub fn isovalue_slider(self) -> (f32, f32) {
        match self {
            DemoScene::Blobs | DemoScene::Glass | DemoScene::Clouds | DemoScene::Shells => {
                (0.05, 1.5)
            }
            DemoScene::TetGyroid => (-1.5, 1.0),
            DemoScene::TetBucky => (0.1, 1.0),
            _ => (MIN_ISOVALUE, 1.5),
        }
    }

    /// The scene at `time` seconds.
    pub fn state_at(self, time: f64) -> Scene {
        let metaballs = match self {
            DemoScene::Blobs => blobs(48, time),
            DemoScene::Scattered30k | DemoScene::Scattered100k | DemoScene::Scattered1k => {
                scattered(self.ball_count(), time)
            }
            DemoScene::Tornado4k | DemoScene::Tornado128k => tornado(self.ball_count(), time),
            DemoScene::Molecule => molecule(time),
            DemoScene::Pool => pool(time),
            DemoScene::TetGyroid => {
                return Scene {
                    geometry: Geometry::Tets(crate::kinds::tets::generate::demo_state(time)),
                    lighting: self.lighting(),
                }
            }
            DemoScene::TetBucky => {
                return Scene {
                    geometry: Geometry::Tets(crate::kinds::tets::bucky::bucky_state(time)),
                    lighting: self.lighting(),
                }
            }
            DemoScene::SurfelBalls => return self.surfels(SurfelDemoKind::Balls, time),
            DemoScene::SurfelImpact => return self.surfels(SurfelDemoKind::Impact, time),
            DemoScene::SurfelHeads => return self.surfels(SurfelDemoKind::Heads, time),
            DemoScene::Glass => demo_effects::glass(time),
            DemoScene::Clouds => demo_effects::clouds(time),
            DemoScene::Shells => demo_effects::shells(time),
        };
        Scene {
            geometry: Geometry::Metaballs(metaballs),
            lighting: self.lighting(),
        }
    }

    fn surfels(self, kind: SurfelDemoKind, time: f64) -> Scene {
        Scene {
            geometry: Geometry::Surfels(demo_surfels::state_at(kind, time)),
            lighting: self.lighting(),
        }
    }

    /// The surfel demo behind this scene, if it is one.
    pub fn surfel_kind(self) -> Option<SurfelDemoKind> {
        match self {
            DemoScene::SurfelBalls => Some(SurfelDemoKind::Balls),
            DemoScene::SurfelImpact => Some(SurfelDemoKind::Impact),
            DemoScene::SurfelHeads => Some(SurfelDemoKind::Heads),
            DemoScene::Blobs
            | DemoScene::Scattered30k
            | DemoScene::Scattered100k
            | DemoScene::Scattered1k
            | DemoScene::Tornado4k
            | DemoScene::Tornado128k
            | DemoScene::Molecule
            | DemoScene::Pool
            | DemoScene::TetGyroid
            | DemoScene::TetBucky
            | DemoScene::Glass
            | DemoScene::Clouds
            | DemoScene::Shells => None,
        }
    }

    /// How the scene is lit and shaded: the default look, or an effects demo's.
    pub fn lighting(self) -> Lighting {
        match self {
            DemoScene::Glass => demo_effects::glass_lighting(),
            DemoScene::Clouds => demo_effects::clouds_lighting(),
            DemoScene::Shells => demo_effects::shells_lighting(),
            DemoScene::TetGyroid => crate::kinds::tets::generate::demo_lighting(),
            DemoScene::TetBucky => crate::kinds::tets::bucky::bucky_lighting(),
            DemoScene::SurfelBalls => demo_surfels::lighting(SurfelDemoKind::Balls),
            DemoScene::SurfelHeads => demo_surfels::lighting(SurfelDemoKind::Heads),
            _ => Lighting::default(),
        }
    }
}

/// The lowest isovalue the paper scenes are built for (the slider's minimum).
const MIN_ISOVALUE: f32 = 0.25;

const PALETTE: [Vec3; 6] = [
    Vec3::new(0.80, 0.18, 0.12),
    Vec3::new(0.95, 0.55, 0.10),
    Vec3::new(0.20, 0.55, 0.85),
    Vec3::new(0.25, 0.70, 0.35),
    Vec3::new(0.65, 0.30, 0.80),
    Vec3::new(0.85, 0.80, 0.70),
];

/// `sin(f·time + p)` with the angle in `f64`, so long-running servers keep smooth motion.
fn wave(f: f32, time: f64, p: f32) -> f32 {
    ((f as f64) * time + p as f64).sin() as f32
}

fn with_floor(kernel: Kernel, balls: Vec<Metaball>, min_isovalue: f32) -> MetaballScene {
    MetaballScene {
        kernel,
        balls,
        min_isovalue,
    }
}

fn blobs(count: usize, time: f64) -> MetaballScene {
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
            let center = amp
                * Vec3::new(
                    wave(freq.x, time, phase.x),
                    wave(freq.y, time, phase.y),
                    wave(freq.z, time, phase.z),
                );
            Metaball::sphere(center, radius, 1.0, PALETTE[i % PALETTE.len()])
        })
        .collect();
    with_floor(Kernel::Wyvill, balls, 0.05)
}

/// Side of the Scattered cube: about three overlapping neighbours per ball of radius 1.
fn scattered_side(count: usize) -> f32 {
    let neighbour_volume = 4.0 / 3.0 * std::f32::consts::PI * 8.0;
    (count as f32 * neighbour_volume / 3.0).cbrt()
}

/// The Scattered generator at any ball count (benchmarks: a million balls), with the camera
/// the Scattered demos frame it with at that count.
pub fn scattered_at(count: usize, time: f64) -> (MetaballScene, Camera) {
    let half = 0.5 * scattered_side(count);
    let camera = Camera {
        eye: Vec3::new(0.4, 0.5, 2.6) * half * 1.25,
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 45.0,
    };
    (scattered(count, time), camera)
}

fn scattered(count: usize, time: f64) -> MetaballScene {
    let mut rng = SplitMix64(0x5CA7_7E2D ^ count as u64);
    let half = 0.5 * scattered_side(count);
    let balls = (0..count)
        .map(|i| {
            let home = Vec3::new(
                rng.range(-half, half),
                rng.range(-half, half),
                rng.range(-half, half),
            );
            let freq = rng.range(0.3, 0.9);
            let phase = rng.range(0.0, 6.3);
            let dir = rng.in_unit_ball();
            let radius = rng.range(0.8, 1.2);
            Metaball::sphere(
                home + 0.6 * dir * wave(freq, time, phase),
                radius,
                1.0,
                PALETTE[i % PALETTE.len()],
            )
        })
        .collect();
    with_floor(Kernel::Wyvill, balls, MIN_ISOVALUE)
}

fn tornado(count: usize, time: f64) -> MetaballScene {
    let mut rng = SplitMix64(0x7023_AD00 ^ count as u64);
    let height = 20.0f32;
    let widen = 0.45f32;
    // Heights drawn with density ∝ funnel radius², so balls fill the shell evenly; the ball
    // radius shrinks with the count so every ball has about a dozen overlapping neighbours.
    let top = (1.0 + widen * height).powi(3);
    let radius = 0.45 * (4000.0 / count as f32).cbrt();
    let balls = (0..count)
        .map(|_| {
            let u = rng.next_f32();
            let h = ((1.0 + u * (top - 1.0)).cbrt() - 1.0) / widen;
            let funnel = 1.0 + widen * h;
            let r = funnel * (0.75 + 0.25 * rng.next_f32());
            let speed = 1.2 / (0.4 + 0.1 * h);
            let angle = rng.range(0.0, std::f32::consts::TAU) + (speed as f64 * time) as f32;
            let wobble = 0.8 * wave(0.3, time, h * 0.35);
            let center = Vec3::new(r * angle.cos() + wobble, h, r * angle.sin());
            let color = Vec3::new(0.55, 0.5, 0.45).lerp(Vec3::new(0.85, 0.8, 0.75), h / height);
            Metaball::sphere(center, radius * rng.range(0.85, 1.15), 1.0, color)
        })
        .collect();
    with_floor(Kernel::Wyvill, balls, MIN_ISOVALUE)
}

/// Where Debian's `pymol-data` keeps 1TII (an AB5 enterotoxin, 5,684 atom records), the
/// real structure the Molecule demo shows when the package is installed.
pub const PYMOL_MOLECULE: &str = "/usr/share/pymol/data/demo/1tii.pdb";

/// The atoms of the synthetic chain the Molecule demo falls back to (the paper's count).
const SYNTHETIC_MOLECULE_ATOMS: usize = 5_440;

/// 1TII's first model (no hydrogens, no waters, centred) as ball rows, read once with
/// pdbtbx; `None` when `pymol-data` is not installed or the file does not read.
pub fn real_molecule() -> Option<&'static [Row]> {
    static REAL: OnceLock<Option<Vec<Row>>> = OnceLock::new();
    REAL.get_or_init(|| {
        read_models(Path::new(PYMOL_MOLECULE), MoleculeOptions::default())
            .ok()
            .and_then(|models| models.into_iter().next())
    })
    .as_deref()
}

/// A synthetic folded chain of `count` atoms in a globule, as ball rows (the fallback
/// when no real structure is installed).
fn synthetic_molecule(count: usize) -> Vec<Row> {
    let mut rng = SplitMix64(0x0000_0A70_3540);
    let globule = 1.05 * (count as f32 * 28.0 * 3.0 / (4.0 * std::f32::consts::PI)).cbrt();
    let pattern = [
        Element::N,
        Element::C,
        Element::C,
        Element::O,
        Element::C,
        Element::C,
        Element::N,
        Element::C,
        Element::C,
        Element::O,
        Element::C,
        Element::S,
    ];
    let mut pos = Vec3::ZERO;
    let mut heading = Vec3::X;
    (0..count)
        .map(|i| {
            heading = (heading + 0.9 * rng.in_unit_ball()).normalize_or(Vec3::Y);
            let next = pos + 1.5 * heading;
            if next.length() > globule {
                // Turn back inwards at the globule's wall.
                heading = (-next.normalize() + 0.5 * rng.in_unit_ball()).normalize_or(Vec3::Y);
            }
            pos += 1.5 * heading;
            let element = pattern[i % pattern.len()];
            let c = element.cpk_color();
            // The support is twice the van der Waals radius, so at T = 0.5 a lone atom's
            // surface is its van der Waals sphere (f(R/2) = 1/2).
            let radius = 2.0 * element.van_der_waals_radius();
            [pos.x, pos.y, pos.z, radius, 1.0, c.x, c.y, c.z]
        })
        .collect()
}

/// The Molecule demo's atoms at rest: 1TII when installed, else the synthetic chain.
fn molecule_atoms() -> std::borrow::Cow<'static, [Row]> {
    match real_molecule() {
        Some(rows) => std::borrow::Cow::Borrowed(rows),
        None => std::borrow::Cow::Owned(synthetic_molecule(SYNTHETIC_MOLECULE_ATOMS)),
    }
}

/// The Molecule demo at `time`: its atoms vibrating (0.15 Å) while the whole slowly turns.
fn molecule(time: f64) -> MetaballScene {
    let spin = Quat::from_rotation_y((0.15 * time) as f32);
    let balls = molecule_atoms()
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let jiggle = 0.15
                * Vec3::new(
                    wave(2.1, time, i as f32 * 0.7),
                    wave(2.3, time, i as f32 * 1.3),
                    wave(1.9, time, i as f32 * 0.4),
                );
            Metaball::sphere(
                spin * (Vec3::new(r[0], r[1], r[2]) + jiggle),
                r[3],
                r[4],
                Vec3::new(r[5], r[6], r[7]),
            )
        })
        .collect();
    with_floor(Kernel::Wyvill, balls, MIN_ISOVALUE)
}

/// How far the Molecule demo's atoms reach from the origin (centre plus support).
fn molecule_reach() -> f32 {
    molecule_atoms()
        .iter()
        .map(|r| Vec3::new(r[0], r[1], r[2]).length() + r[3])
        .fold(1.0, f32::max)
}

/// 10,000 balls: a 50 × 40 × 5 jittered lattice of spacing 0.45 under two travelling waves.
fn pool(time: f64) -> MetaballScene {
    let (nx, nz, ny) = (50usize, 40usize, 5usize);
    let spacing = 0.45f32;
    let mut rng = SplitMix64(0x0000_9001);
    let mut balls = Vec::with_capacity(nx * ny * nz);
    for iy in 0..ny {
        for iz in 0..nz {
            for ix in 0..nx {
                let x = (ix as f32 - 0.5 * nx as f32) * spacing;
                let z = (iz as f32 - 0.5 * nz as f32) * spacing;
                let depth = iy as f32 / (ny - 1) as f32;
                let swell =
                    0.9 * wave(0.9, time, 0.45 * x) + 0.5 * wave(1.3, time, 0.6 * z + 0.3 * x);
                let y = iy as f32 * spacing + depth * swell;
                let jitter = 0.12 * rng.in_unit_ball();
                let color = Vec3::new(0.10, 0.35, 0.75).lerp(Vec3::new(0.55, 0.8, 0.95), depth);
                balls.push(Metaball::sphere(
                    Vec3::new(x, y, z) + jitter,
                    rng.range(0.55, 0.65),
                    1.0,
                    color,
                ));
            }
        }
    }
    with_floor(Kernel::Wyvill, balls, MIN_ISOVALUE)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A demo that stands its objects on a floor under a light shows their shadows on it from
    /// the first frame, so that nothing seems to float (its effects' defaults cast them).
    #[test]
    fn demos_with_a_floor_cast_shadows_on_it_by_default() {
        let mut floors = 0;
        for demo in DemoScene::ALL {
            let lighting = demo.lighting();
            if lighting.floor.is_none() || lighting.lights.is_empty() {
                continue;
            }
            floors += 1;
            assert!(
                lighting.effects.shadows,
                "{demo:?} has a floor and a light, not its shadows"
            );
        }
        assert!(floors >= 5, "the demos with floors: {floors}");
    }

    #[test]
    fn paper_scenes_have_the_paper_counts_and_are_valid_and_deterministic() {
        for demo in DemoScene::ALL {
            // The surfel demos simulate on first use; the small one stands for all three here
            // (the engine's own tests cover every surfel demo at small sizes).
            if demo.surfel_kind().is_some() && demo != DemoScene::SurfelHeads {
                continue;
            }
            let a = demo.state_at(1.5);
            assert_eq!(a.primitive_count(), demo.ball_count(), "{demo:?}");
            a.validate(1_000_000).expect("valid");
            if demo.ball_count() <= 10_000 {
                assert_eq!(a, demo.state_at(1.5));
                assert_ne!(a, demo.state_at(2.5), "{demo:?} is animated");
            }
        }
    }
}
