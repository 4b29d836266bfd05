//! The analytic `f64` reference renderer of the golden scenes, over a floor plane: for
//! metaballs one Wyvill ball, whose isosurface at `T` is exactly the sphere of radius
//! `R·sqrt(s_T)` with `f(s_T) = T` (at `T = 1/2`, `R/2`); for tets the linear field `f = y`,
//! which linear interpolation over any tet mesh reproduces exactly, so its isosurfaces are
//! horizontal squares. Every ray–sphere and ray–plane intersection is solved
//! in closed form; soft shadows and ambient occlusion are integrated by a deterministic
//! stratified quadrature over the light's cap and the hemisphere; a volume's optical depth by
//! composite Simpson over the field; the floor's checker, averaged over each ray's footprint
//! (the engine's closed-form box filter), by a 64×64 midpoint quadrature over the same box.
//! Nothing here calls the engine's tracer: the only thing shared with it is the shading model
//! it is checked against (Lambert + Blinn-Phong in linear light, mirror reflection, Fresnel,
//! opacity, `e^{-τ}`, the footprint's size), written again from its definition.

use glam::DVec3;

/// A light of the reference scene.
#[derive(Clone, Copy, Debug)]
pub enum RefLight {
    Directional {
        to_light: DVec3,
        color: DVec3,
    },
    Sphere {
        center: DVec3,
        radius: f64,
        color: DVec3,
    },
}

#[derive(Clone, Copy, Debug)]
pub struct RefMaterial {
    pub diffuse: DVec3,
    pub specular: f64,
    pub shininess: f64,
    pub reflectivity: f64,
    pub ior: f64,
    pub opacity: f64,
}

impl Default for RefMaterial {
    fn default() -> RefMaterial {
        RefMaterial {
            diffuse: DVec3::ONE,
            specular: 0.0,
            shininess: 32.0,
            reflectivity: 0.0,
            ior: 1.0,
            opacity: 1.0,
        }
    }
}

/// The field whose isosurfaces the scene shows.
#[derive(Clone, Copy, Debug)]
pub enum RefShape {
    /// One Wyvill ball of support radius `support`: its isosurfaces are concentric spheres,
    /// with normals pointing out (down the field).
    Ball {
        center: DVec3,
        support: f64,
        color: DVec3,
    },
    /// The linear field `f = y` on the box `[lo, hi]` (a tet mesh interpolates it exactly):
    /// the isosurface at `v` is the square `y = v` inside the box, its normal `-y` (out of
    /// the solid `f > v`).
    Slab { lo: DVec3, hi: DVec3 },
}

/// A scene of isosurfaces of one field, a floor, lights and effects.
#[derive(Clone, Debug)]
pub struct RefScene {
    pub shape: RefShape,
    /// Isosurfaces: (isovalue, material, albedo for a slab); the first is the session's.
    pub surfaces: Vec<(f64, RefMaterial, DVec3)>,
    /// Their radii (filled by [`RefScene::solve`]).
    pub radii: Vec<f64>,
    pub floor_height: f64,
    pub floor_colors: [DVec3; 2],
    pub checker: f64,
    pub floor_material: RefMaterial,
    /// The angle between neighbouring pixels' camera rays (`2·tan(fov/2)/height`): a ray's
    /// footprint on the floor is this times its length wide across it.
    pub pixel_spread: f64,
    pub lights: Vec<RefLight>,
    pub ambient: DVec3,
    pub background: [DVec3; 2],
    pub clip: Option<(DVec3, DVec3)>,
    pub volume: Option<(f64, DVec3)>,
    pub occlusion_distance: f64,
    // The effects plan, as the engine derives it for this scene.
    pub shadows: bool,
    pub soft: bool,
    pub ao: bool,
    pub reflection_depth: u32,
    pub refraction_depth: u32,
    pub layers: u32,
}

/// Wyvill's kernel in `s = r²/R²`.
pub fn wyvill(s: f64) -> f64 {
    if s >= 1.0 {
        return 0.0;
    }
    1.0 - 22.0 / 9.0 * s + 17.0 / 9.0 * s * s - 4.0 / 9.0 * s * s * s
}

