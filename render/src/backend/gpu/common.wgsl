// The kind-independent part of the trace kernel: one invocation per pixel, the camera ray,
// and the integrator of render/src/integrator.rs (ray casting, or one refinement pass of the
// Whitted-style tracer with every effect of the plan), with the random streams of
// geom/rng.rs PixelRng bit for bit. The kind's part (metaballs.wgsl, tets.wgsl,
// surfels.wgsl) is appended and answers four queries: kind_first_hit, kind_exit_hit,
// kind_any_hit, kind_optical_depth. The structs mirror backend/gpu/layout.rs field by field.
//
// WGSL has no recursion: the tracer's tree of rays (transparency layers, refraction's
// reflected and bent rays, mirror reflections) is walked depth first with an explicit stack
// of weighted rays. Every colour the CPU composes is linear in what the rays behind it bring,
// so each ray carries the weight its radiance has in the pixel; children are pushed in
// reverse so that rays are traced, and random numbers drawn, in the CPU's order.

struct Frame {
    eye: vec4<f32>,
    top_left: vec4<f32>,
    right_step: vec4<f32>,
    down_step: vec4<f32>,
    forward: vec4<f32>,
    background_top: vec4<f32>,
    background_bottom: vec4<f32>,
    ambient: vec4<f32>,
    mapped_albedo: vec4<f32>,
    floor_color0: vec4<f32>,
    floor_color1: vec4<f32>,
    floor_origin: vec4<f32>,
    volume: vec4<f32>,
    clip_min: vec4<f32>,
    clip_max: vec4<f32>,
    isovalue: f32,
    width: u32,
    height: u32,
    flags: u32,
    t_max: f32,
    light_count: u32,
    group_count: u32,
    material_count: u32,
    floor_height: f32,
    floor_checker: f32,
    floor_material: u32,
    pass_index: u32,
    reflection_depth: u32,
    refraction_depth: u32,
    layers: u32,
    ao_samples: u32,
    light_samples: u32,
    occlusion_distance: f32,
    isosurface_count: u32,
    _pad: u32,
}

struct Light {
    position: vec4<f32>,
    color: vec4<f32>,
}

struct Material {
    diffuse: vec4<f32>,
    emission: vec4<f32>,
    extra: vec4<f32>,
}

struct Group {
    first: u32,
    count: u32,
    material: u32,
    _pad: u32,
}

struct IsoSurface {
    color: vec4<f32>,
    isovalue: f32,
    material: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> lights: array<Light>;
@group(0) @binding(2) var<storage, read> materials: array<Material>;
@group(0) @binding(3) var<storage, read> groups: array<Group>;
@group(0) @binding(4) var<storage, read> isosurfaces: array<IsoSurface>;
// Per pixel: linear colour, and the hit distance along the view axis (negative: a miss; CUT:
// the driver cut the pixel's loops short).
@group(0) @binding(5) var<storage, read_write> pixels: array<vec4<f32>>;

const FLAG_PASS: u32 = 1u;
const FLAG_SHADOWS: u32 = 2u;
const FLAG_FLOOR: u32 = 4u;
const FLAG_COLOR_MAP: u32 = 8u;
const FLAG_SOFT_SHADOWS: u32 = 16u;
const FLAG_VOLUME: u32 = 32u;
const FLAG_CLIP: u32 = 64u;
const FLAG_ISOSURFACES: u32 = 128u;
const FLAG_MARK_CUT: u32 = 256u;
const FLAG_STRATIFIED: u32 = 512u;

// integrator.rs INSIDE_EPS.
const INSIDE_EPS: f32 = 2.0e-4;
const BIG: f32 = 3.0e38;
const TAU: f32 = 6.28318530717958647692;
// Rays waiting on the integrator's stack; the upload refuses plans that could need more.
const RAY_STACK: u32 = 24u;
// The depth written, with FLAG_MARK_CUT, for a pixel whose loops the driver cut short
// (retrace.rs CUT_DEPTH, for the backend to trace again on the CPU). Mesa's lavapipe (llvmpipe) counts the loop
// iterations of each SIMD group of invocations (8 pixels on AVX2) in ONE budget of 65,535,
// shared by every loop of the kernel, and once it is spent ends every loop after its
// current iteration, silently: rays waiting on the stack are dropped and a root search
// stops early, for whichever pixels of the group are still working. The integrator's loop
// therefore only finishes in an iteration of its own that finds the stack empty; a cut
// anywhere before it (the budget only shrinks) ends that loop first and marks the pixel.
// (Ray casting's single query is not guarded: no demo's ray casting differs from the CPU's.)
const CUT: f32 = -2.0;

// What a kind's query found (ray.rs Hit; `found` false: nothing).
struct KHit {
    found: bool,
    t: f32,
    position: vec3<f32>,
    normal: vec3<f32>,
    albedo: vec3<f32>,
    primitive: u32,
}

fn no_hit() -> KHit {
    return KHit(false, 0.0, vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), 0u);
}

