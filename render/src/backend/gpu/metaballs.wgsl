// The metaball trace kernel: one invocation per pixel. It walks the flattened Fitted BVH
// front to back (render/src/kinds/metaballs/tree/walk.rs), gathers each leaf's balls the ray
// crosses (engine.rs `gather`), finds the first root with the CPU's marching finder over the
// sorted entry/exit sections (roots.rs `walk_sections` + `march_section` + `bisect`), and
// shades as the CPU does: `Lighting::shade` for ray casting, or the integrator's first pass
// (floor, hard shadows) for a pass (integrator.rs `closest`, `local`, `transmittance`).
// The structs mirror backend/gpu/layout.rs field by field.

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
    kernel: vec4<f32>,
    floor_color0: vec4<f32>,
    floor_color1: vec4<f32>,
    kernel_c4: f32,
    kernel_degree: u32,
    isovalue: f32,
    tolerance: f32,
    width: u32,
    height: u32,
    flags: u32,
    t_max: f32,
    light_count: u32,
    group_count: u32,
    material_count: u32,
    node_count: u32,
    floor_height: f32,
    floor_checker: f32,
    floor_material: u32,
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

struct Node {
    min: vec3<f32>,
    first: u32,
    max: vec3<f32>,
    count: u32,
}

struct Ball {
    center: vec3<f32>,
    strength: f32,
    m0: vec4<f32>,
    m1: vec4<f32>,
    m2: vec4<f32>,
    color: vec4<f32>,
}

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> nodes: array<Node>;
@group(0) @binding(2) var<storage, read> leaf_balls: array<u32>;
@group(0) @binding(3) var<storage, read> balls: array<Ball>;
@group(0) @binding(4) var<storage, read> lights: array<Light>;
@group(0) @binding(5) var<storage, read> materials: array<Material>;
@group(0) @binding(6) var<storage, read> groups: array<Group>;
// Per pixel: linear colour, and the hit distance along the view axis (negative: a miss).
@group(0) @binding(7) var<storage, read_write> pixels: array<vec4<f32>>;

const FLAG_PASS: u32 = 1u;
const FLAG_SHADOWS: u32 = 2u;
const FLAG_FLOOR: u32 = 4u;
const FLAG_COLOR_MAP: u32 = 8u;

// Most balls one leaf may hand the root finder; the upload refuses trees with larger leaves.
const MAX_GATHER: u32 = 192u;
// Traversal stack; the upload refuses deeper trees.
const STACK_SIZE: u32 = 64u;
// roots.rs / bezier.rs ITERATION_CAP.
const ITERATION_CAP: u32 = 20000u;
// integrator.rs INSIDE_EPS.
const INSIDE_EPS: f32 = 2.0e-4;
const BIG: f32 = 3.0e38;

// One ball as one ray sees it (roots.rs RayBall): s(t) = a (t - tc)² + s_min on [t0, t1].
struct RayBall {
    ball: u32,
    t0: f32,
    t1: f32,
    a: f32,
    tc: f32,
    s_min: f32,
    q: f32,
    min_radius: f32,
}

var<private> gathered: array<RayBall, MAX_GATHER>;
var<private> gathered_count: u32;
var<private> stack_node: array<u32, STACK_SIZE>;
var<private> stack_range: array<vec2<f32>, STACK_SIZE>;

// The kernel at w = 1 - s, times `sign` (-1: the exit query's negated field).
fn kernel_at_w(w: f32) -> f32 {
    var acc = frame.kernel_c4;
    if (frame.kernel_degree < 4u) {
        acc = frame.kernel[frame.kernel_degree];
    }
    var k = frame.kernel_degree;
    while (k > 0u) {
        k = k - 1u;
        acc = acc * w + frame.kernel[k];
    }
    return acc;
}

// df/ds at s (zero beyond the support).
fn kernel_derivative(s: f32) -> f32 {
    if (s >= 1.0) {
        return 0.0;
    }
    let w = 1.0 - s;
    var d = 0.0;
    var wk = 1.0;
    for (var k = 1u; k <= frame.kernel_degree; k = k + 1u) {
        var c = frame.kernel_c4;
        if (k < 4u) {
            c = frame.kernel[k];
        }
        d = d + f32(k) * c * wk;
        wk = wk * w;
    }
    return -d;
}

