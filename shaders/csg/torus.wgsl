// The torus primitive [rmin, rmax, rtor] around z: twin of hytrace_csg::kernel::torus_prim
// (torus_spans, torus_prim_sdf) and of the f32 instantiation of hytrace_csg::kernel::torus
// (torus_crossings with its convexity-split Newton search, torus_normal, torus_sdf). See
// torus.rs for the algorithm and why it is robust for grazing rays. This port follows it
// operation by operation; on lavapipe its spans and distances are the CPU's to the last bit
// (crates/trace/tests/gpu_torus.rs). What that rests on:
// * the error-free transformations and the Newton steps are written so that neither fma
//   contraction nor a compiler's inexact algebraic rewrites ((a + b) - a -> b, which Mesa
//   applies, also across inlined functions) change their values: see two_product and
//   two_sum (real.wgsl) and torus_newton_step;
// * elsewhere a compiler that contracts a*b+c into an fma (lavapipe does not) changes last
//   bits, which near a tangency can move a crossing or flip a chord of rounding-noise depth;
// * cbrt is our own correctly rounded one (libm's cbrtf, which the CPU calls, is too in
//   practice);
// * "non-finite" means |x| >= INF (1e38), and divisions by a possibly-zero value are
//   guarded with the CPU's outcome (WGSL may assume no inf or NaN).
// #import real
// #import csg/spans

const TORUS_SPHERE_MARGIN: f32 = 0.015625;
const TORUS_MAX_ITERATIONS: u32 = 64u;
const TORUS_EPSILON: f32 = 1.1920929e-7;

// o + d * t, compensated (one coordinate).
fn torus_exact_at1(o: f32, d: f32, t: f32, one: f32) -> f32 {
    let p = two_product(d, t);
    let s = two_sum(o, p.x, one);
    return s.x + (s.y + p.y);
}

// Cube root of x >= 0, correctly rounded (as the CPU's cbrtf is in practice): pow, one
// Newton step (within an ulp), then a move to the neighbour that is nearer the true root,
// judged from the residual x - y^3 computed with exact products.
fn torus_cbrt(x: f32) -> f32 {
    if x <= 0.0 {
        return 0.0;
    }
    let y0 = pow(x, 1.0 / 3.0);
    let y = y0 - (y0 * y0 * y0 - x) / (3.0 * y0 * y0);
    let yy = two_product(y, y);
    let a = two_product(yy.x, y);
    let b = two_product(yy.y, y);
    // x - a.x is exact (the two are within a factor 2); the rest is small.
    let r = (((x - a.x) - b.x) - a.y) - b.y;
    // The root's offset from y, to first order.
    let delta = r / (3.0 * y * y);
    let up = bitcast<f32>(bitcast<u32>(y) + 1u);
    let down = bitcast<f32>(bitcast<u32>(y) - 1u);
    if delta > 0.5 * (up - y) {
        return up;
    }
    if delta < -0.5 * (y - down) {
        return down;
    }
    return y;
}

// g and g' at s.
struct TorusSample {
    s: f32,
    g: f32,
    d: f32,
}

// The tube function along the line c + s u, in units of rtor + r.
struct TorusLine {
    c: vec3<f32>,
    u: vec3<f32>,
    big: f32,
    small2: f32,
    m2: f32,
    tol: f32,
    // A run-time 1 (opaque_one) that keeps Newton steps rounded as on the CPU.
    one: f32,
}

// Crossings found so far (ascending) and whether an optional value is present.
struct TorusRoots {
    count: u32,
    t: array<f32, 4>,
}

struct TorusMaybe {
    ok: bool,
    s: f32,
}

fn torus_line(c: vec3<f32>, u: vec3<f32>, big: f32, small: f32, one: f32) -> TorusLine {
    let m = c.x * u.y - c.y * u.x;
    return TorusLine(c, u, big, small * small, m * m, 4.0 * TORUS_EPSILON, one);
}

// The Newton step x - g / g'. Multiplied by the run-time 1 so that a compiler cannot
// simplify its later difference with x to -g / g' (which rounds differently from the
// CPU's next - x), also after inlining into the callers.
fn torus_newton_step(l: TorusLine, x: f32, g: f32, d: f32) -> f32 {
    return (x - g / d) * l.one;
}