fn has(flag: u32) -> bool {
    return (frame.flags & flag) != 0u;
}

// ---- geom/rng.rs PixelRng: SplitMix64 on (lo, hi) pairs of 32 bits ----

fn mul_wide(a: u32, b: u32) -> vec2<u32> {
    let a0 = a & 0xffffu;
    let a1 = a >> 16u;
    let b0 = b & 0xffffu;
    let b1 = b >> 16u;
    let p00 = a0 * b0;
    let p01 = a0 * b1;
    let p10 = a1 * b0;
    let p11 = a1 * b1;
    let mid = (p00 >> 16u) + (p01 & 0xffffu) + (p10 & 0xffffu);
    return vec2<u32>((p00 & 0xffffu) | (mid << 16u), p11 + (p01 >> 16u) + (p10 >> 16u) + (mid >> 16u));
}

fn mul64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let w = mul_wide(a.x, b.x);
    return vec2<u32>(w.x, w.y + a.x * b.y + a.y * b.x);
}

fn add64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let lo = a.x + b.x;
    return vec2<u32>(lo, a.y + b.y + select(0u, 1u, lo < a.x));
}

// a ^ (a >> n), 0 < n < 32.
fn xorshift64(a: vec2<u32>, n: u32) -> vec2<u32> {
    let s = vec2<u32>((a.x >> n) | (a.y << (32u - n)), a.y >> n);
    return a ^ s;
}

const GOLDEN: vec2<u32> = vec2<u32>(0x7F4A7C15u, 0x9E3779B9u);

fn mix64(z0: vec2<u32>) -> vec2<u32> {
    var z = mul64(xorshift64(z0, 30u), vec2<u32>(0x1CE4E5B9u, 0xBF58476Du));
    z = mul64(xorshift64(z, 27u), vec2<u32>(0x133111EBu, 0x94D049BBu));
    return xorshift64(z, 31u);
}

var<private> rng_state: vec2<u32>;

var<private> rotation_state: vec2<u32>;
var<private> rng_pass: u32;

fn rng_seed(x: u32, y: u32, pass_index: u32) {
    let key = vec2<u32>(x, y) ^ mix64(add64(vec2<u32>(pass_index, 0u), vec2<u32>(0x1503A7E5u, 0u)));
    rng_state = mix64(mul64(key, GOLDEN));
    rotation_state = mix64(mul64(vec2<u32>(x, y) ^ mix64(vec2<u32>(0x5EED57A7u, 0u)), GOLDEN));
    rng_pass = pass_index;
}

// Uniform in [0, 1).
fn rng_next() -> f32 {
    rng_state = add64(rng_state, GOLDEN);
    let v = mix64(rng_state);
    return f32(v.y >> 8u) * (1.0 / 16777216.0);
}

// PixelRng::points: one estimate's `count` points. Stratified: the pixel's next rotation of
// the R2 sequence (rng.rs R2_STEPS), from point `pass · count` on; else independent points.
var<private> points_rotation: vec2<u32>;
var<private> points_index: u32;

fn points_begin(count: u32) {
    if (has(FLAG_STRATIFIED)) {
        rotation_state = add64(rotation_state, GOLDEN);
        let v = mix64(rotation_state);
        points_rotation = vec2<u32>(v.y, v.x);
        points_index = rng_pass * count;
    }
}

