// The next boundary along a ray among the placed solids: twin of CpuScene::<f32>::trace
// (crates/trace/src/cpu/mod.rs) and SolidAccel::cross / contains (cpu/solid.rs). A flat
// scene answers the first surface crossing of any instance; a hierarchical one the
// navigator's step (locate the origin in the deepest instance containing it, then the
// nearer of leaving it and entering one of its daughters). Ties go where the CPU's go.
//
// Drivers inline every function call (Mesa does), so the code size of a kernel is the
// product of call-site counts along each call chain. Every costly function here is called
// from exactly one place: loops over members (with or without a BVH) go through one walk,
// and the located instance's exit and the daughters' entries share one instance test.
// Locating (inside tests) and crossing are separate entry points (`locate_ray`,
// `cross_from`), so neither kernel carries the other's code.
// #import csg/spans
// #import csg/frame
// #import real
// #import trace/bvh
// #if csg
// #import csg/tree
// #endif
// #if mesh
// #import mesh/mesh
// #endif

struct Hit {
    found: bool,
    t: f32,
    // Outward normal in the frame of the instance's solid until `trace` maps it out.
    normal: vec3<f32>,
    instance: u32,
    prim: u32,
}

fn no_hit() -> Hit {
    return Hit(false, INF, vec3<f32>(0.0), UNSET, UNSET);
}

fn hit_limit(best: Hit, otherwise: f32) -> f32 {
    return select(otherwise, best.t, best.found);
}

fn prim_lo(p: SurfacePrim) -> vec3<f32> {
    return vec3<f32>(p.lo[0], p.lo[1], p.lo[2]);
}

fn prim_hi(p: SurfacePrim) -> vec3<f32> {
    return vec3<f32>(p.hi[0], p.hi[1], p.hi[2]);
}

fn prim_first_crossing(p: SurfacePrim, o: vec3<f32>, d: vec3<f32>, tmin: f32) -> Step {
    // #if csg
    if p.kind == PRIM_CSG {
        return csg_tree_first_crossing(p.index, o, d, tmin);
    }
    // #endif
    // #if mesh
    if p.kind == PRIM_MESH {
        return mesh_first_crossing(p.index, o, d, tmin);
    }
    // #endif
    return step_miss(false);
}

// The least world parameter at which a prim of the trace skipped a short span as a touch,
// or a mesh decided a triangle within rounding, before its search's limit (the CPU's
// Crossings::note_dropped); INF when none did. The scan reports STATUS_DROPPED_SPAN when it
// is not beyond the answer.
var<private> trace_dropped_at: f32 = INF;

fn prim_contains(p: SurfacePrim, x: vec3<f32>) -> bool {
    // #if csg
    if p.kind == PRIM_CSG {
        return csg_tree_contains(p.index, x);
    }
    // #endif
    // #if mesh
    if p.kind == PRIM_MESH {
        return mesh_contains(p.index, x);
    }
    // #endif
    return false;
}

// The first crossing in (tmin, limit) of a ray in solid `solid`'s frame; of crossings at
// the same t, the lowest prim's (twin of SolidAccel::cross). `instance` is left unset.
// `shift` is the world parameter of the local ray's origin (for trace_dropped_at).
fn solid_cross(solid: u32, o: vec3<f32>, d: vec3<f32>, tmin: f32, limit: f32, shift: f32) -> Hit {
    let list = solid_list(solid);
    var best_index = UNSET;
    var best_t = INF;
    var best_normal = vec3<f32>(0.0);
    let r = slab_ray(o, d);
    var w = bvh_walk(list);
    loop {
        let found = best_index != UNSET;
        let within = select(limit, best_t, found);
        let i = bvh_next(&w, r, tmin, within);
        if i == UNSET {
            break;
        }
        // Ids past the surface prims are volume-brick clusters: media, not surfaces.
        if i >= list.count {
            continue;
        }
        let p = surface_prim(list.first + i);
        // A mesh tests its own box (mesh_first_crossing), as the CPU's does when it is a
        // lone prim: the exact test here would skip near misses its f32 test doubts.
        if p.kind != PRIM_MESH && !ray_bounds_entry(o, d, prim_lo(p), prim_hi(p), tmin, within).ok {
            continue;
        }
        dropped_span = INF;
        let step = prim_first_crossing(p, o, d, tmin);
        // A span skipped as a touch, or a mesh triangle decided within rounding, before the
        // limit (the f64 fallback).
        if dropped_span < INF && dropped_span < within {
            trace_dropped_at = min(trace_dropped_at, shift + dropped_span);
        }
        let tie_won = step.t == within && found && i < best_index;
        if step.t > tmin && (step.t < within || tie_won) {
            best_index = i;
            best_t = step.t;
            best_normal = step.normal;
        }
    }
    if best_index == UNSET {
        return no_hit();
    }
    return Hit(true, best_t, best_normal, UNSET, surface_prim(list.first + best_index).foundry_prim);
}

