// The surfel kind's part of the kernel (deforming-point-sampled-surfaces.txt §4.2–§4.3),
// after common.wgsl. The GPU does no lazy updates: the CPU brings every sphere of the
// hierarchy and every deformed surfel up to date before upload (the eager refit of
// kinds/surfels/prepared.rs), so a traversal only reads. A leaf runs the iterative MLS
// ray–surface intersection of kinds/surfels/intersect.rs with the surfel's fixed
// neighbourhood, then the clipping relations; the nearest hit wins, ties to the lower
// surfel, as on the CPU, so the per-pixel cache of §4.2.2 (a first guess only) changes
// nothing and is not needed here.

struct SurfelParams {
    node_count: u32,
    surfel_count: u32,
    mls_iterations: u32,
    mls_epsilon: f32,
}

// One sphere of the updated hierarchy (preorder, root 0); a leaf has kids = (LEAF, surfel).
struct SurfelNode {
    centre: vec3<f32>,
    radius: f32,
    kids: vec2<u32>,
    _pad: vec2<u32>,
}

// One surfel after the step's deformation (eq. 1), with what its MLS intersection reads:
// its rest radius, its support h (grown by the step's stretch) and 1/h², its rest colour,
// and its rows in the neighbour and clip-pair arrays.
struct SurfelData {
    centre: vec3<f32>,
    leaf_radius: f32,
    t1: vec3<f32>,
    radius: f32,
    t2: vec3<f32>,
    support: f32,
    normal: vec3<f32>,
    neighbours_first: u32,
    colour: vec3<f32>,
    clips_first: u32,
    neighbours_count: u32,
    clips_count: u32,
    inv_support2: f32,
    _pad: u32,
}

@group(1) @binding(0) var<uniform> surfel_params: SurfelParams;
@group(1) @binding(1) var<storage, read> surfel_nodes: array<SurfelNode>;
@group(1) @binding(2) var<storage, read> surfel_data: array<SurfelData>;
@group(1) @binding(3) var<storage, read> surfel_neighbours: array<u32>;
@group(1) @binding(4) var<storage, read> surfel_clips: array<vec2<u32>>;

// `kids.x` of a leaf.
const SURFEL_LEAF: u32 = 0xffffffffu;
// The two-tier start gate (intersect.rs's `WIDE` and `DEFER`): an iteration may start from
// a plane point out to SURFEL_WIDE radii when the nearest hit is sought, and a hit so
// started ranks SURFEL_DEFER support radii farther than its distance.
const SURFEL_WIDE: f32 = 1.5;
const SURFEL_DEFER: f32 = 2.0;
// How far a nearest-hit search's iterates may wander from the leaf's centre, in leaf
// radii (intersect.rs's `ROAM`); the converged point must lie in the leaf's sphere.
const SURFEL_ROAM: f32 = 3.0;
// A camera ray's second search, for a crossing into the object before a first hit that
// faced away (surfel_intersect's `entering`, intersect.rs's `RESCUE`): a leaf off the gate
// starts from the ray's point nearest its centre, and its iterates may wander, and converge,
// out to SURFEL_RESCUE_REACH leaf radii (intersect.rs's `RESCUE_REACH`), the hit ranked no
// nearer than the leaf sphere's entry.
const SURFEL_RESCUE_REACH: f32 = 4.0;
// ... and must converge within SURFEL_RESCUE_DISC radii of the ellipse (RESCUE_DISC).
const SURFEL_RESCUE_DISC: f32 = 2.0;
// How far from its start, in support radii, a ray leaving the surface outwards (shadow,
// occlusion and mirror rays: surfel_intersect's `leaving`, intersect.rs's `Search::leaving`)
// passes over a crossing out of the surface (intersect.rs's `OUTWARD`): the start was inside
// a neighbouring leaf's sheet of the same surface.
const SURFEL_OUTWARD: f32 = 2.0;
// surfel_intersect's `nearest` (intersect.rs's `NEAREST` and `ANY`).
const SURFEL_NEAREST: bool = true;
const SURFEL_ANY: bool = false;
// Traversal stack entries; a median-split tree of n surfels needs ceil(log2 n) + 1.
const SURFEL_STACK: u32 = 64u;

// The traversal stacks, shared by every inlined copy of the traversals (the driver inlines
// each query at each of its call sites; one set of arrays, not one per copy, keeps the
// kernel small). No traversal runs inside another, so sharing is safe.
var<private> surfel_stack_node: array<u32, SURFEL_STACK>;
var<private> surfel_stack_entry: array<f32, SURFEL_STACK>;

