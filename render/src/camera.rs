//! A pinhole camera and the rays it shoots through pixel centres.

use crate::geom::frame::LocalFrame;
use crate::ray::Ray;
use glam::Vec3;

/// A look-at pinhole camera in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub fov_y_deg: f32,
}

impl Camera {
    /// The same camera in `frame` (eye and target moved in `f64`; see [`LocalFrame`]).
    pub fn in_frame(&self, frame: &LocalFrame) -> Camera {
        Camera {
            eye: frame.local_from_world(self.eye),
            target: frame.local_from_world(self.target),
            ..*self
        }
    }

    /// The camera turned so that an image `height` pixels high moves by `(dx, dy)` pixels
    /// (right and down) at its centre: a sub-pixel offset for antialiasing passes (a turn, not
    /// a shift of the image plane, so pixels far from the centre move by up to
    /// `1/cos²(fov/2)` times as much, 1.17 at 45°: the samples stay within their pixels'
    /// neighbourhood, which is all an average over them needs).
    pub fn jittered(&self, (dx, dy): (f32, f32), height: u32) -> Camera {
        let offset = self.target - self.eye;
        let [forward, right, up] = self.basis();
        let pixel = 2.0 * (self.fov_y_deg.to_radians() * 0.5).tan() / height.max(1) as f32;
        let turned = forward + (right * dx - up * dy) * pixel;
        Camera {
            target: self.eye + turned.normalize() * offset.length(),
            ..*self
        }
    }

    /// The unit forward, right and up directions of the view.
    fn basis(&self) -> [Vec3; 3] {
        let forward = (self.target - self.eye).normalize();
        let right = forward.cross(self.up).normalize();
        [forward, right, right.cross(forward)]
    }

    /// Precomputes what every primary ray needs for an image of `width` × `height`.
    pub fn rays(&self, width: u32, height: u32) -> PrimaryRays {
        let [forward, right, up] = self.basis();
        let half_h = (self.fov_y_deg.to_radians() * 0.5).tan();
        let half_w = half_h * width as f32 / height.max(1) as f32;
        let right_step = right * (2.0 * half_w / width.max(1) as f32);
        let down_step = -up * (2.0 * half_h / height.max(1) as f32);
        PrimaryRays {
            eye: self.eye,
            forward,
            right_step,
            down_step,
            top_left: forward - right * half_w + up * half_h,
            right_dual: right_step / right_step.length_squared(),
            down_dual: down_step / down_step.length_squared(),
        }
    }
}

/// Pixels [`PrimaryRays::row_rays`] computes together.
pub const ROW_LANES: usize = 8;

/// Generator of primary rays for one image size.
#[derive(Clone, Copy, Debug)]
pub struct PrimaryRays {
    eye: Vec3,
    forward: Vec3,
    right_step: Vec3,
    down_step: Vec3,
    top_left: Vec3,
    /// `right_step / |right_step|²` and likewise: dotted with an offset in the image plane
    /// they give it in pixels (the steps are orthogonal).
    right_dual: Vec3,
    down_dual: Vec3,
}

impl PrimaryRays {
    /// The angle (radians, at the image's centre) between neighbouring pixels' rays: a
    /// pixel's footprint at distance `t` is about `t` times this wide.
    pub fn pixel_spread(&self) -> f32 {
        self.right_step.length()
    }

    /// The ray through the centre of pixel (`x`, `y`), with `y` counted from the top.
    pub fn through_pixel(&self, x: u32, y: u32) -> Ray {
        let dir =
            self.top_left + self.right_step * (x as f32 + 0.5) + self.down_step * (y as f32 + 0.5);
        Ray::new(self.eye, dir)
    }

    /// The rays through pixels `x0..x0 + out.len()` of row `y`, into `out`, and their
    /// directions' reciprocals into `inv` (as long): `through_pixel(x, y)` and `dir.recip()`,
    /// bit for bit ([`PrimaryRays::row_directions`]).
    pub fn row_rays(&self, y: u32, x0: u32, out: &mut [Ray], inv: &mut [Vec3]) {
        let n = out.len().min(inv.len());
        self.row_directions(y, x0, n, |k, dir, recip| {
            out[k] = Ray {
                origin: self.eye,
                dir,
            };
            inv[k] = recip;
        });
    }

