//! The root finders: the first point along a ray segment where the summed field reaches the
//! isovalue, each with a tolerance and an iteration count, generic over `f32` (the hot path)
//! and `f64` (the reference).
//!
//! How it works: the acceleration layer hands a finder the balls whose support the ray
//! crosses, each as a [`RayBall`]: its entry/exit `[t0, t1]` and the quadratic
//! `s(t) = a t² + b t + c = |M (o + t d - p)|²` (`M = I/R` for a sphere, the inverse of the
//! scaled rotation for an ellipsoid, bezier-clipping-metaballs.txt §3.3). The hit is the
//! smallest `t` in `[lo, hi]` with `F(t) ≥ T` (`F(lo) ≥ T` gives `lo`).
//! - [`RootFinder::March`]: metaballs-tutorial.txt §II–III: walk the sorted entry/exit
//!   sections with the active list, step [`FindParams::step`] of the smallest active radius
//!   (the tutorial's quarter by default no more: [`MARCH_STEP`]), then bisect.
//! - [`RootFinder::Secant`]: fitted-bvh-metaballs.txt §3: evaluate `F` at the projections of the
//!   owners' centres on the ray, take `b` as the first with `F ≥ T` and `a` as the sample
//!   before it, then the secant method (Illinois variant, so it keeps a bracket). Rays that
//!   graze the surface between projections are missed, as in the paper, unless a finite
//!   [`FindParams::step`] adds samples so that none is farther apart than that ([`SECANT_STEP`]).
//! - [`RootFinder::BezierClipping`]: bezier-clipping-metaballs.txt §3.2: sort the entry/exit
//!   points, and in each section between consecutive ones express every active ball's field
//!   over the section as a polynomial of degree `2·deg_w` and add them up. The paper adds the
//!   balls' Bézier control points; adding power coefficients and converting the sum once is
//!   the same by linearity and cheaper. The convex hull of the control points clips the
//!   parameter range; when it shrinks by less than 20% the curve is split in half by de
//!   Casteljau and the nearer half is searched first, so the first root comes out first.
//!   A section where one ball alone is active is solved in closed form instead (`one_ball`).
//! - [`RootFinder::SphereTracing`]: per section, step `(T - F)/L` with `L = Σ |q_i|·L_k/R_i`
//!   the Lipschitz bound of the active balls (`L_k` the kernel's steepest slope), never less
//!   than the tolerance, and bisect the last step.
//!
//! What each finder can miss (the "grazing" rays of the tests): marching skips a stretch
//! inside the surface shorter than its step; the secant method one that holds no centre
//! projection; sphere tracing one shorter than its tolerance; Bézier clipping nothing beyond
//! the rounding of the field itself.

// Re-exported for the other crates' paths; the definitions are in `bezier` and `real`.
use crate::kinds::metaballs::bezier::{first_root_or_piece, power_to_bernstein, Piece};
pub use crate::kinds::metaballs::bezier::{HalfStack, ITERATION_CAP, MAX_DEGREE};
pub use crate::kinds::metaballs::counters::Found;
use crate::kinds::metaballs::events::{Event, Events};
pub use crate::kinds::metaballs::kernel::KernelPoly;
use crate::kinds::metaballs::one_ball;
pub use crate::kinds::metaballs::real::Real;

/// Marching's default step, a fraction of the smallest active radius: the tutorial's 1/4 loses
/// silhouette pixels on every paper scene (152 of 115k compared rays); 1/64 is the largest step
/// of the accuracy study (`isoray-bench accuracy`, docs/accuracy.md) that loses none.
pub const MARCH_STEP: f32 = 1.0 / 64.0;
/// The secant method's default largest gap between samples, a fraction of the smallest radius:
/// the paper's centre projections alone lose 32 silhouette pixels on the paper scenes; a gap of
/// at most 1/32 of the smallest radius loses none in the accuracy study.
pub const SECANT_STEP: f32 = 1.0 / 32.0;