// Eq. 2: 1 − 6r² + 8r³ − 3r⁴ for r < 1, else 0.
fn surfel_weight(r: f32) -> f32 {
    if (r >= 1.0) {
        return 0.0;
    }
    let r2 = r * r;
    return 1.0 - 6.0 * r2 + 8.0 * r2 * r - 3.0 * r2 * r2;
}

// Where the ray enters the sphere within [lo, hi]: (1, t) if it meets it there, else (0, 0).
// As the CPU's `traverse::sphere_entry`: the distance to the ray's line as |oc - (oc.d) d|
// and the sphere grown by 1e-6 of its distance (|b| + r), so rounding never puts a
// leaf's hit beyond the entry it prunes by.
fn surfel_sphere_entry(o: vec3<f32>, d: vec3<f32>, c: vec3<f32>, radius: f32, lo: f32, hi: f32) -> vec2<f32> {
    let oc = o - c;
    let b = dot(d, oc);
    let off = oc - b * d;
    let r = radius + 1e-6 * (abs(b) + radius);
    let disc = r * r - dot(off, off);
    if (disc < 0.0) {
        return vec2<f32>(0.0, 0.0);
    }
    let sq = sqrt(disc);
    let t0 = -b - sq;
    let t1 = -b + sq;
    if (t1 < lo || t0 > hi) {
        return vec2<f32>(0.0, 0.0);
    }
    return vec2<f32>(1.0, max(t0, lo));
}

// Whether x on surfel s's surface lies outside a surface that clips it (§4.3): per clipping
// surface, the nearer of its two stored surfels decides by the side of its tangent plane.
fn surfel_clipped(s: u32, x: vec3<f32>) -> bool {
    let first = surfel_data[s].clips_first;
    let end = first + surfel_data[s].clips_count;
    for (var k = first; k < end; k++) {
        let pair = surfel_clips[k];
        let ca = surfel_data[pair.x].centre;
        let cb = surfel_data[pair.y].centre;
        let da = x - ca;
        let db = x - cb;
        var near = pair.y;
        if (dot(da, da) <= dot(db, db)) {
            near = pair.x;
        }
        if (dot(surfel_data[near].normal, x - surfel_data[near].centre) > 0.0) {
            return true;
        }
    }
    return false;
}

// The weighted average rest colour of s's neighbourhood at x (eq. 12's weights).
fn surfel_colour_at(s: u32, x: vec3<f32>, inv_h2: f32) -> vec3<f32> {
    let first = surfel_data[s].neighbours_first;
    let end = first + surfel_data[s].neighbours_count;
    var sw = 0.0;
    var sc = vec3<f32>(0.0);
    for (var k = first; k < end; k++) {
        let nb = surfel_neighbours[k];
        let e = x - surfel_data[nb].centre;
        let r2 = dot(e, e) * inv_h2;
        if (r2 >= 1.0) {
            continue;
        }
        let w = surfel_weight(sqrt(r2));
        sw += w;
        sc += w * surfel_data[nb].colour;
    }
    return sc / sw;
}

// A leaf's hit and the distance it ranks by (intersect.rs's `LeafHit::rank`).
struct SurfelHit {
    hit: KHit,
    rank: f32,
}