fn kernel_value(s: f32) -> f32 {
    if (s >= 1.0) {
        return 0.0;
    }
    return kernel_at_w(1.0 - s);
}

fn term(b: RayBall, t: f32, sign: f32) -> f32 {
    let u = t - b.tc;
    let s = b.a * u * u + b.s_min;
    if (s >= 1.0) {
        return 0.0;
    }
    return sign * b.q * kernel_at_w(1.0 - s);
}

// The ray's view of ball `i`: false when the ray misses its support or [lo, hi].
fn gather(i: u32, o: vec3<f32>, d: vec3<f32>, lo: f32, hi: f32) -> bool {
    let b = balls[i];
    var e: vec3<f32>;
    var g: vec3<f32>;
    if (b.m1.w == 0.0) {
        let inv_r = b.m0.x;
        e = (o - b.center) * inv_r;
        g = d * inv_r;
    } else {
        let v = o - b.center;
        e = vec3<f32>(dot(b.m0.xyz, v), dot(b.m1.xyz, v), dot(b.m2.xyz, v));
        g = vec3<f32>(dot(b.m0.xyz, d), dot(b.m1.xyz, d), dot(b.m2.xyz, d));
    }
    let a = dot(g, g);
    if (!(a > 0.0)) {
        return false;
    }
    let tc = -dot(e, g) / a;
    let q = e + tc * g;
    let s_min = dot(q, q);
    if (!(s_min < 1.0)) {
        return false;
    }
    let half = sqrt((1.0 - s_min) / a);
    let t0 = tc - half;
    let t1 = tc + half;
    if (t1 < lo || t0 > hi) {
        return false;
    }
    gathered[gathered_count] = RayBall(i, t0, t1, a, tc, s_min, b.strength, b.m0.w);
    gathered_count = gathered_count + 1u;
    return true;
}

// Whether gathered ball k is active on the section starting at `t` (clamped to [lo, hi]).
fn is_active(k: u32, t: f32, lo: f32, hi: f32) -> bool {
    let b = gathered[k];
    let t0 = max(b.t0, lo);
    let t1 = min(b.t1, hi);
    return t0 < t1 && t0 <= t && t1 > t;
}

fn field(t: f32, a: f32, lo: f32, hi: f32, sign: f32) -> f32 {
    var f = 0.0;
    for (var k = 0u; k < gathered_count; k = k + 1u) {
        if (is_active(k, a, lo, hi)) {
            f = f + term(gathered[k], t, sign);
        }
    }
    return f;
}

// roots.rs may_reach: an upper bound of the field on [a, b] reaches the isovalue.
fn may_reach(a: f32, b: f32, lo: f32, hi: f32, sign: f32) -> bool {
    let peak = sign * kernel_at_w(1.0);
    var bound = 0.0;
    for (var k = 0u; k < gathered_count; k = k + 1u) {
        if (is_active(k, a, lo, hi)) {
            let ball = gathered[k];
            if (ball.q * peak > 0.0) {
                bound = bound + term(ball, min(max(ball.tc, a), b), sign);
            }
        }
    }
    return !(bound < sign * frame.isovalue);
}

struct Root {
    found: bool,
    t: f32,
}

// roots.rs march_section + bisect on the section [a, b] that starts at `a`.
fn march_section(a: f32, b: f32, lo: f32, hi: f32, sign: f32, iters: ptr<function, u32>) -> Root {
    var step = BIG;
    for (var k = 0u; k < gathered_count; k = k + 1u) {
        if (is_active(k, a, lo, hi)) {
            step = min(step, gathered[k].min_radius);
        }
    }
    step = step * 0.25;
    let iso = sign * frame.isovalue;
    var t0 = a;
    *iters = *iters + 1u;
    if (field(t0, a, lo, hi, sign) - iso >= 0.0) {
        return Root(true, t0);
    }
    loop {
        if (!(t0 < b)) {
            break;
        }
        let t1 = min(t0 + step, b);
        if (!(t1 > t0) || *iters > ITERATION_CAP) {
            return Root(false, 0.0);
        }
        *iters = *iters + 1u;
        if (field(t1, a, lo, hi, sign) - iso >= 0.0) {
            // Bisection to the tolerance; the upper end is the root.
            var l = t0;
            var h = t1;
            loop {
                if (!(h - l > frame.tolerance && *iters < ITERATION_CAP)) {
                    break;
                }
                let mid = 0.5 * (l + h);
                if (!(l < mid && mid < h)) {
                    break;
                }
                *iters = *iters + 1u;
                if (field(mid, a, lo, hi, sign) - iso < 0.0) {
                    l = mid;
                } else {
                    h = mid;
                }
            }
            return Root(true, h);
        }
        t0 = t1;
    }
    return Root(false, 0.0);
}

