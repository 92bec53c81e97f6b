// Unbounded cutting primitives that carve angular segments: the phi wedge around z and the
// theta cone shell around z with its apex at the origin. Twin of hytrace_csg::kernel::cuts.
//
// sin, cos and atan2 are written here because the GPU's built-ins may be far less accurate
// (lavapipe's err by tens of ulps): atan2 is fdlibm's atan2f, as glibc 2.36 computes Rust's
// f32 atan2 (bit-identical there); sin and cos are correctly rounded (double-single
// arithmetic), as glibc's are for |x| <= pi but not everywhere beyond. Another libm (or a
// compiler contracting a * b + c into an fma) can differ in the last bit.
// #import real
// #import csg/spans
// #import csg/quadric

const CUT_PI: f32 = 3.14159265358979323846;

// Double-single arithmetic: a value hi + lo held in two f32 (x = hi, y = lo), enough to round
// sin and cos correctly in all but rare cases, built on real.wgsl's error-free two_sum and
// two_product (see there why they stay exact under Mesa's rewrites and fma contraction);
// quick_sum's error term uses the same run-time 1.0 (opaque_one).
fn ds_quick_sum(a: f32, b: f32, one: f32) -> vec2<f32> {
    let s = a + b;
    return vec2<f32>(s, b - (s * one - a));
}

fn ds_add(a: vec2<f32>, b: vec2<f32>, one: f32) -> vec2<f32> {
    let s = two_sum(a.x, b.x, one);
    return ds_quick_sum(s.x, s.y + (a.y + b.y), one);
}

fn ds_mul(a: vec2<f32>, b: vec2<f32>, one: f32) -> vec2<f32> {
    let p = two_product(a.x, b.x);
    return ds_quick_sum(p.x, p.y + (a.x * b.y + a.y * b.x), one);
}

// (sin x, cos x), correctly rounded but for rare cases for |x| <= pi (as Rust's there), and
// accurate for |x| up to about 1e4: x is reduced by the nearest multiple k of pi/2 (split in
// four parts, k times the first two exact), then Taylor series in double-single.
fn cut_sincos(x: f32) -> vec2<f32> {
    let one = opaque_one(x);
    let k = round(x * 0.636619772367581343076);
    var r = two_sum(x - k * 1.5703125, -(k * 4.837512969970703125e-4), one);
    r = ds_add(r, -two_product(k, 7.549790126404332e-08), one);
    r = ds_add(r, vec2<f32>(k * 1.7151245100058819e-15, 0.0), one);
    let z = ds_mul(r, r, one);
    // sin r = r + r z S(z), cos r = 1 + z C(z): Taylor coefficients as hi + lo.
    var sp = vec2<f32>(-7.647163609812713e-13, 0.0);
    var cp = vec2<f32>(4.7794772561329454e-14, 0.0);
    var sc = array<vec2<f32>, 6>(
        vec2<f32>(-0.1666666716337204, 4.967053879312289e-09),
        vec2<f32>(0.008333333767950535, -4.34617203337595e-10),
        vec2<f32>(-0.00019841270113829523, 2.725596874933456e-12),
        vec2<f32>(2.7557318844628753e-06, 3.793571224297229e-14),
        vec2<f32>(-2.5052107943679403e-08, 0.0),
        vec2<f32>(1.6059044372074283e-10, 0.0),
    );
    var cc = array<vec2<f32>, 7>(
        vec2<f32>(-0.5, 0.0),
        vec2<f32>(0.0416666679084301, -1.2417634698280722e-09),
        vec2<f32>(-0.0013888889225199819, 3.3631094437103215e-11),
        vec2<f32>(2.4801587642286904e-05, -3.40699609366682e-13),
        vec2<f32>(-2.755731998149713e-07, 0.0),
        vec2<f32>(2.0876755879584152e-09, 0.0),
        vec2<f32>(-1.147074536050896e-11, 0.0),
    );
    for (var i = 6; i > 0; i -= 1) {
        sp = ds_add(sc[i - 1], ds_mul(z, sp, one), one);
    }
    for (var i = 7; i > 0; i -= 1) {
        cp = ds_add(cc[i - 1], ds_mul(z, cp, one), one);
    }
    let s = ds_add(r, ds_mul(ds_mul(r, z, one), sp, one), one).x;
    let c = ds_add(vec2<f32>(1.0, 0.0), ds_mul(z, cp, one), one).x;
    let quadrant = i32(k) & 3;
    if quadrant == 0 {
        return vec2<f32>(s, c);
    }
    if quadrant == 1 {
        return vec2<f32>(c, -s);
    }
    if quadrant == 2 {
        return vec2<f32>(-s, -c);
    }
    return vec2<f32>(-c, s);
}