fn points_next() -> vec2<f32> {
    if (has(FLAG_STRATIFIED)) {
        let i = points_index;
        points_index = i + 1u;
        let p = points_rotation + vec2<u32>(i * 3242174889u, i * 2447445414u);
        return vec2<f32>(f32(p.x >> 8u), f32(p.y >> 8u)) * (1.0 / 16777216.0);
    }
    let u1 = rng_next();
    let u2 = rng_next();
    return vec2<f32>(u1, u2);
}

// ---- sampling.rs ----

fn basis_t(n: vec3<f32>) -> vec3<f32> {
    let sign = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    return vec3<f32>(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
}

fn basis_b(n: vec3<f32>) -> vec3<f32> {
    let sign = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    return vec3<f32>(b, sign + n.y * n.y * a, -n.y);
}

fn cosine_hemisphere(n: vec3<f32>, u1: f32, u2: f32) -> vec3<f32> {
    let r = sqrt(u1);
    let phi = TAU * u2;
    let z = sqrt(max(1.0 - u1, 0.0));
    return normalize(basis_t(n) * (r * cos(phi)) + basis_b(n) * (r * sin(phi)) + n * z);
}

fn uniform_cone(axis: vec3<f32>, cos_max: f32, u1: f32, u2: f32) -> vec3<f32> {
    let cos_t = 1.0 - u1 * (1.0 - cos_max);
    let sin_t = sqrt(max(1.0 - cos_t * cos_t, 0.0));
    let phi = TAU * u2;
    return normalize(basis_t(axis) * (sin_t * cos(phi)) + basis_b(axis) * (sin_t * sin(phi)) + axis * cos_t);
}

// ---- shade.rs ----

fn material(index: u32) -> Material {
    return materials[min(index, frame.material_count - 1u)];
}

fn material_of(primitive: u32) -> u32 {
    for (var g = 0u; g < frame.group_count; g = g + 1u) {
        if (primitive - groups[g].first < groups[g].count) {
            return groups[g].material;
        }
    }
    return 0u;
}

fn receives_light(m: Material) -> bool {
    return max(max(m.diffuse.x, m.diffuse.y), m.diffuse.z) > 0.0 || m.diffuse.w > 0.0;
}

fn facing(normal: vec3<f32>, view: vec3<f32>) -> vec3<f32> {
    if (dot(normal, view) > 0.0) {
        return -normal;
    }
    return normal;
}

// A light seen from p: the unit direction towards it, its distance (BIG for a directional
// light) and its irradiance; `ok` false when p sits on a point light.
struct LightSample {
    ok: bool,
    to_light: vec3<f32>,
    distance: f32,
    irradiance: vec3<f32>,
}

fn toward(light: Light, p: vec3<f32>) -> LightSample {
    if (light.position.w == 0.0) {
        return LightSample(true, light.position.xyz, BIG, light.color.xyz);
    }
    let d = light.position.xyz - p;
    let d2 = dot(d, d);
    if (!(d2 > 1.0e-12)) {
        return LightSample(false, vec3<f32>(0.0), 0.0, vec3<f32>(0.0));
    }
    let distance = sqrt(d2);
    return LightSample(true, d / distance, distance, light.color.xyz / d2);
}

// shade.rs direct.
fn direct(m: Material, albedo: vec3<f32>, normal: vec3<f32>, view: vec3<f32>, l: LightSample, visibility: f32) -> vec3<f32> {
    let n_dot_l = dot(normal, l.to_light);
    if (n_dot_l <= 0.0 || visibility <= 0.0) {
        return vec3<f32>(0.0);
    }
    let h = l.to_light - view;
    let h2 = dot(h, h);
    var half = vec3<f32>(0.0);
    if (h2 > 0.0) {
        half = h * inverseSqrt(h2);
    }
    var spec = 0.0;
    let specular = m.diffuse.w;
    if (specular > 0.0) {
        let x = max(dot(normal, half), 0.0);
        if (x > 0.0) {
            spec = pow(x, m.emission.w) * specular;
        }
    }
    return l.irradiance * (albedo * n_dot_l + vec3<f32>(spec)) * visibility;
}

fn background(dir_y: f32) -> vec3<f32> {
    let a = 0.5 * (clamp(dir_y, -1.0, 1.0) + 1.0);
    return frame.background_bottom.xyz + (frame.background_top.xyz - frame.background_bottom.xyz) * a;
}

fn fresnel(cos_i: f32, n1: f32, n2: f32) -> f32 {
    let eta = n1 / n2;
    let sin_t2 = eta * eta * max(1.0 - cos_i * cos_i, 0.0);
    if (sin_t2 >= 1.0) {
        return 1.0;
    }
    let cos_t = sqrt(1.0 - sin_t2);
    let rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t);
    let rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i);
    return 0.5 * (rs * rs + rp * rp);
}