/// The closed set of root finders.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RootFinder {
    /// (a) fixed-step marching over the active sections, refined by bisection.
    March,
    /// (b) centre projections bracket the first root, the secant method narrows it.
    Secant,
    /// (c) Bézier clipping over the sorted entry/exit sections.
    BezierClipping,
    /// (d) sphere tracing with a Lipschitz bound per section.
    SphereTracing,
}

impl RootFinder {
    /// Whether this finder's search starts with the whole-stretch bound (`stretch_may_reach`),
    /// answering "no root" without looking further when the bound is below the isovalue:
    /// every finder that walks the sorted sections does; the secant method samples instead.
    pub fn bounds_whole_stretch(self) -> bool {
        !matches!(self, RootFinder::Secant)
    }

    pub const ALL: [RootFinder; 4] = [
        RootFinder::March,
        RootFinder::Secant,
        RootFinder::BezierClipping,
        RootFinder::SphereTracing,
    ];

    /// The step [`FindParams::step`] this finder uses unless told otherwise: the accuracy study's
    /// (`isoray-bench accuracy`, docs/accuracy.md) largest step that lost no silhouette pixel
    /// against the reference on the paper scenes. Bézier clipping and sphere tracing take none.
    pub fn default_step(self) -> f32 {
        match self {
            RootFinder::March => MARCH_STEP,
            RootFinder::Secant => SECANT_STEP,
            RootFinder::BezierClipping | RootFinder::SphereTracing => f32::INFINITY,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            RootFinder::March => "march+bisect",
            RootFinder::Secant => "projections+secant",
            RootFinder::BezierClipping => "bezier clipping",
            RootFinder::SphereTracing => "sphere tracing",
        }
    }
}

/// One ball as one ray sees it.
///
/// `s(t) = a (t - tc)² + s_min`: the quadratic is kept centred on the projection `tc` of the
/// ball's centre, so that `s` near the ball stays accurate in `f32` however far the ray's
/// origin is (the expanded `a t² + b t + c` cancels catastrophically at large `t`).
#[derive(Clone, Copy, Debug, Default)]
pub struct RayBall<R> {
    /// Index of the ball in its scene.
    pub ball: u32,
    /// Where the ray enters and leaves the support.
    pub t0: R,
    pub t1: R,
    /// Curvature of `s` along the ray (`|M d|²`).
    pub a: R,
    /// The parameter of the centre's projection: where `s` is smallest.
    pub tc: R,
    /// `s` at `tc`, in `[0, 1)`.
    pub s_min: R,
    /// Strength `q_i`.
    pub q: R,
    /// `|q_i| · L_k / (smallest semi-axis)`: this ball's bound on `|dF/dt|`.
    pub lipschitz: R,
    /// Smallest semi-axis, for the marching step.
    pub min_radius: R,
    /// Whether this ball's centre projection is a secant sample point, and (for the BVH with
    /// split metaballs) whether its support marks where this leaf's field is complete.
    pub owner: bool,
}

impl<R: Real> RayBall<R> {
    /// The ball as seen along `o + t d`, from `e = M (o - p)` and `g = M d` (`M` maps the
    /// ball's support to the unit sphere); `None` when the ray misses the support.
    #[inline]
    pub fn along(e: [R; 3], g: [R; 3]) -> Option<(R, R, R, R, R)> {
        let dot = |x: [R; 3], y: [R; 3]| x[0] * y[0] + x[1] * y[1] + x[2] * y[2];
        let a = dot(g, g);
        if !(a > R::default()) {
            return None;
        }
        let tc = -dot(e, g) / a;
        let q = [e[0] + tc * g[0], e[1] + tc * g[1], e[2] + tc * g[2]];
        let s_min = dot(q, q);
        if !(s_min < R::of(1.0)) {
            return None;
        }
        let half = ((R::of(1.0) - s_min) / a).sqrt();
        Some((tc - half, tc + half, a, tc, s_min))
    }