/// The radius of the isosurface `T` of one Wyvill ball of support `support` (bisection).
pub fn iso_radius(support: f64, isovalue: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if wyvill(mid) > isovalue {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    support * (0.5 * (lo + hi)).sqrt()
}

struct Hit {
    t: f64,
    p: DVec3,
    /// Outward normal (sphere) or up (floor).
    n: DVec3,
    albedo: DVec3,
    material: RefMaterial,
}

const EPS: f64 = 1e-7;

impl RefScene {
    /// Solves every isosurface's radius once.
    pub fn solve(&mut self) {
        self.radii = match self.shape {
            RefShape::Ball { support, .. } => self
                .surfaces
                .iter()
                .map(|&(isovalue, _, _)| iso_radius(support, isovalue))
                .collect(),
            RefShape::Slab { .. } => Vec::new(),
        };
    }

    fn inside_clip(&self, p: DVec3) -> bool {
        self.clip
            .is_some_and(|(lo, hi)| p.cmpgt(lo).all() && p.cmplt(hi).all())
    }

    /// Both roots of the ray with the sphere of radius `r` about `center`, ascending.
    fn roots(center: DVec3, o: DVec3, d: DVec3, r: f64) -> Option<(f64, f64)> {
        let oc = o - center;
        let b = oc.dot(d);
        let c = oc.length_squared() - r * r;
        let disc = b * b - c;
        if disc < 0.0 {
            return None;
        }
        let sq = disc.sqrt();
        Some((-b - sq, -b + sq))
    }

    /// Crossings of isosurface `k` on `(t0, t1)` outside the clip box, ascending.
    fn crossings(&self, o: DVec3, d: DVec3, k: usize, t0: f64, t1: f64) -> Vec<f64> {
        let candidates: Vec<f64> = match self.shape {
            RefShape::Ball { center, .. } => match Self::roots(center, o, d, self.radii[k]) {
                Some((a, b)) => vec![a, b],
                None => Vec::new(),
            },
            RefShape::Slab { lo, hi } => {
                let v = self.surfaces[k].0;
                let t = (v - o.y) / d.y;
                let p = o + t * d;
                if p.x > lo.x && p.x < hi.x && p.z > lo.z && p.z < hi.z && v > lo.y && v < hi.y {
                    vec![t]
                } else {
                    Vec::new()
                }
            }
        };
        candidates
            .into_iter()
            .filter(|&t| t > t0 + EPS && t < t1 && !self.inside_clip(o + t * d))
            .collect()
    }

    /// Outward normal and albedo of isosurface `k` at `p`.
    fn surface_at(&self, k: usize, p: DVec3) -> (DVec3, DVec3) {
        match self.shape {
            RefShape::Ball { center, color, .. } => ((p - center).normalize(), color),
            RefShape::Slab { .. } => (DVec3::NEG_Y, self.surfaces[k].2),
        }
    }

    fn closest(&self, o: DVec3, d: DVec3, t0: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut limit = f64::INFINITY;
        if self.volume.is_none() {
            for k in 0..self.surfaces.len() {
                if let Some(&t) = self.crossings(o, d, k, t0, limit).first() {
                    limit = t;
                    let p = o + t * d;
                    let (n, albedo) = self.surface_at(k, p);
                    best = Some(Hit {
                        t,
                        p,
                        n,
                        albedo,
                        material: self.surfaces[k].1,
                    });
                }
            }
        }
        let t = (self.floor_height - o.y) / d.y;
        if t > t0 + EPS && t < limit {
            let p = o + t * d;
            best = Some(Hit {
                t,
                p,
                n: DVec3::Y,
                albedo: self.floor_albedo(p, d, t),
                material: self.floor_material,
            });
        }
        best
    }

    /// The checker's mean colour over the footprint of a ray along unit `d` that meets the
    /// floor at `p`, `t` from its origin: across the ray `pixel_spread · t` wide, along its
    /// heading that divided by `|d.y|`; the mean over the axis-aligned box bounding that
    /// ellipse, by the midpoint rule on 64×64 points.
    fn floor_albedo(&self, p: DVec3, d: DVec3, t: f64) -> DVec3 {
        let square = |x: f64, z: f64| {
            let ix = (x / self.checker).floor() as i64;
            let iz = (z / self.checker).floor() as i64;
            self.floor_colors[((ix + iz) & 1) as usize]
        };
        if self.checker <= 0.0 {
            return self.floor_colors[0];
        }
        let across = self.pixel_spread * t;
        let along = across / d.y.abs().max(1e-3);
        let heading = DVec3::new(d.x, 0.0, d.z).normalize_or_zero();
        // Half-widths of the box bounding the ellipse with these axes.
        let half = |h: f64, o: f64| 0.5 * ((along * h).powi(2) + (across * o).powi(2)).sqrt();
        let (hx, hz) = (half(heading.x, heading.z), half(heading.z, heading.x));
        const N: usize = 64;
        let mut sum = DVec3::ZERO;
        for i in 0..N {
            for k in 0..N {
                let fx = (i as f64 + 0.5) / N as f64 * 2.0 - 1.0;
                let fz = (k as f64 + 0.5) / N as f64 * 2.0 - 1.0;
                sum += square(p.x + fx * hx, p.z + fz * hz);
            }
        }
        sum / (N * N) as f64
    }

    /// `∫ F dt` over `(t0, t1)` outside the clip box, by composite Simpson.
    fn optical_depth(&self, o: DVec3, d: DVec3, t0: f64, t1: f64) -> f64 {
        let RefShape::Ball {
            center, support, ..
        } = self.shape
        else {
            return 0.0;
        };
        let Some((a, b)) = Self::roots(center, o, d, support) else {
            return 0.0;
        };
        let (a, b) = (a.max(t0), b.min(t1));
        if a >= b || a.is_nan() || b.is_nan() {
            return 0.0;
        }
        let n = 4000;
        let h = (b - a) / n as f64;
        let f = |t: f64| {
            let p = o + t * d;
            if self.inside_clip(p) {
                0.0
            } else {
                wyvill((p - center).length_squared() / (support * support))
            }
        };
        let mut sum = f(a) + f(b);
        for k in 1..n {
            sum += if k % 2 == 1 { 4.0 } else { 2.0 } * f(a + k as f64 * h);
        }
        sum * h / 3.0
    }

    /// Share of light passing from `o` along `d` over `(0, t_max)`.
    fn transmittance(&self, o: DVec3, d: DVec3, t_max: f64) -> f64 {
        let t = (self.floor_height - o.y) / d.y;
        if t > EPS && t < t_max {
            return 0.0;
        }
        if let Some((density, _)) = self.volume {
            return (-density * self.optical_depth(o, d, 0.0, t_max)).exp();
        }
        let mut passed = 1.0;
        for k in 0..self.surfaces.len() {
            let crossings = self.crossings(o, d, k, 0.0, t_max);
            if crossings.is_empty() {
                continue;
            }
            if self.layers == 0 || crossings.len() as u32 > self.layers {
                return 0.0;
            }
            for _ in &crossings {
                passed *= 1.0 - self.surfaces[k].1.opacity;
            }
            if passed <= 1e-3 {
                return 0.0;
            }
        }
        passed
    }

    fn background(&self, d: DVec3) -> DVec3 {
        let a = 0.5 * (d.y.clamp(-1.0, 1.0) + 1.0);
        self.background[0].lerp(self.background[1], a)
    }

    /// Linear radiance along `o + t d`, `t > t0`.
    pub fn radiance(&self, o: DVec3, d: DVec3, t0: f64, depth: u32, layers: u32) -> DVec3 {
        let hit = self.closest(o, d, t0);
        let far = hit.as_ref().map_or(1.0e4, |h| h.t);
        let mut color = match &hit {
            Some(h) => self.shade(o, d, h, depth, layers),
            None => self.background(d),
        };
        if let Some((density, vol_color)) = self.volume {
            let tr = (-density * self.optical_depth(o, d, t0, far)).exp();
            color = color * tr + vol_color * (1.0 - tr);
        }
        color
    }

    fn shade(&self, o: DVec3, d: DVec3, h: &Hit, depth: u32, layers: u32) -> DVec3 {
        let m = h.material;
        let n = if h.n.dot(d) > 0.0 { -h.n } else { h.n };
        let entering = h.n.dot(d) < 0.0;
        let albedo = h.albedo * m.diffuse;
        let mut ambient = self.ambient * albedo;
        if self.ao {
            ambient *= self.occlusion(h.p, n);
        }
        let mut color = ambient;
        for light in &self.lights {
            let (to_light, e, t_max) = match *light {
                RefLight::Directional { to_light, color } => (to_light, color, 1.0e4),
                RefLight::Sphere {
                    center,
                    radius,
                    color,
                } => {
                    let v = center - h.p;
                    let d2 = v.length_squared();
                    (v / d2.sqrt(), color / d2, d2.sqrt() - radius)
                }
            };
            let n_dot_l = n.dot(to_light);
            if n_dot_l <= 0.0 {
                continue;
            }
            let visibility = if !self.shadows {
                1.0
            } else {
                match *light {
                    RefLight::Sphere { center, radius, .. } if self.soft => {
                        self.light_cap_visibility(h.p, center, radius)
                    }
                    _ => self.transmittance(h.p, to_light, t_max),
                }
            };
            let half = (to_light - d).normalize();
            let spec = if m.specular > 0.0 {
                n.dot(half).max(0.0).powf(m.shininess) * m.specular
            } else {
                0.0
            };
            color += e * (albedo * n_dot_l + DVec3::splat(spec)) * visibility;
        }
        if m.opacity < 1.0 && (self.layers > 0 || self.refraction_depth > 0) {
            let behind = if m.ior != 1.0 && depth < self.refraction_depth {
                Some(self.refract(h, d, n, entering, &m, depth, layers))
            } else if layers > 0 {
                Some(self.radiance(o, d, h.t, depth, layers - 1))
            } else {
                None
            };
            if let Some(b) = behind {
                color = color * m.opacity + b * (1.0 - m.opacity);
            }
        }
        if m.reflectivity > 0.0 && depth < self.reflection_depth {
            let r = d - 2.0 * d.dot(n) * n;
            let mirror = self.radiance(h.p, r, 0.0, depth + 1, layers);
            color = color * (1.0 - m.reflectivity) + mirror * m.reflectivity;
        }
        color
    }

    #[allow(clippy::too_many_arguments)]
    fn refract(
        &self,
        h: &Hit,
        d: DVec3,
        n: DVec3,
        entering: bool,
        m: &RefMaterial,
        depth: u32,
        layers: u32,
    ) -> DVec3 {
        let (n1, n2) = if entering { (1.0, m.ior) } else { (m.ior, 1.0) };
        let cos_i = (-d.dot(n)).clamp(0.0, 1.0);
        let eta = n1 / n2;
        let sin_t2 = eta * eta * (1.0 - cos_i * cos_i);
        let reflectance = if sin_t2 >= 1.0 {
            1.0
        } else {
            let cos_t = (1.0 - sin_t2).sqrt();
            let rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t);
            let rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i);
            0.5 * (rs * rs + rp * rp)
        };
        let mut color = DVec3::ZERO;
        if reflectance > 0.0 {
            let r = d - 2.0 * d.dot(n) * n;
            color += reflectance * self.radiance(h.p, r, 0.0, depth + 1, layers);
        }
        if reflectance < 1.0 {
            let cos_t = (1.0 - sin_t2).sqrt();
            let t = (eta * d + (eta * cos_i - cos_t) * n).normalize();
            color += (1.0 - reflectance) * self.radiance(h.p, t, 0.0, depth + 1, layers);
        }
        color
    }

    /// Quadrature points per axis of the soft-shadow and occlusion integrals.
    const Q: usize = 48;

    /// Share of the sphere light's cap seen from `p`, uniform in solid angle.
    fn light_cap_visibility(&self, p: DVec3, center: DVec3, radius: f64) -> f64 {
        let v = center - p;
        let dist = v.length();
        let axis = v / dist;
        let cos_max = (1.0 - (radius / dist).powi(2)).max(0.0).sqrt();
        let (t, b) = basis(axis);
        let mut seen = 0.0;
        for i in 0..Self::Q {
            for j in 0..Self::Q {
                let u1 = (i as f64 + 0.5) / Self::Q as f64;
                let u2 = (j as f64 + 0.5) / Self::Q as f64;
                let cos_t = 1.0 - u1 * (1.0 - cos_max);
                let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
                let phi = std::f64::consts::TAU * u2;
                let dir = t * (sin_t * phi.cos()) + b * (sin_t * phi.sin()) + axis * cos_t;
                let oc = p - center;
                let bq = oc.dot(dir);
                let c = oc.length_squared() - radius * radius;
                let t_light = -bq - (bq * bq - c).max(0.0).sqrt();
                seen += self.transmittance(p, dir, t_light);
            }
        }
        seen / (Self::Q * Self::Q) as f64
    }

    /// Share of the cosine-weighted hemisphere about `n` open within the occlusion distance.
    fn occlusion(&self, p: DVec3, n: DVec3) -> f64 {
        let (t, b) = basis(n);
        let mut open = 0.0;
        for i in 0..Self::Q {
            for j in 0..Self::Q {
                let u1 = (i as f64 + 0.5) / Self::Q as f64;
                let u2 = (j as f64 + 0.5) / Self::Q as f64;
                let r = u1.sqrt();
                let phi = std::f64::consts::TAU * u2;
                let z = (1.0 - u1).sqrt();
                let dir = t * (r * phi.cos()) + b * (r * phi.sin()) + n * z;
                open += self.transmittance(p, dir, self.occlusion_distance);
            }
        }
        open / (Self::Q * Self::Q) as f64
    }
}

fn basis(n: DVec3) -> (DVec3, DVec3) {
    let helper = if n.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let t = n.cross(helper).normalize();
    (t, n.cross(t))
}

/// The pinhole camera's ray through the centre of pixel (`x`, `y`), `y` from the top.
pub fn camera_ray(
    eye: DVec3,
    target: DVec3,
    up: DVec3,
    fov_y_deg: f64,
    (width, height): (u32, u32),
    (x, y): (u32, u32),
) -> DVec3 {
    let forward = (target - eye).normalize();
    let right = forward.cross(up).normalize();
    let up = right.cross(forward);
    let half_h = (fov_y_deg.to_radians() * 0.5).tan();
    let half_w = half_h * width as f64 / height as f64;
    let u = (x as f64 + 0.5) / width as f64 * 2.0 - 1.0;
    let v = 1.0 - (y as f64 + 0.5) / height as f64 * 2.0;
    (forward + right * (u * half_w) + up * (v * half_h)).normalize()
}

/// IEC 61966-2-1 encoding of linear light, to 8 bits.
pub fn srgb8(v: f64) -> u8 {
    let v = v.clamp(0.0, 1.0);
    let s = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}
