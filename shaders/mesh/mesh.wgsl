// Triangle-mesh prims: twin of hytrace_csg::MeshPrim::<f32> (crates/csg/src/mesh.rs),
// operation by operation: `first_crossing` (recentred ray, BVH walk nearest box first with
// the reciprocal slab test, or the exact dividing one for rays with a zero component, the
// watertight triangle test of Woop, Benthin and Wald, ties to the lowest triangle) and
// `contains` (parity of the crossings along MESH_PARITY_DIRECTION, with the CPU's fallback
// to successive nearest-crossing queries past MESH_PARITY_BUFFER crossings).
//
// When an f32 edge function comes out exactly 0, the CPU recomputes all three in f64 (exact
// products, one f64 rounding, then f32). WGSL has no f64, and float tricks (TwoSum) are not
// kept exact by shader compilers (llvmpipe simplifies them), so `mesh_exact_edge` does it
// with integers: the same value, rounded to 53 then to 24 bits as the CPU does (subnormal
// inputs not modelled).
//
// Note for llvmpipe: it ends every loop of an invocation after 65535 iterations in all,
// shared by all loops and by the 8 lanes it runs together; the parity fallback (one BVH
// walk per crossing) is what comes nearest to that here.
// #import generated/foundry
// #import real
// #import csg/spans
// #import trace/bvh
// #import mesh/bindings

// One stack slot per BVH level below the root, plus one (the CPU's stack size).
const MESH_STACK: u32 = MESH_MAX_BVH_DEPTH + 1u;

// The gap between 1 and the next f32 (f32::EPSILON).
const MESH_EPSILON: f32 = 1.1920929e-7;

fn mesh_lo(m: MeshRecord) -> vec3<f32> {
    return vec3<f32>(m.lo[0], m.lo[1], m.lo[2]);
}

fn mesh_hi(m: MeshRecord) -> vec3<f32> {
    return vec3<f32>(m.hi[0], m.hi[1], m.hi[2]);
}

// ---- Exact edge functions (the CPU's f64 recomputation) ----------------------------------

// 128-bit unsigned integers as four u32 words, least significant first.

fn mesh_u128_add(a: vec4<u32>, b: vec4<u32>) -> vec4<u32> {
    var r = vec4<u32>(0u);
    var carry = 0u;
    for (var k = 0u; k < 4u; k += 1u) {
        let s = a[k] + b[k];
        let s2 = s + carry;
        carry = select(0u, 1u, s < a[k]) + select(0u, 1u, s2 < s);
        r[k] = s2;
    }
    return r;
}

// a - b for a >= b.
fn mesh_u128_sub(a: vec4<u32>, b: vec4<u32>) -> vec4<u32> {
    var r = vec4<u32>(0u);
    var borrow = 0u;
    for (var k = 0u; k < 4u; k += 1u) {
        let d = a[k] - b[k];
        let d2 = d - borrow;
        borrow = select(0u, 1u, a[k] < b[k]) | select(0u, 1u, d < borrow);
        r[k] = d2;
    }
    return r;
}

fn mesh_u128_less(a: vec4<u32>, b: vec4<u32>) -> bool {
    for (var k = 3i; k >= 0i; k -= 1i) {
        if a[k] != b[k] {
            return a[k] < b[k];
        }
    }
    return false;
}

// v << s for s < 128 (WGSL shifts take their amount modulo 32: whole words move first).
fn mesh_u128_shl(v: vec4<u32>, s: u32) -> vec4<u32> {
    let q = s / 32u;
    let r = s % 32u;
    var out = vec4<u32>(0u);
    for (var i = q; i < 4u; i += 1u) {
        let j = i - q;
        var w = v[j] << r;
        if r > 0u && j > 0u {
            w |= v[j - 1u] >> (32u - r);
        }
        out[i] = w;
    }
    return out;
}

// v >> s for s < 128.
fn mesh_u128_shr(v: vec4<u32>, s: u32) -> vec4<u32> {
    let q = s / 32u;
    let r = s % 32u;
    var out = vec4<u32>(0u);
    for (var i = 0u; i + q < 4u; i += 1u) {
        let j = i + q;
        var w = v[j] >> r;
        if r > 0u && j + 1u < 4u {
            w |= v[j + 1u] << (32u - r);
        }
        out[i] = w;
    }
    return out;
}

