//! What a scene is lit by and made of — lights, materials per primitive group, an optional
//! floor, clip box, extra isosurfaces and absorbing volume — and the local shading model:
//! Lambert diffuse plus Blinn-Phong specular in linear light, emission, and the conversion to
//! 8-bit sRGB.
//!
//! Units: light colours are linear-light radiance scales. A directional light's colour is the
//! irradiance it delivers to a surface facing it; a point or sphere light's colour is its
//! intensity, the irradiance at distance 1 (inverse-square falloff). A uniformly emitting sphere
//! light seen whole from above the horizon delivers exactly the irradiance of a point light at
//! its centre, so unshadowed shading treats both alike; only shadows see the sphere's extent.

use crate::colormap::{srgb_code_to_linear, ColorMap};
use crate::effects::toggles::Effects;
pub use crate::geom::clip::ClipBox;
use crate::geom::frame::LocalFrame;
use crate::ray::{Hit, Ray};
use glam::Vec3;

/// A light source.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Light {
    /// Infinitely far away; `to_light` is a unit vector from the surface towards it.
    Directional { to_light: Vec3, color: Vec3 },
    /// A point at `position` with intensity `color`.
    Point { position: Vec3, color: Vec3 },
    /// A uniformly emitting sphere (an area light): soft shadows sample its extent.
    Sphere {
        center: Vec3,
        radius: f32,
        color: Vec3,
    },
}

/// A light as seen from one surface point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightSample {
    /// Unit vector from the point towards the light's centre.
    pub to_light: Vec3,
    /// Distance to the light's centre (`INFINITY` for a directional light).
    pub distance: f32,
    /// Irradiance on a surface facing the light, before the cosine and shadowing.
    pub irradiance: Vec3,
}

impl Light {
    /// The light seen from `point`, or `None` when the point coincides with a point light.
    #[inline]
    pub fn toward(&self, point: Vec3) -> Option<LightSample> {
        match *self {
            Light::Directional { to_light, color } => Some(LightSample {
                to_light,
                distance: f32::INFINITY,
                irradiance: color,
            }),
            Light::Point { position, color }
            | Light::Sphere {
                center: position,
                color,
                ..
            } => {
                let d = position - point;
                let d2 = d.length_squared();
                if !(d2 > 1e-12) {
                    return None;
                }
                let distance = d2.sqrt();
                Some(LightSample {
                    to_light: d / distance,
                    distance,
                    irradiance: color / d2,
                })
            }
        }
    }

    /// Whether the light delivers any light at all.
    pub fn is_lit(&self) -> bool {
        let color = match self {
            Light::Directional { color, .. }
            | Light::Point { color, .. }
            | Light::Sphere { color, .. } => *color,
        };
        color.max_element() > 0.0
    }
}

/// How a surface reflects, transmits and emits light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// Linear-light diffuse colour, multiplied with the primitive's own colour.
    pub diffuse: Vec3,
    /// Weight of the white Blinn-Phong lobe, and its exponent.
    pub specular: f32,
    pub shininess: f32,
    /// Share of mirror reflection, `[0, 1]`.
    pub reflectivity: f32,
    /// Index of refraction, `≥ 1`; 1 lets transmitted rays pass straight through.
    pub ior: f32,
    /// `[0, 1]`; below 1 the surface transmits `1 - opacity` of what lies behind it.
    pub opacity: f32,
    /// Emitted radiance, linear light.
    pub emission: Vec3,
}

impl Default for Material {
    fn default() -> Material {
        Material {
            diffuse: Vec3::ONE,
            specular: 0.35,
            shininess: 48.0,
            reflectivity: 0.0,
            ior: 1.0,
            opacity: 1.0,
            emission: Vec3::ZERO,
        }
    }
}

impl Material {
    pub fn is_reflective(&self) -> bool {
        self.reflectivity > 0.0
    }

    pub fn is_transparent(&self) -> bool {
        self.opacity < 1.0
    }

    /// Transparent and bending: refraction rays (with Fresnel weighting) apply.
    pub fn is_refractive(&self) -> bool {
        self.is_transparent() && self.ior != 1.0
    }

    /// Whether lights (and so shadows and occlusion) change how it looks.
    pub fn receives_light(&self) -> bool {
        self.diffuse.max_element() > 0.0 || self.specular > 0.0
    }
}

/// Primitives `first .. first + count` use `materials[material]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MaterialGroup {
    pub first: u32,
    pub count: u32,
    pub material: u16,
}