// The ray's MLS intersection with leaf surfel s within [lo, hi] (§4.2.1): start on the
// deformed ellipse (or, when `nearest` is sought, up to SURFEL_WIDE radii out), then
// project onto the plane of the neighbourhood's weighted average position and normal until
// |n·(x − a)| < ε h; leaving the leaf's sphere (SURFEL_ROAM times it for a nearest hit) or
// converging outside it rejects.
fn surfel_intersect(o: vec3<f32>, d: vec3<f32>, s: u32, lo: f32, hi: f32, nearest: bool, leaving: bool, entering: bool) -> SurfelHit {
    let miss = SurfelHit(no_hit(), 0.0);
    let leaf = surfel_data[s];
    let denom = dot(leaf.normal, d);
    if (abs(denom) < 1e-7) {
        return miss;
    }
    let t0 = dot(leaf.normal, leaf.centre - o) / denom;
    // Only from an ellipse point on the segment, as on the CPU (intersect.rs): the leaves
    // around a shadow ray's start are passed over.
    if (!(t0 >= lo)) {
        return miss;
    }
    let q = (o + t0 * d) - leaf.centre;
    let g11 = dot(leaf.t1, leaf.t1);
    let g12 = dot(leaf.t1, leaf.t2);
    let g22 = dot(leaf.t2, leaf.t2);
    let det = g11 * g22 - g12 * g12;
    if (!(det > 0.0)) {
        return miss;
    }
    let r1 = dot(leaf.t1, q);
    let r2 = dot(leaf.t2, q);
    let a = (g22 * r1 - g12 * r2) / det;
    let b = (g11 * r2 - g12 * r1) / det;
    let rr = leaf.radius * leaf.radius;
    let e2 = a * a + b * b;
    let outside = e2 > rr;
    // Off the gate, a rescue (`entering`) starts from the ray's point nearest the centre.
    var start = t0;
    if (outside && !(nearest && e2 <= SURFEL_WIDE * SURFEL_WIDE * rr)) {
        if (!entering) {
            return miss;
        }
        start = max(dot(leaf.centre - o, d), lo);
    }
    let h = leaf.support;
    let inv_h2 = leaf.inv_support2;
    let first = leaf.neighbours_first;
    let end = first + leaf.neighbours_count;
    var x = o + start * d;
    // How far the iterates may wander and where the converged point must lie, in leaf
    // radii from the centre (intersect.rs's `roam` and `reach`).
    var roam = 1.0;
    var reach = 1.0;
    if (entering) {
        roam = SURFEL_RESCUE_REACH;
        reach = SURFEL_RESCUE_REACH;
    } else if (nearest) {
        roam = SURFEL_ROAM;
    }
    // The last step's start and how far its plane moved it (the CPU's `next_step`): when two
    // steps point opposite ways the next point is the secant's root between them.
    var t_last = 0.0;
    var moved_last = 0.0;
    for (var it = 0u; it < surfel_params.mls_iterations; it++) {
        var sw = 0.0;
        var sp = vec3<f32>(0.0);
        var sn = vec3<f32>(0.0);
        for (var k = first; k < end; k++) {
            let nb = surfel_neighbours[k];
            let c = surfel_data[nb].centre;
            let e = x - c;
            let r2 = dot(e, e) * inv_h2;
            if (r2 >= 1.0) {
                continue;
            }
            let w = surfel_weight(sqrt(r2));
            sw += w;
            sp += w * c;
            sn += w * surfel_data[nb].normal;
        }
        if (!(sw > 0.0)) {
            return miss;
        }
        let avg = sp / sw;
        let len = length(sn);
        if (!(len > 0.0)) {
            return miss;
        }
        let n = sn * (1.0 / len);
        if (abs(dot(n, x - avg)) < surfel_params.mls_epsilon * h) {
            let t = dot(x - o, d);
            let off = x - leaf.centre;
            if (dot(off, off) > reach * reach * leaf.leaf_radius * leaf.leaf_radius) {
                return miss;
            }
            if (!(t >= lo && t <= hi) || surfel_clipped(s, x)) {
                return miss;
            }
            if (leaving && dot(n, d) > 0.0 && t <= lo + SURFEL_OUTWARD * h) {
                return miss;
            }
            if (entering && !(dot(n, d) < 0.0)) {
                return miss;
            }
            if (entering) {
                // Within SURFEL_RESCUE_DISC radii of the ellipse (intersect.rs's RESCUE_DISC).
                let qx = x - leaf.centre;
                let rx1 = dot(leaf.t1, qx);
                let rx2 = dot(leaf.t2, qx);
                let ax = (g22 * rx1 - g12 * rx2) / det;
                let bx = (g11 * rx2 - g12 * rx1) / det;
                if (ax * ax + bx * bx > SURFEL_RESCUE_DISC * SURFEL_RESCUE_DISC * rr) {
                    return miss;
                }
            }
            var rank = t;
            if (outside) {
                rank = t + SURFEL_DEFER * h;
            }
            if (entering) {
                // No nearer than the leaf sphere's entry, so pruning by entries stays exact.
                let oc = leaf.centre - o;
                let b = dot(oc, d);
                let off2 = dot(oc, oc) - b * b;
                let r2 = leaf.leaf_radius * leaf.leaf_radius;
                rank = max(rank, b - sqrt(max(r2 - off2, 0.0)));
            }
            return SurfelHit(KHit(true, t, x, n, surfel_colour_at(s, x, inv_h2), s), rank);
        }
        let dn = dot(n, d);
        if (abs(dn) < 1e-7) {
            return miss;
        }
        let t = dot(x - o, d);
        let moved = dot(n, avg - o) / dn - t;
        var step = moved;
        if (moved * moved_last < 0.0) {
            step = moved * (t - t_last) / (moved_last - moved);
        }
        t_last = t;
        moved_last = moved;
        x = o + (t + step) * d;
        let e = x - leaf.centre;
        if (dot(e, e) > roam * roam * leaf.leaf_radius * leaf.leaf_radius) {
            return miss;
        }
    }
    return miss;
}