fn mesh_u128_bit_length(v: vec4<u32>) -> u32 {
    for (var k = 3i; k >= 0i; k -= 1i) {
        if v[k] != 0u {
            return u32(k) * 32u + 32u - countLeadingZeros(v[k]);
        }
    }
    return 0u;
}

// A signed value m * 2^e with an integer magnitude m.
struct MeshExact {
    neg: bool,
    m: vec4<u32>,
    e: i32,
}

// m * 2^e rounded to `bits` significant bits, ties to even (one IEEE rounding).
fn mesh_round_bits(x: MeshExact, bits: u32) -> MeshExact {
    let len = mesh_u128_bit_length(x.m);
    if len <= bits {
        return x;
    }
    let k = len - bits;
    let kept = mesh_u128_shr(x.m, k);
    // The kept bits and the first dropped one; `sticky` when any later one is set.
    let with_half = mesh_u128_shr(x.m, k - 1u);
    let half = (with_half.x & 1u) == 1u;
    let sticky = any(mesh_u128_shl(with_half, k - 1u) != x.m);
    var m = kept;
    if half && (sticky || (kept.x & 1u) == 1u) {
        m = mesh_u128_add(kept, vec4<u32>(1u, 0u, 0u, 0u));
    }
    return MeshExact(x.neg, m, x.e + i32(k));
}

// The exact product of two f32s: 24-bit significands multiplied in 12-bit halves.
fn mesh_exact_product(a: f32, b: f32) -> MeshExact {
    let ba = bitcast<u32>(a);
    let bb = bitcast<u32>(b);
    let ea = (ba >> 23u) & 0xffu;
    let eb = (bb >> 23u) & 0xffu;
    let ma = select((ba & 0x7fffffu) | 0x800000u, ba & 0x7fffffu, ea == 0u);
    let mb = select((bb & 0x7fffffu) | 0x800000u, bb & 0x7fffffu, eb == 0u);
    let xa = select(i32(ea) - 150i, -149i, ea == 0u);
    let xb = select(i32(eb) - 150i, -149i, eb == 0u);
    let a0 = ma & 0xfffu;
    let a1 = ma >> 12u;
    let b0 = mb & 0xfffu;
    let b1 = mb >> 12u;
    // ma * mb = high * 2^24 + mid * 2^12 + low.
    let low = a0 * b0;
    let mid = a1 * b0 + a0 * b1;
    let high = a1 * b1;
    var m = vec4<u32>(low, 0u, 0u, 0u);
    m = mesh_u128_add(m, vec4<u32>(mid << 12u, mid >> 20u, 0u, 0u));
    m = mesh_u128_add(m, vec4<u32>(high << 24u, high >> 8u, 0u, 0u));
    return MeshExact(((ba ^ bb) >> 31u) == 1u, m, xa + xb);
}

// The CPU's f32(f64(px) * f64(qy) - f64(py) * f64(qx)): products exact, the difference
// rounded to 53 bits, then to 24.
fn mesh_exact_edge(px: f32, py: f32, qx: f32, qy: f32) -> f32 {
    var p = mesh_exact_product(px, qy);
    var q = mesh_exact_product(py, qx);
    q.neg = !q.neg;
    let zero = vec4<u32>(0u);
    var sum: MeshExact;
    if all(q.m == zero) {
        sum = p;
    } else if all(p.m == zero) {
        sum = q;
    } else {
        // `hi` has the larger exponent; beyond 80 bits apart (normal inputs) the other is
        // below half an f64 ulp of it and the f64 difference is `hi` itself.
        var hi = p;
        var lo = q;
        if q.e > p.e {
            hi = q;
            lo = p;
        }
        let gap = u32(hi.e - lo.e);
        if gap > 80u {
            sum = hi;
        } else {
            let shifted = mesh_u128_shl(hi.m, gap);
            sum.e = lo.e;
            if hi.neg == lo.neg {
                sum.neg = hi.neg;
                sum.m = mesh_u128_add(shifted, lo.m);
            } else if mesh_u128_less(shifted, lo.m) {
                sum.neg = lo.neg;
                sum.m = mesh_u128_sub(lo.m, shifted);
            } else {
                sum.neg = hi.neg;
                sum.m = mesh_u128_sub(shifted, lo.m);
            }
        }
    }
    if all(sum.m == zero) {
        return 0.0;
    }
    let r = mesh_round_bits(mesh_round_bits(sum, 53u), 24u);
    let magnitude = ldexp(f32(r.m.x), r.e);
    return select(magnitude, -magnitude, r.neg);
}