    /// `s` at `t`.
    #[inline]
    pub fn s_at(&self, t: R) -> R {
        let u = t - self.tc;
        self.a * u * u + self.s_min
    }

    /// The ball's term of the field at `t`.
    #[inline]
    pub fn term(&self, k: &KernelPoly<R>, t: R) -> R {
        self.term_of::<0>(k, t)
    }

    /// [`RayBall::term`] with the kernel's `w`-degree `W` a constant (0: read from `k`).
    #[inline(always)]
    fn term_of<const W: usize>(&self, k: &KernelPoly<R>, t: R) -> R {
        let s = self.s_at(t);
        if s >= R::of(1.0) {
            return R::default();
        }
        self.q * k.at_w_of::<W>(R::of(1.0) - s)
    }

    /// The parameter of the centre's projection.
    #[inline]
    pub fn projection(&self) -> R {
        self.tc
    }
}

/// What a finder needs besides the balls.
#[derive(Clone, Copy, Debug)]
pub struct FindParams<R> {
    pub kernel: KernelPoly<R>,
    pub isovalue: R,
    /// Absolute tolerance on the hit distance, world units.
    pub tolerance: R,
    /// Only search where an owner's support covers the ray (the BVH's leaves, whose field is
    /// complete only inside their own balls).
    pub owners_only: bool,
    /// Marching's step, and the secant method's largest gap between samples, as a fraction of
    /// the smallest radius of the balls it searches (infinite: the secant method samples the
    /// centre projections only, as in the paper). See [`RootFinder::default_step`].
    pub step: R,
    /// The caller has found the whole-stretch bound ([`stretch_may_reach`]) at or above the
    /// isovalue for this search's balls and stretch (the packets answer it in lanes): the
    /// search does not ask it again.
    pub bounded: bool,
}

/// Reusable buffers, one set per thread.
#[derive(Debug, Default)]
pub struct Scratch<R: Real> {
    events: Events<R>,
    samples: Vec<R>,
    domains: Vec<(R, R)>,
    section: SectionScratch<R>,
}

/// What a section search may keep between sections: Bézier clipping's pending halves and the
/// closed form's last ball level.
#[derive(Debug, Default)]
struct SectionScratch<R> {
    halves: HalfStack<R>,
    level: one_ball::LevelMemo<R>,
    /// Set isolated pieces aside instead of solving them ([`find_first_deferring`]).
    defer: bool,
    piece: Option<Piece<R>>,
}

#[inline]
fn field<R: Real>(k: &KernelPoly<R>, balls: &[RayBall<R>], active: &[u32], t: R) -> R {
    let mut f = R::default();
    for &i in active {
        f = f + balls[i as usize].term(k, t);
    }
    f
}

#[inline]
fn field_all<R: Real>(k: &KernelPoly<R>, balls: &[RayBall<R>], t: R) -> R {
    let mut f = R::default();
    for b in balls {
        f = f + b.term(k, t);
    }
    f
}

/// The first `t` in `[lo, hi]` with `F(t) ≥ T`, by `finder`.
pub fn find_first<R: Real>(
    finder: RootFinder,
    p: &FindParams<R>,
    balls: &[RayBall<R>],
    lo: R,
    hi: R,
    scratch: &mut Scratch<R>,
) -> Found<R> {
    if balls.is_empty() || !(lo < hi) {
        return Found::default();
    }
    match finder {
        RootFinder::Secant => secant(p, balls, lo, hi, scratch),
        RootFinder::March => walk_sections::<R, 0, _>(p, balls, lo, hi, scratch, march_section),
        // The default finder gets a copy per kernel degree in use (Wyvill 3, Murakami 2):
        // the section bounds' and the polynomials' loops unroll; the same operations.
        RootFinder::BezierClipping => match p.kernel.degree {
            3 => walk_sections::<R, 3, _>(p, balls, lo, hi, scratch, bezier_section::<R, 3>),
            2 => walk_sections::<R, 2, _>(p, balls, lo, hi, scratch, bezier_section::<R, 2>),
            _ => walk_sections::<R, 0, _>(p, balls, lo, hi, scratch, bezier_section::<R, 0>),
        },
        RootFinder::SphereTracing => {
            walk_sections::<R, 0, _>(p, balls, lo, hi, scratch, trace_section)
        }
    }
}