    /// The rays through pixels `x0..x1` × `y0..y1`, row by row, into `out`, and their
    /// directions' reciprocals into `inv` (both cleared first).
    pub fn tile_rays(
        &self,
        (x0, y0, x1, y1): (u32, u32, u32, u32),
        out: &mut Vec<Ray>,
        inv: &mut Vec<Vec3>,
    ) {
        let width = x1.saturating_sub(x0) as usize;
        let n = width * y1.saturating_sub(y0) as usize;
        out.clear();
        out.resize(n, Ray::new(self.eye, Vec3::Z));
        inv.clear();
        inv.resize(n, Vec3::ZERO);
        for (row, y) in (y0..y1).enumerate() {
            let span = row * width..(row + 1) * width;
            self.row_rays(y, x0, &mut out[span.clone()], &mut inv[span]);
        }
    }

    /// `put(k, dir, recip)` for the pixels `x0 + k`, `k < n`, of row `y`: `through_pixel`'s
    /// unit direction and its `recip()`, bit for bit — the same IEEE operations in the same
    /// order — computed [`ROW_LANES`] pixels at a time in arrays, so that the compiler turns
    /// the square roots and divisions into vector instructions (a 16-wide tile's rays one by
    /// one cost up to a sixth of a metaball packet's traversal).
    #[inline]
    pub fn row_directions(
        &self,
        y: u32,
        x0: u32,
        n: usize,
        mut put: impl FnMut(usize, Vec3, Vec3),
    ) {
        const L: usize = ROW_LANES;
        let fy = y as f32 + 0.5;
        let (tl, rs, ds) = (self.top_left, self.right_step, self.down_step);
        for start in (0..n).step_by(L) {
            let (mut dx, mut dy, mut dz) = ([0f32; L], [0f32; L], [0f32; L]);
            for l in 0..L {
                // `x as f32` for every pixel index (below 2^31, where i32 and u32 agree).
                let fx = (x0 as i32 + (start + l) as i32) as f32 + 0.5;
                dx[l] = tl.x + rs.x * fx + ds.x * fy;
                dy[l] = tl.y + rs.y * fx + ds.y * fy;
                dz[l] = tl.z + rs.z * fx + ds.z * fy;
            }
            // `Vec3::normalize`: `self * (1 / sqrt(x·x + y·y + z·z))`.
            for l in 0..L {
                let r = 1.0 / (dx[l] * dx[l] + dy[l] * dy[l] + dz[l] * dz[l]).sqrt();
                dx[l] *= r;
                dy[l] *= r;
                dz[l] *= r;
            }
            let (mut ix, mut iy, mut iz) = ([0f32; L], [0f32; L], [0f32; L]);
            for l in 0..L {
                ix[l] = 1.0 / dx[l];
                iy[l] = 1.0 / dy[l];
                iz[l] = 1.0 / dz[l];
            }
            for l in 0..L.min(n - start) {
                put(
                    start + l,
                    Vec3::new(dx[l], dy[l], dz[l]),
                    Vec3::new(ix[l], iy[l], iz[l]),
                );
            }
        }
    }

    /// The unnormalised direction (component 1 along the view axis) of the ray through the
    /// continuous pixel coordinates (`x`, `y`): pixel (`x`, `y`)'s own ray at `x + 0.5`,
    /// `y + 0.5`, as in [`PrimaryRays::through_pixel`].
    pub fn direction_at(&self, x: f32, y: f32) -> Vec3 {
        self.top_left + self.right_step * x + self.down_step * y
    }

    /// The eye, every primary ray's origin.
    pub fn eye(&self) -> Vec3 {
        self.eye
    }

    /// Where `point` appears in the image: the continuous pixel coordinates `(x, y)` whose
    /// ray passes through it (pixel `(x, y)`'s own ray has exactly those), or `None` unless
    /// the point lies in front of the eye.
    pub fn pixel_of(&self, point: Vec3) -> Option<(f32, f32)> {
        let v = point - self.eye;
        let depth = v.dot(self.forward);
        if !in_front(depth, v.length_squared()) {
            return None;
        }
        // Scaled so its component along `forward` is 1, like every unnormalised pixel ray.
        let rel = v * (1.0 / depth) - self.top_left;
        Some((
            rel.dot(self.right_dual) - 0.5,
            rel.dot(self.down_dual) - 0.5,
        ))
    }