/// A horizontal plane `y = height`, with an optional checkerboard.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Floor {
    pub height: f32,
    pub material: u16,
    /// Linear-light colours of the two kinds of squares (multiplied with the material's).
    pub colors: [Vec3; 2],
    /// Edge of a square in scene units; 0 for a plain floor of `colors[0]`.
    pub checker: f32,
}

impl Floor {
    /// How far along `ray` (in units of its direction) it meets the floor's plane: negative
    /// behind its origin, infinite or NaN when parallel.
    #[inline]
    pub fn distance(&self, ray: &Ray) -> f32 {
        (self.height - ray.origin.y) / ray.dir.y
    }

    /// The floor's colour seen by a ray along unit `dir` that meets it at `p_in_local`, a
    /// point of `frame`, `t` from the ray's origin, through a pixel `spread` radians wide:
    /// the checkerboard averaged over the pixel's footprint (a box the size of the footprint
    /// ellipse's bounds, [`footprint`]), so that far squares blend to their mean colour
    /// instead of aliasing into moiré. The squares stay where they are in the world: a far
    /// frame's point is moved back in `f64`. `spread` 0: the colour at the point.
    #[inline]
    pub fn color_seen(
        &self,
        p_in_local: Vec3,
        dir: Vec3,
        t: f32,
        spread: f32,
        frame: &LocalFrame,
    ) -> Vec3 {
        if !(self.checker > 0.0) {
            return self.colors[0];
        }
        let c = self.checker as f64;
        let p = frame.world_from_local(p_in_local);
        let (u, v) = (p.x / c, p.z / c);
        let (wu, wv) = footprint(dir, t * spread);
        let (wu, wv) = (wu as f64 / c, wv as f64 / c);
        // Each axis's square wave (+1 on even squares) averaged over its width; the box
        // filter of their product is the product of the averages.
        let s = square_wave_mean(u, wu) * square_wave_mean(v, wv);
        let even = (0.5 + 0.5 * s) as f32;
        self.colors[0] * even + self.colors[1] * (1.0 - even)
    }
}

/// The widths along x and z of the floor's patch a cone of `width` (at the hit, across the
/// ray) covers along unit `dir`: an ellipse stretched by `1/|dir.y|` along the ray's
/// horizontal heading, bounded by an axis-aligned box.
#[inline]
pub fn footprint(dir: Vec3, width: f32) -> (f32, f32) {
    let flat = dir.x * dir.x + dir.z * dir.z;
    if !(width > 0.0) || flat < 1e-12 {
        return (width.max(0.0), width.max(0.0));
    }
    // 1/cos² of the incidence, at most that of a ray 0.06° above the floor.
    let stretch = 1.0 / (dir.y * dir.y).max(1e-6);
    let (hx, hz) = (dir.x * dir.x / flat, dir.z * dir.z / flat);
    (
        width * (hx * stretch + hz).sqrt(),
        width * (hz * stretch + hx).sqrt(),
    )
}

/// The mean over `[u − w/2, u + w/2]` of the square wave that is +1 on `[2k, 2k + 1)` and −1
/// on `[2k + 1, 2k + 2)`: the difference of its integral, a triangle wave, over the width.
#[inline]
fn square_wave_mean(u: f64, w: f64) -> f64 {
    if w < 1e-4 {
        let square = floor(u);
        return if floor(square * 0.5) * 2.0 == square {
            1.0
        } else {
            -1.0
        };
    }
    let integral = |x: f64| {
        let half = x * 0.5;
        1.0 - ((half - floor(half)) * 2.0 - 1.0).abs()
    };
    ((integral(u + 0.5 * w) - integral(u - 0.5 * w)) / w).clamp(-1.0, 1.0)
}

/// `x.floor()` by truncation, which the portable x86-64 build has an instruction for (its
/// `floor` is a library call); exact for `|x| < 2⁶³`, beyond any floor's coordinates.
#[inline]
fn floor(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

/// A further isosurface of the same field, drawn besides the session's own.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Isosurface {
    pub isovalue: f32,
    pub material: u16,
    /// Linear-light albedo in place of the kind's own colour there (a surface a viewer added
    /// with its colour); `None`: the kind's colour, as for the scene's own surfaces.
    pub color: Option<Vec3>,
}

/// The field rendered as an absorbing, scattering volume instead of its isosurface
/// (bezier-clipping-metaballs.txt §5): optical depth `τ = density · ∫ F dl`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Volume {
    /// Extinction per unit of field and length.
    pub density: f32,
    /// Single-scattering albedo colour of the particles, linear light.
    pub color: Vec3,
}

