// Prepared CSG trees: the first crossing of a tree's surface after a ray parameter, signed
// distances and inside tests. Twin of hytrace_csg::PrimTree::<f32> (crates/csg/src/
// prim_tree.rs: first_crossing with its operator-frame stack and `decide` state table,
// list_step, sdf, contains with seam and inside_by_probes) and of Leaf::step / Leaf::sdf
// (crates/csg/src/kernel/mod.rs), operation by operation. The CPU's recursive `seam` is the
// same postorder walk as `sdf` here, done in one pass with it.
// #import generated/foundry
// #import real
// #import csg/spans
// #import csg/primitive
// #import csg/tree_bindings
// #import csg/frame


// Tolerance for crossings near ray parameter t in a tree of size `scale`.
fn csg_tolerance(scale: f32, t: f32) -> f32 {
    return SURFACE_TOLERANCE * (scale + abs(t));
}

fn csg_is_operator(code: u32) -> bool {
    return code >= CSG_UNION && code <= CSG_DIFFERENCE;
}

fn csg_is_list(code: u32) -> bool {
    return code >= CSG_LIST_CONTIGUOUS && code <= CSG_LIST_OVERLAP;
}

// Twin of hytrace_csg::kernel::is_planar (over the primitives a composition has).
fn csg_is_planar(code: u32) -> bool {
    var planar = false;
    // #if box
    planar = planar || code == CSG_BOX3;
    // #endif
    // #if polyhedron
    planar = planar || code == CSG_CONVEX_POLYHEDRON;
    // #endif
    // #if halfspace
    planar = planar || code == CSG_HALFSPACE;
    // #endif
    // #if slab
    planar = planar || code == CSG_SLAB;
    // #endif
    // #if phicut
    planar = planar || code == CSG_PHICUT;
    // #endif
    return planar;
}

// Twin of hytrace_csg::kernel::origin_shift: to the closest approach to the leaf's centre,
// 0 for a ray starting beside the wall of a cylinder or tube (or with a zero direction).
fn csg_origin_shift(code: u32, p: array<f32, 6>, o: vec3<f32>, d: vec3<f32>) -> f32 {
    var walled = false;
    // #if cylinder
    walled = walled || code == CSG_CYLINDER;
    // #endif
    // #if tube
    walled = walled || code == CSG_DISC;
    // #endif
    if walled {
        let x = o.x - p[0];
        let y = o.y - p[1];
        let beside = x * x + y * y <= 4.0 * p[3] * p[3];
        if beside && o.z >= p[4] && o.z <= p[5] {
            return 0.0;
        }
        // Along the axis (d2 = 0) the CPU's quotient is NaN and fails the comparison.
        let across = x * d.x + y * d.y;
        let d2 = d.x * d.x + d.y * d.y;
        if d2 != 0.0 {
            let s = -across / d2;
            let c = o - csg_leaf_centre(code, p);
            if s * s * v3_dot(d, d) <= v3_dot(c, c) {
                return s;
            }
        }
    }
    let len2 = v3_dot(d, d);
    if len2 == 0.0 {
        return 0.0;
    }
    let shift = -v3_dot(o - csg_leaf_centre(code, p), d) / len2;
    if !is_finite_t(shift) {
        return 0.0;
    }
    return shift;
}

// Twin of hytrace_csg::kernel::centre: the middle of the axis of a cone frustum, cylinder or
// tube, else the origin.
fn csg_leaf_centre(code: u32, p: array<f32, 6>) -> vec3<f32> {
    // #if cone
    if code == CSG_CONE {
        return vec3<f32>(0.0, 0.0, (p[1] + p[3]) * 0.5);
    }
    // #endif
    // #if cylinder
    if code == CSG_CYLINDER {
        return vec3<f32>(p[0], p[1], (p[4] + p[5]) * 0.5);
    }
    // #endif
    // #if tube
    if code == CSG_DISC {
        return vec3<f32>(p[0], p[1], (p[4] + p[5]) * 0.5);
    }
    // #endif
    return vec3<f32>(0.0);
}

fn csg_node_params(n: CsgNode) -> array<f32, 6> {
    return array<f32, 6>(n.param.x, n.param.y, n.param.z, n.param.w, n.param_ext[0], n.param_ext[1]);
}