fn placement_frame(p: Placement) -> FrameRecord {
    return FrameRecord(p.rows);
}

fn placement_lo(p: Placement) -> vec3<f32> {
    return vec3<f32>(p.lo[0], p.lo[1], p.lo[2]);
}

fn placement_hi(p: Placement) -> vec3<f32> {
    return vec3<f32>(p.hi[0], p.hi[1], p.hi[2]);
}

// The world point o + o_lo (two f32 parts) in the placed solid's frame, the offset from
// the translation formed part by part (Placement::offset_of).
fn placement_offset_of(p: Placement, o: vec3<f32>, o_lo: vec3<f32>) -> vec3<f32> {
    let f = placement_frame(p);
    let hi = o - frame_origin(f);
    let lo = o_lo - vec3<f32>(p.origin_lo[0], p.origin_lo[1], p.origin_lo[2]);
    return frame_linear(f, hi + lo);
}

// A world ray in a placed solid's frame (LocalRay): t_world = shift + t_local.
struct LocalRay {
    o: vec3<f32>,
    d: vec3<f32>,
    shift: f32,
}

// The world ray o + o_lo, d taken into the solid's frame as Placement::rebase takes it: a
// ray starting beyond the solid's reach is moved along itself to its closest approach to
// the centre of the solid's box.
fn placement_rebase(p: Placement, o: vec3<f32>, o_lo: vec3<f32>, d: vec3<f32>) -> LocalRay {
    let offset = placement_offset_of(p, o, o_lo);
    let ld = frame_linear(placement_frame(p), d);
    let centre = vec3<f32>(p.centre[0], p.centre[1], p.centre[2]);
    var shift = 0.0;
    if max(abs(offset.x), max(abs(offset.y), abs(offset.z))) > p.reach {
        shift = dot(centre - offset, ld) / dot(ld, ld);
    }
    if !is_finite_t(shift) {
        shift = 0.0;
    }
    return LocalRay(offset + ld * shift, ld, shift);
}

// The nearer of `best` and the first crossing of instance `index`'s surface. The ray is
// taken into the solid's frame (`placement_rebase`), the solid asked up to a few ulps past
// the local limit (LocalRay::past_local) and its crossing kept if its world parameter is
// below the limit.
fn cross_instance(index: u32, o: vec3<f32>, o_lo: vec3<f32>, d: vec3<f32>, tmin: f32, tmax: f32, best: Hit) -> Hit {
    let p = placement(index);
    let limit = hit_limit(best, tmax);
    // The CPU's culling test (Placement::local_ray), a superset of the exact one: a mesh's
    // near misses within its rounding are searched alike, so their doubt flags alike.
    if !slab_entry_conservative(slab_ray(o, d), placement_lo(p), placement_hi(p), tmin, limit).ok {
        return best;
    }
    let local = placement_rebase(p, o, o_lo, d);
    let shift = local.shift;
    let past = limit - shift;
    let limit_local = past + 4.0 * EPSILON * abs(past);
    var c = solid_cross(p.solid, local.o, local.d, tmin - shift, limit_local, shift);
    if !c.found {
        return best;
    }
    c.t = shift + c.t;
    if !(c.t < limit) {
        return best;
    }
    c.instance = index;
    return c;
}