/// How a scene is lit and shaded, and the effects a viewer starts with.
#[derive(Clone, Debug, PartialEq)]
pub struct Lighting {
    pub lights: Vec<Light>,
    /// Constant ambient irradiance, linear light (darkened by ambient occlusion).
    pub ambient: Vec3,
    /// Background at the top and bottom of the image, linear light.
    pub background_top: Vec3,
    pub background_bottom: Vec3,
    /// Never empty: `materials[0]` applies to every primitive outside `groups`.
    pub materials: Vec<Material>,
    pub groups: Vec<MaterialGroup>,
    pub floor: Option<Floor>,
    pub clip_box: Option<ClipBox>,
    pub isosurfaces: Vec<Isosurface>,
    pub volume: Option<Volume>,
    /// Length of ambient-occlusion rays, scene units.
    pub occlusion_distance: f32,
    /// The effects a viewer starts with.
    pub effects: Effects,
    /// Colour every isosurface by its value through this map (a session's choice; `None`:
    /// each kind's own colours).
    pub color_map: Option<ColorMap>,
}

impl Default for Lighting {
    fn default() -> Lighting {
        Lighting {
            lights: vec![Light::Directional {
                to_light: Vec3::new(0.4, 0.8, 0.45).normalize(),
                color: Vec3::splat(1.0),
            }],
            ambient: Vec3::splat(0.08),
            background_top: Vec3::new(0.08, 0.09, 0.12),
            background_bottom: Vec3::new(0.015, 0.015, 0.02),
            materials: vec![Material::default()],
            groups: Vec::new(),
            floor: None,
            clip_box: None,
            isosurfaces: Vec::new(),
            volume: None,
            occlusion_distance: 1.0,
            effects: Effects::OFF,
            color_map: None,
        }
    }
}

/// Fallback for an index past the end of `materials` (validation prevents it).
const DEFAULT_MATERIAL: Material = Material {
    diffuse: Vec3::ONE,
    specular: 0.35,
    shininess: 48.0,
    reflectivity: 0.0,
    ior: 1.0,
    opacity: 1.0,
    emission: Vec3::ZERO,
};

impl Lighting {
    /// The same lighting in `frame`: point and sphere lights, the floor's height and the clip
    /// box moved in `f64` (see [`LocalFrame`]); everything else is unchanged.
    pub fn in_frame(&self, frame: &LocalFrame) -> Lighting {
        let mut l = self.clone();
        if frame.is_world() {
            return l;
        }
        for light in &mut l.lights {
            match light {
                Light::Directional { .. } => {}
                Light::Point { position, .. } => *position = frame.local_from_world(*position),
                Light::Sphere { center, .. } => *center = frame.local_from_world(*center),
            }
        }
        if let Some(floor) = &mut l.floor {
            floor.height = (floor.height as f64 - frame.origin.y) as f32;
        }
        if let Some(clip) = &mut l.clip_box {
            clip.min = frame.local_from_world(clip.min);
            clip.max = frame.local_from_world(clip.max);
        }
        l
    }

    /// Whether the field is drawn as an absorbing volume while `transparency` is on (a volume
    /// of positive, finite density): no isosurface is drawn then.
    pub fn has_volume(&self) -> bool {
        self.volume
            .is_some_and(|v| v.density > 0.0 && v.density.is_finite())
    }

    /// The material of `materials[index]`.
    #[inline]
    pub fn material(&self, index: u16) -> &Material {
        self.materials
            .get(index as usize)
            .unwrap_or(&DEFAULT_MATERIAL)
    }

    /// The opacity of every primitive's material, when `materials[0]` and the material of
    /// each group (a group of no primitive included) have the same one.
    pub fn uniform_opacity(&self) -> Option<f32> {
        let first = self.material(0).opacity;
        let same = |m: u16| self.material(m).opacity.to_bits() == first.to_bits();
        self.groups
            .iter()
            .all(|g| same(g.material))
            .then_some(first)
    }

    /// Index of the material of primitive `primitive`.
    #[inline]
    pub fn material_of(&self, primitive: u32) -> u16 {
        for g in &self.groups {
            if primitive.wrapping_sub(g.first) < g.count {
                return g.material;
            }
        }
        0
    }