/// [`find_first`], except that a Bézier search which ends on an isolated piece sets the
/// piece aside instead of solving it: then `Found::t` is a placeholder inside the piece (the
/// search is over: its first root lies in the piece) and the piece comes back, to be solved
/// with others in lanes (`lanes::solve`). `Found`'s iterations then leave out the piece's
/// own.
pub fn find_first_deferring<R: Real>(
    finder: RootFinder,
    p: &FindParams<R>,
    balls: &[RayBall<R>],
    lo: R,
    hi: R,
    scratch: &mut Scratch<R>,
) -> (Found<R>, Option<Piece<R>>) {
    scratch.section.defer = true;
    scratch.section.piece = None;
    let found = find_first(finder, p, balls, lo, hi, scratch);
    scratch.section.defer = false;
    (found, scratch.section.piece.take())
}

/// Whether the field can reach `T` on `[a, b]`. The kernels are monotone in `s` with one
/// sign (a caller may negate them, as the exit query does), and `s` grows with the distance
/// from the ball's nearest point `tc`, so a positive term is largest at the point nearest `tc`
/// and a negative one at the end farthest from it: their sum bounds the field, and sections
/// below it are skipped. The negative terms make it tight for exit queries deep inside a union
/// of balls (Molecule, 4 transparent layers: 28.0 million finder iterations, 5.0 after).
///
/// When every term is `≤ 0` (`falling`: the way-out search with no carving ball) the sum only
/// falls, in floating point too (adding a term `≤ 0` never raises a rounded sum), so a partial
/// sum below `T` (taken every fourth term: after each, Molecule's transparency took 2–3%
/// longer) gives the full sum's "no".
#[inline(always)]
fn may_reach<R: Real, const W: usize>(
    p: &FindParams<R>,
    balls: &[RayBall<R>],
    active: &[u32],
    a: R,
    b: R,
    falling: bool,
) -> bool {
    let peak = p.kernel.at_w_of::<W>(R::of(1.0));
    let term = |i: &u32| term_bound::<R, W>(p, peak, &balls[*i as usize], a, b);
    if !falling {
        return !(active.iter().fold(R::default(), |sum, i| sum + term(i)) < p.isovalue);
    }
    let mut bound = R::default();
    for four in active.chunks(4) {
        bound = four.iter().fold(bound, |sum, i| sum + term(i));
        if bound < p.isovalue {
            return false;
        }
    }
    !(bound < p.isovalue)
}

/// Whether every one of `balls`' terms is `≤ 0` everywhere under `p`'s kernel (one-signed on
/// the support): asked of way-out searches only (a negated kernel), where [`may_reach`] can
/// then stop early; a way-in search answers `false` without looking.
#[inline(always)]
fn all_falling<R: Real, const W: usize>(p: &FindParams<R>, balls: &[RayBall<R>]) -> bool {
    let peak = p.kernel.at_w_of::<W>(R::of(1.0));
    peak < R::default() && balls.iter().all(|b| !(b.q * peak > R::default()))
}

/// The most `ball`'s term can be on `[a, b]`, which its support covers: a positive term at
/// the point nearest the ball's `tc`, a negative one at the end farthest from it.
#[inline(always)]
fn term_bound<R: Real, const W: usize>(
    p: &FindParams<R>,
    peak: R,
    ball: &RayBall<R>,
    a: R,
    b: R,
) -> R {
    let t = if ball.q * peak > R::default() {
        ball.tc.max(a).min(b)
    } else if (a - ball.tc).abs() > (b - ball.tc).abs() {
        a
    } else {
        b
    };
    ball.term_of::<W>(&p.kernel, t)
}