// roots.rs walk_sections with the marching finder over the gathered balls on [lo, hi].
fn find_first(lo: f32, hi: f32, sign: f32) -> Root {
    if (gathered_count == 0u || !(lo < hi)) {
        return Root(false, 0.0);
    }
    var t = BIG;
    for (var k = 0u; k < gathered_count; k = k + 1u) {
        let t0 = max(gathered[k].t0, lo);
        let t1 = min(gathered[k].t1, hi);
        if (t0 < t1) {
            t = min(t, t0);
        }
    }
    var total = 0u;
    loop {
        // The next event strictly after t.
        var next = BIG;
        var any_active = false;
        for (var k = 0u; k < gathered_count; k = k + 1u) {
            let t0 = max(gathered[k].t0, lo);
            let t1 = min(gathered[k].t1, hi);
            if (t0 < t1) {
                if (t0 > t) {
                    next = min(next, t0);
                }
                if (t1 > t) {
                    next = min(next, t1);
                }
                if (t0 <= t && t1 > t) {
                    any_active = true;
                }
            }
        }
        if (next >= BIG) {
            break;
        }
        if (any_active && may_reach(t, next, lo, hi, sign)) {
            var iters = 0u;
            let r = march_section(t, next, lo, hi, sign, &iters);
            total = total + iters;
            if (r.found) {
                return r;
            }
            if (total > ITERATION_CAP) {
                break;
            }
        }
        t = next;
    }
    return Root(false, 0.0);
}

// geom/aabb.rs slab: the range of the ray inside the node's box within [t_min, t_max].
fn slab(n: u32, o: vec3<f32>, inv_d: vec3<f32>, t_min: f32, t_max: f32) -> vec3<f32> {
    let node = nodes[n];
    let t0 = (node.min - o) * inv_d;
    let t1 = (node.max - o) * inv_d;
    let lo = min(t0, t1);
    let hi = max(t0, t1);
    let near = max(max(max(lo.x, lo.y), lo.z), t_min);
    let far = min(min(min(hi.x, hi.y), hi.z), t_max);
    // z = 1 when the range is not empty.
    return vec3<f32>(near, far, select(0.0, 1.0, near <= far));
}

fn safe_inverse(d: vec3<f32>) -> vec3<f32> {
    var r: vec3<f32>;
    for (var k = 0; k < 3; k = k + 1) {
        if (abs(d[k]) < 1.0e-30) {
            r[k] = select(-BIG, BIG, d[k] >= 0.0);
        } else {
            r[k] = 1.0 / d[k];
        }
    }
    return r;
}

// tree/walk.rs Tree::walk with `first_leaf` (the Fitted BVH's disjoint leaves): the first
// leaf with a root answers. On return `gathered` holds that leaf's balls.
fn first_root(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, sign: f32) -> Root {
    if (frame.node_count == 0u || !(t_min < t_max)) {
        return Root(false, 0.0);
    }
    let inv_d = safe_inverse(d);
    var top = 0u;
    let root = slab(0u, o, inv_d, t_min, t_max);
    if (root.z > 0.0) {
        stack_node[0] = 0u;
        stack_range[0] = root.xy;
        top = 1u;
    }
    while (top > 0u) {
        top = top - 1u;
        let i = stack_node[top];
        let near = stack_range[top].x;
        let far = stack_range[top].y;
        if (near > t_max) {
            continue;
        }
        let node = nodes[i];
        if (node.count > 0u || node.first == 0xffffffffu) {
            gathered_count = 0u;
            for (var k = 0u; k < node.count; k = k + 1u) {
                gather(leaf_balls[node.first + k], o, d, near, far);
            }
            if (gathered_count == 0u) {
                continue;
            }
            let r = find_first(near, far, sign);
            if (r.found) {
                return r;
            }
            continue;
        }
        let c = node.first;
        let lo = max(near, t_min);
        let l = slab(c, o, inv_d, lo, t_max);
        let r = slab(c + 1u, o, inv_d, lo, t_max);
        if (l.z > 0.0 && r.z > 0.0) {
            if (l.x <= r.x) {
                stack_node[top] = c + 1u;
                stack_range[top] = r.xy;
                stack_node[top + 1u] = c;
                stack_range[top + 1u] = l.xy;
            } else {
                stack_node[top] = c;
                stack_range[top] = l.xy;
                stack_node[top + 1u] = c + 1u;
                stack_range[top + 1u] = r.xy;
            }
            top = top + 2u;
        } else if (l.z > 0.0) {
            stack_node[top] = c;
            stack_range[top] = l.xy;
            top = top + 1u;
        } else if (r.z > 0.0) {
            stack_node[top] = c + 1u;
            stack_range[top] = r.xy;
            top = top + 1u;
        }
    }
    return Root(false, 0.0);
}