// atan(x), fdlibm's atanf (as glibc's): reduction around 0.5, 1, 1.5 and infinity, then an
// odd polynomial.
fn cut_atan(v: f32) -> f32 {
    // Products that feed a sum are multiplied by a run-time 1: a compiler that contracts
    // the sum into an fma then still rounds the product first, as the CPU does.
    let one = opaque_one(v);
    let negative = sign_bit(v);
    var x = abs(v);
    if x >= 33554432.0 {
        return select(1.5707962513 + 7.5497894159e-08, -(1.5707962513 + 7.5497894159e-08), negative);
    }
    var id = -1;
    if x < 0.4375 {
        if x < 1.8626451e-9 {
            return v;
        }
        x = v;
    } else if x < 0.6875 {
        id = 0;
        x = ((2.0 * x) * one - 1.0) / (2.0 + x);
    } else if x < 1.1875 {
        id = 1;
        x = (x - 1.0) / (x + 1.0);
    } else if x < 2.4375 {
        id = 2;
        x = (x - 1.5) / (1.0 + (1.5 * x) * one);
    } else {
        id = 3;
        x = -1.0 / x;
    }
    let z = x * x;
    let w = z * z;
    var odd = 1.6285819933e-02;
    var odd_c = array<f32, 5>(3.3333334327e-01, 1.4285714924e-01, 9.0908870101e-02, 6.6610731184e-02, 4.9768779427e-02);
    for (var i = 5; i > 0; i -= 1) {
        odd = odd_c[i - 1] + (w * odd) * one;
    }
    var even = -3.6531571299e-02;
    var even_c = array<f32, 4>(-2.0000000298e-01, -1.1111110449e-01, -7.6918758452e-02, -5.8335702866e-02);
    for (var i = 4; i > 0; i -= 1) {
        even = even_c[i - 1] + (w * even) * one;
    }
    let s1 = z * odd;
    let s2 = w * even;
    let xs = (x * (s1 + s2)) * one;
    if id < 0 {
        return x - xs;
    }
    var hi = array<f32, 4>(4.6364760399e-01, 7.8539812565e-01, 9.8279368877e-01, 1.5707962513e+00);
    var lo = array<f32, 4>(5.0121582440e-09, 3.7748947079e-08, 3.4473217170e-08, 7.5497894159e-08);
    let a = hi[id] - ((xs - lo[id]) - x);
    return select(a, -a, negative);
}

// Rust's f32 atan2 (glibc's, fdlibm's atan2f), signed zeros included.
fn cut_atan2(y: f32, x: f32) -> f32 {
    let pi_lo = -8.7422776573e-08;
    let half_pi = 1.5707963705;
    if x == 1.0 {
        return cut_atan(y);
    }
    let y_negative = sign_bit(y);
    let x_negative = sign_bit(x);
    if y == 0.0 {
        if !x_negative {
            return y;
        }
        return select(CUT_PI, -CUT_PI, y_negative);
    }
    if x == 0.0 {
        return select(half_pi, -half_pi, y_negative);
    }
    // Binary exponent difference of |y| and |x|.
    let k = (bitcast<i32>(abs(y)) - bitcast<i32>(abs(x))) >> 23u;
    var z = 0.0;
    if k > 60 {
        z = half_pi + 0.5 * pi_lo;
    } else if !(x_negative && k < -60) {
        z = cut_atan(abs(y / x));
    }
    if !x_negative {
        return select(z, -z, y_negative);
    }
    if !y_negative {
        return CUT_PI - (z - pi_lo);
    }
    return (z - pi_lo) - CUT_PI;
}

// Angle from phi0 (unit (c0, s0)) to the direction (x, y), in [0, 2 pi).
fn angle_from(c0: f32, s0: f32, x: f32, y: f32) -> f32 {
    let a = cut_atan2(c0 * y - s0 * x, c0 * x + s0 * y);
    if a < 0.0 {
        return a + 2.0 * CUT_PI;
    }
    return a;
}

// Opening angle of the wedge [cos phi0, sin phi0, cos phi1, sin phi1], in (0, 2 pi].
fn wedge_width(p: array<f32, 6>) -> f32 {
    let w = angle_from(p[0], p[1], p[2], p[3]);
    if w > 0.0 {
        return w;
    }
    return 2.0 * CUT_PI;
}