fn torus_sample(l: TorusLine, s: f32) -> TorusSample {
    let p = l.c + l.u * s;
    let rho = sqrt(p.x * p.x + p.y * p.y);
    let q = rho - l.big;
    let g = q * q + p.z * p.z - l.small2;
    var drho = 0.0;
    if rho > 0.0 {
        drho = (p.x * l.u.x + p.y * l.u.y) / rho;
    }
    let d = 2.0 * (q * drho + p.z * l.u.z);
    return TorusSample(s, g, d);
}

// [i1, i2] clamped to [lo, hi], outside of which g is convex; ok false when g is convex on
// all of [lo, hi]. Returned as a Span (t0 = i1, t1 = i2) in a MaybeSpan.
fn torus_concave_part(l: TorusLine, lo: f32, hi: f32) -> MaybeSpan {
    let u = l.u;
    let a = u.x * u.x + u.y * u.y;
    if a > TORUS_EPSILON {
        let floor = sqrt(TORUS_EPSILON);
        let rho_i = max(torus_cbrt(l.big * l.m2), floor);
        let w = a * rho_i * rho_i - l.m2;
        if w >= 0.0 {
            let b = l.c.x * u.x + l.c.y * u.y;
            let mid = -b / a;
            let half = sqrt(w) / a;
            let i1 = max(mid - half, lo);
            let i2 = min(mid + half, hi);
            if i1 < i2 {
                return MaybeSpan(true, Span(i1, i2, vec3<f32>(0.0), vec3<f32>(0.0)));
            }
        }
    }
    return MaybeSpan(false, span_everywhere());
}

// The crossing in [a.s, b.s] where g changes sign: Newton safeguarded by bisection.
fn torus_bracketed(l: TorusLine, a: TorusSample, b: TorusSample) -> f32 {
    let a_inside = a.g < 0.0;
    var lo = a.s;
    var hi = b.s;
    var x = 0.5 * (lo + hi);
    if a.g != b.g {
        x = a.s + (b.s - a.s) * (a.g / (a.g - b.g));
    }
    var prev = hi - lo;
    for (var i = 0u; i < TORUS_MAX_ITERATIONS; i += 1u) {
        if !(x > lo && x < hi) {
            x = 0.5 * (lo + hi);
        }
        let y = torus_sample(l, x);
        if y.g == 0.0 {
            return x;
        }
        if (y.g < 0.0) == a_inside {
            lo = x;
        } else {
            hi = x;
        }
        // The CPU's x - g / 0 is infinite (or NaN), which the range test sends to bisection.
        var next = 0.5 * (lo + hi);
        if y.d != 0.0 {
            next = torus_newton_step(l, x, y.g, y.d);
        }
        if !(next > lo && next < hi) || 2.0 * abs(next - x) > prev {
            next = 0.5 * (lo + hi);
        }
        prev = abs(next - x);
        x = next;
        if prev <= l.tol || hi - lo <= l.tol {
            break;
        }
    }
    return x;
}

// Newton's method on g from `start` towards `end` where sigma * g is convex and
// sigma * g(start) > 0: monotone towards the nearest crossing; ok false when there is none.
fn torus_newton_from(l: TorusLine, start: TorusSample, end: f32, sigma: f32) -> TorusMaybe {
    var dir = -1.0;
    if end > start.s {
        dir = 1.0;
    }
    var x = start;
    for (var i = 0u; i < TORUS_MAX_ITERATIONS; i += 1u) {
        if x.g == 0.0 {
            return TorusMaybe(true, x.s);
        }
        if sigma * x.d * dir >= 0.0 || !is_finite_t(x.d) {
            return TorusMaybe(false, 0.0);
        }
        let next = torus_newton_step(l, x.s, x.g, x.d);
        if (next - end) * dir > 0.0 {
            return TorusMaybe(false, 0.0);
        }
        if abs(next - x.s) <= l.tol {
            return TorusMaybe(true, next);
        }
        let y = torus_sample(l, next);
        if (y.g < 0.0) != (x.g < 0.0) {
            if dir > 0.0 {
                return TorusMaybe(true, torus_bracketed(l, x, y));
            }
            return TorusMaybe(true, torus_bracketed(l, y, x));
        }
        x = y;
    }
    return TorusMaybe(true, x.s);
}