    /// The least and greatest continuous pixel coordinates `[x_lo, y_lo, x_hi, y_hi]` of the
    /// eight corners of the box `lo..hi` ([`PrimaryRays::pixel_of`] of each), or `None` unless
    /// every corner lies in front of the eye. A corner's offset from the eye along each axis
    /// is one of two values, so its dot products are sums of per-axis products shared with
    /// three other corners: the 24 products once, then per corner four sums of three, a
    /// division and two multiply-subtracts, over arrays (packed SSE sums and products in the
    /// portable release build, checked in the assembly; the eight divisions stay scalar). A
    /// node's cover on `scattered-1k` takes about 175 instructions against 770. The
    /// coordinates can differ from `pixel_of`'s by rounding (the test
    /// `a_boxs_corners_land_where_pixel_of_puts_them` bounds it), far below the pixel a cover
    /// is widened by.
    pub fn box_on_image(&self, lo: Vec3, hi: Vec3) -> Option<[f32; 4]> {
        let sides = [(lo - self.eye).to_array(), (hi - self.eye).to_array()];
        let (f, r, d) = (
            self.forward.to_array(),
            self.right_dual.to_array(),
            self.down_dual.to_array(),
        );
        // Per axis and side: the offset's products with forward, right_dual and down_dual,
        // and its square.
        let mut terms = [[[0f32; 4]; 2]; 3];
        for (k, axis) in terms.iter_mut().enumerate() {
            for (side, t) in axis.iter_mut().enumerate() {
                let v = sides[side][k];
                *t = [v * f[k], v * r[k], v * d[k], v * v];
            }
        }
        let (cx, cy) = (
            self.top_left.dot(self.right_dual) + 0.5,
            self.top_left.dot(self.down_dual) + 0.5,
        );
        // Per corner (bit k of its index: the side along axis k), in arrays.
        let (mut depth, mut nx, mut ny, mut length_squared) =
            ([0f32; 8], [0f32; 8], [0f32; 8], [0f32; 8]);
        for corner in 0..8 {
            let (a, b, c) = (
                &terms[0][corner & 1],
                &terms[1][(corner >> 1) & 1],
                &terms[2][(corner >> 2) & 1],
            );
            depth[corner] = a[0] + b[0] + c[0];
            nx[corner] = a[1] + b[1] + c[1];
            ny[corner] = a[2] + b[2] + c[2];
            length_squared[corner] = a[3] + b[3] + c[3];
        }
        let mut all_in_front = true;
        for corner in 0..8 {
            let depth = depth[corner];
            all_in_front &= in_front(depth, length_squared[corner]);
        }
        if !all_in_front {
            return None;
        }
        let mut out = [
            f32::INFINITY,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NEG_INFINITY,
        ];
        for corner in 0..8 {
            let inv = 1.0 / depth[corner];
            let (x, y) = (nx[corner] * inv - cx, ny[corner] * inv - cy);
            out = [out[0].min(x), out[1].min(y), out[2].max(x), out[3].max(y)];
        }
        Some(out)
    }

    /// Unit vector along the view axis, for depth along the view direction.
    pub fn forward(&self) -> Vec3 {
        self.forward
    }

    /// What [`PrimaryRays::through_pixel`] is made of, for a backend that builds the rays
    /// itself (the GPU's): eye, direction through the top-left corner, one pixel's step right
    /// and down, and the view axis.
    pub fn parts(&self) -> [Vec3; 5] {
        [
            self.eye,
            self.top_left,
            self.right_step,
            self.down_step,
            self.forward,
        ]
    }
}