// Twin of hytrace_csg::kernel::contacts_outside: whether a ray along the surface of the leaf
// at `position` is outside the tree (no union above it, subtracted an even number of times,
// its complement included).
fn csg_contacts_outside(node_offset: u32, position: u32, complement: bool) -> bool {
    var p = position;
    var subtracted = complement;
    loop {
        if p <= 1u {
            break;
        }
        let code = csg_node(node_offset + p / 2u - 1u).code;
        if code == CSG_UNION {
            return false;
        }
        if code == CSG_DIFFERENCE && p % 2u == 1u {
            subtracted = !subtracted;
        }
        p = p / 2u;
    }
    return !subtracted;
}

// Twin of hytrace_csg::kernel::contact_spans: a bit per span of the ray o + t d (in the
// leaf's frame, o shifted) whose points at a quarter, half and three quarters of its length
// are within tol of the surface; asked only for rays with a zero direction component, not
// along the axis of a phi cut, not for saddles and twisted half-spaces.
fn csg_contact_spans(n: CsgNode, spans: Spans, o: vec3<f32>, d: vec3<f32>, tol: f32) -> u32 {
    if d.x != 0.0 && d.y != 0.0 && d.z != 0.0 {
        return 0u;
    }
    // Not along the axis of a phi cut, where Geant4's solids disagree (kernel::on_phi_axis).
    // #if phicut
    if (n.code & ~COMPLEMENT_BIT) == CSG_PHICUT && o.x == 0.0 && o.y == 0.0 && d.x == 0.0 && d.y == 0.0 {
        return 0u;
    }
    // #endif
    // None for saddles and twisted half-spaces (see kernel::contact_spans).
    let code = n.code & ~COMPLEMENT_BIT;
    if code == CSG_SADDLE || code == CSG_TWISTED_HALFSPACE {
        return 0u;
    }
    var contacts = 0u;
    for (var i = 0u; i < spans.len; i += 1u) {
        let s = spans.items[i];
        // An infinite end replaced by one as far from the other end as that is from the
        // closest approach to the centre (at least a unit), both by the unit around it.
        var t0 = s.t0;
        var t1 = s.t1;
        if !is_finite_t(t0) && !is_finite_t(t1) {
            t0 = -0.5;
            t1 = 0.5;
        } else if !is_finite_t(t1) {
            t1 = t0 + max(abs(t0), 1.0);
        } else if !is_finite_t(t0) {
            t0 = t1 - max(abs(t1), 1.0);
        }
        let length = t1 - t0;
        var on_surface = true;
        for (var k = 1u; k <= 3u; k += 1u) {
            let x = o + d * (t0 + length * (0.25 * f32(k)));
            let v = primitive_sdf(n.code & ~COMPLEMENT_BIT, csg_node_params(n), n.first, n.count, x);
            on_surface = on_surface && abs(v) <= tol;
        }
        contacts |= select(0u, 1u, on_surface) << i;
    }
    return contacts;
}

// The first crossing of a leaf's surface by the ray o + t d (in the tree's frame) after
// tmin + tol; normal in the tree's frame.
// `position`: the leaf's position in the tree whose nodes start at `node_offset`, or 0 for a
// list member (whose contacts are never outside).
fn csg_leaf_step(n: CsgNode, o: vec3<f32>, d: vec3<f32>, tmin: f32, tol: f32, alone: bool, node_offset: u32, position: u32) -> Step {
    var lo = o;
    var ld = d;
    if n.frame != UNSET {
        let f = csg_frame(n.frame);
        lo = frame_point_to_local(f, o);
        ld = frame_linear(f, d);
    }
    let shift = csg_origin_shift(n.code & ~COMPLEMENT_BIT, csg_node_params(n), lo, ld);
    let spans = primitive_spans(n.code & ~COMPLEMENT_BIT, csg_node_params(n), n.first, n.count, lo, ld, shift);
    // Short spans of curved primitives and of leaves sharing faces are touches; a planar
    // leaf alone skips spans within a few ulps of the solid's size of empty only.
    var touch = tol;
    if alone && csg_is_planar(n.code & ~COMPLEMENT_BIT) {
        touch = tol / 4.0;
    }
    // Contact spans are skipped where a ray along the leaf's surface is outside the tree
    // (asked of the tree only when there are some).
    var contacts = 0u;
    if position != 0u {
        contacts = csg_contact_spans(n, spans, lo + ld * shift, ld, tol);
        if contacts != 0u && !csg_contacts_outside(node_offset, position, (n.code & COMPLEMENT_BIT) != 0u) {
            contacts = 0u;
        }
    }
    var step = first_crossing_of_spans(spans, shift, ld, tmin, tol, touch, contacts);
    if n.frame != UNSET {
        step.normal = frame_normal_to_parent(csg_frame(n.frame), step.normal);
    }
    if (n.code & COMPLEMENT_BIT) != 0u {
        step = step_complemented(step);
    }
    return step;
}