fn reflect_dir(dir: vec3<f32>, normal: vec3<f32>) -> vec3<f32> {
    return normalize(dir - 2.0 * dot(dir, normal) * normal);
}

// integrator.rs refract_dir; w = 0 under total internal reflection.
fn refract_dir(dir: vec3<f32>, normal: vec3<f32>, eta: f32) -> vec4<f32> {
    let cos_i = -dot(dir, normal);
    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    if (k < 0.0) {
        return vec4<f32>(0.0);
    }
    return vec4<f32>(normalize(eta * dir + (eta * cos_i - sqrt(k)) * normal), 1.0);
}

// shade.rs Lighting::shade: every light, no shadows (ray casting).
fn shade_cast(h: KHit, view: vec3<f32>) -> vec3<f32> {
    var albedo = h.albedo;
    if (has(FLAG_COLOR_MAP)) {
        albedo = frame.mapped_albedo.xyz;
    }
    return shade_lit(material(material_of(h.primitive)), albedo, h.position, h.normal, view);
}

// Lighting::shade_floor at p.
fn shade_floor_cast(p: vec3<f32>, view: vec3<f32>, t: f32) -> vec3<f32> {
    return shade_lit(material(frame.floor_material), floor_albedo(p, view, t), p, vec3<f32>(0.0, 1.0, 0.0), view);
}

// Lighting::shade_lit: every light without shadows.
fn shade_lit(m: Material, surface_albedo: vec3<f32>, p: vec3<f32>, n: vec3<f32>, view: vec3<f32>) -> vec3<f32> {
    let albedo = surface_albedo * m.diffuse.xyz;
    let normal = facing(n, view);
    var color = m.emission.xyz + frame.ambient.xyz * albedo;
    for (var k = 0u; k < frame.light_count; k = k + 1u) {
        let l = toward(lights[k], p);
        if (l.ok) {
            color = color + direct(m, albedo, normal, view, l, 1.0);
        }
    }
    return color;
}

// integrator.rs offset: how far a secondary ray starts off its surface.
fn offset(p: vec3<f32>) -> f32 {
    let ap = abs(p);
    return 1.0e-3 + 2.0e-5 * max(max(ap.x, ap.y), ap.z);
}

// ---- integrator.rs ----

// The stretches of [a, b] outside the clip box, in order: (lo, hi) pairs in xy and zw, and
// how many (Tracer::segments).
struct Segments {
    s: array<vec2<f32>, 2>,
    n: u32,
}

fn segments(o: vec3<f32>, d: vec3<f32>, a: f32, b: f32) -> Segments {
    var out: Segments;
    out.s[0] = vec2<f32>(a, b);
    out.s[1] = vec2<f32>(0.0, 0.0);
    out.n = 1u;
    if (!has(FLAG_CLIP)) {
        return out;
    }
    let inv = 1.0 / d;
    let t0 = (frame.clip_min.xyz - o) * inv;
    let t1 = (frame.clip_max.xyz - o) * inv;
    let lo = min(t0, t1);
    let hi = max(t0, t1);
    let near = max(max(lo.x, lo.y), lo.z);
    let far = min(min(hi.x, hi.y), hi.z);
    if (!(near <= far) || far <= a || near >= b) {
        return out;
    }
    var n = 0u;
    if (near > a) {
        out.s[n] = vec2<f32>(a, near);
        n = n + 1u;
    }
    if (far < b) {
        out.s[n] = vec2<f32>(far, b);
        n = n + 1u;
    }
    out.n = n;
    return out;
}

