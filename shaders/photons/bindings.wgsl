// The photon kernel's records (group 2, filled by crates/trace/src/gpu/photons.rs from
// crates/trace/src/photons/gpu_tables.rs), the property lookup (twin of
// photons::properties::Property::value) and a photon's history (twin of
// photons::output::History).
// #import generated/foundry
// #import generated/trace_records

// A uniform, not a storage buffer: a streamed run with step points and gensteps binds
// 32 storage buffers without it, the least a device may allow (lavapipe).
@group(2) @binding(0) var<uniform> pparams: PhotonParams;
@group(2) @binding(1) var<storage, read> ptables: array<PhotonTable>;
@group(2) @binding(2) var<storage, read> prows: array<vec2<f32>>;
@group(2) @binding(3) var<storage, read> pmaterials: array<PhotonMaterial>;
@group(2) @binding(4) var<storage, read> psurfaces: array<PhotonSurface>;
@group(2) @binding(5) var<storage, read> pinstances: array<PhotonInstance>;
@group(2) @binding(6) var<storage, read> pborders: array<PhotonBorder>;
// The records of the photons detected or cut short, appended (`pcount` of them).
@group(2) @binding(7) var<storage, read_write> precords: array<PhotonRecord>;
// Every photon's packed history (low, high 32 bits), by its index in the batch (in a
// streamed pass, by its place in the pass, where the host wrote its index first).
@group(2) @binding(8) var<storage, read_write> phistories: array<vec2<u32>>;
@group(2) @binding(9) var<storage, read_write> pcount: atomic<u32>;

// Speed of light in vacuum, mm/ns (photons::properties::C_LIGHT_MM_PER_NS).
const C_LIGHT_MM_PER_NS: f32 = 299.792458;

// Table `t` at photon energy `e`: linear between rows, the first or last value outside
// them; `fallback` for UNSET (no table).
fn property_value(t: u32, e: f32, fallback: f32) -> f32 {
    if t == UNSET {
        return fallback;
    }
    let table = ptables[t];
    let last = table.first + table.count - 1u;
    if e <= prows[table.first].x {
        return prows[table.first].y;
    }
    if e >= prows[last].x {
        return prows[last].y;
    }
    // The first row above e (a partition point): e lies in [row i - 1, row i).
    var lo = table.first;
    var hi = last;
    loop {
        if lo >= hi {
            break;
        }
        let mid = lo + (hi - lo) / 2u;
        if prows[mid].x <= e {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    let a = prows[lo - 1u];
    let b = prows[lo];
    return a.y + (b.y - a.y) * (e - a.x) / (b.x - a.x);
}

// A photon's packed history: labels of 4 bits, first lowest, the first 16 kept, and the
// last label pushed.
struct History {
    lo: u32,
    hi: u32,
    len: u32,
    mask: u32,
    last: u32,
}

fn history_push(h: ptr<function, History>, label: u32) {
    let n = (*h).len;
    if n < 8u {
        (*h).lo |= label << (4u * n);
    } else if n < 16u {
        (*h).hi |= label << (4u * (n - 8u));
    }
    (*h).len = n + 1u;
    (*h).last = label;
    (*h).mask |= 1u << (label - 1u);
}