// Whether sigma * g, convex on [a.s, b.s] and positive at both ends, might dip to zero.
fn torus_may_dip(a: TorusSample, b: TorusSample, sigma: f32) -> bool {
    let ga = sigma * a.g;
    let da = sigma * a.d;
    let gb = sigma * b.g;
    let db = sigma * b.d;
    if !(da < 0.0 && db > 0.0) {
        return true;
    }
    let w = b.s - a.s;
    let y = (gb - ga - db * w) / (da - db);
    let low = ga + da * y;
    let noise = 16.0 * TORUS_EPSILON * (ga + gb + (db - da) * w);
    return low <= noise;
}

fn torus_push(out: ptr<function, TorusRoots>, t: f32) {
    if (*out).count < 4u {
        (*out).t[(*out).count] = t;
        (*out).count += 1u;
    }
}

// The crossings in the piece [a.s, b.s] where g is convex (or concave), appended to out.
fn torus_piece(l: TorusLine, a: TorusSample, b: TorusSample, convex: bool, out: ptr<function, TorusRoots>) {
    if b.s <= a.s {
        return;
    }
    var sigma = -1.0;
    if convex {
        sigma = 1.0;
    }
    let start_a = (a.g >= 0.0) == convex;
    let start_b = (b.g >= 0.0) == convex;
    if start_a && !start_b {
        let n = torus_newton_from(l, a, b.s, sigma);
        if n.ok {
            torus_push(out, n.s);
        } else {
            torus_push(out, torus_bracketed(l, a, b));
        }
    } else if !start_a && start_b {
        let n = torus_newton_from(l, b, a.s, sigma);
        if n.ok {
            torus_push(out, n.s);
        } else {
            torus_push(out, torus_bracketed(l, a, b));
        }
    } else if start_a && start_b {
        if torus_may_dip(a, b, sigma) {
            let first = torus_newton_from(l, a, b.s, sigma);
            if first.ok {
                var last = torus_newton_from(l, b, a.s, sigma);
                if !last.ok {
                    last.s = first.s;
                }
                torus_push(out, first.s);
                torus_push(out, max(last.s, first.s));
            }
        }
    }
}

// The crossings in [lo, hi] (outside the tube at both ends), ascending.
fn torus_line_crossings(l: TorusLine, lo: f32, hi: f32) -> TorusRoots {
    var out: TorusRoots;
    out.count = 0u;
    var first = torus_sample(l, lo);
    first.g = max(first.g, 0.0);
    var last = torus_sample(l, hi);
    last.g = max(last.g, 0.0);
    // The pieces between the concave part's ends, convex, concave, convex (or the one
    // convex piece), solved through one call site: drivers inline every call.
    var a = array<TorusSample, 3>(first, first, first);
    var b = array<TorusSample, 3>(last, last, last);
    var pieces = 1u;
    let concave = torus_concave_part(l, lo, hi);
    if concave.ok {
        let i1 = concave.span.t0;
        let i2 = concave.span.t1;
        var s1 = first;
        if i1 > lo {
            s1 = torus_sample(l, i1);
        }
        var s2 = last;
        if i2 < hi {
            s2 = torus_sample(l, i2);
        }
        a = array<TorusSample, 3>(first, s1, s2);
        b = array<TorusSample, 3>(s1, s2, last);
        pieces = 3u;
    }
    for (var k = 0u; k < pieces; k += 1u) {
        torus_piece(l, a[k], b[k], pieces == 1u || k != 1u, &out);
    }
    return out;
}

