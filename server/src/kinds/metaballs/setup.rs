//! A metaball scene's static part (the kernel and the per-ball defaults), the checks of
//! `metaballs` in a scene description, the layout of its step rows, and the engine scene of
//! one step.

use crate::kinds::convert::{finite, vec3};
use crate::kinds::error::KindError;
use glam::Vec3;
use isoray_protocol::api::MetaballDefaults;
use isoray_render::kinds::metaballs::{Kernel, Metaball, MetaballScene};

/// Per-ball values for columns a metaball step leaves out.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BallDefaults {
    pub kernel: Kernel,
    pub radius: f32,
    pub strength: f32,
    pub color: Vec3,
}

/// Metaball step column counts: positions, + radius, + strength, + linear RGB.
pub const COLUMNS: [u32; 4] = [3, 4, 5, 8];
const COLUMN_NAMES: [&str; 8] = ["x", "y", "z", "radius", "strength", "r", "g", "b"];

/// What the columns hold, for error messages.
pub const COLUMNS_HELP: &str =
    "a metaball step has 3 (x y z), 4 (+ radius), 5 (+ strength) or 8 (+ r g b) columns";

/// The name of column `col`.
pub fn column_name(col: usize) -> &'static str {
    COLUMN_NAMES.get(col).copied().unwrap_or("?")
}

/// Whether a batch of whole, finite rows has a positive radius in every row (when there is
/// a radius column). Branch-free, so it vectorises.
pub fn rows_valid(values: &[f32], columns: usize) -> bool {
    columns < 4
        || values
            .chunks_exact(columns)
            .fold(true, |ok, row| ok & (row[3] > 0.0))
}

/// Why the finite value `v` in column `col` is not allowed, if it is not.
pub fn check_value(col: usize, v: f32) -> Option<String> {
    (col == 3 && v <= 0.0).then(|| format!("is {v}; a radius must be positive"))
}

/// Kernel names accepted in `metaballs.kernel`.
pub const KERNEL_NAMES: &str = "wyvill, quartic, tutorial, power1, power2, power3, power4";

fn kernel(name: &str) -> Result<Kernel, KindError> {
    Ok(match name {
        "wyvill" => Kernel::Wyvill,
        "quartic" => Kernel::Quartic,
        "tutorial" => Kernel::Tutorial,
        "power1" => Kernel::Power { alpha: 1 },
        "power2" => Kernel::Power { alpha: 2 },
        "power3" => Kernel::Power { alpha: 3 },
        "power4" => Kernel::Power { alpha: 4 },
        other => {
            return Err(KindError::invalid(
                "invalid_value",
                format!("kernel `{other}` is not known; the engine has {KERNEL_NAMES}"),
            )
            .field("metaballs.kernel"))
        }
    })
}

/// The `metaballs` part of a scene description, checked.
pub fn setup_from_spec(d: &MetaballDefaults) -> Result<BallDefaults, KindError> {
    let radius = finite(d.radius, "metaballs.radius")?;
    if radius <= 0.0 {
        return Err(
            KindError::invalid("invalid_value", "metaballs.radius must be positive")
                .field("metaballs.radius"),
        );
    }
    Ok(BallDefaults {
        kernel: kernel(&d.kernel)?,
        radius,
        strength: finite(d.strength, "metaballs.strength")?,
        color: vec3(d.color, "metaballs.color")?,
    })
}

/// The engine scene of one step (`None`: before the first, no balls).
pub fn scene(d: &BallDefaults, step: Option<(u32, &[u8])>, min_isovalue: f32) -> MetaballScene {
    let balls = step.map_or_else(Vec::new, |(columns, payload)| {
        balls_from_rows(columns as usize, payload, d)
    });
    let mut m = MetaballScene::new(d.kernel, balls);
    m.min_isovalue = min_isovalue;
    m
}

/// Memory of a prepared step of `rows` balls, roughly: the balls plus about as much again
/// for the acceleration structure.
pub fn prepared_bytes(rows: u64) -> u64 {
    rows * 2 * std::mem::size_of::<Metaball>() as u64
}

/// Engine balls from a metaball step's f32 rows.
fn balls_from_rows(columns: usize, payload: &[u8], d: &BallDefaults) -> Vec<Metaball> {
    let mut row = [0f32; 8];
    payload
        .chunks_exact(columns.max(1) * 4)
        .map(|bytes| {
            for (v, b) in row.iter_mut().zip(bytes.chunks_exact(4)) {
                *v = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
            }
            Metaball::sphere(
                Vec3::new(row[0], row[1], row[2]),
                if columns >= 4 { row[3] } else { d.radius },
                if columns >= 5 { row[4] } else { d.strength },
                if columns >= 8 {
                    Vec3::new(row[5], row[6], row[7])
                } else {
                    d.color
                },
            )
        })
        .collect()
}
