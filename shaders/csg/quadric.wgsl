// Primitives bounded by quadrics of revolution around z, capped by z planes: sphere, z-cut
// sphere, cylinder, tube, cone frustum, hyperboloid, paraboloid; and the uncapped half-space
// below a hyperbolic paraboloid (the saddle). Twin of
// hytrace_csg::kernel::quadric, with the quadric helpers of hytrace_csg::kernel::spans
// (quadratic_roots, quadric_spans); vector arithmetic is real.wgsl's (hytrace_csg::real::V3).
//
// Quadrics are written a t^2 + 2 b t + c in the ray parameter. Every expression keeps the
// CPU's operand order (f32 arithmetic is not associative), and dot products and lengths
// are written out term by term as the CPU sums them.
// #import real
// #import csg/spans

// Whether the sign bit of x is set (Rust's copysign looks at it, so -0.0 counts).
fn sign_bit(x: f32) -> bool {
    return (bitcast<u32>(x) >> 31u) == 1u;
}

// Every span restricted to the window, or nothing without one (Spans::clip_opt).
fn spans_clip_opt(s: Spans, w: MaybeSpan) -> Spans {
    if !w.ok {
        return spans_empty();
    }
    return spans_clip(s, w.span);
}

// Real roots of a t^2 + 2 b t + c, ascending (r1 <= r2), computed without cancellation.
struct Roots {
    ok: bool,
    r1: f32,
    r2: f32,
}

fn quadratic_roots(a: f32, b: f32, c: f32) -> Roots {
    let disc = b * b - a * c;
    if disc < 0.0 || !is_finite_t(disc) {
        return Roots(false, 0.0, 0.0);
    }
    let root = sqrt(disc);
    let q = -(b + select(root, -root, sign_bit(b)));
    if q == 0.0 {
        // b = 0 and a c = 0: a double root at 0 (c = 0) or no roots.
        return Roots(c == 0.0, 0.0, 0.0);
    }
    let r2 = c / q;
    // a = 0 (or q / a overflows): the one root of the linear equation.
    if a == 0.0 {
        return Roots(true, r2, r2);
    }
    let r1 = q / a;
    if !is_finite_t(r1) {
        return Roots(true, r2, r2);
    }
    if r1 <= r2 {
        return Roots(true, r1, r2);
    }
    return Roots(true, r2, r1);
}

// Spans where a t^2 + 2 b t + c <= 0, with zero normals: the caller sets the normals at
// finite ends (the CPU's quadric_spans takes the normal as a closure).
fn quadric_spans(a: f32, b: f32, c: f32) -> Spans {
    let z = vec3<f32>(0.0);
    if a == 0.0 {
        // Linear: 2 b t + c <= 0.
        if b == 0.0 {
            if c <= 0.0 {
                return spans_one(span_everywhere());
            }
            return spans_empty();
        }
        let t = -c / (2.0 * b);
        if b > 0.0 {
            return spans_one(Span(-INF, t, z, z));
        }
        return spans_one(Span(t, INF, z, z));
    }
    let r = quadratic_roots(a, b, c);
    if !r.ok {
        if a > 0.0 {
            return spans_empty();
        }
        return spans_one(span_everywhere());
    }
    if a > 0.0 {
        return spans_one(Span(r.r1, r.r2, z, z));
    }
    var s = spans_one(Span(-INF, r.r1, z, z));
    spans_push(&s, Span(r.r2, INF, z, z));
    return s;
}

// o + d t (the CPU's V3::at).
fn ray_at(o: vec3<f32>, d: vec3<f32>, t: f32) -> vec3<f32> {
    return vec3<f32>(o.x + d.x * t, o.y + d.y * t, o.z + d.z * t);
}