// What shading needs of a surface point.
struct Surface {
    t: f32,
    position: vec3<f32>,
    // Outward (or up from the floor); not turned towards the viewer.
    normal: vec3<f32>,
    albedo: vec3<f32>,
    material: u32,
}

fn material_of(primitive: u32) -> u32 {
    for (var g = 0u; g < frame.group_count; g = g + 1u) {
        if (primitive - groups[g].first < groups[g].count) {
            return groups[g].material;
        }
    }
    return 0u;
}

// scene.rs surface_detail over the gathered balls at p.
fn surface_at(t: f32, p: vec3<f32>) -> Surface {
    var gradient = vec3<f32>(0.0);
    var color = vec3<f32>(0.0);
    var weight = 0.0;
    var dominant = 0u;
    var dominant_w = 0.0;
    for (var k = 0u; k < gathered_count; k = k + 1u) {
        let i = gathered[k].ball;
        let b = balls[i];
        let dp = p - b.center;
        var s: f32;
        var ds: vec3<f32>;
        if (b.m1.w == 0.0) {
            let inv_r2 = b.m0.x * b.m0.x;
            s = dot(dp, dp) * inv_r2;
            ds = 2.0 * inv_r2 * dp;
        } else {
            let md = vec3<f32>(dot(b.m0.xyz, dp), dot(b.m1.xyz, dp), dot(b.m2.xyz, dp));
            s = dot(md, md);
            ds = 2.0 * (b.m0.xyz * md.x + b.m1.xyz * md.y + b.m2.xyz * md.z);
        }
        if (s >= 1.0) {
            continue;
        }
        gradient = gradient + b.strength * kernel_derivative(s) * ds;
        let w = max(b.strength * kernel_value(s), 0.0);
        color = color + w * b.color.xyz;
        weight = weight + w;
        if (w > dominant_w) {
            dominant = i;
            dominant_w = w;
        }
    }
    var normal = vec3<f32>(0.0, 0.0, 1.0);
    let len2 = dot(gradient, gradient);
    if (len2 > 0.0) {
        normal = -gradient * inverseSqrt(len2);
    }
    var albedo = vec3<f32>(0.5);
    if (weight > 0.0) {
        albedo = color / weight;
    }
    if ((frame.flags & FLAG_COLOR_MAP) != 0u) {
        albedo = frame.mapped_albedo.xyz;
    }
    return Surface(t, p, normal, albedo, material_of(dominant));
}

fn material(index: u32) -> Material {
    return materials[min(index, frame.material_count - 1u)];
}

fn facing(normal: vec3<f32>, view: vec3<f32>) -> vec3<f32> {
    if (dot(normal, view) > 0.0) {
        return -normal;
    }
    return normal;
}

// A light seen from p: to_light (xyz) and distance (w; BIG for a directional light), and
// its irradiance; `ok` false when p sits on a point light.
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

// shade.rs Lighting::shade: every light, no shadows (ray casting).
fn shade_cast(s: Surface, view: vec3<f32>) -> vec3<f32> {
    let m = material(s.material);
    let albedo = s.albedo * m.diffuse.xyz;
    let normal = facing(s.normal, view);
    var color = m.emission.xyz + frame.ambient.xyz * albedo;
    for (var k = 0u; k < frame.light_count; k = k + 1u) {
        let l = toward(lights[k], s.position);
        if (l.ok) {
            color = color + direct(m, albedo, normal, view, l, 1.0);
        }
    }
    return color;
}