// Signed distance bound of a leaf at a point of the tree's frame (negative inside).
fn csg_leaf_sdf(n: CsgNode, x: vec3<f32>) -> f32 {
    var local = x;
    if n.frame != UNSET {
        local = frame_point_to_local(csg_frame(n.frame), x);
    }
    let s = primitive_sdf(n.code & ~COMPLEMENT_BIT, csg_node_params(n), n.first, n.count, local);
    if (n.code & COMPLEMENT_BIT) != 0u {
        return -s;
    }
    return s;
}

// A ray with its origin moved by +pad (up) and -pad (down), for slab tests against boxes
// widened by pad on every side.
struct CsgWidenedRay {
    up: vec3<f32>,
    down: vec3<f32>,
    d: vec3<f32>,
}

// Whether the widened ray meets box b = [min, max] at some parameter in [tmin, tmax].
fn csg_meets_widened(w: CsgWidenedRay, b: array<f32, 6>, tmin: f32, tmax: f32) -> bool {
    var bb = b;
    var lo = tmin;
    var hi = tmax;
    for (var k = 0u; k < 3u; k += 1u) {
        let d = w.d[k];
        let a = bb[k];
        let c = bb[k + 3u];
        if d == 0.0 {
            if w.up[k] < a || w.down[k] > c {
                return false;
            }
            continue;
        }
        let ta = (a - w.up[k]) / d;
        let tb = (c - w.down[k]) / d;
        lo = max(lo, min(ta, tb));
        hi = min(hi, max(ta, tb));
    }
    return lo <= hi;
}

fn csg_list_inside(code: u32, count: u32, all: u32) -> bool {
    if code == CSG_LIST_OVERLAP {
        return count == all;
    }
    return count > 0u;
}

// The first crossing of the non-operator slot n. A list slot walks its members' crossings
// in order, counting the members the ray is inside, until the count crosses the list's
// threshold (PrimTree::list_step; members whose widened bounds the ray misses are skipped).
// A leaf slot is the same walk over the leaf alone without culling, which returns the
// leaf's own step (PrimTree::non_operator_step): so the primitive kernels are inlined once.
// The slot is the one at `position` of the tree whose nodes start at `node_offset` (at the
// root, position 1, a leaf is the whole prim).
fn csg_slot_step(scale: f32, node_offset: u32, position: u32, o: vec3<f32>, d: vec3<f32>, tmin: f32) -> Step {
    let slot = node_offset + position - 1u;
    let root = position == 1u;
    let n = csg_node(slot);
    if n.code == CSG_ZERO {
        return step_miss(false);
    }
    let list = csg_is_list(n.code);
    var first = slot;
    var all = 1u;
    var w = CsgWidenedRay(o, o, d);
    if list {
        first = n.first;
        all = n.count;
        let lo = vec3<f32>(n.bounds[0], n.bounds[1], n.bounds[2]);
        let hi = vec3<f32>(n.bounds[3], n.bounds[4], n.bounds[5]);
        let reach = max(v3_max_abs(o - lo), v3_max_abs(o - hi));
        let pad = vec3<f32>(csg_tolerance(scale, abs(tmin) + reach));
        w = CsgWidenedRay(o + pad, o - pad, d);
        if !csg_meets_widened(w, n.bounds, tmin, INF) {
            return step_miss(false);
        }
    }
    var tau = tmin;
    var result = step_miss(false);
    loop {
        var best = INF;
        // The last of the crossings merged with the first (`best`).
        var last = INF;
        var count = 0u;
        var entries = 0u;
        var exits = 0u;
        var entry_normal = vec3<f32>(0.0);
        var exit_normal = vec3<f32>(0.0);
        for (var m = first; m < first + all; m += 1u) {
            let member = csg_node(m);
            if list && !csg_meets_widened(w, member.bounds, tau, INF) {
                continue;
            }
            let s = csg_leaf_step(member, o, d, tau, csg_tolerance(scale, tau), root && !list, node_offset, select(position, 0u, list));
            count += select(0u, 1u, s.inside_before);
            if !step_is_hit(s) {
                continue;
            }
            let tol = csg_tolerance(scale, s.t);
            if s.t < best - tol {
                best = s.t;
                last = s.t;
                entries = 0u;
                exits = 0u;
            } else if s.t > best + tol {
                continue;
            }
            best = min(best, s.t);
            last = max(last, s.t);
            if s.inside_before {
                exits += 1u;
                exit_normal = s.normal;
            } else {
                entries += 1u;
                entry_normal = s.normal;
            }
        }
        let before = csg_list_inside(n.code, count, all);
        if best == INF {
            result = step_miss(before);
            break;
        }
        let after = csg_list_inside(n.code, count + entries - exits, all);
        // Entries and exits merged with the result unchanged, at different points or where
        // surfaces meet at an angle: a chord or a gap between members may lie between them
        // (list_step's, noted).
        let apart = last != best || csg_meet_at_an_angle(entry_normal, exit_normal);
        if entries > 0u && exits > 0u && apart && before == after {
            dropped_span = min(dropped_span, best);
        }
        if before != after {
            result = Step(best, select(exit_normal, entry_normal, after), before);
            break;
        }
        tau = best;
    }
    return result;
}

