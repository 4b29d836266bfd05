// The metaball root finders (appended to metaballs.wgsl): the first t of a leaf's range where
// the summed field of the gathered balls reaches the isovalue, by the finder the CPU state
// uses (render/src/kinds/metaballs/roots.rs): Bézier clipping or marching over the sorted
// entry/exit sections (`walk_sections`), or the secant method over the whole range. The
// finder is dispatched once inside the section loop (and once before it for the secant
// method): every call of a finder is inlined whole by lavapipe, in every query that reaches
// it, so each finder has one call site.

// Finders (the kind's uniform `finder`; layout.rs `finder`).
const FINDER_MARCH: u32 = 0u;
const FINDER_SECANT: u32 = 1u;
const FINDER_BEZIER: u32 = 2u;
// bezier.rs MAX_DEGREE + 1 control points.
const CONTROL_POINTS: u32 = 9u;
// bezier.rs MAX_PENDING_HALVES.
const MAX_PENDING_HALVES: u32 = 48u;
// f32's machine epsilon (the gap above 1).
const F32_EPSILON: f32 = 1.1920929e-7;
// roots.rs `secant`: the Illinois iterations one bracket may take.
const SECANT_ITERATIONS: u32 = 200u;

// The finder of the query under way (the exit query always clips, as on the CPU).
var<private> mb_finder: u32;
// Bézier clipping's pending halves: control points, and the range [lo, hi] they cover.
var<private> halves_c: array<array<f32, CONTROL_POINTS>, MAX_PENDING_HALVES>;
var<private> halves_r: array<vec2<f32>, MAX_PENDING_HALVES>;

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