// integrator.rs crossing: the first crossing on [a, b], or the way out of the solid when the
// ray starts inside it.
fn crossing(o: vec3<f32>, d: vec3<f32>, a: f32, b: f32) -> Root {
    let r = first_root(o, d, a, b, 1.0);
    if (!r.found || r.t > a + INSIDE_EPS) {
        return r;
    }
    return first_root(o, d, a, b, -1.0);
}

fn floor_t(o: vec3<f32>, d: vec3<f32>) -> f32 {
    if (d.y == 0.0) {
        return -1.0;
    }
    return (frame.floor_height - o.y) / d.y;
}

// integrator.rs transmittance with no layers, clip box or volume: 0 or 1.
fn transmittance(o: vec3<f32>, d: vec3<f32>, t_max: f32) -> f32 {
    if ((frame.flags & FLAG_FLOOR) != 0u) {
        let t = floor_t(o, d);
        if (t > 0.0 && t < t_max && material(frame.floor_material).extra.x >= 1.0) {
            return 0.0;
        }
    }
    let r = first_root(o, d, 0.0, t_max, 1.0);
    if (!r.found) {
        return 1.0;
    }
    if (r.t > INSIDE_EPS) {
        return 0.0;
    }
    // Starting inside the solid: its boundary blocks if the ray leaves it here.
    if (first_root(o, d, 0.0, t_max, -1.0).found) {
        return 0.0;
    }
    return 1.0;
}

// integrator.rs shade_hit (emission and `local`, no reflection or transmission rays).
fn shade_pass(s: Surface, view: vec3<f32>) -> vec3<f32> {
    let m = material(s.material);
    let normal = facing(s.normal, view);
    let ap = abs(s.position);
    let eps = 1.0e-3 + 2.0e-5 * max(max(ap.x, ap.y), ap.z);
    let above = s.position + normal * eps;
    var color = m.emission.xyz;
    let receives = max(max(m.diffuse.x, m.diffuse.y), m.diffuse.z) > 0.0 || m.diffuse.w > 0.0;
    if (!receives) {
        return color;
    }
    let albedo = s.albedo * m.diffuse.xyz;
    color = color + frame.ambient.xyz * albedo;
    for (var k = 0u; k < frame.light_count; k = k + 1u) {
        let light = lights[k];
        let l = toward(light, s.position);
        if (!l.ok || dot(normal, l.to_light) <= 0.0) {
            continue;
        }
        var visibility = 1.0;
        if ((frame.flags & FLAG_SHADOWS) != 0u) {
            var reach = min(l.distance, frame.t_max);
            if (light.position.w == 2.0) {
                reach = max(l.distance - light.color.w, 0.0);
            }
            visibility = transmittance(above, l.to_light, reach);
        }
        color = color + direct(m, albedo, normal, view, l, visibility);
    }
    return color;
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
    let in_pass = (frame.flags & FLAG_PASS) != 0u;
    var color = background(d.y);
    var t = -1.0;
    var hit = false;
    var s: Surface;
    var limit = frame.t_max;
    var root: Root;
    if (in_pass) {
        root = crossing(o, d, 0.0, frame.t_max);
    } else {
        root = first_root(o, d, 0.0, frame.t_max, 1.0);
    }
    if (root.found) {
        s = surface_at(root.t, o + root.t * d);
        hit = true;
        limit = root.t;
    }
    if (in_pass && (frame.flags & FLAG_FLOOR) != 0u) {
        let tf = floor_t(o, d);
        if (tf > 0.0 && tf < limit) {
            let p = o + tf * d;
            var albedo = frame.floor_color0.xyz;
            if (frame.floor_checker > 0.0) {
                let ix = i32(floor(p.x / frame.floor_checker));
                let iz = i32(floor(p.z / frame.floor_checker));
                if (((ix + iz) & 1) != 0) {
                    albedo = frame.floor_color1.xyz;
                }
            }
            s = Surface(tf, p, vec3<f32>(0.0, 1.0, 0.0), albedo, frame.floor_material);
            hit = true;
        }
    }
    if (hit) {
        if (in_pass) {
            color = shade_pass(s, d);
        } else {
            color = shade_cast(s, d);
        }
        t = s.t * dot(d, frame.forward.xyz);
    }
    pixels[id.y * frame.width + id.x] = vec4<f32>(color, t);
}
