//! A tile of a camera's image and the tile's pixels a shape may cover: the culling test of
//! packet traversal (tetrahedral-isosurface-ray-tracing.txt §5.2), shared by the metaball
//! packets (boxes of the Fitted BVH) and the tet packets (boxes and isopolygons).

use crate::camera::PrimaryRays;
use glam::Vec3;

/// The pixels of a tile: `width × height` from `(x0, y0)` of a camera's image.
#[derive(Clone, Copy, Debug)]
pub struct TileGrid {
    pub rays: PrimaryRays,
    pub x0: u32,
    pub y0: u32,
    pub width: u32,
    pub height: u32,
}

/// The tile pixels whose rays may meet a convex shape.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Cover {
    /// No bound (a point is not in front of the eye).
    Unknown,
    /// No pixel of the tile.
    Empty,
    /// Tile-relative columns `c0..=c1` and rows `r0..=r1`.
    Rect { c0: u32, c1: u32, r0: u32, r1: u32 },
}

impl TileGrid {
    /// The pixels of the projection of the convex hull of `points`, widened by one pixel
    /// (far beyond rounding) and clipped to the tile.
    #[inline]
    pub fn cover(&self, points: impl IntoIterator<Item = Vec3>) -> Cover {
        let (mut lo_x, mut lo_y) = (f32::INFINITY, f32::INFINITY);
        let (mut hi_x, mut hi_y) = (f32::NEG_INFINITY, f32::NEG_INFINITY);
        for p in points {
            let Some((x, y)) = self.rays.pixel_of(p) else {
                return Cover::Unknown;
            };
            lo_x = lo_x.min(x);
            lo_y = lo_y.min(y);
            hi_x = hi_x.max(x);
            hi_y = hi_y.max(y);
        }
        self.rect_around([lo_x, lo_y, hi_x, hi_y])
    }

    /// [`TileGrid::cover`] of the box `lo..hi` (its eight corners), projected at once
    /// ([`PrimaryRays::box_on_image`]).
    #[inline]
    pub fn cover_box(&self, lo: Vec3, hi: Vec3) -> Cover {
        match self.rays.box_on_image(lo, hi) {
            Some(bounds) => self.rect_around(bounds),
            None => Cover::Unknown,
        }
    }

    /// The tile's pixels within `[lo_x, hi_x] × [lo_y, hi_y]` widened by one pixel.
    #[inline]
    fn rect_around(&self, [lo_x, lo_y, hi_x, hi_y]: [f32; 4]) -> Cover {
        let (x0, y0) = (self.x0 as f32, self.y0 as f32);
        let (x1, y1) = (x0 + self.width as f32 - 1.0, y0 + self.height as f32 - 1.0);
        let (lo_x, lo_y) = ((lo_x - 1.0).max(x0), (lo_y - 1.0).max(y0));
        let (hi_x, hi_y) = ((hi_x + 1.0).min(x1), (hi_y + 1.0).min(y1));
        if !(lo_x <= hi_x && lo_y <= hi_y) {
            return Cover::Empty;
        }
        Cover::Rect {
            c0: (lo_x.ceil() - x0) as u32,
            c1: (hi_x.floor() - x0) as u32,
            r0: (lo_y.ceil() - y0) as u32,
            r1: (hi_y.floor() - y0) as u32,
        }
    }
}

/// The four side planes of the pyramid from the eye that holds every ray of a [`Cover`]'s
/// pixels, each moved out by one more pixel: unit normals pointing inwards, the eye on every
/// plane. A sphere farther than its radius outside one of them meets none of those rays, by a
/// margin of at least a pixel's width at its distance (far beyond the rounding of a ray's own
/// sphere test).
#[derive(Clone, Copy, Debug)]
pub struct Frustum {
    pub eye: Vec3,
    pub normals: [Vec3; 4],
}

impl Frustum {
    /// Whether the sphere at `centre` of radius `radius` lies wholly outside the pyramid.
    #[inline]
    pub fn excludes_sphere(&self, centre: Vec3, radius: f32) -> bool {
        let v = centre - self.eye;
        self.normals.iter().any(|n| n.dot(v) < -radius)
    }
}

