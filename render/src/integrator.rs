//! Follows rays through a scene and shades what they hit, tracing only the rays the
//! [`EffectsPlan`] calls for.
//!
//! How it works: [`trace_primary`] is ray casting (first hit, local shading of every light
//! without shadows); it is the whole frame when the plan is primary-only, so switching on an
//! effect no visible material can use costs nothing. [`Tracer`] is the Whitted-style
//! integrator for everything else, per hit:
//! - local shading: emission, ambient darkened by ambient occlusion (cosine-weighted any-hit
//!   rays within the occlusion distance, fitted-bvh-metaballs.txt Fig. 8d), and for every light
//!   facing the surface Lambert plus Blinn-Phong times its visibility: one shadow ray towards a
//!   directional or point light or a sphere light's centre (hard), or `light_samples` rays
//!   towards points of the sphere light's visible cap (soft, averaged over refinement passes);
//! - mirror reflection to the plan's depth (ibid. Fig. 8a,b);
//! - transparency: a surface of opacity `α` shows `α` of its own shading and `1 - α` of what
//!   lies behind; behind is a refraction ray with Fresnel weighting of the reflected and bent
//!   parts when the material's IOR is not 1 (ibid. Fig. 8e), else the same ray continued past
//!   the hit (depth peeling, tetrahedral-isosurface-ray-tracing.txt §7), layer by layer;
//! - a volume (bezier-clipping-metaballs.txt §5, eq. 16 with single scattering of a constant
//!   in-scattered radiance `color`): a segment of optical depth `τ` shows
//!   `I₀ e^{-τ} + color (1 - e^{-τ})`, the closed form of eq. 16's integral in that case;
//! - the clip box cuts primitives away (ibid. §7): a ray sees them only outside it, and a ray
//!   that leaves the box inside a solid sees the solid's inner side;
//! - further isosurfaces of the same field are hit like the first (ibid. §7).
//!
//! Shadow and occlusion rays ask the scene for any hit, with early exit; with transparent
//! materials in the plan they walk the crossings instead and multiply `1 - α` of each.

mod batch;

use crate::effects::plan::EffectsPlan;
use crate::effects::rays::{RayCounts, RayKind};
pub use crate::geom::optics::{reflect, refract_dir};
use crate::geom::rng::PixelRng;
use crate::kinds::contract::{OcclusionHint, RayStart};
use crate::kinds::counters::SceneCounters;
use crate::ray::{surface_offset, Hit, Ray, INSIDE_EPS};
use crate::sampling::{cosine_hemisphere, uniform_cone};
use crate::scene::PreparedScene;
use crate::shade::{direct, facing, fresnel, Light, Lighting, Material};
/// The hard shadow rays of a frame as the renderer traces them (the stability suite checks
/// their answers against each kind's reference).
pub use batch::{trace_shadows, ShadowQuery};
use glam::Vec3;

/// Far limit of every ray, in scene units.
pub const T_MAX: f32 = 1.0e4;

/// Shaded linear colour and hit distance (`INFINITY` on a miss) of one primary ray, by ray
/// casting alone; `spread`: the angle between neighbouring pixels' rays
/// ([`crate::camera::PrimaryRays::pixel_spread`]).
#[inline]
pub fn trace_primary(scene: &PreparedScene, ray: &Ray, isovalue: f32, spread: f32) -> (Vec3, f32) {
    shade_primary(
        scene,
        ray,
        scene.first_hit(ray, 0.0, T_MAX, isovalue).as_ref(),
        isovalue,
        spread,
    )
}

/// [`trace_primary`] once the hit is known (the backend finds a tile's hits together). The
/// floor, scene geometry like the field's surface, is drawn where it is nearer, as
/// [`Tracer::primary`] draws it with every effect off.
#[inline]
pub fn shade_primary(
    scene: &PreparedScene,
    ray: &Ray,
    hit: Option<&Hit>,
    isovalue: f32,
    spread: f32,
) -> (Vec3, f32) {
    let lighting = scene.lighting_in_frame();
    if let Some(floor) = &lighting.floor {
        // `Tracer::closest`'s test: past the ray's start, before the surface or `T_MAX`.
        let t = floor.distance(ray);
        if t > 0.0 && t < hit.map_or(T_MAX, |h| h.t) {
            let position = ray.at(t);
            let seen = (ray.dir, t, spread);
            let color = lighting.shade_floor(floor, position, seen, scene.frame());
            return (color, t);
        }
    }
    match hit {
        Some(hit) => match &lighting.color_map {
            None => (lighting.shade(hit, ray.dir), hit.t),
            Some(map) => {
                let mapped = Hit {
                    albedo: map.albedo(isovalue),
                    ..*hit
                };
                (lighting.shade(&mapped, ray.dir), hit.t)
            }
        },
        None => (lighting.background(ray.dir.y), f32::INFINITY),
    }
}