// The nearest hit in [lo, hi]: near child first, a subtree skipped once it starts beyond
// the best hit's rank so far (its distance, deferred for a hit started in the gate's second
// tier, as LeafHit::rank on the CPU); ties to the lower surfel.
fn surfel_nearest(o: vec3<f32>, d: vec3<f32>, lo: f32, hi: f32, leaving: bool, entering: bool) -> KHit {
    var best = no_hit();
    var best_rank = 0.0;
    if (surfel_params.node_count == 0u) {
        return best;
    }
    var top = 0u;
    let root = surfel_nodes[0];
    let re = surfel_sphere_entry(o, d, root.centre, root.radius, lo, hi);
    if (re.x > 0.0) {
        surfel_stack_node[0] = 0u;
        surfel_stack_entry[0] = re.y;
        top = 1u;
    }
    while (top > 0u) {
        top -= 1u;
        let n = surfel_stack_node[top];
        var limit = hi;
        if (best.found) {
            limit = min(best_rank, hi);
        }
        if (surfel_stack_entry[top] > limit) {
            continue;
        }
        let kids = surfel_nodes[n].kids;
        if (kids.x == SURFEL_LEAF) {
            let h = surfel_intersect(o, d, kids.y, lo, limit, SURFEL_NEAREST, leaving, entering);
            if (h.hit.found && (!best.found || h.rank < best_rank || (h.rank == best_rank && h.hit.primitive < best.primitive))) {
                best = h.hit;
                best_rank = h.rank;
            }
            continue;
        }
        // Far first on the stack, so the near child is popped first (the CPU's order).
        var kid = array<u32, 2>(0u, 0u);
        var entry = array<f32, 2>(0.0, 0.0);
        var count = 0u;
        for (var i = 0u; i < 2u; i++) {
            let k = kids[i];
            let node = surfel_nodes[k];
            let e = surfel_sphere_entry(o, d, node.centre, node.radius, lo, limit);
            if (e.x > 0.0) {
                kid[count] = k;
                entry[count] = e.y;
                count += 1u;
            }
        }
        if (count == 2u && entry[1] > entry[0]) {
            kid = array<u32, 2>(kid[1], kid[0]);
            entry = array<f32, 2>(entry[1], entry[0]);
        }
        for (var i = 0u; i < count; i++) {
            if (top < SURFEL_STACK) {
                surfel_stack_node[top] = kid[i];
                surfel_stack_entry[top] = entry[i];
                top += 1u;
            }
        }
    }
    return best;
}

// A camera ray (from 0, not leaving a surface) whose nearest hit faces away from it is
// searched again for a crossing into the object before that hit, from leaves the start gate
// turned away (PreparedSurfels::camera_nearest on the CPU). One call site of
// surfel_nearest, looped, so the compilers inline it once.
fn kind_first_hit(o: vec3<f32>, d: vec3<f32>, lo: f32, hi: f32, iso: f32, leaving: bool) -> KHit {
    var entering = false;
    var end = hi;
    var first = no_hit();
    loop {
        let h = surfel_nearest(o, d, lo, end, leaving, entering);
        if (entering) {
            if (h.found) {
                return h;
            }
            return first;
        }
        if (!(lo == 0.0 && !leaving && h.found && dot(h.normal, d) > 0.0)) {
            return h;
        }
        first = h;
        entering = true;
        end = h.t;
    }
    return first;
}

// A surfel surface is a sheet: the way out of a closed object is its next crossing.
fn kind_exit_hit(o: vec3<f32>, d: vec3<f32>, lo: f32, hi: f32, iso: f32) -> KHit {
    return surfel_nearest(o, d, lo, hi, false, false);
}

// Some hit in [lo, hi], the first found (first child first, as the CPU's updated tree).
fn kind_any_hit(o: vec3<f32>, d: vec3<f32>, lo: f32, hi: f32, iso: f32) -> f32 {
    if (surfel_params.node_count == 0u) {
        return -1.0;
    }
    surfel_stack_node[0] = 0u;
    var top = 1u;
    while (top > 0u) {
        top -= 1u;
        let node = surfel_nodes[surfel_stack_node[top]];
        let e = surfel_sphere_entry(o, d, node.centre, node.radius, lo, hi);
        if (e.x == 0.0) {
            continue;
        }
        if (node.kids.x == SURFEL_LEAF) {
            let h = surfel_intersect(o, d, node.kids.y, lo, hi, SURFEL_ANY, true, false);
            if (h.hit.found) {
                return h.hit.t;
            }
            continue;
        }
        if (top + 2u <= SURFEL_STACK) {
            surfel_stack_node[top] = node.kids.y;
            surfel_stack_node[top + 1u] = node.kids.x;
            top += 2u;
        }
    }
    return -1.0;
}

// Surfels have no density.
fn kind_optical_depth(o: vec3<f32>, d: vec3<f32>, lo: f32, hi: f32) -> f32 {
    return 0.0;
}