/// Whether the field can reach `T` anywhere on `[lo, hi]`: [`may_reach`]'s bound over the
/// whole stretch ([`stretch_bound`]) against the isovalue. It is at least every section's
/// bound, so when it says no, every section would have been skipped: the stretch is passed
/// over before its events are sorted (an exit search through a leaf that lies inside the
/// solid).
#[inline(always)]
fn stretch_may_reach<R: Real, const W: usize>(
    p: &FindParams<R>,
    balls: &[RayBall<R>],
    lo: R,
    hi: R,
) -> bool {
    !(stretch_bound::<R, W>(p, balls, lo, hi) < p.isovalue)
}

/// [`may_reach`]'s bound over the whole of `[lo, hi]`, where a negative term counts only if
/// its ball covers the whole stretch (a ball that does not may add 0).
#[inline(always)]
fn stretch_bound<R: Real, const W: usize>(
    p: &FindParams<R>,
    balls: &[RayBall<R>],
    lo: R,
    hi: R,
) -> R {
    let peak = p.kernel.at_w_of::<W>(R::of(1.0));
    let mut bound = R::default();
    for ball in balls {
        let (a, b) = (ball.t0.max(lo), ball.t1.min(hi));
        if !(a < b) || (!(ball.q * peak > R::default()) && (a > lo || b < hi)) {
            continue;
        }
        bound = bound + term_bound::<R, W>(p, peak, ball, a, b);
    }
    bound
}

/// Takes the entry/exit points in `[lo, hi]` in order ([`Events`]: the entries sorted, the
/// exits as they come) and calls `section` on each stretch between consecutive ones with the
/// balls active there (the tutorial's active list).
/// `section` is generic (not a function pointer): each finder's search is its own copy.
#[inline(always)]
fn walk_sections<R: Real, const W: usize, S>(
    p: &FindParams<R>,
    balls: &[RayBall<R>],
    lo: R,
    hi: R,
    scratch: &mut Scratch<R>,
    section: S,
) -> Found<R>
where
    S: Fn(
        &FindParams<R>,
        &[RayBall<R>],
        &[u32],
        R,
        R,
        &mut u32,
        &mut SectionScratch<R>,
    ) -> Option<R>,
{
    if !p.bounded && !stretch_may_reach::<R, W>(p, balls, lo, hi) {
        return Found::default();
    }
    let events = &mut scratch.events;
    events.clear();
    for (i, b) in balls.iter().enumerate() {
        let t0 = b.t0.max(lo);
        if t0 < b.t1.min(hi) {
            events.push_entry(t0.event_key((i as u32) << 1));
        }
    }
    events.sort();
    let falling = all_falling::<R, W>(p, balls);
    let mut owners = 0u32;
    let mut found = Found::default();
    let (mut key, mut from) = events.next();
    while key != R::NO_EVENT {
        let (t, _) = R::of_event_key(key);
        // Apply every event at this parameter.
        let next = loop {
            let (at, code) = R::of_event_key(key);
            if t < at || key == R::NO_EVENT {
                break at;
            }
            let ball = &balls[(code >> 1) as usize];
            match from {
                Event::Entry => {
                    events.enter(code >> 1, ball.t1.min(hi).event_key(code | 1));
                    owners += ball.owner as u32;
                }
                Event::Exit(pos) => {
                    events.leave(pos);
                    owners -= ball.owner as u32;
                }
            }
            (key, from) = events.next();
        };
        let active = events.active();
        if key == R::NO_EVENT || active.is_empty() || (p.owners_only && owners == 0) {
            continue;
        }
        if !may_reach::<R, W>(p, balls, active, t, next, falling) {
            continue;
        }
        let mut iters = 0;
        let hit = section(p, balls, active, t, next, &mut iters, &mut scratch.section);
        found.iterations += iters;
        found.capped |= iters >= ITERATION_CAP;
        if hit.is_some() {
            found.t = hit;
            found.hit_iterations = iters;
            return found;
        }
        if found.iterations > ITERATION_CAP {
            found.capped = true;
            return found;
        }
    }
    found
}

