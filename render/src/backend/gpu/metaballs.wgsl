// The metaball part of the trace kernel (appended to common.wgsl, and followed by
// metaball_finders.wgsl): the kind's queries `kind_first_hit`, `kind_exit_hit`, `kind_any_hit`
// and `kind_optical_depth`. It walks the flattened Fitted BVH front to back
// (render/src/kinds/metaballs/tree/walk.rs), gathers each leaf's balls the ray crosses
// (engine.rs `gather`), and finds the first root with the CPU state's finder (`finder` of the
// uniform: Bézier clipping, marching or the secant method; the exit query always clips, as
// the CPU's does). The structs mirror backend/gpu/layout.rs field by field.

struct MbParams {
    kernel: vec4<f32>,
    kernel_c4: f32,
    kernel_degree: u32,
    tolerance: f32,
    step: f32,
    node_count: u32,
    finder: u32,
    _pad1: u32,
    _pad2: u32,
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

@group(1) @binding(0) var<uniform> mb: MbParams;
@group(1) @binding(1) var<storage, read> nodes: array<Node>;
@group(1) @binding(2) var<storage, read> leaf_balls: array<u32>;
@group(1) @binding(3) var<storage, read> balls: array<Ball>;

// Most balls one leaf may hand the root finder; the upload refuses trees with larger leaves.
const MAX_GATHER: u32 = 192u;
// Traversal stack; the upload refuses deeper trees.
const STACK_SIZE: u32 = 64u;
// roots.rs / bezier.rs ITERATION_CAP.
const ITERATION_CAP: u32 = 20000u;

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
// The isovalue of the query under way.
var<private> mb_iso: f32;

// The kernel at w = 1 - s, times `sign` (-1: the exit query's negated field).
fn kernel_at_w(w: f32) -> f32 {
    var acc = mb.kernel_c4;
    if (mb.kernel_degree < 4u) {
        acc = mb.kernel[mb.kernel_degree];
    }
    var k = mb.kernel_degree;
    while (k > 0u) {
        k = k - 1u;
        acc = acc * w + mb.kernel[k];
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
    for (var k = 1u; k <= mb.kernel_degree; k = k + 1u) {
        var c = mb.kernel_c4;
        if (k < 4u) {
            c = mb.kernel[k];
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
    if (mb.node_count == 0u || !(t_min < t_max)) {
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

// scene.rs surface_detail over the gathered balls at p.
fn surface_at(t: f32, p: vec3<f32>) -> KHit {
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
    return KHit(true, t, p, normal, albedo, dominant);
}


// The kind's queries (render/src/kinds/contract.rs).

fn kind_first_hit(o: vec3<f32>, d: vec3<f32>, lo: f32, hi: f32, iso: f32, leaving: bool) -> KHit {
    mb_iso = iso;
    mb_finder = mb.finder;
    let r = first_root(o, d, lo, hi, 1.0);
    if (!r.found) {
        return no_hit();
    }
    return surface_at(r.t, o + r.t * d);
}

// queries.rs exit_hit_counted searches -F ≥ -T with Bézier clipping whatever the finder.
fn kind_exit_hit(o: vec3<f32>, d: vec3<f32>, lo: f32, hi: f32, iso: f32) -> KHit {
    mb_iso = iso;
    mb_finder = FINDER_BEZIER;
    let r = first_root(o, d, lo, hi, -1.0);
    if (!r.found) {
        return no_hit();
    }
    return surface_at(r.t, o + r.t * d);
}

fn kind_any_hit(o: vec3<f32>, d: vec3<f32>, lo: f32, hi: f32, iso: f32) -> f32 {
    mb_iso = iso;
    mb_finder = mb.finder;
    let r = first_root(o, d, lo, hi, 1.0);
    return select(-1.0, r.t, r.found);
}

// queries.rs ball_integral: ∫ of one ball's kernel over [lo, hi] (the polynomial in u = t - lo).
fn ball_integral(b: RayBall, lo: f32, hi: f32) -> f32 {
    let h = hi - lo;
    let dd = lo - b.tc;
    let s0 = b.a * dd * dd + b.s_min;
    let s1 = 2.0 * b.a * dd;
    let w = vec3<f32>(1.0 - s0, -s1, -b.a);
    var wk: array<f32, 9>;
    var poly: array<f32, 9>;
    for (var j = 0u; j < 9u; j = j + 1u) {
        wk[j] = 0.0;
        poly[j] = 0.0;
    }
    wk[0] = 1.0;
    var len = 1u;
    poly[0] = mb.kernel[0];
    for (var k = 1u; k <= mb.kernel_degree; k = k + 1u) {
        var ck = mb.kernel_c4;
        if (k < 4u) {
            ck = mb.kernel[k];
        }
        var next: array<f32, 9>;
        for (var j = 0u; j < 9u; j = j + 1u) {
            next[j] = 0.0;
        }
        for (var j = 0u; j < len; j = j + 1u) {
            for (var l = 0u; l < 3u; l = l + 1u) {
                next[j + l] = next[j + l] + wk[j] * w[l];
            }
        }
        wk = next;
        len = len + 2u;
        for (var j = 0u; j < len; j = j + 1u) {
            poly[j] = poly[j] + ck * wk[j];
        }
    }
    var acc = 0.0;
    var j = len;
    while (j > 0u) {
        j = j - 1u;
        acc = acc * h + poly[j] / f32(j + 1u);
    }
    return acc * h;
}

// queries.rs optical_depth through the Fitted BVH: every leaf the segment crosses, each ball's
// integral over its part of the leaf's range.
fn kind_optical_depth(o: vec3<f32>, d: vec3<f32>, lo: f32, hi: f32) -> f32 {
    let t_max = min(hi, 1.0e30);
    if (mb.node_count == 0u || !(lo < t_max)) {
        return 0.0;
    }
    let inv_d = safe_inverse(d);
    var sum = 0.0;
    var top = 0u;
    let root = slab(0u, o, inv_d, lo, t_max);
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
        let node = nodes[i];
        if (node.count > 0u || node.first == 0xffffffffu) {
            gathered_count = 0u;
            for (var k = 0u; k < node.count; k = k + 1u) {
                gather(leaf_balls[node.first + k], o, d, near, far);
            }
            for (var k = 0u; k < gathered_count; k = k + 1u) {
                let b = gathered[k];
                let a = max(b.t0, near);
                let z = min(b.t1, far);
                if (a < z) {
                    sum = sum + b.q * ball_integral(b, a, z);
                }
            }
            continue;
        }
        for (var c = node.first; c < node.first + 2u; c = c + 1u) {
            let r = slab(c, o, inv_d, lo, t_max);
            if (r.z > 0.0 && top < STACK_SIZE) {
                stack_node[top] = c;
                stack_range[top] = r.xy;
                top = top + 1u;
            }
        }
    }
    return sum;
}