// ---- Rays and triangles ------------------------------------------------------------------

// The per-ray part of the watertight test: `kz` the direction's dominant axis, `kx, ky`
// swapped when its component there is negative (triangles keep their winding), and the
// shear mapping the direction to +z.
struct MeshShear {
    kx: u32,
    ky: u32,
    kz: u32,
    x: f32,
    y: f32,
    z: f32,
}

// The direction must not be zero.
fn mesh_shear(d: vec3<f32>) -> MeshShear {
    let ax = abs(d.x);
    let ay = abs(d.y);
    let az = abs(d.z);
    var kz = 2u;
    if ax >= ay && ax >= az {
        kz = 0u;
    } else if ay >= az {
        kz = 1u;
    }
    var kx = (kz + 1u) % 3u;
    var ky = (kz + 2u) % 3u;
    if d[kz] < 0.0 {
        let k = kx;
        kx = ky;
        ky = k;
    }
    let dz = d[kz];
    return MeshShear(kx, ky, kz, d[kx] / dz, d[ky] / dz, 1.0 / dz);
}

// Whether the triangle's hit or miss is within f32 rounding (twin of edge_doubt in
// crates/csg/src/mesh/wide.rs, operation by operation): some edge function is within the
// bound of its rounding of 0, and moving each by that bound can make all three agree.
// (x, y) are the vertices' sheared coordinates, z their unsheared heights, `reach` the
// origin's largest coordinate plus how far the recentring moved its parameter.
// Returns the bound when the triangle is doubtful, else -1.
fn mesh_doubt(ax: f32, ay: f32, az: f32, bx: f32, by: f32, bz: f32, cx: f32, cy: f32, cz: f32, u: f32, v: f32, w: f32, reach: f32) -> f32 {
    let sheared = abs(ax) + abs(ay) + (abs(bx) + abs(by)) + (abs(cx) + abs(cy));
    let heights = abs(az) + abs(bz) + abs(cz);
    let bound = (2.0 * MESH_EPSILON) * sheared * ((sheared + heights) * 2.0 + reach);
    let low = -bound;
    let near = abs(u) <= bound || abs(v) <= bound || abs(w) <= bound;
    let from_front = u >= low && v >= low && w >= low;
    let from_behind = u <= bound && v <= bound && w <= bound;
    return select(-1.0, bound, near && (from_front || from_behind));
}

// The latest distance at which the ray may cross a doubtful triangle's plane (twin of
// latest_crossing in crates/csg/src/mesh/wide.rs, operation by operation).
fn mesh_latest_crossing(t: f32, za: f32, zb: f32, zc: f32, det: f32, bound: f32) -> f32 {
    let spread = abs(za - t) + abs(zb - t) + abs(zc - t);
    let late = t + bound * spread / abs(det);
    var far = select(zb, za, za > zb);
    far = select(far, zc, zc > far);
    return select(far, late, late < far);
}

// A triangle test's answer: `ok` and `t` where the ray crosses it, whether its hit or miss
// is within rounding (`doubtful`, mesh_doubt) and then `doubt`, the latest distance at
// which the ray may cross its plane (mesh_latest_crossing; else INF).
struct MeshCrossing {
    ok: bool,
    t: f32,
    doubtful: bool,
    doubt: f32,
}