/// A surface a ray reached: of the geometry or of the floor.
#[derive(Clone, Copy, Debug)]
struct SurfaceHit {
    t: f32,
    position: Vec3,
    /// Out of the solid (or up from the floor); not turned towards the viewer.
    normal: Vec3,
    albedo: Vec3,
    material: u16,
    /// The kind's primitive hit (`None`: the floor).
    primitive: Option<u32>,
}

/// The integrator of one frame on one thread: the scene, the plan, and the rays it traced.
pub struct Tracer<'a> {
    scene: &'a PreparedScene,
    lighting: &'a Lighting,
    plan: &'a EffectsPlan,
    isovalue: f32,
    /// The angle between neighbouring pixels' camera rays: the floor's squares are averaged
    /// over a footprint this many radians wide per unit of a ray's length.
    pixel_spread: f32,
    /// Rays traced so far, per kind.
    pub counts: RayCounts,
    /// Traversal and root-finder counters of every query.
    pub counters: SceneCounters,
    /// Scratch for the crossings of a ray through transparent surfaces.
    hits: Vec<Hit>,
    /// A camera ray's first hit on `[0, T_MAX]` as the kind's tile query found it, for the
    /// next [`Tracer::closest`] to use instead of asking again ([`Tracer::primary_from`]).
    given: Option<Option<Hit>>,
    /// Hard shadow rays of a tile's camera rays traced together ([`Tracer::primaries_from`]).
    batch: batch::ShadowBatch,
    /// The terms of the colours shaded while the batch notes shadow rays.
    terms: Vec<batch::Term>,
    /// The point light the next shadow ray goes to (`None`: directional), for the batch.
    shadow_light: Option<Vec3>,
    /// Where the tile's latest blocked shadow rays were blocked.
    hint: OcclusionHint,
    /// Whether the next occlusion queries search `hint`'s leaves first (not for ambient
    /// occlusion rays).
    hinting: bool,
    /// Whether the next [`Tracer::closest`] is for a mirror ray leaving a surface outwards
    /// (`PreparedKind::first_hit_leaving`).
    leaving: bool,
    /// While a kind's hit seen from outside is lit (no clip box opening the surfaces), its
    /// outward normal and primitive: the shadow and occlusion rays that leave it on that
    /// side start outside that primitive's body ([`RayStart::Leaving`]).
    outward: Option<(Vec3, u32)>,
}