fn in_wedge(p: array<f32, 6>, x: f32, y: f32) -> bool {
    return angle_from(p[0], p[1], x, y) <= wedge_width(p);
}

// Angle within which a direction runs along a cut's surface (see the CPU twin): 4 eps.
const CUT_ANGLE_TOLERANCE: f32 = 4.0 * 1.1920929e-7;

// Whether the direction (x, y) points strictly between the wedge's half-planes.
fn strictly_in_wedge(p: array<f32, 6>, x: f32, y: f32) -> bool {
    let a = angle_from(p[0], p[1], x, y);
    return a > CUT_ANGLE_TOLERANCE && a < wedge_width(p) - CUT_ANGLE_TOLERANCE;
}

// Whether the line through o along d passes through the origin within rounding:
// |o x d|^2 <= (8 eps)^2 |o|^2 |d|^2 (see the CPU twin).
fn through_origin(o: vec3<f32>, d: vec3<f32>) -> bool {
    let c = vec3<f32>(o.y * d.z - o.z * d.y, o.z * d.x - o.x * d.z, o.x * d.y - o.y * d.x);
    let eps = 8.0 * 1.1920929e-7;
    return v3_dot(c, c) <= eps * eps * v3_dot(o, o) * v3_dot(d, d);
}

// Spans of a ray whose line passes through the edge of a cut (the wedge's axis, the cone's
// apex) at t: from the side `before` to the side `after`, one crossing or none.
fn through_edge(before: bool, after: bool, t: f32, normal: vec3<f32>) -> Spans {
    if before == after {
        if before {
            return spans_one(span_everywhere());
        }
        return spans_empty();
    }
    var c: Crossings;
    c.count = 1u;
    c.t[0] = t;
    c.n[0] = normal;
    return spans_from_toggles(before, c);
}

// Phi wedge [cos phi0, sin phi0, cos phi1, sin phi1]: azimuths from phi0 counter-clockwise
// to phi1.
fn phicut_spans(p: array<f32, 6>, o: vec3<f32>, d: vec3<f32>) -> Spans {
    if d.x == 0.0 && d.y == 0.0 {
        if in_wedge(p, o.x, o.y) {
            return spans_one(span_everywhere());
        }
        return spans_empty();
    }
    // A ray whose line passes through the axis goes from the azimuth of -d to that of d
    // there (see the CPU twin).
    if through_origin(vec3<f32>(o.x, o.y, 0.0), vec3<f32>(d.x, d.y, 0.0)) {
        let t = -(o.x * d.x + o.y * d.y) / (d.x * d.x + d.y * d.y);
        return through_edge(
            strictly_in_wedge(p, -d.x, -d.y),
            strictly_in_wedge(p, d.x, d.y),
            t,
            -d,
        );
    }
    // Outward normals of the two bounding half-planes, and the unit direction of each.
    var normals = array<vec3<f32>, 2>(vec3<f32>(p[1], -p[0], 0.0), vec3<f32>(-p[3], p[2], 0.0));
    var sides = array<vec2<f32>, 2>(vec2<f32>(p[0], p[1]), vec2<f32>(p[2], p[3]));
    var c: Crossings;
    c.count = 0u;
    for (var k = 0u; k < 2u; k += 1u) {
        let n = normals[k];
        let dn = v3_dot(n, d);
        if dn == 0.0 {
            continue;
        }
        let t = -v3_dot(n, o) / dn;
        let q = ray_at(o, d, t);
        // Only the half-plane on the phi side of the axis bounds the wedge.
        let side = sides[k];
        if side.x * q.x + side.y * q.y >= 0.0 {
            c.t[c.count] = t;
            c.n[c.count] = n;
            c.count += 1u;
        }
    }
    if c.count == 2u && c.t[1] < c.t[0] {
        let t = c.t[0];
        let n = c.n[0];
        c.t[0] = c.t[1];
        c.n[0] = c.n[1];
        c.t[1] = t;
        c.n[1] = n;
    }
    // The state before the first crossing follows from that crossing's own normal (see the
    // CPU twin).
    var inside_before = false;
    if c.count == 0u {
        inside_before = in_wedge(p, o.x, o.y);
    } else {
        inside_before = v3_dot(c.n[0], d) > 0.0;
    }
    return spans_from_toggles(inside_before, c);
}

