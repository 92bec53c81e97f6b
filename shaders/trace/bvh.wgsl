// Slab tests and the walk of the tracers' box BVHs (twins of hytrace_csg::{ray_bounds_span,
// SlabRay} and of the CPU's BoxBvh::visit_ray / candidates_at in crates/trace/src/cpu/bvh.rs).
//
// visit_ray calls a visitor on each item; WGSL has no closures, so the walk is an iterator:
// `bvh_next` returns the next item the CPU would visit given the limit the visitor has set
// so far (the nearest crossing found), and the caller tests the item and moves the limit.
// #import generated/foundry
// #import csg/spans
// #import trace/bindings

// Deepest BVH the CPU accepts (MAX_DEPTH in bvh.rs) plus the node being expanded and one.
const BVH_STACK: u32 = BOX_BVH_MAX_DEPTH + 2u;

struct MaybeT {
    ok: bool,
    t: f32,
}

// The part [t0, t1] of [tmin, tmax] in which the ray is inside the box (exact for zero
// direction components); `ok` false if none.
struct MaybeRange {
    ok: bool,
    t0: f32,
    t1: f32,
}

fn ray_bounds_span(o: vec3<f32>, d: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>, tmin: f32, tmax: f32) -> MaybeRange {
    var a = tmin;
    var b = tmax;
    for (var k = 0u; k < 3u; k += 1u) {
        if d[k] == 0.0 {
            if o[k] < lo[k] || o[k] > hi[k] {
                return MaybeRange(false, a, b);
            }
            continue;
        }
        let ta = (lo[k] - o[k]) / d[k];
        let tb = (hi[k] - o[k]) / d[k];
        a = max(a, min(ta, tb));
        b = min(b, max(ta, tb));
    }
    return MaybeRange(a <= b, a, b);
}

fn ray_bounds_entry(o: vec3<f32>, d: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>, tmin: f32, tmax: f32) -> MaybeT {
    let r = ray_bounds_span(o, d, lo, hi, tmin, tmax);
    return MaybeT(r.ok, r.t0);
}

// A ray set up for many box tests: by the reciprocal direction unless a component has
// none (zero or subnormal), which takes the exact dividing test.
struct SlabRay {
    o: vec3<f32>,
    d: vec3<f32>,
    inv: vec3<f32>,
    exact: bool,
}

fn slab_ray(o: vec3<f32>, d: vec3<f32>) -> SlabRay {
    // 1.1754944e-38 is the least normal f32: every normal component has a finite reciprocal.
    let exact = any(abs(d) < vec3<f32>(1.1754944e-38));
    var inv = vec3<f32>(0.0);
    if !exact {
        inv = vec3<f32>(1.0) / d;
    }
    return SlabRay(o, d, inv, exact);
}

// The entry into the box within [after, limit] by the reciprocal, with the slab bounds
// widened by four machine epsilons of their size: a superset of the exact test.
fn slab_entry_conservative(r: SlabRay, lo: vec3<f32>, hi: vec3<f32>, after: f32, limit: f32) -> MaybeT {
    if r.exact {
        return ray_bounds_entry(r.o, r.d, lo, hi, after, limit);
    }
    let t0 = (lo - r.o) * r.inv;
    let t1 = (hi - r.o) * r.inv;
    let near = min(t0, t1);
    let far = max(t0, t1);
    var a = max(near.x, max(near.y, near.z));
    var b = min(far.x, min(far.y, far.z));
    let widen = 4.0 * 1.1920929e-7;
    a = a - widen * abs(a);
    b = b + widen * abs(b);
    if after > a {
        a = after;
    }
    if limit < b {
        b = limit;
    }
    return MaybeT(a <= b, a);
}

fn node_lo(n: BoxNode) -> vec3<f32> {
    return vec3<f32>(n.lo[0], n.lo[1], n.lo[2]);
}

fn node_hi(n: BoxNode) -> vec3<f32> {
    return vec3<f32>(n.hi[0], n.hi[1], n.hi[2]);
}

// The state of one ray walk over a search list: its members in order (no BVH), or the
// items of its BVH.
struct BvhWalk {
    // No BVH: the members are returned as positions 0..count in order.
    linear: bool,
    nodes: array<u32, BVH_STACK>,
    entries: array<f32, BVH_STACK>,
    len: u32,
    // Item-list positions still to visit: the unbounded items, then the current leaf's.
    next: u32,
    end: u32,
    root: u32,
    root_pending: bool,
}

fn bvh_walk(list: SearchList) -> BvhWalk {
    var w: BvhWalk;
    w.linear = list.has_bvh == 0u;
    w.len = 0u;
    if w.linear {
        w.next = 0u;
        w.end = list.count;
        w.root_pending = false;
    } else {
        w.next = list.unbounded_first;
        w.end = list.unbounded_first + list.unbounded_count;
        w.root = list.root;
        w.root_pending = true;
    }
    return w;
}