// Twin of prim_tree's meet_at_an_angle: surfaces crossed at one point with normals a and b
// meet there at an angle (sine over 1e-3).
fn csg_meet_at_an_angle(a: vec3<f32>, b: vec3<f32>) -> bool {
    let c = v3_cross(a, b);
    return v3_dot(c, c) > 1e-6 * v3_dot(a, a) * v3_dot(b, b);
}

fn csg_operator_inside(code: u32, a: bool, b: bool) -> bool {
    if code == CSG_UNION || code == CSG_LIST_CONTIGUOUS || code == CSG_LIST_DISCONTIGUOUS {
        return a || b;
    }
    if code == CSG_INTERSECTION || code == CSG_LIST_OVERLAP {
        return a && b;
    }
    return a && !b;
}

// What an operator does with its children's next crossings: `done` with its crossing (or
// miss), or query again the children that cross first.
struct CsgDecision {
    done: bool,
    step: Step,
    again_left: bool,
    again_right: bool,
}

// The state table of a binary operator.
fn csg_decide(code: u32, a: Step, b: Step, scale: f32) -> CsgDecision {
    let t = min(a.t, b.t);
    let before = csg_operator_inside(code, a.inside_before, b.inside_before);
    if !is_finite_t(t) {
        return CsgDecision(true, step_miss(before), false, false);
    }
    let tol = csg_tolerance(scale, t);
    let cross_a = a.t <= t + tol;
    let cross_b = b.t <= t + tol;
    let a_after = a.inside_before != cross_a;
    let b_after = b.inside_before != cross_b;
    if csg_operator_inside(code, a_after, b_after) == before {
        // A chord through an edge where the children meet (or a gap between them) dropped
        // (decide's sliver): noted in `dropped_span`; where their surfaces meet at an
        // angle, in either order.
        let a_first = csg_operator_inside(code, a_after, b.inside_before) != before;
        let b_first = csg_operator_inside(code, a.inside_before, b_after) != before;
        var sliver = false;
        if cross_a && cross_b {
            if csg_meet_at_an_angle(a.normal, b.normal) {
                sliver = a_first || b_first;
            } else if a.t < b.t {
                sliver = a_first;
            } else {
                sliver = a.t > b.t && b_first;
            }
        }
        if sliver {
            dropped_span = min(dropped_span, t);
        }
        return CsgDecision(false, step_miss(false), cross_a, cross_b);
    }
    // The crossing child that changes the result on its own gives the surface.
    let use_a = cross_a && (!cross_b || csg_operator_inside(code, a_after, b.inside_before) != before);
    if use_a {
        return CsgDecision(true, Step(a.t, a.normal, before), false, false);
    }
    var normal = b.normal;
    if code == CSG_DIFFERENCE {
        normal = -b.normal;
    }
    return CsgDecision(true, Step(b.t, normal, before), false, false);
}