// Where the ray o + t d meets triangle `tri` (MeshPrim::crossing, and the doubt of the
// CPU's 4-lane test, WideRay::test): `ok` false if it does not. Zero edge functions count
// as inside, so a ray through a shared edge hits both sides.
fn mesh_crossing(tri: MeshTriangle, o: vec3<f32>, s: MeshShear, reach: f32) -> MeshCrossing {
    let a = tri.v[0].xyz - o;
    let b = tri.v[1].xyz - o;
    let c = tri.v[2].xyz - o;
    let ax = a[s.kx] - s.x * a[s.kz];
    let ay = a[s.ky] - s.y * a[s.kz];
    let bx = b[s.kx] - s.x * b[s.kz];
    let by = b[s.ky] - s.y * b[s.kz];
    let cx = c[s.kx] - s.x * c[s.kz];
    let cy = c[s.ky] - s.y * c[s.kz];
    var u = cx * by - cy * bx;
    var v = ax * cy - ay * cx;
    var w = bx * ay - by * ax;
    let az = s.z * a[s.kz];
    let bz = s.z * b[s.kz];
    let cz = s.z * c[s.kz];
    // A parity count (reach -1) asks for no doubt.
    var bound = -1.0;
    if reach >= 0.0 {
        bound = mesh_doubt(ax, ay, a[s.kz], bx, by, b[s.kz], cx, cy, c[s.kz], u, v, w, reach);
    }
    let doubtful = bound >= 0.0;
    var doubt = INF;
    if doubtful {
        let det32 = u + v + w;
        doubt = mesh_latest_crossing((u * az + v * bz + w * cz) / det32, az, bz, cz, det32, bound);
    }
    if u == 0.0 || v == 0.0 || w == 0.0 {
        u = mesh_exact_edge(cx, cy, bx, by);
        v = mesh_exact_edge(ax, ay, cx, cy);
        w = mesh_exact_edge(bx, by, ax, ay);
    }
    let negative = u < 0.0 || v < 0.0 || w < 0.0;
    let positive = u > 0.0 || v > 0.0 || w > 0.0;
    let det = u + v + w;
    if (negative && positive) || det == 0.0 {
        return MeshCrossing(false, 0.0, doubtful, doubt);
    }
    return MeshCrossing(true, (u * az + v * bz + w * cz) / det, doubtful, doubt);
}

// The ray's entry into a padded node box within [after, limit] (SlabRay::entry).
fn mesh_slab_entry(r: SlabRay, n: MeshNode, after: f32, limit: f32) -> MaybeT {
    let lo = vec3<f32>(n.lo[0], n.lo[1], n.lo[2]);
    let hi = vec3<f32>(n.hi[0], n.hi[1], n.hi[2]);
    if r.exact {
        return ray_bounds_entry(r.o, r.d, lo, hi, after, limit);
    }
    let t0 = (lo - r.o) * r.inv;
    let t1 = (hi - r.o) * r.inv;
    // The CPU's comparisons (`if a < b { a } else { b }`), in its order.
    let near = select(t1, t0, t0 < t1);
    let far = select(t1, t0, t0 > t1);
    let near_yz = select(near.z, near.y, near.y > near.z);
    let far_yz = select(far.z, far.y, far.y < far.z);
    var a = select(near_yz, near.x, near.x > near_yz);
    var b = select(far_yz, far.x, far.x < far_yz);
    if after > a {
        a = after;
    }
    if limit < b {
        b = limit;
    }
    return MaybeT(a <= b, a);
}

// The ray moved to its closest approach to the mesh's centre (MeshPrim::recentred), unless
// it starts within twice the mesh's size of the centre.
struct MeshRay {
    o: vec3<f32>,
    shift: f32,
}

fn mesh_recentred(m: MeshRecord, o: vec3<f32>, d: vec3<f32>) -> MeshRay {
    let centre = (mesh_lo(m) + mesh_hi(m)) * 0.5;
    let offset = o - centre;
    let far = v3_max_abs(offset);
    let l2 = v3_dot(d, d);
    var shift = 0.0;
    if l2 != 0.0 && far > 4.0 * m.scale {
        shift = -v3_dot(offset, d) / l2;
        if !is_finite_t(shift) {
            shift = 0.0;
        }
    }
    return MeshRay(o + d * shift, shift);
}

// ---- The BVH walk ------------------------------------------------------------------------

// One walk's state: a nearest-crossing query (`collect` false: the best crossing after
// `after`, which becomes the limit) or a parity count (`collect` true: every crossing after
// `after`, the first MESH_PARITY_BUFFER of them kept).
struct MeshWalk {
    collect: bool,
    after: f32,
    found: bool,
    best_t: f32,
    best_index: u32,
    // Whether the best crossing's triangle is doubtful.
    best_doubtful: bool,
    // The least distance of a doubtful crossing (MeshCrossing::doubt) in range when seen.
    doubt: f32,
    // The origin's largest coordinate plus |after| (mesh_doubt's `reach`); -1 for a parity
    // count, which needs no doubt.
    reach: f32,
    count: u32,
    crossings: array<f32, MESH_PARITY_BUFFER>,
}

