// The ray walks of hytrace_volume::dda in f32: the hierarchical segment walk over the range
// mips (SegmentWalk) and the unit-cell walk (CellWalk), with the same face rule, the same
// plane formula everywhere, zero direction components branched on and never divided by,
// and the same step budgets. No recursion; VOLUME_INF stands for an infinite tmax.
// #import volume/bindings

const WALK_LEADING: u32 = 0u;
const WALK_INSIDE: u32 = 1u;
const WALK_TRAILING: u32 = 2u;
const WALK_DONE: u32 = 3u;
// The coarsest mip level (RANGE_LEVELS - 1).
const WALK_TOP: u32 = 3u;

struct Walk {
    // The ray moved to its box entry: positions origin + (t - base) dir ("local t").
    origin: vec3<f32>,
    dir: vec3<f32>,
    base: f32,
    tmin: f32,
    tmax: f32,
    // Local t reached, local t where the ray leaves the box.
    t: f32,
    t_end: f32,
    phase: u32,
    global: bool,
    level: u32,
    cell: vec3<i32>,
    budget: u32,
}

// A piece [t0, t1] of the ray and the range bounding every lookup on it.
struct Segment {
    valid: bool,
    outside: bool,
    t0: f32,
    t1: f32,
    lo: f32,
    hi: f32,
}

fn level_side(level: u32) -> f32 {
    return f32(vparams.level_lo[level].w);
}

// The range of block `block` of `level` (the background's outside the level's box).
fn level_range(level: u32, block: vec3<i32>) -> vec2<f32> {
    let dims = vparams.level_dims[level];
    let local = block - vparams.level_lo[level].xyz;
    if any(local < vec3<i32>(0)) || any(local >= vec3<i32>(dims.xyz)) {
        return vec2<f32>(vparams.background);
    }
    let l = vec3<u32>(local);
    return block_range(dims.w + (l.z * dims.y + l.y) * dims.x + l.x);
}

// Local t at which the walk's ray meets plane `j * side - 0.5` of axis `k` (dir[k] != 0).
fn walk_plane(w: ptr<function, Walk>, k: u32, j: i32, side: f32) -> f32 {
    return (f32(j) * side - 0.5 - (*w).origin[k]) / (*w).dir[k];
}

fn walk_absolute(w: ptr<function, Walk>, t: f32) -> f32 {
    return min((*w).base + t, (*w).tmax);
}

// The walk of ray o + t d over [tmin, tmax]: its box entry, exit and first block.
fn walk_start(o: vec3<f32>, d: vec3<f32>, tmin: f32, tmax: f32, global: bool) -> Walk {
    // Without an overlap with the box, the leading segment is the whole ray.
    var w = Walk(o, d, tmax, tmin, tmax, 0.0, 0.0, WALK_LEADING, global, WALK_TOP, vec3<i32>(0), 0u);
    let lo = vparams.level_lo[WALK_TOP].xyz;
    let dims = vparams.level_dims[WALK_TOP].xyz;
    if any(dims == vec3<u32>(0u)) {
        return w;
    }
    let s = level_side(WALK_TOP);
    var t_in = tmin;
    var t_out = tmax;
    for (var k = 0u; k < 3u; k++) {
        let blo = f32(lo[k]) * s - 0.5;
        let bhi = (f32(lo[k]) + f32(dims[k])) * s - 0.5;
        if d[k] == 0.0 {
            if o[k] < blo || o[k] > bhi {
                return w;
            }
        } else {
            let ta = (blo - o[k]) / d[k];
            let tb = (bhi - o[k]) / d[k];
            t_in = max(t_in, min(ta, tb));
            t_out = min(t_out, max(ta, tb));
        }
    }
    if !(t_in < t_out) {
        return w;
    }
    w.base = t_in;
    w.origin = o + t_in * d;
    // The exit by the walk's own plane formula: the last block's exit is the walk's end.
    var t_end = tmax - t_in;
    for (var k = 0u; k < 3u; k++) {
        if d[k] != 0.0 {
            let far = lo[k] + select(0, i32(dims[k]), d[k] > 0.0);
            t_end = min(t_end, walk_plane(&w, k, far, s));
        }
    }
    w.t_end = max(t_end, 0.0);
    // The first block of the coarsest level, by the face rule, kept inside the box.
    for (var k = 0u; k < 3u; k++) {
        let first_lo = lo[k];
        let last_hi = lo[k] + i32(dims[k]) - 1;
        var c = i32(clamp(floor((w.origin[k] + 0.5) / s), f32(first_lo), f32(last_hi)));
        let dk = d[k];
        if dk == 0.0 {
            while c < last_hi && w.origin[k] >= f32(c + 1) * s - 0.5 {
                c += 1;
            }
            while c > first_lo && w.origin[k] < f32(c) * s - 0.5 {
                c -= 1;
            }
        } else {
            let up = dk > 0.0;
            let dc = select(-1, 1, up);
            let last = select(first_lo, last_hi, up);
            let first = select(last_hi, first_lo, up);
            while c != last && walk_plane(&w, k, c + select(0, 1, up), s) <= 0.0 {
                c += dc;
            }
            while c != first && walk_plane(&w, k, c + select(1, 0, up), s) > 0.0 {
                c -= dc;
            }
        }
        w.cell[k] = c;
    }
    // Each step enters the next block of level `finest` or coarser; between two steps the
    // walk descends at most WALK_TOP - finest times.
    let depth = WALK_TOP - vparams.finest;
    let fine_cells = (dims.x << depth) + (dims.y << depth) + (dims.z << depth);
    w.budget = (fine_cells + 1u) * (depth + 1u) + 1u;
    return w;
}