// What the one instance test of `cross_from` is doing.
const PHASE_EXIT: u32 = 0u;
const PHASE_EXIT_BAND: u32 = 1u;
const PHASE_ENTER: u32 = 2u;

// The navigator's step from the instance the origin is located in (UNSET: none, and for
// flat scenes): the nearer of leaving it (CpuScene::exit) and entering one of the members
// of its group of daughters (CpuScene::enter; the roots or the whole flat scene when
// UNSET). Ties go to the exit, then to the lowest instance index.
fn cross_from(located: u32, o: vec3<f32>, o_lo: vec3<f32>, d: vec3<f32>, tmin: f32, tmax: f32) -> Hit {
    var g = 0u;
    var phase = PHASE_ENTER;
    if located != UNSET {
        g = located + 1u;
        phase = PHASE_EXIT;
    }
    let list = group_list(g);
    var best = no_hit();
    // The best is the exit (or a crossing found in order): members visited out of order
    // must then beat it, not tie it.
    var seeded = false;
    let r = slab_ray(o, d);
    var w = bvh_walk(list);
    loop {
        var index = located;
        var start = tmin;
        var seed = no_hit();
        var out_of_order = false;
        if phase == PHASE_EXIT_BAND {
            // An origin within the surface tolerance of the located instance's surface,
            // moving out: the exit it starts on, found again from a start moved back by
            // the solid's tolerance there (its size plus the origin's distance from the
            // centre of its box).
            let p = placement(located);
            let size = max(p.hi[0] - p.lo[0], max(p.hi[1] - p.lo[1], p.hi[2] - p.lo[2]));
            let far = max(abs(o.x - 0.5 * (p.lo[0] + p.hi[0])), max(abs(o.y - 0.5 * (p.lo[1] + p.hi[1])), abs(o.z - 0.5 * (p.lo[2] + p.hi[2]))));
            start = tmin - 4.0 * SURFACE_TOLERANCE * (size + far);
        } else if phase == PHASE_ENTER {
            let k = bvh_next(&w, r, tmin, hit_limit(best, tmax));
            if k == UNSET {
                break;
            }
            index = select(k, group_member(list.first + k), w.linear);
            out_of_order = !w.linear && best.found && !seeded && index < best.instance;
            if out_of_order {
                // Visited out of order: an earlier member wins a tie with a later one.
                let p = placement(index);
                if !ray_bounds_entry(o, d, placement_lo(p), placement_hi(p), tmin, best.t).ok {
                    continue;
                }
            } else {
                seed = best;
            }
        }
        let h = cross_instance(index, o, o_lo, d, start, tmax, seed);
        if phase == PHASE_EXIT {
            if h.found {
                best = h;
                seeded = true;
                phase = PHASE_ENTER;
            } else {
                phase = PHASE_EXIT_BAND;
            }
        } else if phase == PHASE_EXIT_BAND {
            if h.found {
                best = h;
                best.t = max(h.t, tmin);
                seeded = true;
            }
            phase = PHASE_ENTER;
        } else if out_of_order {
            if h.found && h.t <= best.t {
                best = h;
            }
        } else {
            best = h;
            if best.found && best.instance == index {
                seeded = false;
            }
        }
    }
    if best.found {
        let n = frame_normal_to_parent(placement_frame(placement(best.instance)), best.normal);
        let l = sqrt(dot(n, n));
        if l > 0.0 {
            best.normal = n * (1.0 / l);
        }
    }
    return best;
}

// Whether a point of solid `solid`'s frame is inside one of its surface prims.
fn solid_contains(solid: u32, x: vec3<f32>) -> bool {
    let list = solid_list(solid);
    for (var i = 0u; i < list.count; i += 1u) {
        if prim_contains(surface_prim(list.first + i), x) {
            return true;
        }
    }
    return false;
}