// The triangles `first..first + count` of a leaf (the closures of MeshPrim::nearest and
// MeshPrim::contains); returns the new limit.
fn mesh_leaf(m: MeshRecord, first: u32, count: u32, o: vec3<f32>, s: MeshShear, limit: f32, w: ptr<function, MeshWalk>) -> f32 {
    for (var i = first; i < first + count; i += 1u) {
        let c = mesh_crossing(mesh_triangle(m.triangle_offset + i), o, s, (*w).reach);
        // A doubtful crossing within the search's range so far (Best::doubt_at).
        let within = select(limit, (*w).best_t, (*w).found);
        if c.doubt > (*w).after && c.doubt <= within && c.doubt < (*w).doubt {
            (*w).doubt = c.doubt;
        }
        if !c.ok {
            continue;
        }
        if (*w).collect {
            if c.t > (*w).after && c.t < INF {
                if (*w).count < MESH_PARITY_BUFFER {
                    (*w).crossings[(*w).count] = c.t;
                }
                (*w).count += 1u;
            }
            continue;
        }
        // Strictly below the limit when nothing is found yet: an overflowed distance is no
        // crossing. Equal distances go to the lowest triangle.
        var better = c.t < limit;
        if (*w).found {
            better = c.t < (*w).best_t || (c.t == (*w).best_t && i < (*w).best_index);
        }
        if c.t > (*w).after && better {
            (*w).found = true;
            (*w).best_t = c.t;
            (*w).best_index = i;
            (*w).best_doubtful = c.doubtful;
        }
    }
    if !(*w).collect && (*w).found {
        return (*w).best_t;
    }
    return limit;
}

// The leaves whose boxes the (recentred) ray meets within [after, limit], nearest box entry
// first (MeshPrim::walk); subtrees entered beyond the limit are skipped.
fn mesh_walk(m: MeshRecord, o: vec3<f32>, d: vec3<f32>, s: MeshShear, w: ptr<function, MeshWalk>) {
    let boxes = slab_ray(o, d);
    var limit = INF;
    if !mesh_slab_entry(boxes, mesh_node(m.node_offset), (*w).after, limit).ok {
        return;
    }
    // The farther children and their box entries (one push per level of descent).
    var stack_node: array<u32, MESH_STACK>;
    var stack_entry: array<f32, MESH_STACK>;
    var top = 0u;
    var node = 0u;
    var walking = true;
    while walking {
        let n = mesh_node(m.node_offset + node);
        var descended = false;
        if n.count == 0u {
            let a = n.first;
            let b = n.first + 1u;
            let ea = mesh_slab_entry(boxes, mesh_node(m.node_offset + a), (*w).after, limit);
            let eb = mesh_slab_entry(boxes, mesh_node(m.node_offset + b), (*w).after, limit);
            descended = ea.ok || eb.ok;
            if ea.ok && eb.ok {
                if eb.t < ea.t {
                    stack_node[top] = a;
                    stack_entry[top] = ea.t;
                    node = b;
                } else {
                    stack_node[top] = b;
                    stack_entry[top] = eb.t;
                    node = a;
                }
                top += 1u;
            } else if ea.ok {
                node = a;
            } else if eb.ok {
                node = b;
            }
        } else {
            limit = mesh_leaf(m, n.first, n.count, o, s, limit, w);
        }
        if !descended {
            // The nearest postponed subtree still entered within the limit, if any.
            walking = false;
            while top > 0u {
                top -= 1u;
                if stack_entry[top] <= limit {
                    node = stack_node[top];
                    walking = true;
                    break;
                }
            }
        }
    }
}

fn mesh_walk_start(collect: bool, o: vec3<f32>, after: f32) -> MeshWalk {
    var w: MeshWalk;
    w.collect = collect;
    w.after = after;
    w.found = false;
    w.best_t = INF;
    w.best_index = 0u;
    w.best_doubtful = false;
    w.doubt = INF;
    w.reach = select(v3_max_abs(o) + abs(after), -1.0, collect);
    w.count = 0u;
    return w;
}