impl TileGrid {
    /// The pyramid of the rays of `cover`'s pixels, widened by a pixel on every side; `None`
    /// without a rectangle.
    pub fn frustum(&self, cover: Cover) -> Option<Frustum> {
        let Cover::Rect { c0, c1, r0, r1 } = cover else {
            return None;
        };
        // Pixel (x, y)'s ray is at x + 0.5, y + 0.5; one pixel more on each side.
        let (xl, xr) = ((self.x0 + c0) as f32 - 0.5, (self.x0 + c1) as f32 + 1.5);
        let (yt, yb) = ((self.y0 + r0) as f32 - 0.5, (self.y0 + r1) as f32 + 1.5);
        let d = |x: f32, y: f32| self.rays.direction_at(x, y);
        let corners = [d(xl, yt), d(xr, yt), d(xr, yb), d(xl, yb)];
        let inside = d(0.5 * (xl + xr), 0.5 * (yt + yb));
        let mut normals = [Vec3::ZERO; 4];
        for (k, n) in normals.iter_mut().enumerate() {
            let m = corners[k].cross(corners[(k + 1) % 4]).normalize_or_zero();
            *n = if m.dot(inside) < 0.0 { -m } else { m };
            if *n == Vec3::ZERO {
                return None;
            }
        }
        Some(Frustum {
            eye: self.rays.eye(),
            normals,
        })
    }
}

/// The eight corners of `lo..hi`.
#[inline]
pub fn box_corners(lo: Vec3, hi: Vec3) -> impl Iterator<Item = Vec3> {
    (0..8).map(move |i| {
        Vec3::new(
            if i & 1 != 0 { hi.x } else { lo.x },
            if i & 2 != 0 { hi.y } else { lo.y },
            if i & 4 != 0 { hi.z } else { lo.z },
        )
    })
}

impl Cover {
    /// Ray indices (row-major in a tile `width` wide) in the cover, from `from` on; all of
    /// `from..n` when there is no bound.
    #[inline]
    pub fn rays(self, width: u32, from: usize, n: usize) -> impl Iterator<Item = usize> {
        let (rect, all) = match self {
            Cover::Rect { c0, c1, r0, r1 } => (Some((c0, c1, r0, r1)), 0..0),
            Cover::Empty => (None, 0..0),
            Cover::Unknown => (None, from..n),
        };
        let w = width as usize;
        let in_rect = rect.into_iter().flat_map(move |(c0, c1, r0, r1)| {
            let first_row = (from / w).max(r0 as usize);
            (first_row..=r1 as usize).flat_map(move |r| {
                (c0 as usize..=c1 as usize)
                    .map(move |c| r * w + c)
                    .filter(move |&i| i >= from)
            })
        });
        all.chain(in_rect)
    }

