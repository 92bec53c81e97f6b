// The twisted half-space [nx, ny, nz, d, w, h]: the points of the slab |z| <= h that, turned
// back about z by the angle w z, lie in the half-space n . q <= d. Twin of
// hytrace_csg::kernel::twisted (twisted_spans, twisted_sdf): see twisted.rs for the
// function f(t) = m(t) . q(t) + nz z(t) - d along the ray and how its crossings are
// isolated (a bound on |f''|, chord and monotonicity tests, bisection, bracketed Newton).
// The bisection keeps its pieces on a fixed-size stack; every expression keeps the CPU's
// operand order. sin and cos are WGSL's, whose last bits may differ from the CPU's.
// #import real
// #import csg/spans
// #import csg/quadric

const TWISTED_MAX_DEPTH: u32 = 40u;
const TWISTED_MAX_NEWTON: u32 = 60u;
const TWISTED_MAX_PIECES: u32 = 256u;

struct TwistedFace {
    n: vec2<f32>,
    nz: f32,
    d: f32,
    w: f32,
    o: vec3<f32>,
    u: vec3<f32>,
}

fn twisted_face(p: array<f32, 6>, o: vec3<f32>, u: vec3<f32>) -> TwistedFace {
    return TwistedFace(vec2<f32>(p[0], p[1]), p[2], p[3], p[4], o, u);
}

// m(z) = R(w z) (nx, ny).
fn twisted_turned(f: TwistedFace, z: f32) -> vec2<f32> {
    let a = f.w * z;
    let c = cos(a);
    let s = sin(a);
    return vec2<f32>(c * f.n.x - s * f.n.y, s * f.n.x + c * f.n.y);
}

fn twisted_value(f: TwistedFace, t: f32) -> f32 {
    let q = ray_at(f.o, f.u, t);
    let m = twisted_turned(f, q.z);
    return m.x * q.x + m.y * q.y + f.nz * q.z - f.d;
}

fn twisted_slope(f: TwistedFace, t: f32) -> f32 {
    let q = ray_at(f.o, f.u, t);
    let m = twisted_turned(f, q.z);
    let omega = f.w * f.u.z;
    return omega * (m.x * q.y - m.y * q.x) + m.x * f.u.x + m.y * f.u.y + f.nz * f.u.z;
}

fn twisted_gradient(f: TwistedFace, t: f32) -> vec3<f32> {
    let q = ray_at(f.o, f.u, t);
    let m = twisted_turned(f, q.z);
    return vec3<f32>(m.x, m.y, f.nz + f.w * (m.x * q.y - m.y * q.x));
}

// The crossing in [a, b], where f is monotonic with opposite signs at the ends.
fn twisted_crossing(f: TwistedFace, a0: f32, b0: f32, fa: f32) -> f32 {
    var a = a0;
    var b = b0;
    let inside_a = fa <= 0.0;
    var t = (a + b) * 0.5;
    for (var i = 0u; i < TWISTED_MAX_NEWTON; i += 1u) {
        let v = twisted_value(f, t);
        if v == 0.0 {
            return t;
        }
        if (v <= 0.0) == inside_a {
            a = t;
        } else {
            b = t;
        }
        let step = t - v / twisted_slope(f, t);
        var next = (a + b) * 0.5;
        if step > a && step < b {
            next = step;
        }
        if next == t || b <= a {
            break;
        }
        t = next;
    }
    return t;
}

struct TwistedPiece {
    a: f32,
    fa: f32,
    b: f32,
    fb: f32,
    depth: u32,
}

fn twisted_crossings(f: TwistedFace, a: f32, b: f32) -> Crossings {
    var out: Crossings;
    out.count = 0u;
    let qa = ray_at(f.o, f.u, a);
    let qb = ray_at(f.o, f.u, b);
    let q_max = sqrt(max(qa.x * qa.x + qa.y * qa.y, qb.x * qb.x + qb.y * qb.y));
    let omega = abs(f.w * f.u.z);
    let n_xy = sqrt(f.n.x * f.n.x + f.n.y * f.n.y);
    let u_xy = sqrt(f.u.x * f.u.x + f.u.y * f.u.y);
    let bound = n_xy * (omega * omega * q_max + 2.0 * omega * u_xy);
    var stack: array<TwistedPiece, 41>;
    stack[0] = TwistedPiece(a, twisted_value(f, a), b, twisted_value(f, b), 0u);
    var len = 1u;
    var pieces = 0u;
    while len > 0u && pieces < TWISTED_MAX_PIECES && out.count < MAX_SPANS {
        len -= 1u;
        pieces += 1u;
        let s = stack[len];
        let length = s.b - s.a;
        let differ = (s.fa <= 0.0) != (s.fb <= 0.0);
        let eighth = bound * length * length * 0.5 * 0.5 * 0.5;
        if !differ && min(abs(s.fa), abs(s.fb)) > eighth {
            continue;
        }
        let mid = (s.a + s.b) * 0.5;
        let monotonic = abs(twisted_slope(f, mid)) > bound * length * 0.5;
        if monotonic || s.depth >= TWISTED_MAX_DEPTH || mid <= s.a || mid >= s.b {
            if differ {
                var t = mid;
                if monotonic {
                    t = twisted_crossing(f, s.a, s.b, s.fa);
                }
                out.t[out.count] = t;
                out.count += 1u;
            }
            continue;
        }
        let fm = twisted_value(f, mid);
        stack[len] = TwistedPiece(mid, fm, s.b, s.fb, s.depth + 1u);
        stack[len + 1u] = TwistedPiece(s.a, s.fa, mid, fm, s.depth + 1u);
        len += 2u;
    }
    return out;
}

// Twisted half-space [nx, ny, nz, d, w, h], from start + shift d (caps met from start).
fn twisted_spans(p: array<f32, 6>, start: vec3<f32>, u: vec3<f32>, shift: f32) -> Spans {
    let slab = slab_span(start.z, u.z, -p[5], p[5], vec3<f32>(0.0, 0.0, 1.0));
    if !slab.ok {
        return spans_empty();
    }
    var window = slab.span;
    window.t0 = window.t0 - shift;
    window.t1 = window.t1 - shift;
    let f = twisted_face(p, start + u * shift, u);
    if u.z == 0.0 {
        let c = twisted_value(f, 0.0);
        let slope = twisted_slope(f, 0.0);
        var s = quadric_spans(0.0, slope * 0.5, c);
        for (var i = 0u; i < s.len; i += 1u) {
            if is_finite_t(s.items[i].t0) {
                s.items[i].n0 = twisted_gradient(f, s.items[i].t0);
            }
            if is_finite_t(s.items[i].t1) {
                s.items[i].n1 = twisted_gradient(f, s.items[i].t1);
            }
        }
        return spans_clip(s, window);
    }
    var c = twisted_crossings(f, window.t0, window.t1);
    for (var i = 0u; i < c.count; i += 1u) {
        c.n[i] = twisted_gradient(f, c.t[i]);
    }
    let inside = twisted_value(f, window.t0) <= 0.0;
    return spans_clip(spans_from_toggles(inside, c), window);
}

fn twisted_sdf(p: array<f32, 6>, x: vec3<f32>) -> f32 {
    let f = twisted_face(p, x, vec3<f32>(0.0));
    let g = v3_length(twisted_gradient(f, 0.0));
    return max(twisted_value(f, 0.0) / g, abs(x.z) - p[5]);
}