fn phicut_sdf(p: array<f32, 6>, x: vec3<f32>) -> f32 {
    let a = v3_dot(vec3<f32>(p[1], -p[0], 0.0), x);
    let b = v3_dot(vec3<f32>(-p[3], p[2], 0.0), x);
    if wedge_width(p) <= CUT_PI {
        return max(a, b);
    }
    return min(a, b);
}

// Polar angle of a direction, in [0, pi].
fn polar(v: vec3<f32>) -> f32 {
    return cut_atan2(v3_length(vec3<f32>(v.x, v.y, 0.0)), v.z);
}

// Adds the crossing of a theta cone at t, with the direction of increasing theta (times
// rho |q|) as its normal; the caller orients normals.
fn theta_crossing(c: ptr<function, Crossings>, o: vec3<f32>, d: vec3<f32>, t: f32) {
    let q = ray_at(o, d, t);
    let rho2 = q.x * q.x + q.y * q.y;
    var n = vec3<f32>(q.x * q.z, q.y * q.z, -rho2);
    if rho2 == 0.0 {
        n = vec3<f32>(0.0, 0.0, -1.0);
    }
    (*c).t[(*c).count] = t;
    (*c).n[(*c).count] = n;
    (*c).count += 1u;
}

// Theta cone shell [theta0, theta1]: polar angles from +z between theta0 and theta1
// (theta0 = 0 or theta1 = pi leave that side open).
fn thetacut_spans(p: array<f32, 6>, o: vec3<f32>, d: vec3<f32>) -> Spans {
    // A ray through the apex goes from the polar angle of -d to that of d there (see the
    // CPU twin).
    if through_origin(o, d) {
        let back = polar(-d);
        let ahead = polar(d);
        let tol = CUT_ANGLE_TOLERANCE;
        let before = (p[0] <= 0.0 || back > p[0] + tol) && (p[1] >= CUT_PI || back < p[1] - tol);
        let after = (p[0] <= 0.0 || ahead > p[0] + tol) && (p[1] >= CUT_PI || ahead < p[1] - tol);
        return through_edge(before, after, -v3_dot(o, d) / v3_dot(d, d), -d);
    }
    var c: Crossings;
    c.count = 0u;
    for (var k = 0u; k < 2u; k += 1u) {
        var theta = p[0];
        var open = theta <= 0.0;
        if k == 1u {
            theta = p[1];
            open = theta >= CUT_PI;
        }
        if open {
            continue;
        }
        let sc = cut_sincos(theta);
        let st = sc.x;
        let ct = sc.y;
        if abs(ct) < 2.0e-6 {
            // theta = pi/2: the plane z = 0.
            if d.z != 0.0 {
                theta_crossing(&c, o, d, -o.z / d.z);
            }
            continue;
        }
        // c^2 rho^2 - s^2 z^2 = 0 on the nappe where z has the sign of cos(theta).
        let c2 = ct * ct;
        let s2 = st * st;
        let a = c2 * (d.x * d.x + d.y * d.y) - s2 * d.z * d.z;
        let b = c2 * (o.x * d.x + o.y * d.y) - s2 * o.z * d.z;
        let cc = c2 * (o.x * o.x + o.y * o.y) - s2 * o.z * o.z;
        let r = quadratic_roots(a, b, cc);
        if r.ok {
            if (o.z + d.z * r.r1) * ct >= 0.0 {
                theta_crossing(&c, o, d, r.r1);
            }
            if (o.z + d.z * r.r2) * ct >= 0.0 {
                theta_crossing(&c, o, d, r.r2);
            }
        }
    }
    // Stable insertion sort by t.
    for (var i = 1u; i < c.count; i += 1u) {
        let t = c.t[i];
        let n = c.n[i];
        var j = i;
        while j > 0u && c.t[j - 1u] > t {
            c.t[j] = c.t[j - 1u];
            c.n[j] = c.n[j - 1u];
            j -= 1u;
        }
        c.t[j] = t;
        c.n[j] = n;
    }
    let far = polar(-d);
    return spans_from_toggles(p[0] <= far && far <= p[1], c);
}

fn thetacut_sdf(p: array<f32, 6>, x: vec3<f32>) -> f32 {
    let r = v3_length(x);
    let theta = polar(x);
    let half_pi = 0.5 * CUT_PI;
    var sdf = -INF;
    if p[0] > 0.0 {
        sdf = max(sdf, r * cut_sincos(min(max(p[0] - theta, -half_pi), half_pi)).x);
    }
    if p[1] < CUT_PI {
        sdf = max(sdf, r * cut_sincos(min(max(theta - p[1], -half_pi), half_pi)).x);
    }
    return sdf;
}