fn bvh_push(w: ptr<function, BvhWalk>, node: u32, t: f32) {
    (*w).nodes[(*w).len] = node;
    (*w).entries[(*w).len] = t;
    (*w).len += 1u;
}

// The next member of a list without a BVH (its position), or the next item whose node
// boxes the ray meets within [tmin, limit], nearer nodes first (boxes met exactly at the
// limit are still visited); UNSET when there is none.
fn bvh_next(w: ptr<function, BvhWalk>, r: SlabRay, tmin: f32, limit: f32) -> u32 {
    if (*w).linear {
        if (*w).next < (*w).end {
            (*w).next += 1u;
            return (*w).next - 1u;
        }
        return UNSET;
    }
    loop {
        if (*w).next < (*w).end {
            let item = box_item((*w).next);
            (*w).next += 1u;
            return item;
        }
        if (*w).root_pending {
            (*w).root_pending = false;
            if (*w).root != UNSET {
                let root = box_node((*w).root);
                let e = slab_entry_conservative(r, node_lo(root), node_hi(root), tmin, limit);
                if e.ok {
                    bvh_push(w, (*w).root, e.t);
                }
            }
            continue;
        }
        if (*w).len == 0u {
            return UNSET;
        }
        (*w).len -= 1u;
        let index = (*w).nodes[(*w).len];
        if (*w).entries[(*w).len] > limit {
            continue;
        }
        let node = box_node(index);
        if node.count > 0u {
            (*w).next = node.first;
            (*w).end = node.first + node.count;
            continue;
        }
        let a = box_node(node.first);
        let b = box_node(node.first + 1u);
        let ta = slab_entry_conservative(r, node_lo(a), node_hi(a), tmin, limit);
        let tb = slab_entry_conservative(r, node_lo(b), node_hi(b), tmin, limit);
        // Farther child pushed first, so the nearer one is walked first.
        if ta.ok && tb.ok {
            if ta.t <= tb.t {
                bvh_push(w, node.first + 1u, tb.t);
                bvh_push(w, node.first, ta.t);
            } else {
                bvh_push(w, node.first, ta.t);
                bvh_push(w, node.first + 1u, tb.t);
            }
        } else if ta.ok {
            bvh_push(w, node.first, ta.t);
        } else if tb.ok {
            bvh_push(w, node.first + 1u, tb.t);
        }
    }
    // Not reached (the loop only returns); naga wants a return on every path.
    return UNSET;
}

fn holds(lo: vec3<f32>, hi: vec3<f32>, x: vec3<f32>) -> bool {
    return all(x >= lo) && all(x <= hi);
}

// Whether the box lo..hi widened by `margin` holds x (bvh::holds_within).
fn holds_within(lo: vec3<f32>, hi: vec3<f32>, x: vec3<f32>, margin: f32) -> bool {
    return all(x >= lo - vec3<f32>(margin)) && all(x <= hi + vec3<f32>(margin));
}

// The state of one point query over a search list: its members last first (no BVH, as
// positions), or every item whose node boxes, widened by the query's margin, contain the
// point (a superset of those whose own boxes do), in no particular order.
struct PointWalk {
    linear: bool,
    nodes: array<u32, BVH_STACK>,
    len: u32,
    next: u32,
    end: u32,
}

fn point_walk(list: SearchList) -> PointWalk {
    var w: PointWalk;
    w.linear = list.has_bvh == 0u;
    w.len = 0u;
    if w.linear {
        // Counts down: `end` is the number of members not yet returned.
        w.next = 0u;
        w.end = list.count;
        return w;
    }
    w.next = list.unbounded_first;
    w.end = list.unbounded_first + list.unbounded_count;
    if list.root != UNSET {
        w.nodes[0] = list.root;
        w.len = 1u;
    }
    return w;
}

fn point_next(w: ptr<function, PointWalk>, x: vec3<f32>, margin: f32) -> u32 {
    if (*w).linear {
        if (*w).end > 0u {
            (*w).end -= 1u;
            return (*w).end;
        }
        return UNSET;
    }
    loop {
        if (*w).next < (*w).end {
            let item = box_item((*w).next);
            (*w).next += 1u;
            return item;
        }
        if (*w).len == 0u {
            return UNSET;
        }
        (*w).len -= 1u;
        let node = box_node((*w).nodes[(*w).len]);
        if !holds_within(node_lo(node), node_hi(node), x, margin) {
            continue;
        }
        if node.count > 0u {
            (*w).next = node.first;
            (*w).end = node.first + node.count;
        } else {
            (*w).nodes[(*w).len] = node.first;
            (*w).nodes[(*w).len + 1u] = node.first + 1u;
            (*w).len += 2u;
        }
    }
    // Not reached (the loop only returns); naga wants a return on every path.
    return UNSET;
}