impl<'a> Tracer<'a> {
    pub fn new(
        scene: &'a PreparedScene,
        plan: &'a EffectsPlan,
        isovalue: f32,
        pixel_spread: f32,
    ) -> Tracer<'a> {
        Tracer {
            scene,
            pixel_spread,
            lighting: scene.lighting_in_frame(),
            plan,
            isovalue,
            counts: RayCounts::default(),
            counters: SceneCounters::default(),
            hits: Vec::new(),
            given: None,
            batch: batch::ShadowBatch::Off,
            terms: Vec::new(),
            shadow_light: None,
            hint: OcclusionHint::default(),
            hinting: true,
            leaving: false,
            outward: None,
        }
    }

    /// Whether a camera ray's first crossing is the kind's first hit on `[0, T_MAX]` (no clip
    /// box cuts the ray, no volume is integrated along it), so that a tile's primary hits,
    /// found together (as a packet where the kind has one), can stand in for it.
    pub fn takes_tile_hits(&self) -> bool {
        self.plan.clip_box.is_none() && !self.plan.volume
    }

    /// [`Tracer::primary`] given the ray's first hit on `[0, T_MAX]`, found by the kind's tile
    /// query ([`PreparedScene::primary_hits`], the same hit as [`PreparedScene::first_hit`]);
    /// only when [`Tracer::takes_tile_hits`]. The image is [`Tracer::primary`]'s.
    pub fn primary_from(
        &mut self,
        ray: &Ray,
        first: Option<Hit>,
        rng: &mut PixelRng,
    ) -> (Vec3, f32) {
        debug_assert!(self.takes_tile_hits());
        self.given = Some(first);
        let out = self.primary(ray, rng);
        debug_assert!(self.given.is_none(), "closest took the given hit");
        out
    }

    /// Whether a tile's camera rays spawn nothing but hard shadow rays towards the lights (no
    /// reflection, refraction, layers, occlusion, soft shadows, further isosurfaces, volume
    /// or clip box), so that [`Tracer::primaries_from`] can trace those together.
    pub fn batches_shadows(&self) -> bool {
        let p = self.plan;
        self.takes_tile_hits()
            && p.shadows
            && !p.soft_shadows
            && p.reflection_depth == 0
            && p.refraction_depth == 0
            && p.layers == 0
            && p.ao_samples == 0
            && (!p.isosurfaces || self.lighting.isosurfaces.is_empty())
    }

    /// [`Tracer::primary_from`] for each camera ray of a tile (`hits` from the kind's tile
    /// query, `pixels` their pixels) in order. Where the camera rays spawn only hard shadow
    /// rays, shading notes those as unblocked with the terms of each colour, they are traced
    /// together ([`batch::trace_shadows`]), and the colours with a blocked light are summed
    /// again without it ([`batch::resolve`]); the image is [`Tracer::primary`]'s.
    pub fn primaries_from(
        &mut self,
        hits: &[(Ray, Option<Hit>)],
        pixels: &[(u32, u32)],
        pass: u32,
    ) -> Vec<(Vec3, f32)> {
        let batched = self.batches_shadows();
        if batched {
            self.batch = batch::ShadowBatch::Record(Vec::new());
            self.terms.clear();
        }
        let mut spans = Vec::with_capacity(if batched { hits.len() } else { 0 });
        let mut out: Vec<(Vec3, f32)> = (hits.iter().zip(pixels))
            .map(|(&(ray, hit), &(x, y))| {
                let start = self.terms.len();
                let shaded = self.primary_from(&ray, hit, &mut PixelRng::new(x, y, pass));
                if batched {
                    spans.push(start..self.terms.len());
                }
                shaded
            })
            .collect();
        if let batch::ShadowBatch::Record(queries) = std::mem::take(&mut self.batch) {
            let blocked =
                batch::trace_shadows(self.scene, self.isovalue, &queries, &mut self.counters);
            for (pixel, span) in out.iter_mut().zip(spans) {
                let terms = &self.terms[span];
                if batch::any_blocked(terms, &blocked) {
                    pixel.0 = batch::resolve(terms, &blocked);
                }
            }
        }
        out
    }

    /// The isosurface a camera ray sees first, outside the plan's clip box (inside the solid
    /// where the ray leaves the box there); no floor, no further isosurfaces, no volume.
    pub fn surface_hit(&mut self, ray: &Ray) -> Option<Hit> {
        self.crossing(ray, 0.0, T_MAX, self.isovalue, false)
    }

    /// Linear colour and hit distance (`INFINITY` on a miss) of a camera ray.
    pub fn primary(&mut self, ray: &Ray, rng: &mut PixelRng) -> (Vec3, f32) {
        self.counts.bump(RayKind::Primary);
        self.radiance(ray, 0.0, 0, self.plan.layers, rng)
    }

    fn radiance(
        &mut self,
        ray: &Ray,
        t0: f32,
        depth: u32,
        layers: u32,
        rng: &mut PixelRng,
    ) -> (Vec3, f32) {
        let hit = self.closest(ray, t0, T_MAX);
        let (far, mut color) = match &hit {
            Some(h) => (h.t, self.shade_hit(ray, h, depth, layers, rng)),
            None => (T_MAX, self.lighting.background(ray.dir.y)),
        };
        if self.plan.volume {
            if let Some(volume) = self.lighting.volume {
                self.counts.bump(RayKind::Volume);
                let tau = volume.density * self.optical_depth(ray, t0, far);
                let transmitted = (-tau).exp();
                color = color * transmitted + volume.color * (1.0 - transmitted);
            }
        }
        (color, hit.map_or(f32::INFINITY, |h| h.t))
    }

    /// The stretches of `[a, b]` outside the clip box, in order.
    #[inline]
    fn segments(&self, ray: &Ray, a: f32, b: f32) -> ([(f32, f32); 2], usize) {
        let mut out = [(a, b), (0.0, 0.0)];
        let Some(clip) = &self.plan.clip_box else {
            return (out, 1);
        };
        let Some((near, far)) = clip.range(ray.origin, ray.dir) else {
            return (out, 1);
        };
        if far <= a || near >= b {
            return (out, 1);
        }
        let mut n = 0;
        if near > a {
            out[n] = (a, near);
            n += 1;
        }
        if far < b {
            out[n] = (far, b);
            n += 1;
        }
        (out, n)
    }

    /// The first crossing of the isosurface at `isovalue` on `[a, b]` outside the clip box,
    /// entering the solid or, when the ray starts inside it, leaving it; `leaving`: the ray
    /// leaves a surface outwards (a mirror ray from outside).
    fn crossing(&mut self, ray: &Ray, a: f32, b: f32, isovalue: f32, leaving: bool) -> Option<Hit> {
        let (segments, n) = self.segments(ray, a, b);
        for &(lo, hi) in &segments[..n] {
            let (scene, c) = (self.scene, &mut self.counters);
            let first = match leaving {
                true => scene.first_hit_leaving_counted(ray, lo, hi, isovalue, c),
                false => scene.first_hit_counted(ray, lo, hi, isovalue, c),
            };
            let Some(hit) = first else {
                continue;
            };
            if hit.t > lo + INSIDE_EPS {
                return Some(hit);
            }
            if let Some(exit) =
                self.scene
                    .exit_hit_counted(ray, lo, hi, isovalue, &mut self.counters)
            {
                return Some(exit);
            }
        }
        None
    }

    /// The albedo of `hit` on the isosurface at `isovalue`: the session's colour map of the
    /// isovalue if it has one, else the surface's `own` colour (a viewer's added surface), else
    /// the kind's.
    #[inline]
    fn albedo(&self, hit: &Hit, isovalue: f32, own: Option<Vec3>) -> Vec3 {
        match &self.lighting.color_map {
            None => own.unwrap_or(hit.albedo),
            Some(map) => map.albedo(isovalue),
        }
    }

    /// The nearest surface on `[t0, t1]`: every drawn isosurface, and the floor.
    fn closest(&mut self, ray: &Ray, t0: f32, t1: f32) -> Option<SurfaceHit> {
        let mut best: Option<SurfaceHit> = None;
        let mut limit = t1;
        let (given, leaving) = (self.given.take(), std::mem::take(&mut self.leaving));
        if !self.plan.volume {
            let first = match given {
                // A camera ray's tile hit is `crossing`'s answer unless the ray starts inside
                // the solid (then `crossing` asks for the way out).
                Some(Some(h)) if h.t > t0 + INSIDE_EPS => Some(h),
                Some(None) => None,
                Some(Some(_)) | None => self.crossing(ray, t0, limit, self.isovalue, leaving),
            };
            if let Some(h) = first {
                limit = h.t;
                best = Some(SurfaceHit {
                    t: h.t,
                    position: h.position,
                    normal: h.normal,
                    albedo: self.albedo(&h, self.isovalue, None),
                    material: self.lighting.material_of(h.primitive),
                    primitive: Some(h.primitive),
                });
            }
            if self.plan.isosurfaces {
                for k in 0..self.lighting.isosurfaces.len() {
                    let surface = self.lighting.isosurfaces[k];
                    if let Some(h) = self.crossing(ray, t0, limit, surface.isovalue, leaving) {
                        limit = h.t;
                        best = Some(SurfaceHit {
                            t: h.t,
                            position: h.position,
                            normal: h.normal,
                            albedo: self.albedo(&h, surface.isovalue, surface.color),
                            material: surface.material,
                            primitive: Some(h.primitive),
                        });
                    }
                }
            }
        }
        if let Some(floor) = &self.lighting.floor {
            let t = floor.distance(ray);
            if t > t0 && t < limit {
                let position = ray.at(t);
                best = Some(SurfaceHit {
                    t,
                    position,
                    normal: Vec3::Y,
                    albedo: floor.color_seen(
                        position,
                        ray.dir,
                        t,
                        self.pixel_spread,
                        self.scene.frame(),
                    ),
                    material: floor.material,
                    primitive: None,
                });
            }
        }
        best
    }

    fn shade_hit(
        &mut self,
        ray: &Ray,
        hit: &SurfaceHit,
        depth: u32,
        layers: u32,
        rng: &mut PixelRng,
    ) -> Vec3 {
        let material = *self.lighting.material(hit.material);
        let view = ray.dir;
        let normal = facing(hit.normal, view);
        let entering = hit.normal.dot(view) < 0.0;
        let eps = surface_offset(hit.position);
        let above = hit.position + normal * eps;
        let mut color = material.emission;
        if material.receives_light() {
            if self.batch.is_recording() {
                self.terms.push(batch::Term::Emission(color));
            }
            self.outward = (hit.primitive)
                .filter(|_| entering && self.plan.clip_box.is_none())
                .map(|p| (hit.normal, p));
            color += self.local(&material, hit, normal, view, above, rng);
            self.outward = None;
        }

        // Transparency is on (some visible material is transparent) when either kind of
        // transmitted ray is planned; with neither, transparent surfaces look opaque.
        let transmits =
            material.is_transparent() && (self.plan.layers > 0 || self.plan.refraction_depth > 0);
        if transmits {
            let behind = if material.is_refractive() && depth < self.plan.refraction_depth {
                Some(self.refract(&material, hit, normal, view, entering, depth, layers, rng))
            } else if layers > 0 {
                self.counts.bump(RayKind::Transparency);
                let t_next = hit.t + eps;
                Some(self.radiance(ray, t_next, depth, layers - 1, rng).0)
            } else {
                None
            };
            if let Some(behind) = behind {
                color = color * material.opacity + behind * (1.0 - material.opacity);
            }
        }

        if material.is_reflective() && depth < self.plan.reflection_depth {
            self.counts.bump(RayKind::Reflection);
            let reflected = Ray {
                origin: above,
                dir: reflect(view, normal),
            };
            self.leaving = entering;
            let mirror = self.radiance(&reflected, 0.0, depth + 1, layers, rng).0;
            color = color * (1.0 - material.reflectivity) + mirror * material.reflectivity;
        }
        color
    }

    /// Emission aside: ambient (with occlusion) and every light (with shadows).
    fn local(
        &mut self,
        material: &Material,
        hit: &SurfaceHit,
        normal: Vec3,
        view: Vec3,
        above: Vec3,
        rng: &mut PixelRng,
    ) -> Vec3 {
        let albedo = hit.albedo * material.diffuse;
        let mut ambient = self.lighting.ambient * albedo;
        let ao = self.plan.ao_samples;
        if ao > 0 && ambient.max_element() > 0.0 {
            // Occlusion rays leave in every direction, so the leaves that blocked their
            // neighbours rarely block them and searching those first costs more than it saves
            // (Pool with occlusion at 640×480: 10% slower): they are asked without a hint.
            self.hinting = false;
            let mut open = 0.0;
            for (u1, u2) in rng.points(ao, self.plan.sampling) {
                let dir = cosine_hemisphere(normal, u1, u2);
                self.counts.bump(RayKind::Occlusion);
                let ray = Ray { origin: above, dir };
                open += self.transmittance(&ray, self.lighting.occlusion_distance);
            }
            self.hinting = true;
            ambient *= open / ao as f32;
        }
        let recording = self.batch.is_recording();
        if recording {
            self.terms.push(batch::Term::Ambient(ambient));
        }
        let mut color = ambient;
        for k in 0..self.lighting.lights.len() {
            let light = self.lighting.lights[k];
            let Some(sample) = light.toward(hit.position) else {
                continue;
            };
            // A light behind the surface adds nothing: no shadow ray for it.
            if normal.dot(sample.to_light) <= 0.0 {
                continue;
            }
            let noted = self.batch.noted();
            let visibility = if self.plan.shadows {
                self.visibility(&light, sample.to_light, sample.distance, above, rng)
            } else {
                1.0
            };
            let term = direct(material, albedo, normal, view, &sample, visibility);
            if recording {
                let waits = (self.batch.noted() > noted).then_some(noted);
                self.terms.push(batch::Term::Light(waits, term));
            }
            color += term;
        }
        color
    }

    /// The share of `light` that reaches `origin`.
    fn visibility(
        &mut self,
        light: &Light,
        to_light: Vec3,
        distance: f32,
        origin: Vec3,
        rng: &mut PixelRng,
    ) -> f32 {
        match *light {
            Light::Sphere { center, radius, .. } if self.plan.soft_shadows => {
                if distance <= radius {
                    return 1.0;
                }
                let cos_max = (1.0 - (radius / distance).powi(2)).max(0.0).sqrt();
                let n = self.plan.light_samples.max(1);
                let mut seen = 0.0;
                for (u1, u2) in rng.points(n, self.plan.sampling) {
                    let dir = uniform_cone(to_light, cos_max, u1, u2);
                    // Distance to the sphere along `dir`, nearer root.
                    let oc = origin - center;
                    let b = oc.dot(dir);
                    let c = oc.length_squared() - radius * radius;
                    let t = -b - (b * b - c).max(0.0).sqrt();
                    self.counts.bump(RayKind::Shadow);
                    seen += self.transmittance(&Ray { origin, dir }, t.max(0.0));
                }
                seen / n as f32
            }
            Light::Sphere { center, radius, .. } => {
                self.counts.bump(RayKind::Shadow);
                self.shadow_light = Some(center);
                let ray = Ray {
                    origin,
                    dir: to_light,
                };
                self.transmittance(&ray, (distance - radius).max(0.0))
            }
            Light::Point { position, .. } => {
                self.counts.bump(RayKind::Shadow);
                self.shadow_light = Some(position);
                let ray = Ray {
                    origin,
                    dir: to_light,
                };
                self.transmittance(&ray, distance.min(T_MAX))
            }
            Light::Directional { .. } => {
                self.counts.bump(RayKind::Shadow);
                self.shadow_light = None;
                let ray = Ray {
                    origin,
                    dir: to_light,
                };
                self.transmittance(&ray, distance.min(T_MAX))
            }
        }
    }

    /// The share of light that passes along `ray` over `[0, t_max]`: 0 or 1 through opaque
    /// scenes (any hit, early exit), `Π (1 - α)` through transparent surfaces, `e^{-τ}`
    /// through a volume.
    fn transmittance(&mut self, ray: &Ray, t_max: f32) -> f32 {
        let start = match self.outward {
            Some((n, primitive)) if n.dot(ray.dir) > 0.0 => RayStart::Leaving(primitive),
            _ => RayStart::Unknown,
        };
        if let Some(floor) = &self.lighting.floor {
            let t = floor.distance(ray);
            if t > 0.0 && t < t_max && self.lighting.material(floor.material).opacity >= 1.0 {
                return 0.0;
            }
        }
        if self.plan.volume {
            let Some(volume) = self.lighting.volume else {
                return 1.0;
            };
            return (-volume.density * self.optical_depth(ray, 0.0, t_max)).exp();
        }
        let mut transmitted = 1.0;
        let surfaces = 1 + if self.plan.isosurfaces {
            self.lighting.isosurfaces.len()
        } else {
            0
        };
        for k in 0..surfaces {
            let (isovalue, fixed_material) = if k == 0 {
                (self.isovalue, None)
            } else {
                let s = self.lighting.isosurfaces[k - 1];
                (s.isovalue, Some(s.material))
            };
            if self.plan.layers == 0 {
                let batched = if k == 0 {
                    self.batch.answer(batch::ShadowQuery {
                        ray: *ray,
                        t_max,
                        light: self.shadow_light,
                        start,
                    })
                } else {
                    None
                };
                let blocked = match batched {
                    Some(blocked) => blocked,
                    None => self.blocked(ray, (0.0, t_max), isovalue, start),
                };
                if blocked {
                    return 0.0;
                }
                continue;
            }
            // Walk the crossings outside the clip box, each letting `1 - α` through; more than
            // `layers` of them block. The ray leaves its surface outside the solid, and each
            // stretch beyond the clip box starts afresh (its cut face is open).
            let most = self.plan.layers as usize + 1;
            let (segments, n) = self.segments(ray, 0.0, t_max);
            let opacity = match fixed_material {
                Some(m) => Some(self.lighting.material(m).opacity),
                None => self.lighting.uniform_opacity(),
            };
            if let Some(opacity) = opacity {
                // One opacity for every crossing: their number is enough.
                let mut count = 0;
                for &(lo, hi) in &segments[..n] {
                    count += self.scene.crossing_count(
                        ray,
                        lo,
                        hi,
                        isovalue,
                        false,
                        most - count,
                        &mut self.counters,
                    );
                    if count >= most {
                        break;
                    }
                }
                for _ in 0..count {
                    transmitted *= 1.0 - opacity.clamp(0.0, 1.0);
                }
                if count >= most || transmitted <= 1e-3 {
                    return 0.0;
                }
                continue;
            }
            let mut hits = std::mem::take(&mut self.hits);
            hits.clear();
            for &(lo, hi) in &segments[..n] {
                self.scene.crossings_counted(
                    ray,
                    lo,
                    hi,
                    isovalue,
                    false,
                    most - hits.len(),
                    &mut hits,
                    &mut self.counters,
                );
                if hits.len() >= most {
                    break;
                }
            }
            for hit in &hits {
                let material =
                    fixed_material.unwrap_or_else(|| self.lighting.material_of(hit.primitive));
                transmitted *= 1.0 - self.lighting.material(material).opacity.clamp(0.0, 1.0);
            }
            let blocked = hits.len() >= most || transmitted <= 1e-3;
            self.hits = hits;
            if blocked {
                return 0.0;
            }
        }
        transmitted
    }

    /// Whether the isosurface at `isovalue` crosses `[a, b]` outside the clip box (any hit),
    /// each query searching first where the tile's last blocked ray was blocked.
    fn blocked(&mut self, ray: &Ray, (a, b): (f32, f32), isovalue: f32, start: RayStart) -> bool {
        let (segments, n) = self.segments(ray, a, b);
        let mut none = OcclusionHint::default();
        let hint = if self.hinting {
            &mut self.hint
        } else {
            &mut none
        };
        segments[..n].iter().any(|&span| {
            (self.scene).occluded_counted(ray, span, isovalue, start, hint, &mut self.counters)
        })
    }

    /// `∫ F dt` over `[a, b]` outside the clip box.
    fn optical_depth(&mut self, ray: &Ray, a: f32, b: f32) -> f32 {
        let (segments, n) = self.segments(ray, a, b);
        segments[..n]
            .iter()
            .map(|&(lo, hi)| self.scene.optical_depth(ray, lo, hi))
            .sum()
    }

    /// What a refractive surface passes on: Fresnel-weighted reflected and bent rays.
    #[allow(clippy::too_many_arguments)]
    fn refract(
        &mut self,
        material: &Material,
        hit: &SurfaceHit,
        normal: Vec3,
        view: Vec3,
        entering: bool,
        depth: u32,
        layers: u32,
        rng: &mut PixelRng,
    ) -> Vec3 {
        let (n1, n2) = if entering {
            (1.0, material.ior)
        } else {
            (material.ior, 1.0)
        };
        let cos_i = (-view.dot(normal)).clamp(0.0, 1.0);
        let reflectance = fresnel(cos_i, n1, n2);
        let eps = surface_offset(hit.position);
        let mut color = Vec3::ZERO;
        if reflectance > 0.0 {
            self.counts.bump(RayKind::Reflection);
            let ray = Ray {
                origin: hit.position + normal * eps,
                dir: reflect(view, normal),
            };
            self.leaving = entering;
            color += reflectance * self.radiance(&ray, 0.0, depth + 1, layers, rng).0;
        }
        if reflectance < 1.0 {
            if let Some(dir) = refract_dir(view, normal, n1 / n2) {
                self.counts.bump(RayKind::Refraction);
                let ray = Ray {
                    origin: hit.position - normal * eps,
                    dir,
                };
                color += (1.0 - reflectance) * self.radiance(&ray, 0.0, depth + 1, layers, rng).0;
            }
        }
        color
    }
}