    /// Indices of the materials some primitive of `0..primitive_count` uses, plus the floor's.
    pub fn visible_materials(&self, primitive_count: usize) -> Vec<u16> {
        let n = primitive_count as u64;
        let mut used = Vec::new();
        let mut covered = 0u64;
        let mut spans: Vec<(u64, u64)> = Vec::new();
        for g in &self.groups {
            let lo = (g.first as u64).min(n);
            let hi = (g.first as u64 + g.count as u64).min(n);
            if lo < hi {
                used.push(g.material);
                spans.push((lo, hi));
            }
        }
        // Primitives outside every group use material 0.
        spans.sort_unstable();
        let mut end = 0u64;
        for (lo, hi) in spans {
            if lo > end {
                break;
            }
            end = end.max(hi);
            covered = end;
        }
        if covered < n {
            used.push(0);
        }
        if let Some(floor) = &self.floor {
            used.push(floor.material);
        }
        used.sort_unstable();
        used.dedup();
        used
    }

    /// Background seen along a ray whose direction has vertical component `dir_y`.
    #[inline]
    pub fn background(&self, dir_y: f32) -> Vec3 {
        let a = 0.5 * (dir_y.clamp(-1.0, 1.0) + 1.0);
        self.background_bottom.lerp(self.background_top, a)
    }

    /// Colour of a hit seen from direction `view_dir` (unit, towards the surface), lit by
    /// every light without shadows, with the default material and no ambient occlusion.
    /// The ray-cast-only image is made of this.
    pub fn shade(&self, hit: &Hit, view_dir: Vec3) -> Vec3 {
        let material = self.material(self.material_of(hit.primitive));
        self.shade_lit(material, hit.albedo, hit.position, hit.normal, view_dir)
    }

    /// [`Lighting::shade`] of the floor at `position`, a point of `frame`, met `t` along
    /// `view_dir` by a ray of a pixel `spread` wide ([`Floor::color_seen`]).
    pub fn shade_floor(
        &self,
        floor: &Floor,
        position: Vec3,
        (view_dir, t, spread): (Vec3, f32, f32),
        frame: &LocalFrame,
    ) -> Vec3 {
        let albedo = floor.color_seen(position, view_dir, t, spread, frame);
        self.shade_lit(
            self.material(floor.material),
            albedo,
            position,
            Vec3::Y,
            view_dir,
        )
    }

    /// A surface of `material` and `albedo` at `position` with outward `normal`, lit by every
    /// light without shadows.
    #[inline(always)]
    fn shade_lit(
        &self,
        material: &Material,
        albedo: Vec3,
        position: Vec3,
        normal: Vec3,
        view_dir: Vec3,
    ) -> Vec3 {
        let albedo = albedo * material.diffuse;
        let normal = facing(normal, view_dir);
        let mut color = material.emission + self.ambient * albedo;
        for light in &self.lights {
            if let Some(l) = light.toward(position) {
                color += direct(material, albedo, normal, view_dir, &l, 1.0);
            }
        }
        color
    }
}

/// `normal` turned to face a viewer looking along `view_dir`.
#[inline]
pub fn facing(normal: Vec3, view_dir: Vec3) -> Vec3 {
    if normal.dot(view_dir) > 0.0 {
        -normal
    } else {
        normal
    }
}

/// Light arriving from `light` and leaving towards the viewer, scaled by `visibility`.
#[inline]
pub fn direct(
    material: &Material,
    albedo: Vec3,
    normal: Vec3,
    view_dir: Vec3,
    light: &LightSample,
    visibility: f32,
) -> Vec3 {
    let n_dot_l = normal.dot(light.to_light);
    if n_dot_l <= 0.0 || visibility <= 0.0 {
        return Vec3::ZERO;
    }
    let half = (light.to_light - view_dir).normalize_or_zero();
    let spec = if material.specular > 0.0 {
        specular_power(normal.dot(half).max(0.0), material.shininess) * material.specular
    } else {
        0.0
    };
    light.irradiance * (albedo * n_dot_l + Vec3::splat(spec)) * visibility
}

/// `x^shininess` for `x` in `[0, 1]`: by repeated squaring for a whole exponent up to 1024
/// (every material of the demos; a few multiplications against `powf`'s logarithm and
/// exponential, which were 4–6% of a ray-cast frame of `blobs` and `scattered-1k`; within
/// `shininess` ulps, and the demos' images the same to the 8-bit step), `powf` otherwise.
#[inline]
pub fn specular_power(x: f32, shininess: f32) -> f32 {
    if shininess.fract() == 0.0 && (1.0..=1024.0).contains(&shininess) {
        x.powi(shininess as i32)
    } else {
        x.powf(shininess)
    }
}