// Which child an operator frame waits for.
const CSG_PHASE_FIRST_LEFT: u32 = 0u;
const CSG_PHASE_FIRST_RIGHT: u32 = 1u;
const CSG_PHASE_AGAIN_LEFT: u32 = 2u;
const CSG_PHASE_AGAIN_LEFT_THEN_RIGHT: u32 = 3u;
const CSG_PHASE_AGAIN_RIGHT: u32 = 4u;
const CSG_PHASE_DECIDE: u32 = 5u;

// The evaluation state of one operator node.
struct CsgOperatorFrame {
    position: u32,
    tmin: f32,
    left: Step,
    right: Step,
    phase: u32,
}

// The first crossing of tree `tree`'s surface by the ray o + t d (in the solid's frame)
// after tmin, with the outward normal in the solid's frame (not normalized) and whether the
// ray is inside before. Slots are queried at one place (the pending query), so the
// primitive kernels are inlined once per kind of slot.
fn csg_tree_first_crossing(tree: u32, o: vec3<f32>, d: vec3<f32>, tmin: f32) -> Step {
    let tr = csg_tree(tree);
    var stack: array<CsgOperatorFrame, MAX_TREE_HEIGHT + 1u>;
    var depth = 0u;
    // The slot to query next (the root first) and after which parameter.
    var query = 1u;
    var query_tmin = tmin;
    var has_query = true;
    // The last answer, of a slot or operator, for the frame on top (the result at depth 0).
    var incoming = step_miss(false);
    var has_incoming = false;
    loop {
        if has_query {
            has_query = false;
            let n = csg_node(tr.node_offset + query - 1u);
            if csg_is_operator(n.code) {
                stack[depth] = CsgOperatorFrame(query, query_tmin, step_miss(false), step_miss(false), CSG_PHASE_FIRST_LEFT);
                depth += 1u;
            } else {
                incoming = csg_slot_step(tr.scale, tr.node_offset, query, o, d, query_tmin);
                has_incoming = true;
                if depth == 0u {
                    break;
                }
            }
            continue;
        }
        let top = depth - 1u;
        if has_incoming {
            has_incoming = false;
            let phase = stack[top].phase;
            if phase == CSG_PHASE_FIRST_LEFT {
                stack[top].left = incoming;
                stack[top].phase = CSG_PHASE_FIRST_RIGHT;
            } else if phase == CSG_PHASE_FIRST_RIGHT {
                stack[top].right = incoming;
                stack[top].phase = CSG_PHASE_DECIDE;
            } else if phase == CSG_PHASE_AGAIN_LEFT_THEN_RIGHT {
                stack[top].left = incoming;
                stack[top].phase = CSG_PHASE_AGAIN_RIGHT;
            } else if phase == CSG_PHASE_AGAIN_LEFT {
                stack[top].left = incoming;
                stack[top].phase = CSG_PHASE_DECIDE;
            } else {
                stack[top].right = incoming;
                stack[top].phase = CSG_PHASE_DECIDE;
            }
        }
        let frame = stack[top];
        if frame.phase == CSG_PHASE_DECIDE {
            let code = csg_node(tr.node_offset + frame.position - 1u).code;
            let decision = csg_decide(code, frame.left, frame.right, tr.scale);
            if decision.done {
                depth -= 1u;
                incoming = decision.step;
                has_incoming = true;
                if depth == 0u {
                    break;
                }
            } else if decision.again_left {
                stack[top].phase = select(CSG_PHASE_AGAIN_LEFT, CSG_PHASE_AGAIN_LEFT_THEN_RIGHT, decision.again_right);
            } else {
                stack[top].phase = CSG_PHASE_AGAIN_RIGHT;
            }
            continue;
        }
        query = 2u * frame.position;
        query_tmin = frame.tmin;
        if frame.phase == CSG_PHASE_FIRST_RIGHT {
            query += 1u;
        } else if frame.phase == CSG_PHASE_AGAIN_LEFT || frame.phase == CSG_PHASE_AGAIN_LEFT_THEN_RIGHT {
            query_tmin = frame.left.t;
        } else if frame.phase == CSG_PHASE_AGAIN_RIGHT {
            query += 1u;
            query_tmin = frame.right.t;
        }
        has_query = true;
    }
    return incoming;
}