    /// Calls `f` on [`Cover::rays`] until it returns `true`, with plain loops (the metaball
    /// packets' leaf loop, where the iterator chain measured slower).
    #[inline]
    pub fn visit(self, width: usize, from: usize, n: usize, mut f: impl FnMut(usize) -> bool) {
        match self {
            Cover::Empty => {}
            Cover::Unknown => {
                for i in from..n {
                    if f(i) {
                        return;
                    }
                }
            }
            Cover::Rect { c0, c1, r0, r1 } => {
                for r in (from / width).max(r0 as usize)..=r1 as usize {
                    for c in c0 as usize..=c1 as usize {
                        let i = r * width + c;
                        if i >= from && f(i) {
                            return;
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;

    fn grid() -> TileGrid {
        let camera = Camera {
            eye: Vec3::new(0.0, 0.0, 5.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            fov_y_deg: 45.0,
        };
        TileGrid {
            rays: camera.rays(64, 64),
            x0: 16,
            y0: 16,
            width: 16,
            height: 16,
        }
    }

    /// The tile's pixels (row-major indices) whose rays meet the box `lo..hi` (slab test).
    fn pixels_meeting(g: &TileGrid, lo: Vec3, hi: Vec3) -> Vec<usize> {
        let mut out = Vec::new();
        for y in 0..g.height {
            for x in 0..g.width {
                let ray = g.rays.through_pixel(g.x0 + x, g.y0 + y);
                let inv = ray.dir.recip();
                let (t0, t1) = ((lo - ray.origin) * inv, (hi - ray.origin) * inv);
                let (near, far) = (t0.min(t1).max_element(), t0.max(t1).min_element());
                if near <= far && far > 0.0 {
                    out.push((y * g.width + x) as usize);
                }
            }
        }
        out
    }

    /// Every pixel of the tile whose ray meets a small box lies in the box's cover, and a
    /// box behind the eye has no bound.
    #[test]
    fn the_cover_holds_every_pixel_whose_ray_meets_the_shape() {
        let g = grid();
        let (lo, hi) = (Vec3::new(-0.2, -0.1, -0.3), Vec3::new(0.1, 0.25, 0.2));
        let cover = g.cover(box_corners(lo, hi));
        assert!(matches!(cover, Cover::Rect { .. }), "{cover:?}");
        assert_eq!(
            g.cover_box(lo, hi),
            cover,
            "the box's cover from its corners at once"
        );
        let inside: Vec<usize> = cover.rays(g.width, 0, 256).collect();
        let mut visited = Vec::new();
        cover.visit(16, 0, 256, |i| {
            visited.push(i);
            false
        });
        assert_eq!(inside, visited, "both walks give the same rays");
        let meeting = pixels_meeting(&g, lo, hi);
        let hit = meeting.len();
        for i in meeting {
            assert!(inside.contains(&i), "pixel {i}");
        }
        assert!(
            hit > 0 && inside.len() < 256,
            "{hit} hits, {} covered",
            inside.len()
        );
        let behind = g.cover(box_corners(
            Vec3::new(-1.0, -1.0, 6.0),
            Vec3::splat(1.0) + 6.0 * Vec3::Z,
        ));
        assert_eq!(behind, Cover::Unknown);
        let behind_box = g.cover_box(Vec3::new(-1.0, -1.0, 6.0), Vec3::splat(1.0) + 6.0 * Vec3::Z);
        assert_eq!(behind_box, Cover::Unknown);
        let aside = g.cover(box_corners(
            Vec3::new(3.0, 3.0, -0.1),
            Vec3::new(3.1, 3.1, 0.1),
        ));
        assert_eq!(aside, Cover::Empty);
        let aside_box = g.cover_box(Vec3::new(3.0, 3.0, -0.1), Vec3::new(3.1, 3.1, 0.1));
        assert_eq!(aside_box, Cover::Empty);
    }

    /// A box's cover projected corner by corner and all at once agree on random boxes
    /// around the tile, and every pixel whose ray meets the box lies in the latter (slab
    /// test per pixel ray): the packets' culling by `cover_box` is as conservative as by
    /// `cover`.
    #[test]
    fn the_box_cover_holds_every_pixel_whose_ray_meets_the_box() {
        let g = grid();
        let mut rng = crate::geom::rng::SplitMix64(5);
        let (mut same, mut rects, mut hits) = (0, 0, 0);
        for _ in 0..3000 {
            let centre = Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-3.0, 6.0),
            );
            let half = Vec3::new(
                rng.range(0.0, 0.4),
                rng.range(0.0, 0.4),
                rng.range(0.0, 0.4),
            );
            let (lo, hi) = (centre - half, centre + half);
            let cover = g.cover_box(lo, hi);
            same += (cover == g.cover(box_corners(lo, hi))) as usize;
            let inside: Vec<usize> = cover.rays(g.width, 0, 256).collect();
            rects += matches!(cover, Cover::Rect { .. }) as usize;
            if cover == Cover::Unknown {
                continue;
            }
            for i in pixels_meeting(&g, lo, hi) {
                hits += 1;
                assert!(inside.contains(&i), "pixel {i} of box {lo} {hi}");
            }
        }
        assert!(same >= 2990, "{same} of 3000 covers the same both ways");
        assert!(
            rects > 300 && hits > 1000,
            "{rects} rectangles, {hits} pixel hits"
        );
    }

    /// A sphere the cover's pyramid excludes meets no ray of the cover's pixels (distance from
    /// the centre to each ray in `f64`, well over the radius), and the test does exclude
    /// spheres off to the side.
    #[test]
    fn a_sphere_outside_the_frustum_meets_no_ray_of_the_cover() {
        let g = grid();
        let cover = g.cover(box_corners(
            Vec3::new(-0.2, -0.1, -0.3),
            Vec3::new(0.1, 0.25, 0.2),
        ));
        let Cover::Rect { c0, c1, r0, r1 } = cover else {
            panic!("{cover:?}");
        };
        let frustum = g.frustum(cover).expect("a rectangle has a pyramid");
        let mut rng = crate::geom::rng::SplitMix64(11);
        let (mut excluded, mut kept) = (0, 0);
        for _ in 0..4000 {
            let centre = Vec3::new(
                rng.range(-1.5, 1.5),
                rng.range(-1.5, 1.5),
                rng.range(-2.0, 2.0),
            );
            let radius = rng.range(0.01, 0.4);
            if !frustum.excludes_sphere(centre, radius) {
                kept += 1;
                continue;
            }
            excluded += 1;
            for r in r0..=r1 {
                for c in c0..=c1 {
                    let ray = g.rays.through_pixel(g.x0 + c, g.y0 + r);
                    let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3().normalize());
                    let v = centre.as_dvec3() - o;
                    let closest = v - d * v.dot(d).max(0.0);
                    assert!(
                        closest.length() > radius as f64,
                        "pixel {c},{r} meets the excluded sphere at {centre} r {radius}"
                    );
                }
            }
        }
        assert!(
            excluded > 100 && kept > 100,
            "{excluded} excluded, {kept} kept"
        );
    }
}