// roots.rs field_all: every gathered ball's term (the secant method's field).
fn field_all(t: f32, sign: f32) -> f32 {
    var f = 0.0;
    for (var k = 0u; k < gathered_count; k = k + 1u) {
        f = f + term(gathered[k], t, sign);
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
    return !(bound < sign * mb_iso);
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
    step = step * mb.step;
    let iso = sign * mb_iso;
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
                if (!(h - l > mb.tolerance && *iters < ITERATION_CAP)) {
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

// The kernel's coefficient of w^k.
fn kernel_coefficient(k: u32) -> f32 {
    if (k < 4u) {
        return mb.kernel[k];
    }
    return mb.kernel_c4;
}

struct Split {
    left: array<f32, CONTROL_POINTS>,
    right: array<f32, CONTROL_POINTS>,
}

// bezier.rs de_casteljau at v: the control points of [0, v] and of [v, 1].
fn de_casteljau(b: array<f32, CONTROL_POINTS>, n: u32, v: f32) -> Split {
    var tmp = b;
    var out: Split;
    let u = 1.0 - v;
    for (var r = 0u; r <= n; r = r + 1u) {
        out.left[r] = tmp[0];
        out.right[n - r] = tmp[n - r];
        for (var i = 0u; i < n - r; i = i + 1u) {
            tmp[i] = u * tmp[i] + v * tmp[i + 1u];
        }
    }
    return out;
}

// bezier.rs isolated: control points negative up to some index and non-negative from it on,
// ending positive: exactly one root in (0, 1).
fn isolated(c: array<f32, CONTROL_POINTS>, n: u32) -> bool {
    if (!(c[n] > 0.0)) {
        return false;
    }
    var k = 0u;
    while (k < n && c[k] < 0.0) {
        k = k + 1u;
    }
    for (var i = k; i <= n; i = i + 1u) {
        if (!(c[i] >= 0.0)) {
            return false;
        }
    }
    return true;
}

// bezier.rs isolated_root's evaluation: the Bernstein form with binomials folded into `d`, by
// Horner's rule in v with the powers of 1 - v alongside (no division, no branch).
fn bernstein_at(d: array<f32, CONTROL_POINTS>, n: u32, v: f32) -> f32 {
    let u = 1.0 - v;
    var h = d[n];
    var up = 1.0;
    for (var k = n; k > 0u; k = k - 1u) {
        up = up * u;
        h = h * v + d[k - 1u] * up;
    }
    return h;
}

// bezier.rs isolated_root: the one root of an isolated piece by regula falsi with Anderson
// and Björck's modification, each evaluation at least half the tolerance inside the bracket;
// the chord's crossing once the bracket is within tol_v.
fn isolated_root(c: array<f32, CONTROL_POINTS>, n: u32, lo: f32, hi: f32, tol_v: f32, iters: ptr<function, u32>) -> Root {
    var d: array<f32, CONTROL_POINTS>;
    // C(n, k) built up exactly along k.
    var binomial = 1.0;
    for (var k = 0u; k <= n; k = k + 1u) {
        d[k] = c[k] * binomial;
        binomial = binomial * f32(n - k) / f32(k + 1u);
    }
    let width = hi - lo;
    let nudge = 0.5 * tol_v / width;
    var a = 0.0;
    var ga = c[0];
    var b = 1.0;
    var gb = c[n];
    var fa = ga;
    var fb = gb;
    var side = 0i;
    loop {
        if (width * (b - a) <= tol_v) {
            let chord = a + (b - a) * (ga / (ga - gb));
            return Root(true, lo + width * select(a, chord, a <= chord && chord <= b));
        }
        if (*iters > ITERATION_CAP) {
            return Root(false, 0.0);
        }
        *iters = *iters + 1u;
        let secant = a + (b - a) * (fa / (fa - fb));
        var x = min(max(secant, a + nudge), b - nudge);
        if (!(a < x && x < b)) {
            x = 0.5 * (a + b);
            if (!(a < x && x < b)) {
                return Root(true, lo + width * a);
            }
        }
        let gx = bernstein_at(d, n, x);
        if (gx < 0.0) {
            if (side < 0) {
                let m = 1.0 - gx / fa;
                fb = fb * select(0.5, m, m > 0.0);
            }
            a = x;
            ga = gx;
            fa = gx;
            side = -1;
        } else {
            if (side > 0) {
                let m = 1.0 - gx / fb;
                fa = fa * select(0.5, m, m > 0.0);
            }
            b = x;
            gb = gx;
            fb = gx;
            side = 1;
        }
    }
    return Root(false, 0.0);
}

// bezier.rs bezier_first_root: the smallest v in [0, 1] where the Bernstein polynomial `b` of
// degree n reaches zero from below (b_0 ≥ 0 gives 0), to within tol_v.
fn bezier_first_root(b: array<f32, CONTROL_POINTS>, n: u32, tol_v: f32, iters: ptr<function, u32>) -> Root {
    let inv_n = 1.0 / f32(max(n, 1u));
    var top = 0u;
    var c = b;
    var lo = 0.0;
    var hi = 1.0;
    loop {
        *iters = *iters + 1u;
        var done = *iters > ITERATION_CAP;
        if (c[0] >= 0.0) {
            return Root(true, lo);
        }
        if (!done) {
            // The hull lies below the axis: no root here.
            done = true;
            for (var i = 0u; i <= n; i = i + 1u) {
                if (!(c[i] < 0.0)) {
                    done = false;
                }
            }
        }
        if (!done && isolated(c, n)) {
            return isolated_root(c, n, lo, hi, tol_v, iters);
        }
        if (!done) {
            // Where the convex hull of (k/n, c_k) meets the axis: over every segment from a
            // negative to a non-negative control point.
            var xl = 1.0;
            var xr = 0.0;
            for (var i = 0u; i <= n; i = i + 1u) {
                if (c[i] >= 0.0) {
                    continue;
                }
                for (var j = 0u; j <= n; j = j + 1u) {
                    if (c[j] < 0.0) {
                        continue;
                    }
                    let xi = f32(i) * inv_n;
                    let xj = f32(j) * inv_n;
                    let x = xi + (xj - xi) * (-c[i]) / (c[j] - c[i]);
                    xl = min(xl, x);
                    xr = max(xr, x);
                }
            }
            xl = max(xl, 0.0);
            xr = min(xr, 1.0);
            let width = hi - lo;
            let converged = width * (xr - xl) <= tol_v || width <= tol_v;
            // Clipping stalls (several roots or a flat stretch): split in half, the right
            // half pending; otherwise keep [xl, xr]: cut at xr, then the left part at xl / xr.
            let split = !converged && xr - xl > 0.8 && top < MAX_PENDING_HALVES;
            var cut = select(xr, 0.5, split);
            // A trip count lavapipe cannot unroll, so that de Casteljau is inlined once.
            let passes = select(2u, 1u, split);
            for (var cuts = 0u; cuts < passes; cuts = cuts + 1u) {
                let parts = de_casteljau(c, n, cut);
                if (split) {
                    let mid = lo + width * 0.5;
                    halves_c[top] = parts.right;
                    halves_r[top] = vec2<f32>(mid, hi);
                    top = top + 1u;
                    c = parts.left;
                    hi = mid;
                    break;
                }
                if (cuts == 0u) {
                    c = parts.left;
                    cut = select(0.0, xl / xr, xr > 0.0);
                } else {
                    c = parts.right;
                    let new_lo = lo + width * xl;
                    hi = lo + width * xr;
                    lo = new_lo;
                }
            }
            if (!converged) {
                continue;
            }
            // A hull meeting the axis on a stretch narrower than the tolerance proves no
            // root (bezier.rs first_root_or_piece): an end of the clipped polygon (the curve's
            // own value) at the axis, up to what the subdivisions may have rounded it by, puts
            // the root within the stretch; a polygon wholly below it proves no root; an inner
            // point alone at the axis decides nothing, and clipping goes on until the stretch
            // is so short that the curve lies within rounding of its polygon.
            var scale = 0.0;
            for (var i = 0u; i <= n; i = i + 1u) {
                scale = max(scale, abs(b[i]));
            }
            let reach = -(F32_EPSILON * 512.0 * scale);
            if (max(c[0], c[n]) >= reach) {
                return Root(true, lo);
            }
            var inner_reach = false;
            for (var i = 0u; i <= n; i = i + 1u) {
                if (c[i] >= reach) {
                    inner_reach = true;
                }
            }
            if (inner_reach) {
                if (hi - lo <= F32_EPSILON * 64.0) {
                    return Root(true, lo);
                }
                continue;
            }
        }
        if (*iters > ITERATION_CAP || top == 0u) {
            return Root(false, 0.0);
        }
        top = top - 1u;
        c = halves_c[top];
        lo = halves_r[top].x;
        hi = halves_r[top].y;
    }
    return Root(false, 0.0);
}

// roots.rs bezier_section: the section's field minus the isovalue as a polynomial in
// v = (t - a) / (b - a), summed over the active balls in power form, converted to Bernstein
// form once, then Bézier clipping.
fn bezier_section(a: f32, b: f32, lo: f32, hi: f32, sign: f32, iters: ptr<function, u32>) -> Root {
    let h = b - a;
    let degree = 2u * mb.kernel_degree;
    var poly: array<f32, CONTROL_POINTS>;
    for (var j = 0u; j < CONTROL_POINTS; j = j + 1u) {
        poly[j] = 0.0;
    }
    for (var i = 0u; i < gathered_count; i = i + 1u) {
        if (!is_active(i, a, lo, hi)) {
            continue;
        }
        let ball = gathered[i];
        // s(a + h v) = s0 + s1 v + s2 v², so w = 1 - s in power form.
        let d = a - ball.tc;
        let s0 = ball.a * d * d + ball.s_min;
        let s1 = 2.0 * ball.a * d * h;
        let s2 = ball.a * h * h;
        let w0 = 1.0 - s0;
        let w1 = -s1;
        let w2 = -s2;
        var wk: array<f32, CONTROL_POINTS>;
        for (var j = 0u; j < CONTROL_POINTS; j = j + 1u) {
            wk[j] = 0.0;
        }
        wk[0] = w0;
        wk[1] = w1;
        wk[2] = w2;
        var len = 3u;
        var k = 1u;
        loop {
            // The CPU negates the kernel's coefficients for the exit query; so does `sign`.
            let ck = sign * kernel_coefficient(k) * ball.q;
            if (ck != 0.0) {
                for (var j = 0u; j < len; j = j + 1u) {
                    poly[j] = poly[j] + ck * wk[j];
                }
            }
            if (k >= mb.kernel_degree) {
                break;
            }
            // wk ← wk · (w0 + w1 v + w2 v²), from the top down so it works in place.
            wk[len + 1u] = wk[len - 1u] * w2;
            wk[len] = wk[len - 1u] * w1 + wk[len - 2u] * w2;
            var j = len - 1u;
            while (j >= 2u) {
                wk[j] = wk[j] * w0 + wk[j - 1u] * w1 + wk[j - 2u] * w2;
                j = j - 1u;
            }
            wk[1] = wk[1] * w0 + wk[0] * w1;
            wk[0] = wk[0] * w0;
            len = len + 2u;
            k = k + 1u;
        }
    }
    poly[0] = poly[0] - sign * mb_iso;
    // bezier.rs power_to_bernstein: b_j = Σ_{i ≤ j} C(j, i) / C(n, i) · p_i, the binomials
    // built up exactly along i (loops over the degree, not the array: lavapipe unrolls
    // constant trip counts, and the whole conversion with them).
    var bern: array<f32, CONTROL_POINTS>;
    for (var j = 0u; j <= degree; j = j + 1u) {
        var acc = 0.0;
        var cj = 1.0;
        var cn = 1.0;
        for (var i = 0u; i <= j; i = i + 1u) {
            acc = acc + cj / cn * poly[i];
            cj = cj * f32(j - i) / f32(i + 1u);
            cn = cn * f32(degree - i) / f32(i + 1u);
        }
        bern[j] = acc;
    }
    let r = bezier_first_root(bern, degree, mb.tolerance / h, iters);
    return Root(r.found, a + h * r.t);
}

// roots.rs secant over the whole range [lo, hi] (a Fitted BVH leaf: every ball an owner):
// samples at the centre projections in (lo, hi) and every `step` smallest radii from lo; `a`
// the last sample below the isovalue, `b` the first at or above it (or hi), then Illinois
// regula falsi to the tolerance. The samples are visited in increasing order without sorting
// them: each next one is the smaller of the next grid point and the nearest projection
// beyond the last (a repeated sample would change nothing).
fn secant(lo: f32, hi: f32, sign: f32) -> Root {
    let iso = sign * mb_iso;
    var gap = BIG;
    for (var k = 0u; k < gathered_count; k = k + 1u) {
        gap = min(gap, gathered[k].min_radius * mb.step);
    }
    // mb.step is 0 for a state without the grid (the paper's projections only).
    var grid = BIG;
    if (gap > 0.0 && (hi - lo) / gap < f32(ITERATION_CAP)) {
        grid = lo + gap;
    }
    var a = lo;
    var ga = field_all(lo, sign) - iso;
    if (ga >= 0.0) {
        return Root(true, lo);
    }
    var b = hi;
    var gb = 0.0;
    var bracket = false;
    var last = lo;
    for (var guard = 0u; guard < ITERATION_CAP + MAX_GATHER; guard = guard + 1u) {
        var t = select(BIG, grid, grid < hi);
        for (var k = 0u; k < gathered_count; k = k + 1u) {
            let p = gathered[k].tc;
            if (last < p && p < hi) {
                t = min(t, p);
            }
        }
        if (!(t < hi)) {
            break;
        }
        if (t == grid) {
            grid = grid + gap;
        }
        last = t;
        let gt = field_all(t, sign) - iso;
        if (gt >= 0.0) {
            b = t;
            gb = gt;
            bracket = true;
            break;
        }
        a = t;
        ga = gt;
    }
    if (!bracket) {
        // The range's end is a sample too.
        gb = field_all(hi, sign) - iso;
        if (!(gb >= 0.0)) {
            return Root(false, 0.0);
        }
        b = hi;
    }
    // Illinois regula falsi: the secant step, halving the stale end's weight.
    var side = 0;
    for (var it = 0u; it < SECANT_ITERATIONS && b - a > mb.tolerance; it = it + 1u) {
        var c = b - gb * (b - a) / (gb - ga);
        if (!(a < c && c < b)) {
            c = 0.5 * (a + b);
            if (!(a < c && c < b)) {
                break;
            }
        }
        let gc = field_all(c, sign) - iso;
        if (gc >= 0.0) {
            b = c;
            gb = gc;
            if (side == 1) {
                ga = ga * 0.5;
            }
            side = 1;
        } else {
            a = c;
            ga = gc;
            if (side == -1) {
                gb = gb * 0.5;
            }
            side = -1;
        }
    }
    return Root(true, b);
}

// roots.rs find_first over the gathered balls on [lo, hi]: the secant method, or
// walk_sections with Bézier clipping or marching in each section.
fn find_first(lo: f32, hi: f32, sign: f32) -> Root {
    if (gathered_count == 0u || !(lo < hi)) {
        return Root(false, 0.0);
    }
    if (mb_finder == FINDER_SECANT) {
        return secant(lo, hi, sign);
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
            var r: Root;
            if (mb_finder == FINDER_BEZIER) {
                r = bezier_section(t, next, lo, hi, sign, &iters);
            } else {
                r = march_section(t, next, lo, hi, sign, &iters);
            }
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