// Tracer::crossing: the first crossing of `iso` on [a, b] outside the clip box,
// entering the solid or, when the ray starts inside it (or `inside`), leaving it; `leaving`:
// the ray leaves a surface outwards (a mirror ray from outside, PreparedKind::
// first_hit_leaving), which kind_first_hit may use.
//
// Every query site of the kind is inlined whole by the shader compilers (lavapipe's NIR
// inlines every call), so the integrator asks the kind from as few places as it can: each of
// kind_first_hit and kind_exit_hit is called once here, and crossing_from itself from two
// places (closest, transmittance).
fn crossing_from(o: vec3<f32>, d: vec3<f32>, a: f32, b: f32, iso: f32, inside: bool, leaving: bool) -> KHit {
    let segs = segments(o, d, a, b);
    for (var k = 0u; k < segs.n; k = k + 1u) {
        let lo = segs.s[k].x;
        let hi = segs.s[k].y;
        var exit = inside && k == 0u && lo == a;
        loop {
            var h: KHit;
            if (exit) {
                h = kind_exit_hit(o, d, lo, hi, iso);
            } else {
                h = kind_first_hit(o, d, lo, hi, iso, leaving);
            }
            if (exit) {
                if (h.found) {
                    return h;
                }
                break;
            }
            if (!h.found) {
                break;
            }
            if (h.t > lo + INSIDE_EPS) {
                return h;
            }
            // A root at the segment's start: the ray starts inside; the way out counts.
            exit = true;
        }
    }
    return no_hit();
}

// A surface a ray reached: of the geometry or of the floor.
struct SurfaceHit {
    found: bool,
    t: f32,
    position: vec3<f32>,
    normal: vec3<f32>,
    albedo: vec3<f32>,
    material: u32,
}

fn floor_t(o: vec3<f32>, d: vec3<f32>) -> f32 {
    return (frame.floor_height - o.y) / d.y;
}

// shade.rs Floor::color_seen: the checker, counted in world coordinates, averaged over the
// footprint of a pixel's ray along unit d met t from its origin.
fn floor_albedo(p: vec3<f32>, d: vec3<f32>, t: f32) -> vec3<f32> {
    if (!(frame.floor_checker > 0.0)) {
        return frame.floor_color0.xyz;
    }
    let w = (p + frame.floor_origin.xyz) / frame.floor_checker;
    let spread = length(frame.right_step.xyz);
    let foot = floor_footprint(d, t * spread) / frame.floor_checker;
    let s = square_wave_mean(w.x, foot.x) * square_wave_mean(w.z, foot.y);
    let even = 0.5 + 0.5 * s;
    return frame.floor_color0.xyz * even + frame.floor_color1.xyz * (1.0 - even);
}

// shade.rs footprint.
fn floor_footprint(d: vec3<f32>, width: f32) -> vec2<f32> {
    let flat = d.x * d.x + d.z * d.z;
    if (!(width > 0.0) || flat < 1.0e-12) {
        let w = max(width, 0.0);
        return vec2<f32>(w, w);
    }
    let stretch = 1.0 / max(d.y * d.y, 1.0e-6);
    let hx = d.x * d.x / flat;
    let hz = d.z * d.z / flat;
    return width * vec2<f32>(sqrt(hx * stretch + hz), sqrt(hz * stretch + hx));
}

// shade.rs square_wave_mean.
fn square_wave_mean(u: f32, w: f32) -> f32 {
    if (w < 1.0e-4) {
        if (fract(floor(u) * 0.5) == 0.0) {
            return 1.0;
        }
        return -1.0;
    }
    let a = 1.0 - abs(fract((u + 0.5 * w) * 0.5) * 2.0 - 1.0);
    let b = 1.0 - abs(fract((u - 0.5 * w) * 0.5) * 2.0 - 1.0);
    return clamp((a - b) / w, -1.0, 1.0);
}