// The ray parameters where origin + t direction crosses the tube of radius r around the
// core circle of radius rtor, ascending (count 0, 2 or 4; rarely 3 within rounding noise
// of a tangency). None for a zero direction, r <= 0 or rtor < 0.
fn torus_crossings(origin: vec3<f32>, direction: vec3<f32>, r: f32, rtor: f32) -> TorusRoots {
    var none: TorusRoots;
    none.count = 0u;
    let big = v3_max_abs(direction);
    let scale = rtor + r;
    if !(big > 0.0 && is_finite_t(big) && r > 0.0 && rtor >= 0.0 && is_finite_t(scale)) {
        return none;
    }
    let dn = direction / big;
    let ln = sqrt(v3_dot(dn, dn));
    let u = dn * (1.0 / ln);
    let len = big * ln;
    // Closest approach to the centre, compensated (see torus.rs), then one projection.
    var t_c = -v3_dot(origin, u) / len;
    let one = opaque_one(origin.x);
    var c = vec3<f32>(
        torus_exact_at1(origin.x, direction.x, t_c, one),
        torus_exact_at1(origin.y, direction.y, t_c, one),
        torus_exact_at1(origin.z, direction.z, t_c, one),
    );
    let along = v3_dot(c, u);
    c = c - u * along;
    t_c = t_c - along / len;
    let inv_scale = 1.0 / scale;
    c = c * inv_scale;
    let c2 = v3_dot(c, c);
    if !(c2 < 1.0 && is_finite_t(t_c)) {
        return none;
    }
    let outer = 1.0 + TORUS_SPHERE_MARGIN;
    let reach = sqrt(outer * outer - c2);
    let line = torus_line(c, u, rtor * inv_scale, r * inv_scale, one);
    var out = torus_line_crossings(line, -reach, reach);
    let per_s = scale / len;
    for (var i = 0u; i < out.count; i += 1u) {
        out.t[i] = t_c + out.t[i] * per_s;
    }
    return out;
}

// Outward normal (not normalised) of the tube at p: p minus the nearest core point
// ((rtor, 0, 0) on the z axis).
fn torus_normal(p: vec3<f32>, rtor: f32) -> vec3<f32> {
    let rho = sqrt(p.x * p.x + p.y * p.y);
    if rho > 0.0 {
        let k = (rho - rtor) / rho;
        return vec3<f32>(p.x * k, p.y * k, p.z);
    }
    return vec3<f32>(-rtor, 0.0, p.z);
}

// Exact signed distance to the tube surface (negative inside).
fn torus_sdf(p: vec3<f32>, r: f32, rtor: f32) -> f32 {
    let rho = sqrt(p.x * p.x + p.y * p.y);
    let q = rho - rtor;
    return sqrt(q * q + p.z * p.z) - r;
}

// Spans of the ray inside the tube of radius r.
fn torus_tube_spans(o: vec3<f32>, d: vec3<f32>, r: f32, rtor: f32) -> Spans {
    var roots = torus_crossings(o, d, r, rtor);
    var c: Crossings;
    c.count = roots.count;
    for (var i = 0u; i < roots.count; i += 1u) {
        c.t[i] = roots.t[i];
        c.n[i] = torus_normal(o + d * roots.t[i], rtor);
    }
    return spans_from_toggles(false, c);
}

// Spans of a ray inside the torus p = [rmin, rmax, rtor].
// The outer tube, then the inner one of a hollow torus, through one call site.
fn torus_spans(p: array<f32, 6>, o: vec3<f32>, d: vec3<f32>) -> Spans {
    var outer = spans_empty();
    for (var k = 0u; k < 2u; k += 1u) {
        if k == 1u && !(p[0] > 0.0) {
            break;
        }
        let tube = torus_tube_spans(o, d, select(p[1], p[0], k == 1u), p[2]);
        if k == 0u {
            outer = tube;
        } else {
            outer = spans_subtract(outer, tube);
        }
    }
    return outer;
}

// Signed distance to the torus p = [rmin, rmax, rtor] (exact).
fn torus_prim_sdf(p: array<f32, 6>, x: vec3<f32>) -> f32 {
    let outer = torus_sdf(x, p[1], p[2]);
    if p[0] > 0.0 {
        return max(outer, -torus_sdf(x, p[0], p[2]));
    }
    return outer;
}