// The deepest instance containing x (the navigator's locate): in each group from the
// roots down, the last-placed member containing x. UNSET when none; `status` gets
// STATUS_DEPTH_LIMIT if the placement tree is deeper than the instances (impossible for a
// validated Foundry: a guard, never silent).
fn locate_point(x: vec3<f32>, x_lo: vec3<f32>, status: ptr<function, u32>) -> u32 {
    var current = UNSET;
    var g = 0u;
    var list = group_list(0);
    var w = point_walk(list);
    var found = UNSET;
    let levels = arrayLength(&placements) + 1u;
    var level = 0u;
    loop {
        let k = point_next(&w, x, 0.0);
        if k == UNSET {
            // The group is done: descend into the daughters of the member found.
            if found == UNSET {
                break;
            }
            current = found;
            level += 1u;
            if level > levels {
                *status |= STATUS_DEPTH_LIMIT;
                break;
            }
            g = found + 1u;
            list = group_list(g);
            w = point_walk(list);
            found = UNSET;
            continue;
        }
        let c = select(k, group_member(list.first + k), w.linear);
        // Only members above the best so far need the (costly) inside test: the highest
        // containing one is the last placed.
        if found != UNSET && c < found {
            continue;
        }
        let p = placement(c);
        if !holds(placement_lo(p), placement_hi(p), x) {
            continue;
        }
        if solid_contains(p.solid, placement_offset_of(p, x, x_lo)) {
            found = c;
        }
    }
    return current;
}

// The tolerance band about a start at tmin for solids of size up to `size` (cpu::band).
fn start_band(size: f32, tmin: f32) -> f32 {
    return 8.0 * SURFACE_TOLERANCE * (size + abs(tmin));
}

// Whether a point of solid `solid`'s frame lies within `band` of a CSG prim's surface by
// the prim's signed distance (SolidAccel::near_surface; meshes have none).
fn solid_near_surface(solid: u32, x: vec3<f32>, band: f32) -> bool {
    // #if csg
    let list = solid_list(solid);
    for (var i = 0u; i < list.count; i += 1u) {
        let p = surface_prim(list.first + i);
        if p.kind == PRIM_CSG && abs(csg_tree_sdf(p.index, x)) <= band {
            return true;
        }
    }
    // #endif
    return false;
}

// Instance `index`'s part of `start_flags` (CpuScene::start_flag).
fn start_flag(index: u32, o: vec3<f32>, o_lo: vec3<f32>, d: vec3<f32>, start: vec3<f32>, tmin: f32, pad: f32) -> u32 {
    let p = placement(index);
    let lo = placement_lo(p);
    let hi = placement_hi(p);
    let b = start_band(max(hi.x - lo.x, max(hi.y - lo.y, hi.z - lo.z)), tmin);
    if !holds_within(lo, hi, start, b + pad) {
        return 0u;
    }
    let local = placement_rebase(p, o, o_lo, d);
    let x = local.o + local.d * (tmin - local.shift);
    if solid_near_surface(p.solid, x, b) {
        return STATUS_START_NEAR;
    }
    if p.sdf_decides != 0u {
        return 0u;
    }
    return STATUS_START_BAND;
}

// Whether the ray starts within the tolerance band of a surface of the instances the trace
// asks about there: the one its origin is located in (`located`, UNSET for none and in flat
// scenes) and the members of its group (CpuScene::start_flags, the same bits).
fn start_flags(located: u32, o: vec3<f32>, o_lo: vec3<f32>, d: vec3<f32>, tmin: f32) -> u32 {
    let start = o + d * tmin;
    let pad = 4.0 * EPSILON * (v3_max_abs(start) + abs(tmin));
    var g = 0u;
    if located != UNSET {
        g = located + 1u;
    }
    let list = group_list(g);
    let margin = start_band(list.largest, tmin) + pad;
    var w = point_walk(list);
    // The located instance first, then the group's members near the start (one call site
    // of `start_flag`, which drivers inline).
    var pending = located;
    var flags = 0u;
    loop {
        var index = pending;
        pending = UNSET;
        if index == UNSET {
            let k = point_next(&w, start, margin);
            if k == UNSET {
                break;
            }
            index = select(k, group_member(list.first + k), w.linear);
        }
        flags |= start_flag(index, o, o_lo, d, start, tmin, pad);
    }
    return flags;
}