/// Whether a point at `depth` along the view axis and squared distance `length_squared` from
/// the eye lies far enough in front of it to project ([`PrimaryRays::pixel_of`]).
#[inline(always)]
fn in_front(depth: f32, length_squared: f32) -> bool {
    depth > 0.0 && depth * depth > 1e-12 * length_squared
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_pixel_looks_at_the_target() {
        let camera = Camera {
            eye: Vec3::new(0.0, 0.0, 5.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            fov_y_deg: 45.0,
        };
        let rays = camera.rays(101, 101);
        let ray = rays.through_pixel(50, 50);
        assert!((ray.dir - Vec3::NEG_Z).length() < 1e-6);
        let top = rays.through_pixel(50, 0);
        assert!(top.dir.y > 0.0, "row 0 is the top of the image");
        let (x, y) = rays.pixel_of(top.at(3.0)).expect("in front of the eye");
        assert!((x - 50.0).abs() < 1e-3 && y.abs() < 1e-3, "{x} {y}");
        let corner = camera.rays(64, 48).through_pixel(63, 47);
        let (x, y) = camera
            .rays(64, 48)
            .pixel_of(corner.at(7.0))
            .expect("in front");
        assert!(
            (x - 63.0).abs() < 1e-3 && (y - 47.0).abs() < 1e-3,
            "{x} {y}"
        );
        assert!(
            rays.pixel_of(Vec3::new(0.0, 0.0, 6.0)).is_none(),
            "behind the eye"
        );
    }

    /// Cameras looking along and across the axes.
    fn cameras() -> [Camera; 3] {
        [
            (Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, 45.0),
            (Vec3::new(3.1, -2.7, 11.3), Vec3::new(0.2, 0.4, -0.9), 30.0),
            (Vec3::new(-40.0, 25.0, 0.5), Vec3::new(1.0, -3.0, 2.0), 70.0),
        ]
        .map(|(eye, target, fov_y_deg)| Camera {
            eye,
            target,
            up: Vec3::Y,
            fov_y_deg,
        })
    }

    /// `box_on_image` gives the least and greatest of `pixel_of` over a box's eight corners,
    /// within a thousandth of a pixel plus 1e-5 of the coordinate (rounding), and `None`
    /// exactly where a corner is not in front of the eye: random boxes around, beside and
    /// behind three cameras at two image sizes.
    #[test]
    fn a_boxs_corners_land_where_pixel_of_puts_them() {
        let mut rng = crate::geom::rng::SplitMix64(23);
        let (mut bounded, mut unbounded) = (0, 0);
        for camera in cameras() {
            let (eye, target) = (camera.eye, camera.target);
            let reach = (target - eye).length() * 2.0;
            for (w, h) in [(1920, 1080), (64, 48)] {
                let rays = camera.rays(w, h);
                for _ in 0..2000 {
                    let centre = eye
                        + Vec3::new(
                            rng.range(-reach, reach),
                            rng.range(-reach, reach),
                            rng.range(-reach, reach),
                        );
                    let half = Vec3::new(
                        rng.range(0.0, 0.2 * reach),
                        rng.range(0.0, 0.2 * reach),
                        rng.range(0.0, 0.2 * reach),
                    );
                    let (lo, hi) = (centre - half, centre + half);
                    let corners: Option<Vec<(f32, f32)>> = crate::geom::tile::box_corners(lo, hi)
                        .map(|p| rays.pixel_of(p))
                        .collect();
                    let got = rays.box_on_image(lo, hi);
                    let (Some(corners), Some(got)) = (&corners, got) else {
                        assert_eq!(corners.is_some(), got.is_some(), "box {lo} {hi}");
                        unbounded += 1;
                        continue;
                    };
                    let fold = |pick: fn(&(f32, f32)) -> f32, hi: bool| {
                        let vals = corners.iter().map(pick);
                        if hi {
                            vals.fold(f32::NEG_INFINITY, f32::max)
                        } else {
                            vals.fold(f32::INFINITY, f32::min)
                        }
                    };
                    let want = [
                        fold(|c| c.0, false),
                        fold(|c| c.1, false),
                        fold(|c| c.0, true),
                        fold(|c| c.1, true),
                    ];
                    for k in 0..4 {
                        let slack = 1e-3 + 1e-5 * want[k].abs();
                        assert!(
                            (got[k] - want[k]).abs() <= slack,
                            "box {lo} {hi}: {got:?} against {want:?}"
                        );
                    }
                    bounded += 1;
                }
            }
        }
        assert!(
            bounded > 2000 && unbounded > 2000,
            "{bounded} bounded, {unbounded} not"
        );
    }

    /// The row generator gives `through_pixel`'s rays and their reciprocal directions bit
    /// for bit, at any start and length (partial lane groups included), for cameras looking
    /// along and across the axes.
    #[test]
    fn row_rays_are_through_pixel_bit_for_bit() {
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        let mut compared = 0;
        for camera in cameras() {
            for (w, h) in [(1920, 1080), (37, 29)] {
                let rays = camera.rays(w, h);
                for y in [0, h / 3, h - 1] {
                    for (x0, len) in [(0, w), (5, 16), (w - 3, 3), (17, 1)] {
                        let mut out = vec![Ray::new(Vec3::ZERO, Vec3::Z); len as usize];
                        let mut inv = vec![Vec3::ZERO; len as usize];
                        rays.row_rays(y, x0, &mut out, &mut inv);
                        for (k, (r, i)) in out.iter().zip(&inv).enumerate() {
                            let want = rays.through_pixel(x0 + k as u32, y);
                            assert_eq!(bits(r.origin), bits(want.origin));
                            assert_eq!(bits(r.dir), bits(want.dir), "pixel {} {y}", x0 + k as u32);
                            assert_eq!(bits(*i), bits(want.dir.recip()));
                            compared += 1;
                        }
                    }
                }
            }
        }
        assert!(compared > 10_000);
    }
}