// Moves to the child block holding the ray at the walk's t.
fn walk_descend(w: ptr<function, Walk>) {
    (*w).level -= 1u;
    let half = level_side((*w).level);
    for (var k = 0u; k < 3u; k++) {
        let mid = 2 * (*w).cell[k] + 1;
        let d = (*w).dir[k];
        var upper: bool;
        if d > 0.0 {
            upper = walk_plane(w, k, mid, half) <= (*w).t;
        } else if d < 0.0 {
            upper = walk_plane(w, k, mid, half) > (*w).t;
        } else {
            upper = (*w).origin[k] >= f32(mid) * half - 0.5;
        }
        (*w).cell[k] = 2 * (*w).cell[k] + select(0, 1, upper);
    }
}

// Steps into the next block along axis k, and up as far as the face is a coarser one's.
fn walk_step(w: ptr<function, Walk>, k: u32) {
    var was = (*w).cell[k];
    (*w).cell[k] += select(-1, 1, (*w).dir[k] > 0.0);
    var to = (*w).cell[k];
    while (*w).level < WALK_TOP && (was >> 1u) != (to >> 1u) {
        (*w).level += 1u;
        (*w).cell = (*w).cell >> vec3<u32>(1u);
        was = was >> 1u;
        to = to >> 1u;
    }
}

fn outside_segment(t0: f32, t1: f32) -> Segment {
    return Segment(true, true, t0, t1, vparams.background, vparams.background);
}

// The next segment of positive length, or one with `valid` false at the end.
fn walk_next(w: ptr<function, Walk>) -> Segment {
    loop {
        var s = Segment(false, false, 0.0, 0.0, 0.0, 0.0);
        let phase = (*w).phase;
        if phase == WALK_LEADING {
            (*w).phase = WALK_INSIDE;
            s = outside_segment((*w).tmin, (*w).base);
        } else if phase == WALK_INSIDE {
            if (*w).t >= (*w).t_end {
                (*w).phase = WALK_TRAILING;
                continue;
            }
            if (*w).global {
                s = Segment(true, false, walk_absolute(w, (*w).t), walk_absolute(w, (*w).t_end), vparams.global_min, vparams.global_max);
                (*w).t = (*w).t_end;
            } else {
                loop {
                    if (*w).budget == 0u {
                        // Unreachable (the budget outlasts every walk); as the CPU, the rest
                        // of the box gets the global range rather than an endless loop.
                        s = Segment(true, false, walk_absolute(w, (*w).t), walk_absolute(w, (*w).t_end), vparams.global_min, vparams.global_max);
                        (*w).t = (*w).t_end;
                        break;
                    }
                    (*w).budget -= 1u;
                    let side = level_side((*w).level);
                    var t_exit = (*w).t_end;
                    var axis = 3u;
                    for (var k = 0u; k < 3u; k++) {
                        if (*w).dir[k] != 0.0 {
                            let tk = walk_plane(w, k, (*w).cell[k] + select(0, 1, (*w).dir[k] > 0.0), side);
                            if tk < t_exit {
                                t_exit = tk;
                                axis = k;
                            }
                        }
                    }
                    t_exit = max(t_exit, (*w).t);
                    let range = level_range((*w).level, (*w).cell);
                    if (*w).level > vparams.finest && range.x != range.y && t_exit > (*w).t {
                        walk_descend(w);
                        continue;
                    }
                    s = Segment(true, false, walk_absolute(w, (*w).t), walk_absolute(w, t_exit), range.x, range.y);
                    (*w).t = t_exit;
                    if axis < 3u {
                        walk_step(w, axis);
                    }
                    break;
                }
            }
        } else if phase == WALK_TRAILING {
            (*w).phase = WALK_DONE;
            s = outside_segment(walk_absolute(w, (*w).t_end), (*w).tmax);
        } else {
            return s;
        }
        // Zero-length pieces (edges, corners, rounding) carry nothing.
        if s.t1 > s.t0 {
            return s;
        }
    }
    return Segment(false, false, 0.0, 0.0, 0.0, 0.0);
}

