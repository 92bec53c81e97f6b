// Primitives bounded by planes: box, convex polyhedron (planes from csg_planes), half-space
// and slab. Twin of hytrace_csg::kernel::planar.
// #import real
// #import csg/spans
// #import csg/quadric
// #import csg/planes

// The span of the ray on the inner side (dot(n, x) <= dist) of one plane.
fn plane_span(o: vec3<f32>, d: vec3<f32>, n: vec3<f32>, dist: f32) -> MaybeSpan {
    let on = v3_dot(n, o);
    let dn = v3_dot(n, d);
    if dn == 0.0 {
        return MaybeSpan(on <= dist, span_everywhere());
    }
    let t = (dist - on) / dn;
    let z = vec3<f32>(0.0);
    if dn > 0.0 {
        return MaybeSpan(true, Span(-INF, t, z, n));
    }
    return MaybeSpan(true, Span(t, INF, n, z));
}

// Box [sx, sy, sz] (full side lengths) centred on the origin.
fn box_spans(p: array<f32, 6>, o: vec3<f32>, d: vec3<f32>) -> Spans {
    var span = span_everywhere();
    for (var k = 0u; k < 3u; k += 1u) {
        var axis = vec3<f32>(0.0);
        axis[k] = 1.0;
        var size = p[0];
        if k == 1u {
            size = p[1];
        } else if k == 2u {
            size = p[2];
        }
        let h = 0.5 * size;
        let s = slab_span(o[k], d[k], -h, h, axis);
        if !s.ok {
            return spans_empty();
        }
        let c = span_clip(span, s.span);
        if !c.ok {
            return spans_empty();
        }
        span = c.span;
    }
    return spans_one(span);
}

fn box_sdf(p: array<f32, 6>, x: vec3<f32>) -> f32 {
    let q = vec3<f32>(abs(x.x) - 0.5 * p[0], abs(x.y) - 0.5 * p[1], abs(x.z) - 0.5 * p[2]);
    let outside = v3_length(max(q, vec3<f32>(0.0)));
    return min(max(max(q.x, q.y), q.z), 0.0) + outside;
}

// Convex polyhedron: the intersection of the inner sides of planes
// csg_planes[first .. first + count].
fn polyhedron_spans(first: u32, count: u32, o: vec3<f32>, d: vec3<f32>) -> Spans {
    var span = span_everywhere();
    for (var i = first; i < first + count; i += 1u) {
        let pl = csg_plane(i);
        let s = plane_span(o, d, pl.xyz, pl.w);
        if !s.ok {
            return spans_empty();
        }
        let c = span_clip(span, s.span);
        if !c.ok {
            return spans_empty();
        }
        span = c.span;
    }
    return spans_one(span);
}

// The largest plane distance (a bound with the exact sign).
fn polyhedron_sdf(first: u32, count: u32, x: vec3<f32>) -> f32 {
    var sdf = -INF;
    for (var i = first; i < first + count; i += 1u) {
        let pl = csg_plane(i);
        sdf = max(sdf, v3_dot(pl.xyz, x) - pl.w);
    }
    return sdf;
}

// Half-space [nx, ny, nz, d]: dot(n, x) <= d.
fn halfspace_spans(p: array<f32, 6>, o: vec3<f32>, d: vec3<f32>) -> Spans {
    let s = plane_span(o, d, vec3<f32>(p[0], p[1], p[2]), p[3]);
    if !s.ok {
        return spans_empty();
    }
    return spans_one(s.span);
}

fn halfspace_sdf(p: array<f32, 6>, x: vec3<f32>) -> f32 {
    return v3_dot(vec3<f32>(p[0], p[1], p[2]), x) - p[3];
}

// Slab [nx, ny, nz, -], [a, b]: a <= dot(n, x) <= b.
fn slab_spans(p: array<f32, 6>, o: vec3<f32>, d: vec3<f32>) -> Spans {
    let n = vec3<f32>(p[0], p[1], p[2]);
    let s = slab_span(v3_dot(n, o), v3_dot(n, d), p[4], p[5], n);
    if !s.ok {
        return spans_empty();
    }
    return spans_one(s.span);
}

fn slab_sdf(p: array<f32, 6>, x: vec3<f32>) -> f32 {
    let s = v3_dot(vec3<f32>(p[0], p[1], p[2]), x);
    return max(p[4] - s, s - p[5]);
}