// Tracer::closest: the nearest surface on [t0, t1], every drawn isosurface and the floor.
fn closest(o: vec3<f32>, d: vec3<f32>, t0: f32, t1: f32, leaving: bool) -> SurfaceHit {
    var best = SurfaceHit(false, 0.0, vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), 0u);
    var limit = t1;
    if (!has(FLAG_VOLUME)) {
        var surfaces = 1u;
        if (has(FLAG_ISOSURFACES)) {
            surfaces = surfaces + frame.isosurface_count;
        }
        for (var k = 0u; k < surfaces; k = k + 1u) {
            var iso = frame.isovalue;
            if (k > 0u) {
                iso = isosurfaces[k - 1u].isovalue;
            }
            let h = crossing_from(o, d, t0, limit, iso, false, leaving);
            if (!h.found) {
                continue;
            }
            limit = h.t;
            var albedo = h.albedo;
            var m = 0u;
            if (k == 0u) {
                if (has(FLAG_COLOR_MAP)) {
                    albedo = frame.mapped_albedo.xyz;
                }
                m = material_of(h.primitive);
            } else {
                let s = isosurfaces[k - 1u];
                if (s.color.w > 0.0) {
                    albedo = s.color.xyz;
                }
                m = s.material;
            }
            best = SurfaceHit(true, h.t, h.position, h.normal, albedo, m);
        }
    }
    if (has(FLAG_FLOOR)) {
        let t = floor_t(o, d);
        if (t > t0 && t < limit) {
            let p = o + t * d;
            best = SurfaceHit(true, t, p, vec3<f32>(0.0, 1.0, 0.0), floor_albedo(p, d, t), frame.floor_material);
        }
    }
    return best;
}

fn optical_depth(o: vec3<f32>, d: vec3<f32>, a: f32, b: f32) -> f32 {
    let segs = segments(o, d, a, b);
    var sum = 0.0;
    for (var k = 0u; k < segs.n; k = k + 1u) {
        sum = sum + kind_optical_depth(o, d, segs.s[k].x, segs.s[k].y);
    }
    return sum;
}

// Tracer::transmittance: the share of light that passes along the ray over [0, t_max].
fn transmittance(o: vec3<f32>, d: vec3<f32>, t_max: f32) -> f32 {
    if (has(FLAG_FLOOR)) {
        let t = floor_t(o, d);
        if (t > 0.0 && t < t_max && material(frame.floor_material).extra.x >= 1.0) {
            return 0.0;
        }
    }
    if (has(FLAG_VOLUME)) {
        return exp(-frame.volume.w * optical_depth(o, d, 0.0, t_max));
    }
    var transmitted = 1.0;
    var surfaces = 1u;
    if (has(FLAG_ISOSURFACES)) {
        surfaces = surfaces + frame.isosurface_count;
    }
    for (var k = 0u; k < surfaces; k = k + 1u) {
        var iso = frame.isovalue;
        var fixed = false;
        var fixed_material = 0u;
        if (k > 0u) {
            iso = isosurfaces[k - 1u].isovalue;
            fixed = true;
            fixed_material = isosurfaces[k - 1u].material;
        }
        // Walk the crossings, each letting 1 - α through. Without layers the first crossing
        // blocks (Tracer::blocked's any hit, found here as the first one).
        var t = 0.0;
        var crossings = 0u;
        var inside = false;
        loop {
            let h = crossing_from(o, d, t, t_max, iso, inside, false);
            if (!h.found) {
                break;
            }
            inside = dot(h.normal, d) < 0.0;
            var m = fixed_material;
            if (!fixed) {
                m = material_of(h.primitive);
            }
            transmitted = transmitted * (1.0 - clamp(material(m).extra.x, 0.0, 1.0));
            crossings = crossings + 1u;
            if (transmitted <= 1.0e-3 || crossings > frame.layers) {
                return 0.0;
            }
            t = h.t + offset(h.position);
        }
    }
    return transmitted;
}