// The span between the planes z = lo and z = hi of the ray o + t d, in parameters from
// o + shift d: the caps are met from the unmoved origin, so that leaves sharing a z plane
// meet it at the same parameter (twin of the CPU's z_slab).
fn z_slab(o: vec3<f32>, d: vec3<f32>, shift: f32, lo: f32, hi: f32) -> MaybeSpan {
    var s = slab_span(o.z, d.z, lo, hi, vec3<f32>(0.0, 0.0, 1.0));
    s.span.t0 = s.span.t0 - shift;
    s.span.t1 = s.span.t1 - shift;
    return s;
}

// Signed distance of a capped solid of revolution from its radial distance dr (negative
// inside the side wall) and the z range.
fn capped(dr: f32, z: f32, z1: f32, z2: f32) -> f32 {
    let dz = max(z1 - z, z - z2);
    let outside = v3_length(vec3<f32>(max(dr, 0.0), max(dz, 0.0), 0.0));
    return min(max(dr, dz), 0.0) + outside;
}

// Spans of the infinite cylinder of `radius` around the z axis through (cx, cy).
fn cylinder_wall(o: vec3<f32>, d: vec3<f32>, cx: f32, cy: f32, radius: f32) -> Spans {
    let ox = o.x - cx;
    let oy = o.y - cy;
    let a = d.x * d.x + d.y * d.y;
    let b = ox * d.x + oy * d.y;
    let c = ox * ox + oy * oy - radius * radius;
    var s = quadric_spans(a, b, c);
    for (var i = 0u; i < s.len; i += 1u) {
        let t0 = s.items[i].t0;
        let t1 = s.items[i].t1;
        if is_finite_t(t0) {
            s.items[i].n0 = vec3<f32>(ox + d.x * t0, oy + d.y * t0, 0.0);
        }
        if is_finite_t(t1) {
            s.items[i].n1 = vec3<f32>(ox + d.x * t1, oy + d.y * t1, 0.0);
        }
    }
    return s;
}

// Sphere [cx, cy, cz, r].
fn sphere_spans(p: array<f32, 6>, o: vec3<f32>, d: vec3<f32>) -> Spans {
    let oc = o - vec3<f32>(p[0], p[1], p[2]);
    let c = v3_dot(oc, oc) - p[3] * p[3];
    var s = quadric_spans(v3_dot(d, d), v3_dot(oc, d), c);
    for (var i = 0u; i < s.len; i += 1u) {
        let t0 = s.items[i].t0;
        let t1 = s.items[i].t1;
        if is_finite_t(t0) {
            s.items[i].n0 = ray_at(oc, d, t0);
        }
        if is_finite_t(t1) {
            s.items[i].n1 = ray_at(oc, d, t1);
        }
    }
    return s;
}

fn sphere_sdf(p: array<f32, 6>, x: vec3<f32>) -> f32 {
    return v3_length(x - vec3<f32>(p[0], p[1], p[2])) - p[3];
}

// Z-cut sphere [cx, cy, cz, r], [z1, z2] relative to the centre.
fn zsphere_spans(p: array<f32, 6>, start: vec3<f32>, d: vec3<f32>, shift: f32) -> Spans {
    let o = start + d * shift;
    let slab = z_slab(start, d, shift, p[2] + p[4], p[2] + p[5]);
    return spans_clip_opt(sphere_spans(p, o, d), slab);
}

fn zsphere_sdf(p: array<f32, 6>, x: vec3<f32>) -> f32 {
    let z = x.z - p[2];
    return max(max(sphere_sdf(p, x), p[4] - z), z - p[5]);
}

// Cylinder [cx, cy, -, r], [z1, z2].
fn cylinder_spans(p: array<f32, 6>, start: vec3<f32>, d: vec3<f32>, shift: f32) -> Spans {
    let o = start + d * shift;
    return spans_clip_opt(cylinder_wall(o, d, p[0], p[1], p[3]), z_slab(start, d, shift, p[4], p[5]));
}

fn cylinder_sdf(p: array<f32, 6>, x: vec3<f32>) -> f32 {
    let rho = v3_length(vec3<f32>(x.x - p[0], x.y - p[1], 0.0));
    return capped(rho - p[3], x.z, p[4], p[5]);
}