// A signed distance, and whether some union (binary or list) has the point within `near`
// of, but not inside, two or more of its children (see PrimTree::seam).
struct CsgSeam {
    value: f32,
    seam: bool,
}

// Signed distance bound of tree `tree` at x with its seam flag for tolerance `near`: a
// postorder walk of the perfect tree with a value stack (PrimTree::sdf and PrimTree::seam).
fn csg_tree_walk(tree: u32, x: vec3<f32>, near: f32) -> CsgSeam {
    let tr = csg_tree(tree);
    var values: array<f32, MAX_TREE_HEIGHT + 2u>;
    var seams: array<bool, MAX_TREE_HEIGHT + 2u>;
    var top = 0u;
    // Start at the leftmost deepest position; a left child is followed by the leftmost
    // deepest descendant of its sibling, a right child by its parent.
    let deepest = tr.height;
    var position = 1u << deepest;
    loop {
        let n = csg_node(tr.node_offset + position - 1u);
        if csg_is_operator(n.code) {
            let a = values[top - 2u];
            let b = values[top - 1u];
            let seam_ab = seams[top - 2u] || seams[top - 1u];
            top -= 1u;
            var v = max(a, -b);
            var seam = false;
            if n.code == CSG_UNION {
                v = min(a, b);
                seam = max(a, b) <= near && min(a, b) >= 0.0;
            } else if n.code == CSG_INTERSECTION {
                v = max(a, b);
            }
            values[top - 1u] = v;
            seams[top - 1u] = seam || seam_ab;
        } else if n.code != CSG_ZERO {
            // A leaf is evaluated as a one-member union list (its value, no seam).
            let list = csg_is_list(n.code);
            let overlap = n.code == CSG_LIST_OVERLAP;
            var first = tr.node_offset + position - 1u;
            var all = 1u;
            if list {
                first = n.first;
                all = n.count;
            }
            var v = select(INF, -INF, overlap);
            var close = 0u;
            for (var m = first; m < first + all; m += 1u) {
                let s = csg_leaf_sdf(csg_node(m), x);
                if overlap {
                    v = max(v, s);
                } else {
                    v = min(v, s);
                    close += select(0u, 1u, s <= near);
                }
            }
            values[top] = v;
            seams[top] = !overlap && close > 1u && v >= 0.0;
            top += 1u;
        }
        if position == 1u {
            break;
        }
        if (position & 1u) == 1u {
            position = position >> 1u;
        } else {
            let sibling = position + 1u;
            position = sibling << (deepest - firstLeadingBit(sibling));
        }
    }
    return CsgSeam(values[0], seams[0]);
}

// Signed distance bound of tree `tree` at a point of the solid's frame: negative inside.
fn csg_tree_sdf(tree: u32, x: vec3<f32>) -> f32 {
    return csg_tree_walk(tree, x, 0.0).value;
}

// Whether rays from x in the CSG_SEAM_PROBES directions all start inside (see
// PrimTree::inside_by_probes): a crossing within 2 near is the surface the ray starts on,
// rays crossing another surface within 1000 near are left out.
fn csg_inside_by_probes(tree: u32, x: vec3<f32>, near: f32) -> bool {
    let start = 2.0 * near;
    let far = 1000.0 * near;
    var probes = CSG_SEAM_PROBES;
    var inside = false;
    for (var k = 0u; k < CSG_SEAM_PROBE_COUNT; k += 1u) {
        // At most two queries: the second after a crossing within `start`.
        var after = 0.0;
        var step = step_miss(false);
        for (var query = 0u; query < 2u; query += 1u) {
            step = csg_tree_first_crossing(tree, x, probes[k], after);
            if query == 1u || step.t > start {
                break;
            }
            after = step.t;
        }
        if step.t > far {
            if !step.inside_before {
                return false;
            }
            inside = true;
        }
    }
    return inside;
}

// Whether a point of the solid's frame is inside tree `tree`: in its interior, points of
// its surface outside, points of faces its union members share inside.
fn csg_tree_contains(tree: u32, x: vec3<f32>) -> bool {
    let tr = csg_tree(tree);
    let near = csg_tolerance(tr.scale, v3_max_abs(x));
    let w = csg_tree_walk(tree, x, near);
    if w.value < 0.0 {
        return true;
    }
    return w.value <= tr.near_max && w.value <= near && w.seam && csg_inside_by_probes(tree, x, near);
}