// Tracer::local: ambient (with occlusion) and every light (with shadows, Tracer::visibility).
// One loop over the occlusion rays, then each light's shadow rays, so that transmittance
// (and the kind's queries in it) has one call site; the random numbers are drawn in the
// CPU's order.
fn local(m: Material, h: SurfaceHit, normal: vec3<f32>, view: vec3<f32>, above: vec3<f32>) -> vec3<f32> {
    let albedo = h.albedo * m.diffuse.xyz;
    var ambient = frame.ambient.xyz * albedo;
    var ao = 0u;
    if (frame.ao_samples > 0u && max(max(ambient.x, ambient.y), ambient.z) > 0.0) {
        ao = frame.ao_samples;
    }
    var open = 0.0;
    var color = vec3<f32>(0.0);
    for (var j = 0u; j < ao + frame.light_count; j = j + 1u) {
        let is_ao = j < ao;
        var n = 1u;
        var light: Light;
        var l: LightSample;
        var soft = false;
        var cos_max = 1.0;
        if (!is_ao) {
            light = lights[j - ao];
            l = toward(light, h.position);
            // A light behind the surface adds nothing: no shadow ray for it.
            if (!l.ok || dot(normal, l.to_light) <= 0.0) {
                continue;
            }
            if (!has(FLAG_SHADOWS)) {
                color = color + direct(m, albedo, normal, view, l, 1.0);
                continue;
            }
            if (light.position.w == 2.0 && has(FLAG_SOFT_SHADOWS)) {
                let radius = light.color.w;
                if (l.distance <= radius) {
                    color = color + direct(m, albedo, normal, view, l, 1.0);
                    continue;
                }
                let q = radius / l.distance;
                cos_max = sqrt(max(1.0 - q * q, 0.0));
                soft = true;
                n = max(frame.light_samples, 1u);
            }
        }
        // One estimate's points: all the occlusion rays' (j = 0 begins them), or a soft light's.
        if (is_ao && j == 0u) {
            points_begin(ao);
        } else if (soft) {
            points_begin(n);
        }
        var seen = 0.0;
        for (var s = 0u; s < n; s = s + 1u) {
            var dir = l.to_light;
            var reach = 0.0;
            if (is_ao) {
                let u = points_next();
                dir = cosine_hemisphere(normal, u.x, u.y);
                reach = frame.occlusion_distance;
            } else if (soft) {
                let u = points_next();
                dir = uniform_cone(l.to_light, cos_max, u.x, u.y);
                // Distance to the sphere along dir, nearer root.
                let oc = above - light.position.xyz;
                let b = dot(oc, dir);
                let c = dot(oc, oc) - light.color.w * light.color.w;
                reach = max(-b - sqrt(max(b * b - c, 0.0)), 0.0);
            } else if (light.position.w == 2.0) {
                reach = max(l.distance - light.color.w, 0.0);
            } else {
                reach = min(l.distance, frame.t_max);
            }
            seen = seen + transmittance(above, dir, reach);
        }
        if (is_ao) {
            open = open + seen;
        } else {
            color = color + direct(m, albedo, normal, view, l, seen / f32(n));
        }
    }
    if (ao > 0u) {
        ambient = ambient * (open / f32(ao));
    }
    return ambient + color;
}

// A ray waiting to be traced: its radiance adds `weight` times itself to the pixel.
struct Task {
    origin: vec3<f32>,
    t0: f32,
    dir: vec3<f32>,
    depth: u32,
    weight: vec3<f32>,
    layers: u32,
    // A mirror ray leaving a surface outwards (Tracer::leaving; kind_first_hit's `leaving`).
    leaving: bool,
}

var<private> tasks: array<Task, RAY_STACK>;
var<private> task_count: u32;

fn push(origin: vec3<f32>, dir: vec3<f32>, t0: f32, depth: u32, layers: u32, weight: vec3<f32>, leaving: bool) {
    if (task_count < RAY_STACK && max(max(weight.x, weight.y), weight.z) > 0.0) {
        tasks[task_count] = Task(origin, t0, dir, depth, weight, layers, leaving);
        task_count = task_count + 1u;
    }
}