/// Unpolarised Fresnel reflectance at a boundary where the ray goes from index `n1` to `n2`
/// with `cos_i = cos θ_i > 0`; 1 under total internal reflection.
#[inline]
pub fn fresnel(cos_i: f32, n1: f32, n2: f32) -> f32 {
    let eta = n1 / n2;
    let sin_t2 = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin_t2 >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin_t2).sqrt();
    let rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t);
    let rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i);
    0.5 * (rs * rs + rp * rp)
}

/// Linear light in `[0, 1]` to an 8-bit sRGB value (IEC 61966-2-1), by table: exactly the
/// formula's code ([`crate::srgb`]).
#[inline]
pub fn linear_to_srgb8(v: f32) -> u8 {
    crate::srgb::encode8(v)
}

/// An 8-bit sRGB value to linear light (the inverse of [`linear_to_srgb8`] up to rounding).
pub fn srgb8_to_linear(v: u8) -> f32 {
    srgb_code_to_linear(v as f32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;

    /// A unit checker of black and white squares seen from 1.6 above it, looking down at
    /// 8° to the horizon through a 64×48 view (fov 50°): every pixel's colour filtered over
    /// its footprint, point-sampled at its centre, and the mean of 16×16 point samples
    /// spread over it (the reference, by brute force). Rows near the horizon are where one
    /// sample a pixel turns the squares into moiré.
    #[test]
    fn a_far_checker_is_the_mean_of_its_pixels_not_moire() {
        let floor = Floor {
            height: 0.0,
            material: 0,
            colors: [Vec3::ONE, Vec3::ZERO],
            checker: 1.0,
        };
        let frame = LocalFrame::WORLD;
        let camera = Camera {
            eye: Vec3::new(0.3, 1.6, 0.1),
            target: Vec3::new(2.3, 1.6 - 2.0 * 8f32.to_radians().tan(), -8.0),
            up: Vec3::Y,
            fov_y_deg: 50.0,
        };
        let (w, h) = (64, 48);
        let rays = camera.rays(w, h);
        let spread = rays.pixel_spread();
        let seen = |x: f32, y: f32, spread: f32| -> Option<f32> {
            let d = rays.direction_at(x, y).normalize();
            let t = (floor.height - camera.eye.y) / d.y;
            (t > 0.0).then(|| floor.color_seen(camera.eye + d * t, d, t, spread, &frame).x)
        };
        let (mut filtered, mut point, mut pixels) = (0.0f64, 0.0f64, 0);
        for y in 0..h {
            for x in 0..w {
                let (cx, cy) = (x as f32 + 0.5, y as f32 + 0.5);
                let Some(f) = seen(cx, cy, spread) else {
                    continue;
                };
                let p = seen(cx, cy, 0.0).expect("the centre meets the floor");
                let mut sum = 0.0f64;
                for k in 0..256 {
                    let (sx, sy) = ((k % 16) as f32 + 0.5, (k / 16) as f32 + 0.5);
                    let y_sample = y as f32 + sy / 16.0;
                    // Samples above the horizon see the sky: the mean of what meets the floor.
                    sum += seen(x as f32 + sx / 16.0, y_sample, 0.0).unwrap_or(0.5) as f64;
                }
                let reference = sum / 256.0;
                assert!((0.0..=1.0).contains(&f), "({x}, {y}): {f}");
                filtered += (f as f64 - reference).abs();
                point += (p as f64 - reference).abs();
                pixels += 1;
            }
        }
        let (filtered, point) = (filtered / pixels as f64, point / pixels as f64);
        eprintln!(
            "{pixels} floor pixels, mean error: filtered {filtered:.4}, one sample {point:.4}"
        );
        assert!(pixels > 1000, "{pixels} pixels see the floor");
        // Measured: filtered 0.043, one sample 0.235 (a white or black pixel where the
        // pixel's squares average grey).
        assert!(
            filtered < 0.08 && filtered < 0.35 * point,
            "mean error against 256 samples a pixel: filtered {filtered:.3}, one sample {point:.3}"
        );
    }

    /// The footprint's square-wave mean against the wave summed over 100,000 points.
    #[test]
    fn the_square_wave_mean_is_its_average_over_the_width() {
        let wave = |u: f64| {
            if u.floor().rem_euclid(2.0) == 0.0 {
                1.0
            } else {
                -1.0
            }
        };
        for (u, w) in [
            (0.3, 0.2),
            (-3.7, 1.3),
            (12.45, 0.05),
            (5.0, 2.0),
            (-0.5, 7.3),
            (2.999, 0.01),
        ] {
            let n = 100_000;
            let sum: f64 = (0..n)
                .map(|k| wave(u - 0.5 * w + w * (k as f64 + 0.5) / n as f64))
                .sum();
            let mean = sum / n as f64;
            let got = square_wave_mean(u, w);
            assert!((got - mean).abs() < 1e-3, "u {u}, w {w}: {got} vs {mean}");
        }
        // Narrower than 1e-4 (a point): the square's own sign.
        assert_eq!(square_wave_mean(0.5, 0.0), 1.0);
        assert_eq!(square_wave_mean(-0.5, 0.0), -1.0);
    }

    /// The specular power against `f64`'s `powf`: whole exponents by repeated squaring (each
    /// rounding's error multiplied by at most the exponent on its way to the result, so
    /// within `shininess` ulps: 1.85e-6 relative at `0.354^48`, far below an 8-bit step)
    /// and others by `f32`'s `powf`; below `f32`'s smallest normal number, zero will do.
    #[test]
    fn the_specular_power_is_x_to_the_shininess() {
        for shininess in [
            1.0f32, 2.0, 7.0, 48.0, 120.0, 200.0, 1024.0, 0.5, 33.3, 2000.0,
        ] {
            for k in 0..=1000 {
                let x = k as f32 / 1000.0;
                let exact = (x as f64).powf(shininess as f64);
                let got = specular_power(x, shininess) as f64;
                let error = (got - exact).abs();
                assert!(
                    error
                        <= shininess.max(1.0) as f64 * f32::EPSILON as f64 * exact
                            + f32::MIN_POSITIVE as f64,
                    "{x}^{shininess}: {got} against {exact}"
                );
            }
        }
    }

    #[test]
    fn srgb_endpoints_and_midpoint() {
        assert_eq!(linear_to_srgb8(0.0), 0);
        assert_eq!(linear_to_srgb8(1.0), 255);
        assert_eq!(linear_to_srgb8(0.5), 188, "linear 0.5 is sRGB 0.735");
        assert_eq!(
            linear_to_srgb8(f32::NAN),
            0,
            "NaN never reaches the image as garbage"
        );
        for v in 0..=255u8 {
            assert_eq!(linear_to_srgb8(srgb8_to_linear(v)), v);
        }
    }

    #[test]
    fn fresnel_is_four_percent_for_glass_at_normal_incidence_and_total_beyond_critical() {
        let r0 = fresnel(1.0, 1.0, 1.5);
        assert!((r0 - 0.04).abs() < 1e-6, "{r0}");
        // Inside glass, past the critical angle asin(1/1.5) = 41.8°.
        assert_eq!(fresnel(50f32.to_radians().cos(), 1.5, 1.0), 1.0);
        assert!(fresnel(0.01, 1.0, 1.5) > 0.9, "grazing incidence reflects");
    }

    #[test]
    fn groups_pick_materials_and_visible_materials_follow_the_primitives() {
        let mut l = Lighting::default();
        l.materials.push(Material {
            reflectivity: 0.5,
            ..Material::default()
        });
        l.groups.push(MaterialGroup {
            first: 10,
            count: 5,
            material: 1,
        });
        assert_eq!(l.material_of(9), 0);
        assert_eq!(l.material_of(10), 1);
        assert_eq!(l.material_of(14), 1);
        assert_eq!(l.material_of(15), 0);
        assert_eq!(l.visible_materials(20), vec![0, 1]);
        assert_eq!(
            l.visible_materials(8),
            vec![0],
            "group 1 has no primitive yet"
        );
        l.groups[0].first = 0;
        assert_eq!(
            l.visible_materials(5),
            vec![1],
            "every primitive is in group 1"
        );
    }

    #[test]
    fn clip_box_range() {
        let b = ClipBox {
            min: Vec3::splat(-1.0),
            max: Vec3::splat(1.0),
        };
        let (near, far) = b
            .range(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z)
            .expect("hits");
        assert!((near - 4.0).abs() < 1e-6 && (far - 6.0).abs() < 1e-6);
        assert!(b.range(Vec3::new(0.0, 3.0, 5.0), Vec3::NEG_Z).is_none());
    }
}