// Tube [cx, cy, rin, r], [z1, z2]; rin = 0 is a cylinder.
fn tube_spans(p: array<f32, 6>, start: vec3<f32>, d: vec3<f32>, shift: f32) -> Spans {
    let o = start + d * shift;
    var walls = cylinder_wall(o, d, p[0], p[1], p[3]);
    if p[2] > 0.0 {
        walls = spans_subtract(walls, cylinder_wall(o, d, p[0], p[1], p[2]));
    }
    return spans_clip_opt(walls, z_slab(start, d, shift, p[4], p[5]));
}

fn tube_sdf(p: array<f32, 6>, x: vec3<f32>) -> f32 {
    let rho = v3_length(vec3<f32>(x.x - p[0], x.y - p[1], 0.0));
    return capped(max(rho - p[3], p[2] - rho), x.z, p[4], p[5]);
}

// Cone frustum [r1, z1, r2, z2]: radius r1 at z1, r2 at z2.
fn cone_spans(p: array<f32, 6>, start: vec3<f32>, d: vec3<f32>, shift: f32) -> Spans {
    let o = start + d * shift;
    let r1 = p[0];
    let z1 = p[1];
    let k = (p[2] - r1) / (p[3] - z1);
    let ro = r1 + k * (o.z - z1);
    let a = d.x * d.x + d.y * d.y - k * k * d.z * d.z;
    let b = o.x * d.x + o.y * d.y - k * d.z * ro;
    let c = o.x * o.x + o.y * o.y - ro * ro;
    var s = quadric_spans(a, b, c);
    // Normals: the gradient of x^2 + y^2 - r(z)^2 (halved).
    for (var i = 0u; i < s.len; i += 1u) {
        let t0 = s.items[i].t0;
        let t1 = s.items[i].t1;
        if is_finite_t(t0) {
            let q = ray_at(o, d, t0);
            s.items[i].n0 = vec3<f32>(q.x, q.y, -k * (r1 + k * (q.z - z1)));
        }
        if is_finite_t(t1) {
            let q = ray_at(o, d, t1);
            s.items[i].n1 = vec3<f32>(q.x, q.y, -k * (r1 + k * (q.z - z1)));
        }
    }
    return spans_clip_opt(s, z_slab(start, d, shift, z1, p[3]));
}

fn cone_sdf(p: array<f32, 6>, x: vec3<f32>) -> f32 {
    let r1 = p[0];
    let z1 = p[1];
    let rho = v3_length(vec3<f32>(x.x, x.y, 0.0));
    let ez = p[3] - z1;
    let er = p[2] - r1;
    let side = ((rho - r1) * ez - (x.z - z1) * er) / sqrt(ez * ez + er * er);
    return max(max(side, z1 - x.z), x.z - p[3]);
}

// One-sheet hyperboloid [r0, tan(stereo), z1, z2]: x^2 + y^2 = r0^2 + tan^2 z^2.
fn hyperboloid_spans(p: array<f32, 6>, start: vec3<f32>, d: vec3<f32>, shift: f32) -> Spans {
    let o = start + d * shift;
    let r0 = p[0];
    let s2 = p[1] * p[1];
    let a = d.x * d.x + d.y * d.y - s2 * d.z * d.z;
    let b = o.x * d.x + o.y * d.y - s2 * o.z * d.z;
    let c = o.x * o.x + o.y * o.y - r0 * r0 - s2 * o.z * o.z;
    var s = quadric_spans(a, b, c);
    for (var i = 0u; i < s.len; i += 1u) {
        let t0 = s.items[i].t0;
        let t1 = s.items[i].t1;
        if is_finite_t(t0) {
            let q = ray_at(o, d, t0);
            s.items[i].n0 = vec3<f32>(q.x, q.y, -s2 * q.z);
        }
        if is_finite_t(t1) {
            let q = ray_at(o, d, t1);
            s.items[i].n1 = vec3<f32>(q.x, q.y, -s2 * q.z);
        }
    }
    return spans_clip_opt(s, z_slab(start, d, shift, p[2], p[3]));
}

