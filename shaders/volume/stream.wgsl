// A brick store streamed through the GPU's brick pool (crates/trace/src/gpu/brick_pool.rs):
// the page table is the indirection, whose entries are pool slots, VOLUME_NO_BRICK for a
// dropped brick, or VOLUME_ABSENT_BRICK | record for a kept brick not in the pool. A lookup
// there records the brick in the request list (once a pass: a per-brick flag bit set
// atomically decides which invocation appends it), marks the invocation's item as missing
// (its answer is discarded and it runs again after the host uploads the brick) and reads,
// in kernels composed with `stream_lods`, the brick's coarser level of detail (what a
// preview shows until it arrives). A lookup in a resident brick stamps its slot with the pass number, which
// the host's least-recently-used eviction reads.
// #import generated/trace_records

// Header (STREAM_* words), then the request list, the flag bits, the slot stamps.
@group(0) @binding(20) var<storage, read_write> stream_state: array<atomic<u32>>;
// #if stream_lods
// The store's coarser levels of detail, nine values a kept brick (by record): its mean, then
// its eight octants' means (x fastest).
@group(0) @binding(21) var<storage, read> stream_lods: array<f32>;
// #endif

// Whether this invocation read a brick that is not in the pool.
var<private> stream_missing: bool = false;
// The slot this invocation stamped last (consecutive lookups mostly share a brick).
var<private> stream_last_slot: u32 = 0xffffffffu;

// Records brick `brick` (its index in the page table) as needed and missing.
fn stream_request(brick: u32) {
    stream_missing = true;
    let bit = 1u << (brick & 31u);
    let word = atomicLoad(&stream_state[STREAM_FLAGS]) + (brick >> 5u);
    if (atomicOr(&stream_state[word], bit) & bit) == 0u {
        let k = atomicAdd(&stream_state[STREAM_REQUESTED], 1u);
        if k < atomicLoad(&stream_state[STREAM_CAPACITY]) {
            atomicStore(&stream_state[STREAM_HEADER_WORDS + k], brick);
        }
    }
}

// Stamps pool slot `slot` as used in this pass.
fn stream_touch(slot: u32) {
    if slot != stream_last_slot {
        stream_last_slot = slot;
        let stamps = atomicLoad(&stream_state[STREAM_STAMPS]);
        atomicMax(&stream_state[stamps + slot], atomicLoad(&stream_state[STREAM_PASS]));
    }
}

// The value an absent brick shows while it is requested: in kernels composed with
// `stream_lods`, the mean of the octant of record `record`'s brick that holds texel `b` (0 to
// 7 on each axis); else (the photon kernel on a device without a binding to spare for them:
// what it computes there is discarded anyway) zero.
fn stream_coarse(record: u32, b: vec3<u32>) -> f32 {
    // #if stream_lods
    let octant = (b.x >> 2u) | ((b.y >> 2u) << 1u) | ((b.z >> 2u) << 2u);
    return stream_lods[record * 9u + 1u + octant];
    // #endif
    return 0.0;
}