// The nearest crossing after `after` of a recentred ray (MeshPrim::nearest): `found`,
// `best_t` and `best_index` (relative to the mesh) of the returned walk.
fn mesh_nearest(m: MeshRecord, o: vec3<f32>, d: vec3<f32>, s: MeshShear, after: f32) -> MeshWalk {
    var w = mesh_walk_start(false, o, after);
    mesh_walk(m, o, d, s, &w);
    return w;
}

// ---- The prim ----------------------------------------------------------------------------

// The first crossing of mesh `mesh`'s surface after tmin (crossings within the surface
// tolerance of tmin are the surface the ray starts on), with the triangle's geometric
// normal (v1 - v0) x (v2 - v0), and whether the ray comes from behind that triangle.
fn mesh_first_crossing(mesh: u32, o: vec3<f32>, d: vec3<f32>, tmin: f32) -> Step {
    let m = mesh_record(mesh);
    if !ray_bounds_span(o, d, mesh_lo(m), mesh_hi(m), tmin, INF).ok {
        return step_miss(false);
    }
    // A zero direction meets no triangle (the CPU's NaN shear rejects them all).
    if all(d == vec3<f32>(0.0)) {
        return step_miss(false);
    }
    let after = tmin + SURFACE_TOLERANCE * (m.scale + abs(tmin));
    let moved = mesh_recentred(m, o, d);
    let w = mesh_nearest(m, moved.o, d, mesh_shear(d), after - moved.shift);
    // Doubtful crossings (WideBvh::found): the answer's own triangle, and those met before
    // it by more than the rounding of its distance (all of them when there is none). The
    // scan traces the ray again in f64, as for a dropped span (MeshPrim::step_at).
    var earlier = w.doubt < INF;
    if w.found {
        let margin = (2.0 * MESH_EPSILON) * (w.reach + abs(w.best_t));
        earlier = w.doubt < w.best_t - margin;
    }
    var doubt = select(INF, w.doubt, earlier);
    if w.found && w.best_doubtful {
        doubt = min(doubt, w.best_t);
    }
    if doubt < INF {
        dropped_span = min(dropped_span, doubt + moved.shift);
    }
    if !w.found {
        return step_miss(false);
    }
    let tri = mesh_triangle(m.triangle_offset + w.best_index);
    let v0 = tri.v[0].xyz;
    let normal = v3_cross(tri.v[1].xyz - v0, tri.v[2].xyz - v0);
    return Step(w.best_t + moved.shift, normal, v3_dot(normal, d) > 0.0);
}

// Whether point x of the solid's frame is inside mesh `mesh` (parity of the distinct
// crossing distances of a ray from it); meaningful for closed meshes only.
fn mesh_contains(mesh: u32, x: vec3<f32>) -> bool {
    let m = mesh_record(mesh);
    let d = MESH_PARITY_DIRECTION;
    if !ray_bounds_span(x, d, mesh_lo(m), mesh_hi(m), 0.0, INF).ok {
        return false;
    }
    let moved = mesh_recentred(m, x, d);
    let s = mesh_shear(d);
    var w = mesh_walk_start(true, moved.o, -moved.shift);
    mesh_walk(m, moved.o, d, s, &w);
    var inside = false;
    if w.count > MESH_PARITY_BUFFER {
        // Too many to keep: one nearest-crossing query after another.
        var after = -moved.shift;
        loop {
            let next = mesh_nearest(m, moved.o, d, s, after);
            if !next.found {
                break;
            }
            inside = !inside;
            after = next.best_t;
        }
    } else {
        // Sorted (insertion sort), then counted once per distinct distance.
        for (var i = 1u; i < w.count; i += 1u) {
            let ti = w.crossings[i];
            var j = i;
            while j > 0u && w.crossings[j - 1u] > ti {
                w.crossings[j] = w.crossings[j - 1u];
                j -= 1u;
            }
            w.crossings[j] = ti;
        }
        var distinct = 0u;
        for (var i = 0u; i < w.count; i += 1u) {
            if i == 0u || w.crossings[i - 1u] < w.crossings[i] {
                distinct += 1u;
            }
        }
        inside = distinct % 2u == 1u;
    }
    return inside;
}