/// (a) Fixed steps of `p.step` times the smallest active radius, then bisection to tolerance.
fn march_section<R: Real>(
    p: &FindParams<R>,
    balls: &[RayBall<R>],
    active: &[u32],
    a: R,
    b: R,
    iters: &mut u32,
    _: &mut SectionScratch<R>,
) -> Option<R> {
    let mut step = R::of(f64::INFINITY);
    for &i in active {
        step = step.min(balls[i as usize].min_radius);
    }
    let step = step * p.step;
    let g = |t: R| field(&p.kernel, balls, active, t) - p.isovalue;
    let mut t0 = a;
    *iters += 1;
    if g(t0) >= R::default() {
        return Some(t0);
    }
    while t0 < b {
        let t1 = (t0 + step).min(b);
        if !(t1 > t0) || *iters > ITERATION_CAP {
            return None; // the precision (or the budget) is exhausted
        }
        *iters += 1;
        if g(t1) >= R::default() {
            return Some(bisect(&g, t0, t1, p.tolerance, iters));
        }
        t0 = t1;
    }
    None
}

/// (d) Sphere tracing: steps of `(T - F) / L`, which cannot pass a root, but never shorter
/// than the tolerance (so a near-tangency cannot stall it; only a stretch inside the surface
/// shorter than the tolerance can be stepped over); the last step is refined by bisection.
fn trace_section<R: Real>(
    p: &FindParams<R>,
    balls: &[RayBall<R>],
    active: &[u32],
    a: R,
    b: R,
    iters: &mut u32,
    _: &mut SectionScratch<R>,
) -> Option<R> {
    let mut lipschitz = R::default();
    for &i in active {
        lipschitz = lipschitz + balls[i as usize].lipschitz;
    }
    let g = |t: R| field(&p.kernel, balls, active, t) - p.isovalue;
    let mut t = a;
    let mut prev: Option<R> = None;
    loop {
        *iters += 1;
        let gt = g(t);
        if gt >= R::default() {
            return Some(match prev {
                None => t,
                Some(lo) => bisect(&g, lo, t, p.tolerance, iters),
            });
        }
        if !(t < b) || *iters > ITERATION_CAP {
            return None;
        }
        let step = (-gt / lipschitz).max(p.tolerance);
        let next = (t + step).min(b);
        if !(next > t) {
            return None; // the precision is exhausted
        }
        prev = Some(t);
        t = next;
    }
}