fn hyperboloid_sdf(p: array<f32, 6>, x: vec3<f32>) -> f32 {
    let r0 = p[0];
    let s2 = p[1] * p[1];
    let rho2 = x.x * x.x + x.y * x.y;
    let f = rho2 - r0 * r0 - s2 * x.z * x.z;
    let grad = 2.0 * sqrt(rho2 + s2 * s2 * x.z * x.z);
    var wall = -r0;
    if grad > 0.0 {
        wall = f / grad;
    }
    return max(max(wall, p[2] - x.z), x.z - p[3]);
}

// x^2 + y^2 = k1 z + k2 through radius p[0] at z = -p[2] and p[1] at z = +p[2].
fn paraboloid_coefficients(p: array<f32, 6>) -> vec2<f32> {
    let lo2 = p[0] * p[0];
    let hi2 = p[1] * p[1];
    return vec2<f32>((hi2 - lo2) / (2.0 * p[2]), 0.5 * (hi2 + lo2));
}

// Paraboloid [rlo, rhi, dz], capped at z = -dz and +dz.
fn paraboloid_spans(p: array<f32, 6>, start: vec3<f32>, d: vec3<f32>, shift: f32) -> Spans {
    let o = start + d * shift;
    let k = paraboloid_coefficients(p);
    let k1 = k.x;
    let a = d.x * d.x + d.y * d.y;
    let b = o.x * d.x + o.y * d.y - 0.5 * k1 * d.z;
    let c = o.x * o.x + o.y * o.y - k1 * o.z - k.y;
    var s = quadric_spans(a, b, c);
    for (var i = 0u; i < s.len; i += 1u) {
        let t0 = s.items[i].t0;
        let t1 = s.items[i].t1;
        if is_finite_t(t0) {
            let q = ray_at(o, d, t0);
            s.items[i].n0 = vec3<f32>(q.x, q.y, -0.5 * k1);
        }
        if is_finite_t(t1) {
            let q = ray_at(o, d, t1);
            s.items[i].n1 = vec3<f32>(q.x, q.y, -0.5 * k1);
        }
    }
    return spans_clip_opt(s, z_slab(start, d, shift, -p[2], p[2]));
}

fn paraboloid_sdf(p: array<f32, 6>, x: vec3<f32>) -> f32 {
    let k = paraboloid_coefficients(p);
    let k1 = k.x;
    let rho2 = x.x * x.x + x.y * x.y;
    let f = rho2 - k1 * x.z - k.y;
    let grad = sqrt(2.0 * 2.0 * rho2 + k1 * k1);
    var wall = f;
    if grad > 0.0 {
        wall = f / grad;
    }
    return max(max(wall, -p[2] - x.z), x.z - p[2]);
}

// The gradient of y - kappa x z at x (never zero: its y component is 1).
fn saddle_gradient(k: f32, x: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(-k * x.z, 1.0, -k * x.x);
}

// Saddle [kappa]: the half-space y - kappa x z <= 0, uncapped.
fn saddle_spans(p: array<f32, 6>, o: vec3<f32>, d: vec3<f32>) -> Spans {
    let k = p[0];
    let a = -k * d.x * d.z;
    let b = 0.5 * (d.y - k * (o.x * d.z + o.z * d.x));
    let c = o.y - k * o.x * o.z;
    var s = quadric_spans(a, b, c);
    for (var i = 0u; i < s.len; i += 1u) {
        let t0 = s.items[i].t0;
        let t1 = s.items[i].t1;
        if is_finite_t(t0) {
            s.items[i].n0 = saddle_gradient(k, ray_at(o, d, t0));
        }
        if is_finite_t(t1) {
            s.items[i].n1 = saddle_gradient(k, ray_at(o, d, t1));
        }
    }
    return s;
}

fn saddle_sdf(p: array<f32, 6>, x: vec3<f32>) -> f32 {
    let k = p[0];
    return (x.y - k * x.x * x.z) / v3_length(saddle_gradient(k, x));
}
