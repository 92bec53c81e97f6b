// Where a ray is inside a primitive: up to four sorted, disjoint parameter intervals, each
// end with the surface normal there (twin of hytrace_csg::kernel::spans), and the first
// crossing of a node after a ray parameter (twin of hytrace_csg::kernel::Step).
//
// WGSL may assume no infinities, so "infinite" parameters are +-INF, a finite value far
// beyond any distance a scene holds; a value is finite when its magnitude is below INF.

const INF: f32 = 1.0e38;
const MAX_SPANS: u32 = 4u;

fn is_finite_t(x: f32) -> bool {
    return abs(x) < INF;
}

struct Span {
    t0: f32,
    t1: f32,
    n0: vec3<f32>,
    n1: vec3<f32>,
}

struct Spans {
    len: u32,
    items: array<Span, 4>,
}

fn span_everywhere() -> Span {
    return Span(-INF, INF, vec3<f32>(0.0), vec3<f32>(0.0));
}

fn spans_empty() -> Spans {
    var s: Spans;
    s.len = 0u;
    return s;
}

fn spans_one(span: Span) -> Spans {
    var s = spans_empty();
    s.items[0] = span;
    s.len = 1u;
    return s;
}

// Appends a span that starts after the last one ends (at most MAX_SPANS are kept).
fn spans_push(s: ptr<function, Spans>, span: Span) {
    if (*s).len < MAX_SPANS {
        (*s).items[(*s).len] = span;
        (*s).len += 1u;
    }
}

// `a` restricted to `w` (the later entry, the earlier exit); not ok when empty. Twin of
// Span::clip.
fn span_clip(a: Span, w: Span) -> MaybeSpan {
    var c = a;
    if w.t0 > a.t0 {
        c.t0 = w.t0;
        c.n0 = w.n0;
    }
    if w.t1 < a.t1 {
        c.t1 = w.t1;
        c.n1 = w.n1;
    }
    return MaybeSpan(c.t0 <= c.t1, c);
}

// Every span restricted to `w`, empty ones dropped.
fn spans_clip(s: Spans, w: Span) -> Spans {
    var out = spans_empty();
    for (var i = 0u; i < s.len; i += 1u) {
        let c = span_clip(s.items[i], w);
        if c.ok {
            spans_push(&out, c.span);
        }
    }
    return out;
}

// The parts of `s` outside every span of `hole`.
fn spans_subtract(s: Spans, hole: Spans) -> Spans {
    var out = spans_empty();
    for (var i = 0u; i < s.len; i += 1u) {
        var r = s.items[i];
        var has_rest = true;
        for (var j = 0u; j < hole.len && has_rest; j += 1u) {
            let h = hole.items[j];
            // A zero-length hole (a tangent ray) removes nothing (see the CPU twin).
            if h.t1 <= h.t0 || h.t1 <= r.t0 || h.t0 >= r.t1 {
                continue;
            }
            if h.t0 > r.t0 {
                spans_push(&out, Span(r.t0, h.t0, r.n0, h.n0));
            }
            if h.t1 < r.t1 {
                r = Span(h.t1, r.t1, h.n1, r.n1);
            } else {
                has_rest = false;
            }
        }
        if has_rest {
            spans_push(&out, r);
        }
    }
    return out;
}

// Up to four sorted surface crossings of a region (parameters and normals).
struct Crossings {
    count: u32,
    t: array<f32, 4>,
    n: array<vec3<f32>, 4>,
}

// Spans from sorted crossings, given whether the ray is inside as t -> -inf: the inside
// state toggles at every crossing.
fn spans_from_toggles(inside_at_start: bool, c: Crossings) -> Spans {
    var out = spans_empty();
    var inside = inside_at_start;
    var start_t = -INF;
    var start_n = vec3<f32>(0.0);
    for (var i = 0u; i < c.count; i += 1u) {
        if inside {
            spans_push(&out, Span(start_t, c.t[i], start_n, c.n[i]));
        } else {
            start_t = c.t[i];
            start_n = c.n[i];
        }
        inside = !inside;
    }
    if inside {
        spans_push(&out, Span(start_t, INF, start_n, vec3<f32>(0.0)));
    }
    return out;
}

// The first crossing of a node after a ray parameter, or a miss (t = INF).
struct Step {
    t: f32,
    // Outward normal of the node's region at the crossing (not normalized).
    normal: vec3<f32>,
    // Whether the ray is inside the node's region just before t (for a miss: all along).
    inside_before: bool,
}

// The least start of a span that `first_crossing_of_spans` skipped as a touch or a contact
// although it ended past the search's start, since the caller last set it to INF: the twin of
// hytrace_csg::kernel::Step::dropped, which the CPU carries in its steps (here one value
// per invocation, read by the scan kernel after each prim's first crossing).
var<private> dropped_span: f32 = INF;

fn step_miss(inside: bool) -> Step {
    return Step(INF, vec3<f32>(0.0), inside);
}

fn step_is_hit(s: Step) -> bool {
    return s.t < INF;
}

fn step_complemented(s: Step) -> Step {
    return Step(s.t, -s.normal, !s.inside_before);
}

// The first span end after tmin + tol among `spans` shifted by `shift`, skipping spans no
// longer than `touch` (tangent touches) and those whose bit is set in `contacts` (see
// csg_contact_spans). Normals face against the ray at entries, along it at exits.
fn first_crossing_of_spans(spans: Spans, shift: f32, d: vec3<f32>, tmin: f32, tol: f32, touch: f32, contacts: u32) -> Step {
    let after = tmin + tol;
    for (var i = 0u; i < spans.len; i += 1u) {
        let s = spans.items[i];
        if s.t1 - s.t0 <= touch || (contacts & (1u << i)) != 0u {
            // (Spans of empty parts sit at INF, where the CPU's infinite ones never pass.)
            if s.t1 + shift > after && s.t0 < INF {
                dropped_span = min(dropped_span, s.t0 + shift);
            }
            continue;
        }
        let t0 = s.t0 + shift;
        let t1 = s.t1 + shift;
        if t0 > after {
            var n = s.n0;
            if dot(s.n0, d) > 0.0 {
                n = -s.n0;
            }
            return Step(t0, n, false);
        }
        if t1 > after {
            var n = s.n1;
            if dot(s.n1, d) < 0.0 {
                n = -s.n1;
            }
            return Step(t1, n, true);
        }
    }
    return step_miss(false);
}

// The span where lo <= o + t d <= hi along one axis (normals -axis at lo, +axis at hi);
// the whole line when d = 0 and o lies between; `ok` false when there is none.
struct MaybeSpan {
    ok: bool,
    span: Span,
}

fn slab_span(o: f32, d: f32, lo: f32, hi: f32, axis: vec3<f32>) -> MaybeSpan {
    if d == 0.0 {
        return MaybeSpan(lo <= o && o <= hi, span_everywhere());
    }
    let ta = (lo - o) / d;
    let tb = (hi - o) / d;
    if d > 0.0 {
        return MaybeSpan(true, Span(ta, tb, -axis, axis));
    }
    return MaybeSpan(true, Span(tb, ta, axis, -axis));
}