// Tracer::radiance + shade_hit for one ray: what it adds to the pixel now, and the rays it
// spawns (pushed, in reverse of the CPU's order). Returns the hit distance (BIG: a miss).
fn radiance(task: Task, color: ptr<function, vec3<f32>>) -> f32 {
    let o = task.origin;
    let d = task.dir;
    let h = closest(o, d, task.t0, frame.t_max, task.leaving);
    var far = frame.t_max;
    if (h.found) {
        far = h.t;
    }
    var w = task.weight;
    if (has(FLAG_VOLUME)) {
        let tr = exp(-(frame.volume.w * optical_depth(o, d, task.t0, far)));
        *color = *color + w * frame.volume.xyz * (1.0 - tr);
        w = w * tr;
    }
    if (!h.found) {
        *color = *color + w * background(d.y);
        return BIG;
    }
    let m = material(h.material);
    let view = d;
    let normal = facing(h.normal, view);
    let entering = dot(h.normal, view) < 0.0;
    let eps = offset(h.position);
    let above = h.position + normal * eps;
    var own = m.emission.xyz;
    if (receives_light(m)) {
        own = own + local(m, h, normal, view, above);
    }
    let opacity = m.extra.x;
    let reflectivity = m.extra.y;
    let ior = m.extra.z;
    // The mirror's share (shade_hit's last step), then what lies behind.
    var keep = w;
    if (reflectivity > 0.0 && task.depth < frame.reflection_depth) {
        push(above, reflect_dir(view, normal), 0.0, task.depth + 1u, task.layers, w * reflectivity, entering);
        keep = w * (1.0 - reflectivity);
    }
    let transparent = opacity < 1.0;
    let transmits = transparent && (frame.layers > 0u || frame.refraction_depth > 0u);
    if (transmits && ior != 1.0 && task.depth < frame.refraction_depth) {
        let behind = keep * (1.0 - opacity);
        var n1 = 1.0;
        var n2 = ior;
        if (!entering) {
            n1 = ior;
            n2 = 1.0;
        }
        let cos_i = clamp(-dot(view, normal), 0.0, 1.0);
        let reflectance = fresnel(cos_i, n1, n2);
        if (reflectance < 1.0) {
            let bent = refract_dir(view, normal, n1 / n2);
            if (bent.w > 0.0) {
                push(h.position - normal * eps, bent.xyz, 0.0, task.depth + 1u, task.layers, behind * (1.0 - reflectance), false);
            }
        }
        if (reflectance > 0.0) {
            push(h.position + normal * eps, reflect_dir(view, normal), 0.0, task.depth + 1u, task.layers, behind * reflectance, entering);
        }
        *color = *color + keep * opacity * own;
    } else if (transmits && task.layers > 0u) {
        push(o, d, h.t + eps, task.depth, task.layers - 1u, keep * (1.0 - opacity), false);
        *color = *color + keep * opacity * own;
    } else {
        *color = *color + keep * own;
    }
    return h.t;
}

@compute @workgroup_size(8, 8, 1)
fn trace(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= frame.width || id.y >= frame.height) {
        return;
    }
    let raw = frame.top_left.xyz + frame.right_step.xyz * (f32(id.x) + 0.5)
        + frame.down_step.xyz * (f32(id.y) + 0.5);
    let d = normalize(raw);
    let o = frame.eye.xyz;
    var color = vec3<f32>(0.0);
    var t = -1.0;
    if (has(FLAG_PASS)) {
        rng_seed(id.x, id.y, frame.pass_index);
        tasks[0] = Task(o, 0.0, d, 0u, vec3<f32>(1.0), frame.layers, false);
        task_count = 1u;
        var primary = true;
        // Whether the loop saw the stack empty in an iteration of its own (see CUT).
        var finished = false;
        loop {
            if (task_count == 0u) {
                finished = true;
                break;
            }
            task_count = task_count - 1u;
            let next = tasks[task_count];
            let hit_t = radiance(next, &color);
            if (primary && hit_t < BIG) {
                t = hit_t * dot(d, frame.forward.xyz);
            }
            primary = false;
        }
        if (!finished && has(FLAG_MARK_CUT)) {
            t = CUT;
        }
    } else {
        let h = kind_first_hit(o, d, 0.0, frame.t_max, frame.isovalue, false);
        var limit = frame.t_max;
        if (h.found) {
            limit = h.t;
        }
        // shade_primary: the floor where it is nearer than the surface.
        var ft = BIG;
        if (has(FLAG_FLOOR)) {
            ft = floor_t(o, d);
        }
        if (ft > 0.0 && ft < limit) {
            color = shade_floor_cast(o + ft * d, d, ft);
            t = ft * dot(d, frame.forward.xyz);
        } else if (h.found) {
            color = shade_cast(h, d);
            t = h.t * dot(d, frame.forward.xyz);
        } else {
            color = background(d.y);
        }
    }
    pixels[id.y * frame.width + id.x] = vec4<f32>(color, t);
}
