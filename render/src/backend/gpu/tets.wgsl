// The tet kind's part of the kernel (concatenated after common.wgsl): the single-ray
// traversal of the implicit min–max BVH (render/src/kinds/tets/traverse.rs, walk.rs) with
// the isopolygon of each tet extracted on the fly and intersected by the edge-plane test
// (march.rs `extract`, `intersect_one`), and the hit record (prepared.rs `hit_record`):
// faceted or interpolated per-vertex gradients, the colour map of the isovalue.
// tetrahedral-isosurface-ray-tracing.txt §4–5. The structs mirror backend/gpu/tets_layout.rs.

struct TetParams {
    // Nodes of the BVH (at least 1: the root).
    node_count: u32,
    // 1: interpolate per-vertex gradients (Normals::Smooth); 0: the tet's own gradient.
    smooth_normals: u32,
    // The scene's colour range (TetScene::color_of).
    color_lo: f32,
    color_hi: f32,
}

// bvh.rs Node: `lo.xyz`/`hi.xyz` the padded box, `lo.w`/`hi.w` the scalar range; children
// at `first` and `first + 1` when `count` is 0, else `count` tets at `first` in leaf order.
struct TetNode {
    lo: vec4<f32>,
    hi: vec4<f32>,
    first: u32,
    count: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(1) @binding(0) var<uniform> tet_params: TetParams;
@group(1) @binding(1) var<storage, read> tet_nodes: array<TetNode>;
// The four global vertex indices of each tet, in leaf order.
@group(1) @binding(2) var<storage, read> tet_leaf_tets: array<vec4<u32>>;
// The mesh's index of each tet, in leaf order (the hit's `primitive`).
@group(1) @binding(3) var<storage, read> tet_leaf_ids: array<u32>;
// Per vertex: position (xyz) in the scene's frame and scalar (w).
@group(1) @binding(4) var<storage, read> tet_verts: array<vec4<f32>>;
// Per vertex: the smoothed gradient (xyz); one zero element with faceted normals.
@group(1) @binding(5) var<storage, read> tet_gradients: array<vec4<f32>>;

// Traversal stack; the upload refuses deeper trees (tets_layout.rs MAX_DEPTH + 1).
const TET_STACK_SIZE: u32 = 64u;
const TET_NONE: u32 = 0xffffffffu;
// march.rs EDGE_NOISE: (16 ε)² for f32's ε.
const TET_EDGE_NOISE: f32 = 3.6379788e-12;

var<private> tet_stack_node: array<u32, TET_STACK_SIZE>;
var<private> tet_stack_t: array<f32, TET_STACK_SIZE>;

// march.rs CASES, packed: bits 0..4 the vertex count, then the four edges 4 bits each.
var<private> tet_cases: array<u32, 16> = array<u32, 16>(
    0x00000u, 0x02103u, 0x04303u, 0x34214u, 0x05313u, 0x35204u, 0x15404u, 0x05423u,
    0x05423u, 0x45104u, 0x25304u, 0x05313u, 0x24314u, 0x04303u, 0x02103u, 0x00000u
);
// march.rs EDGES: corner a and corner b of edge e are nibble e of these.
const TET_EDGE_A: u32 = 0x211000u;
const TET_EDGE_B: u32 = 0x332321u;

// The isopolygon being tested, its points and relative to the ray origin, and its corners.
var<private> tet_pts: array<vec3<f32>, 4>;
var<private> tet_rel: array<vec3<f32>, 4>;
var<private> tet_corner: array<vec4<f32>, 4>;

// The best hit so far: distance, the mesh's tet index (TET_NONE: none) and the tet's
// position in leaf order.
struct TetBest {
    t: f32,
    tet: u32,
    leaf: u32,
}

fn tet_spans(lo: f32, hi: f32, iso: f32) -> bool {
    return lo <= iso && iso < hi;
}

fn tet_inverse(d: vec3<f32>) -> vec3<f32> {
    var r: vec3<f32>;
    for (var k = 0; k < 3; k = k + 1) {
        if (d[k] == 0.0) {
            r[k] = select(-BIG, BIG, d[k] >= 0.0);
        } else {
            r[k] = 1.0 / d[k];
        }
    }
    return r;
}

// geom/aabb.rs slab's entry distance into node `n` within [t_min, t_max]; -1 when missed
// (the entry is never negative: t_min >= 0).
fn tet_slab(n: u32, o: vec3<f32>, inv: vec3<f32>, t_min: f32, t_max: f32) -> f32 {
    let node = tet_nodes[n];
    let t0 = (node.lo.xyz - o) * inv;
    let t1 = (node.hi.xyz - o) * inv;
    let lo = min(t0, t1);
    let hi = max(t0, t1);
    let near = max(max(max(lo.x, lo.y), lo.z), t_min);
    let far = min(min(min(hi.x, hi.y), hi.z), t_max);
    if (near <= far) {
        return near;
    }
    return -1.0;
}

// march.rs extract for the tet at leaf position k: fills `tet_corner`, `tet_pts` and,
// relative to `o`, `tet_rel`; returns the polygon's vertex count (0: the isovalue misses
// the tet).
fn tet_extract(k: u32, o: vec3<f32>, iso: f32) -> u32 {
    let ids = tet_leaf_tets[k];
    var which = 0u;
    for (var c = 0u; c < 4u; c = c + 1u) {
        let v = tet_verts[ids[c]];
        tet_corner[c] = v;
        if (v.w > iso) {
            which = which | (1u << c);
        }
    }
    let packed = tet_cases[which];
    let count = packed & 0xfu;
    for (var i = 0u; i < count; i = i + 1u) {
        let e = (packed >> (4u + 4u * i)) & 0xfu;
        var a = (TET_EDGE_A >> (4u * e)) & 0xfu;
        var b = (TET_EDGE_B >> (4u * e)) & 0xfu;
        // From the lower global index, so a shared edge gives the same point in every tet.
        if (ids[b] < ids[a]) {
            let s = a;
            a = b;
            b = s;
        }
        let pa = tet_corner[a];
        let pb = tet_corner[b];
        let s = (iso - pa.w) / (pb.w - pa.w);
        let p = pa.xyz + (pb.xyz - pa.xyz) * s;
        tet_pts[i] = p;
        tet_rel[i] = p - o;
    }
    return count;
}

// march.rs intersect_one on the polygon in `tet_rel`: the distance in [t_min, t_max] if the
// ray passes inside, else -1.
fn tet_intersect(count: u32, d: vec3<f32>, t_min: f32, t_max: f32) -> f32 {
    // march.rs plane_normal: from the points' own differences.
    var normal: vec3<f32>;
    if (count == 3u) {
        normal = cross(tet_pts[1] - tet_pts[0], tet_pts[2] - tet_pts[0]);
    } else {
        normal = cross(tet_pts[2] - tet_pts[0], tet_pts[3] - tet_pts[1]);
    }
    let numerator = dot(normal, tet_rel[0]);
    let denominator = dot(normal, d);
    if (denominator == 0.0) {
        return -1.0;
    }
    let t = numerator / denominator;
    if (!(t >= t_min && t <= t_max && abs(t) < BIG)) {
        return -1.0;
    }
    var sign = 1.0;
    if (numerator < 0.0) {
        sign = -1.0;
    }
    var dropped = 0u;
    for (var i = 0u; i < count; i = i + 1u) {
        var j = i + 1u;
        if (j == count) {
            j = 0u;
        }
        // march.rs edge_normal: the plane formed about the edge's midpoint, with the edge as
        // the points give it; an edge whose plane normal rounding sets is not tested, and a
        // polygon left with fewer than three tested edges is never hit (march.rs closed).
        let c = (tet_rel[i] + tet_rel[j]) * 0.5;
        let m = cross(c, tet_pts[j] - tet_pts[i]);
        let cc = dot(c, c);
        if (dot(m, m) <= TET_EDGE_NOISE * (cc * cc)) {
            dropped = dropped + 1u;
        } else if (dot(m * sign, d) < 0.0) {
            return -1.0;
        }
    }
    if (count < dropped + 3u) {
        return -1.0;
    }
    return t;
}

// traverse.rs trace: the nearest hit in [t_min, t_max] (ties to the lower tet index), or
// with `any` the first found. `tet` is TET_NONE when nothing is hit.
fn tet_trace(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, iso: f32, first_found: bool) -> TetBest {
    var best = TetBest(t_max, TET_NONE, 0u);
    if (tet_params.node_count == 0u || !(t_min <= t_max)) {
        return best;
    }
    let inv = tet_inverse(d);
    let root = tet_nodes[0];
    if (!tet_spans(root.lo.w, root.hi.w, iso)) {
        return best;
    }
    let t_root = tet_slab(0u, o, inv, t_min, t_max);
    if (t_root < 0.0) {
        return best;
    }
    tet_stack_node[0] = 0u;
    tet_stack_t[0] = t_root;
    var top = 1u;
    while (top > 0u) {
        top = top - 1u;
        let index = tet_stack_node[top];
        if (tet_stack_t[top] > best.t) {
            continue;
        }
        let node = tet_nodes[index];
        if (node.count > 0u) {
            for (var k = node.first; k < node.first + node.count; k = k + 1u) {
                let count = tet_extract(k, o, iso);
                if (count == 0u) {
                    continue;
                }
                let t = tet_intersect(count, d, t_min, best.t);
                if (t < 0.0) {
                    continue;
                }
                let tet = tet_leaf_ids[k];
                if (t < best.t || (t == best.t && tet < best.tet)) {
                    best = TetBest(t, tet, k);
                    if (first_found) {
                        return best;
                    }
                }
            }
            continue;
        }
        let a = node.first;
        let b = a + 1u;
        var ta = -1.0;
        var tb = -1.0;
        let na = tet_nodes[a];
        if (tet_spans(na.lo.w, na.hi.w, iso)) {
            ta = tet_slab(a, o, inv, t_min, best.t);
        }
        let nb = tet_nodes[b];
        if (tet_spans(nb.lo.w, nb.hi.w, iso)) {
            tb = tet_slab(b, o, inv, t_min, best.t);
        }
        // The nearer child on top (a first on a tie), as walk.rs pushes them.
        if (ta >= 0.0 && tb >= 0.0) {
            if (ta <= tb) {
                tet_stack_node[top] = b;
                tet_stack_t[top] = tb;
                tet_stack_node[top + 1u] = a;
                tet_stack_t[top + 1u] = ta;
            } else {
                tet_stack_node[top] = a;
                tet_stack_t[top] = ta;
                tet_stack_node[top + 1u] = b;
                tet_stack_t[top + 1u] = tb;
            }
            top = top + 2u;
        } else if (ta >= 0.0) {
            tet_stack_node[top] = a;
            tet_stack_t[top] = ta;
            top = top + 1u;
        } else if (tb >= 0.0) {
            tet_stack_node[top] = b;
            tet_stack_t[top] = tb;
            top = top + 1u;
        }
    }
    return best;
}

// mesh.rs colormap: cool to warm in linear light, x clamped to [0, 1].
fn tet_colormap(x_in: f32) -> vec3<f32> {
    var x = 0.0;
    if (x_in == x_in) {
        x = clamp(x_in, 0.0, 1.0);
    }
    let f = x * 4.0;
    let i = min(u32(f), 3u);
    var a: vec3<f32>;
    var b: vec3<f32>;
    switch i {
        case 0u: {
            a = vec3<f32>(0.05, 0.18, 0.60);
            b = vec3<f32>(0.10, 0.50, 0.75);
        }
        case 1u: {
            a = vec3<f32>(0.10, 0.50, 0.75);
            b = vec3<f32>(0.60, 0.60, 0.55);
        }
        case 2u: {
            a = vec3<f32>(0.60, 0.60, 0.55);
            b = vec3<f32>(0.85, 0.40, 0.12);
        }
        default: {
            a = vec3<f32>(0.85, 0.40, 0.12);
            b = vec3<f32>(0.70, 0.06, 0.06);
        }
    }
    let s = f - f32(i);
    return a + (b - a) * s;
}

// march.rs gradient of the corners in `tet_corner`: the field's gradient (xyz) and six
// times the signed volume (w).
fn tet_gradient() -> vec4<f32> {
    let p0 = tet_corner[0].xyz;
    let e1 = tet_corner[1].xyz - p0;
    let e2 = tet_corner[2].xyz - p0;
    let e3 = tet_corner[3].xyz - p0;
    let c23 = cross(e2, e3);
    let c31 = cross(e3, e1);
    let c12 = cross(e1, e2);
    let det = dot(e1, c23);
    let s0 = tet_corner[0].w;
    let g = (c23 * (tet_corner[1].w - s0) + c31 * (tet_corner[2].w - s0)
        + c12 * (tet_corner[3].w - s0)) / det;
    return vec4<f32>(g, det);
}

fn tet_volume(p0: vec3<f32>, p1: vec3<f32>, p2: vec3<f32>, p3: vec3<f32>) -> f32 {
    return dot(cross(p1 - p0, p2 - p0), p3 - p0);
}

// march.rs barycentric of p in the tet in `tet_corner`, clamped and renormalised.
fn tet_barycentric(p: vec3<f32>) -> vec4<f32> {
    let a = tet_corner[0].xyz;
    let b = tet_corner[1].xyz;
    let c = tet_corner[2].xyz;
    let d = tet_corner[3].xyz;
    let total = tet_volume(a, b, c, d);
    var l = vec4<f32>(
        tet_volume(p, b, c, d) / total,
        tet_volume(a, p, c, d) / total,
        tet_volume(a, b, p, d) / total,
        tet_volume(a, b, c, p) / total
    );
    for (var k = 0; k < 4; k = k + 1) {
        if (abs(l[k]) < BIG) {
            l[k] = max(l[k], 0.0);
        } else {
            l[k] = 0.0;
        }
    }
    let sum = l.x + l.y + l.z + l.w;
    if (sum > 0.0) {
        return l / sum;
    }
    return vec4<f32>(0.25);
}

// prepared.rs hit_record for the hit `best` of the ray (o, d) on the isovalue `iso`.
fn tet_record(o: vec3<f32>, d: vec3<f32>, best: TetBest, iso: f32) -> KHit {
    let position = o + d * best.t;
    let ids = tet_leaf_tets[best.leaf];
    for (var c = 0u; c < 4u; c = c + 1u) {
        tet_corner[c] = tet_verts[ids[c]];
    }
    let facet = tet_gradient().xyz;
    var gradient = facet;
    if (tet_params.smooth_normals != 0u) {
        let l = tet_barycentric(position);
        var n = vec3<f32>(0.0);
        for (var c = 0u; c < 4u; c = c + 1u) {
            n = n + l[c] * tet_gradients[ids[c]].xyz;
        }
        if (dot(n, n) > 1.0e-12 * dot(facet, facet)) {
            gradient = n;
        }
    }
    var normal = -d;
    let len2 = dot(gradient, gradient);
    if (len2 > 0.0 && len2 < BIG) {
        normal = -gradient * (1.0 / sqrt(len2));
    }
    let albedo = tet_colormap((iso - tet_params.color_lo) / (tet_params.color_hi - tet_params.color_lo));
    return KHit(true, best.t, position, normal, albedo, best.tet);
}

// The kind contract (kinds/tets/kind.rs): one isovalue, no clip box (the integrator's).
fn kind_first_hit(o: vec3<f32>, d: vec3<f32>, lo: f32, hi: f32, iso: f32, leaving: bool) -> KHit {
    let best = tet_trace(o, d, lo, hi, iso, false);
    if (best.tet == TET_NONE) {
        return KHit(false, 0.0, vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), 0u);
    }
    return tet_record(o, d, best, iso);
}

// Every crossing of a tet isosurface is a surface: the way out is the first crossing.
fn kind_exit_hit(o: vec3<f32>, d: vec3<f32>, lo: f32, hi: f32, iso: f32) -> KHit {
    return kind_first_hit(o, d, lo, hi, iso, false);
}

fn kind_any_hit(o: vec3<f32>, d: vec3<f32>, lo: f32, hi: f32, iso: f32) -> f32 {
    let best = tet_trace(o, d, lo, hi, iso, true);
    if (best.tet == TET_NONE) {
        return -1.0;
    }
    return best.t;
}

// The tet paper renders isosurfaces only (§8.8): no density to absorb.
fn kind_optical_depth(o: vec3<f32>, d: vec3<f32>, lo: f32, hi: f32) -> f32 {
    return 0.0;
}