/// Narrows `[lo, hi]` with `g(lo) < 0 ≤ g(hi)` to the tolerance; returns the upper end.
#[inline]
fn bisect<R: Real>(g: &impl Fn(R) -> R, lo: R, hi: R, tolerance: R, iters: &mut u32) -> R {
    let (mut lo, mut hi) = (lo, hi);
    while hi - lo > tolerance && *iters < ITERATION_CAP {
        let mid = R::of(0.5) * (lo + hi);
        if !(lo < mid && mid < hi) {
            break; // the precision is exhausted
        }
        *iters += 1;
        if g(mid) < R::default() {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// (b) fitted-bvh-metaballs.txt §3: bracket by centre projections, then the secant method.
///
/// The search runs over `[lo, hi]`, or (for a BVH leaf, `owners_only`) over each stretch of
/// it that the leaf's own balls cover, where the leaf's field is complete. In each stretch,
/// `a` starts at its entry and `b` is the first projection with `F ≥ T`, or the stretch's end
/// (our addition: without it a root between the last projection and a leaf's exit would be
/// reported at the next leaf's entry, inside the surface); then Illinois regula falsi keeps
/// `g(a) < 0 ≤ g(b)` and narrows to the tolerance.
fn secant<R: Real>(
    p: &FindParams<R>,
    balls: &[RayBall<R>],
    lo: R,
    hi: R,
    scratch: &mut Scratch<R>,
) -> Found<R> {
    let g = |t: R| field_all(&p.kernel, balls, t) - p.isovalue;
    let mut found = Found::default();
    let samples = &mut scratch.samples;
    samples.clear();
    samples.extend(
        balls
            .iter()
            .filter(|b| b.owner)
            .map(|b| b.projection())
            .filter(|&t| lo < t && t < hi),
    );
    // A finite step also samples every `step` smallest radii, so that no gap between samples
    // is wider than that (a thin stretch inside the surface between two projections).
    let mut gap = R::of(f64::INFINITY);
    for b in balls.iter() {
        gap = gap.min(b.min_radius * p.step);
    }
    if gap > R::default() && (hi - lo) / gap < R::of(ITERATION_CAP as f64) {
        let mut t = lo + gap;
        while t < hi {
            samples.push(t);
            t = t + gap;
        }
    }
    samples.sort_unstable_by(|x, y| x.partial_cmp(y).unwrap_or(std::cmp::Ordering::Equal));
    let domains = &mut scratch.domains;
    domains.clear();
    if p.owners_only {
        domains.extend(
            balls
                .iter()
                .filter(|b| b.owner)
                .map(|b| (b.t0.max(lo), b.t1.min(hi)))
                .filter(|(a, b)| a < b),
        );
        domains.sort_unstable_by(|x, y| x.0.partial_cmp(&y.0).unwrap_or(std::cmp::Ordering::Equal));
        // Merge overlapping stretches in place.
        let mut merged = 0;
        for k in 0..domains.len() {
            let d = domains[k];
            if merged > 0 && !(domains[merged - 1].1 < d.0) {
                domains[merged - 1].1 = domains[merged - 1].1.max(d.1);
            } else {
                domains[merged] = d;
                merged += 1;
            }
        }
        domains.truncate(merged);
    } else {
        domains.push((lo, hi));
    }
    let mut next_sample = 0;
    for &(d0, d1) in domains.iter() {
        let (mut a, mut ga) = (d0, g(d0));
        found.iterations += 1;
        if ga >= R::default() {
            found.t = Some(d0);
            return found;
        }
        let mut bracket = None;
        while next_sample < samples.len() && !(d0 < samples[next_sample]) {
            next_sample += 1;
        }
        while next_sample < samples.len() && samples[next_sample] < d1 {
            let t = samples[next_sample];
            next_sample += 1;
            found.iterations += 1;
            let gt = g(t);
            if gt >= R::default() {
                bracket = Some((t, gt));
                break;
            }
            (a, ga) = (t, gt);
        }
        if bracket.is_none() {
            // The stretch's end is a sample too, so a root just before a leaf or section
            // boundary is bracketed here rather than reported at the next one's entry.
            found.iterations += 1;
            let g1 = g(d1);
            if g1 >= R::default() {
                bracket = Some((d1, g1));
            }
        }
        let Some((mut b, mut gb)) = bracket else {
            continue;
        };
        // Illinois regula falsi: the secant step, halving the stale end's weight.
        let mut side = 0i8;
        let mut iters = 0;
        while b - a > p.tolerance && iters < 200 {
            iters += 1;
            let mut c = b - gb * (b - a) / (gb - ga);
            if !(a < c && c < b) {
                c = R::of(0.5) * (a + b);
                if !(a < c && c < b) {
                    break; // the precision is exhausted
                }
            }
            let gc = g(c);
            if gc >= R::default() {
                (b, gb) = (c, gc);
                if side == 1 {
                    ga = ga * R::of(0.5);
                }
                side = 1;
            } else {
                (a, ga) = (c, gc);
                if side == -1 {
                    gb = gb * R::of(0.5);
                }
                side = -1;
            }
        }
        found.t = Some(b);
        found.iterations += iters;
        found.hit_iterations = iters;
        found.capped |= iters >= 200;
        return found;
    }
    found
}

/// (c) The section's field minus `T` as a Bernstein polynomial, then Bézier clipping.
///
/// `W` is the kernel's `w`-degree as a constant (0: read from `p.kernel` at run time): the
/// kernels in use, Wyvill (3) and Murakami (2), each get a copy whose per-ball polynomial
/// products and clipping loops are unrolled; the operations and their order are those of the
/// general copy, so the roots are bit for bit the same.
fn bezier_section<R: Real, const W: usize>(
    p: &FindParams<R>,
    balls: &[RayBall<R>],
    active: &[u32],
    a: R,
    b: R,
    iters: &mut u32,
    scratch: &mut SectionScratch<R>,
) -> Option<R> {
    if let [i] = active {
        let one = &balls[*i as usize];
        let term = (one.a, one.tc, one.s_min, one.q);
        let memo = &mut scratch.level;
        if let Ok(t) = one_ball::first_root(&p.kernel, p.isovalue, term, a, b, iters, memo) {
            return t;
        }
    }
    let w_degree = if W == 0 { p.kernel.degree } else { W };
    bezier_section_of(w_degree, p, balls, active, a, b, iters, scratch)
}

/// [`bezier_section`] for a kernel of `w`-degree `w_degree` (`p.kernel.degree`).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn bezier_section_of<R: Real>(
    w_degree: usize,
    p: &FindParams<R>,
    balls: &[RayBall<R>],
    active: &[u32],
    a: R,
    b: R,
    iters: &mut u32,
    scratch: &mut SectionScratch<R>,
) -> Option<R> {
    let h = b - a;
    let degree = 2 * w_degree;
    let mut poly = [R::default(); MAX_DEGREE + 1];
    for &i in active {
        let ball = &balls[i as usize];
        // s(a + h v) = s0 + s1 v + s2 v², so w = 1 - s in power form.
        let d = a - ball.tc;
        let s0 = ball.a * d * d + ball.s_min;
        let s1 = R::of(2.0) * ball.a * d * h;
        let s2 = ball.a * h * h;
        // w = 1 - s as a quadratic in v, and its powers up to the kernel's degree.
        let (w0, w1, w2) = (R::of(1.0) - s0, -s1, -s2);
        let mut wk = [R::default(); MAX_DEGREE + 1];
        wk[0] = w0;
        wk[1] = w1;
        wk[2] = w2;
        let mut len = 3;
        let mut k = 1;
        loop {
            let ck = p.kernel.c[k] * ball.q;
            if ck != R::default() {
                for j in 0..len {
                    poly[j] = poly[j] + ck * wk[j];
                }
            }
            if k == w_degree {
                break;
            }
            // wk ← wk · (w0 + w1 v + w2 v²), from the top down so it works in place.
            wk[len + 1] = wk[len - 1] * w2;
            wk[len] = wk[len - 1] * w1 + wk[len - 2] * w2;
            let mut j = len - 1;
            while j >= 2 {
                wk[j] = wk[j] * w0 + wk[j - 1] * w1 + wk[j - 2] * w2;
                j -= 1;
            }
            wk[1] = wk[1] * w0 + wk[0] * w1;
            wk[0] = wk[0] * w0;
            len += 2;
            k += 1;
        }
    }
    poly[0] = poly[0] - p.isovalue;
    let mut bern = [R::default(); MAX_DEGREE + 1];
    power_to_bernstein(&poly, degree, &mut bern);
    let tol_v = p.tolerance / h;
    let defer = scratch.defer.then_some(&mut scratch.piece);
    let v = first_root_or_piece(&bern, degree, tol_v, iters, &mut scratch.halves, defer);
    if let Some(piece) = &mut scratch.piece {
        (piece.a, piece.h) = (a, h);
    }
    v.map(|v| a + h * v)
}

#[cfg(test)]
#[path = "roots_tests.rs"]
pub(crate) mod tests;