struct CellWalk {
    // The ray moved to start at `base`, counted in local t.
    origin: vec3<f32>,
    dir: vec3<f32>,
    base: f32,
    end: f32,
    // Cell i spans [i + offset, i + 1 + offset].
    offset: f32,
    t: f32,
    t_end: f32,
    cell: vec3<i32>,
    budget: u32,
}

// The piece of the ray inside one cell.
struct CellPiece {
    valid: bool,
    t0: f32,
    t1: f32,
    cell: vec3<i32>,
    // Point at t0.
    entry: vec3<f32>,
}

fn cell_plane(w: ptr<function, CellWalk>, k: u32, j: i32) -> f32 {
    return (f32(j) + (*w).offset - (*w).origin[k]) / (*w).dir[k];
}

// The cells (offset 0: trilinear, -0.5: nearest) of the ray starting at `o` (its point at
// t0) with direction `d`, over [t0, t1].
fn cells_start(o: vec3<f32>, d: vec3<f32>, t0: f32, t1: f32, offset: f32) -> CellWalk {
    let len = t1 - t0;
    var w = CellWalk(o, d, t0, t1, offset, 0.0, len, vec3<i32>(0), 0u);
    if !(len > 0.0 && len < VOLUME_INF) {
        w.t_end = 0.0;
        return w;
    }
    var faces = 0.0;
    for (var k = 0u; k < 3u; k++) {
        let ok = o[k];
        let dk = d[k];
        var c = i32(floor(ok - offset));
        if dk == 0.0 {
            while ok >= f32(c + 1) + offset {
                c += 1;
            }
            while ok < f32(c) + offset {
                c -= 1;
            }
        } else {
            let up = dk > 0.0;
            let dc = select(-1, 1, up);
            while cell_plane(&w, k, c + select(0, 1, up)) <= 0.0 {
                c += dc;
            }
            while cell_plane(&w, k, c + select(1, 0, up)) > 0.0 {
                c -= dc;
            }
        }
        w.cell[k] = c;
        faces += ceil(abs(dk) * len) + 1.0;
    }
    w.budget = u32(faces) + 1u;
    return w;
}

fn cells_absolute(w: ptr<function, CellWalk>, t: f32) -> f32 {
    if t >= (*w).t_end {
        return (*w).end;
    }
    return min((*w).base + t, (*w).end);
}

// The next piece of positive length, or one with `valid` false at the end.
fn cells_next(w: ptr<function, CellWalk>) -> CellPiece {
    while (*w).t < (*w).t_end {
        var t_exit = (*w).t_end;
        var axis = 3u;
        if (*w).budget > 1u {
            for (var k = 0u; k < 3u; k++) {
                if (*w).dir[k] != 0.0 {
                    let tk = cell_plane(w, k, (*w).cell[k] + select(0, 1, (*w).dir[k] > 0.0));
                    if tk < t_exit {
                        t_exit = tk;
                        axis = k;
                    }
                }
            }
        }
        (*w).budget = max((*w).budget, 1u) - 1u;
        t_exit = max(t_exit, (*w).t);
        let piece = CellPiece(true, cells_absolute(w, (*w).t), cells_absolute(w, t_exit), (*w).cell, (*w).origin + (*w).t * (*w).dir);
        (*w).t = t_exit;
        if axis < 3u {
            (*w).cell[axis] += select(-1, 1, (*w).dir[axis] > 0.0);
        }
        if piece.t1 > piece.t0 {
            return piece;
        }
    }
    return CellPiece(false, 0.0, 0.0, vec3<i32>(0), vec3<f32>(0.0));
}
