// Voxel reads straight from a raw NanoVDB grid buffer: the twin of hytrace_volume's
// `NanoGrid::voxel` for Float, Fp4, Fp8, Fp16 and FpN grids (root tiles, upper and lower
// internal nodes, leaves, tile values and the background, as the CPU reader walks them).
// The grid's bytes sit in the volume atlas (volume/bindings) as little-endian words from
// word `vparams.atlas_base` (format VOLUME_FORMAT_NANOVDB); every offset below is a byte
// offset of NanoVDB's layout from the grid's start (crates/volume/src/nanovdb/layout.rs).
// The host (crates/trace/src/gpu/nanovdb.rs) uploads only grids the CPU reader validated
// (every node inside the buffer, no repeated root keys) of at most 2^32 bytes, so the low
// word of each 64-bit offset is the offset modulo 2^32 and `node + low word` is the
// child's byte position.
// #import real
// #import volume/bindings

// Grid header: its size (the tree header follows) and the value type's offset.
const NANOVDB_TREE: u32 = 672u;
const NANOVDB_GRID_TYPE: u32 = 636u;
// Value types (NanoVDB's GridType): f32 values, and the quantized ones.
const NANOVDB_FLOAT: u32 = 1u;
const NANOVDB_FP4: u32 = 13u;
const NANOVDB_FPN: u32 = 16u;
// Tree header: the root's offset from the tree header.
const NANOVDB_ROOT_OFFSET: u32 = 24u;
// Root node: tile count, background, first tile; tiles of 32 bytes: u64 key, i64 child
// offset (from the root), u32 state, f32 value.
const NANOVDB_ROOT_TABLE_SIZE: u32 = 24u;
const NANOVDB_ROOT_BACKGROUND: u32 = 28u;
const NANOVDB_ROOT_TILES: u32 = 64u;
const NANOVDB_TILE_SIZE: u32 = 32u;
// Internal nodes: the value mask at 32, the child mask after it, statistics (32 bytes),
// then one 8-byte entry per slot (an f32 tile value or an i64 child offset from the node).
const NANOVDB_VALUE_MASK: u32 = 32u;
// Leaves: flags byte (FpN's bit-width code in its top 3 bits) in the word at 12, value mask,
// the quantized leaves' f32 minimum and quantum, then values or codes.
const NANOVDB_LEAF_FLAGS_WORD: u32 = 12u;
const NANOVDB_LEAF_VALUE_MASK: u32 = 16u;
const NANOVDB_LEAF_MINIMUM: u32 = 80u;
const NANOVDB_LEAF_QUANTUM: u32 = 84u;
const NANOVDB_LEAF_VALUES: u32 = 96u;

// Where a walk stands: at a node (upper, lower or leaf) to enter, at a tile value, or in
// the background.
const NANOVDB_AT_NODE: u32 = 0u;
const NANOVDB_AT_VALUE: u32 = 1u;
const NANOVDB_AT_BACKGROUND: u32 = 2u;

// One step of a walk: where it stands (NANOVDB_AT_*) and the byte position there.
struct NanoStep {
    kind: u32,
    // Byte position of the node or of the tile value.
    at: u32,
}

// The word holding byte `at` (4-aligned).
fn nanovdb_word(at: u32) -> u32 {
    return atlas_word(vparams.atlas_base + (at >> 2u));
}

// Bit `n` of the bit mask starting at byte `mask` (64-bit little-endian words read as
// pairs of 32-bit words).
fn nanovdb_bit(mask: u32, n: u32) -> bool {
    return ((nanovdb_word(mask + 4u * (n >> 5u)) >> (n & 31u)) & 1u) != 0u;
}

// The root tile of the 4096^3 region holding `ijk`: a linear search for its key (each
// coordinate >> 12 as u32, in 21-bit fields: x at bit 42, y at 21, z at 0).
fn nanovdb_root(root: u32, ijk: vec3<i32>) -> NanoStep {
    let p = vec3<u32>(ijk) >> vec3<u32>(12u);
    let key_lo = p.z | (p.y << 21u);
    let key_hi = (p.y >> 11u) | (p.x << 10u);
    // Never more tiles than the buffer holds, whatever the count says.
    let tiles = min(nanovdb_word(root + NANOVDB_ROOT_TABLE_SIZE), vparams.nanovdb_words / 8u);
    for (var t = 0u; t < tiles; t += 1u) {
        let tile = root + NANOVDB_ROOT_TILES + NANOVDB_TILE_SIZE * t;
        if nanovdb_word(tile) == key_lo && nanovdb_word(tile + 4u) == key_hi {
            let child = nanovdb_word(tile + 8u);
            if (child | nanovdb_word(tile + 12u)) != 0u {
                return NanoStep(NANOVDB_AT_NODE, root + child);
            }
            if nanovdb_word(tile + 16u) != 0u {
                return NanoStep(NANOVDB_AT_VALUE, tile + 20u);
            }
            return NanoStep(NANOVDB_AT_BACKGROUND, 0u);
        }
    }
    return NanoStep(NANOVDB_AT_BACKGROUND, 0u);
}

// One step down the internal node at byte `node` towards `ijk`: level 0 is an upper node
// (32^3 slots of 128^3 voxels), level 1 a lower node (16^3 slots of 8^3 voxels). Slots run
// x slowest, z fastest.
fn nanovdb_internal(node: u32, level: u32, ijk: vec3<i32>) -> NanoStep {
    let log2 = 5u - level;
    let child_log2 = 7u - 4u * level;
    let mask_bytes = 4096u >> (3u * level);
    let c = (vec3<u32>(ijk) >> vec3<u32>(child_log2)) & vec3<u32>((1u << log2) - 1u);
    let n = (c.x << (2u * log2)) | (c.y << log2) | c.z;
    let entry = node + 2u * NANOVDB_VALUE_MASK + 2u * mask_bytes + 8u * n;
    if nanovdb_bit(node + NANOVDB_VALUE_MASK + mask_bytes, n) {
        return NanoStep(NANOVDB_AT_NODE, node + nanovdb_word(entry));
    }
    if nanovdb_bit(node + NANOVDB_VALUE_MASK, n) {
        return NanoStep(NANOVDB_AT_VALUE, entry);
    }
    return NanoStep(NANOVDB_AT_BACKGROUND, 0u);
}

// Voxel `ijk` of the leaf at byte `leaf`: the background when inactive, else the f32 value
// (Float) or `code * quantum + minimum` with 4, 8 or 16-bit codes (Fp4, Fp8, Fp16) or the
// leaf's own width 1 << (flags >> 5) (FpN), codes packed from the low bits of words.
fn nanovdb_leaf(leaf: u32, ijk: vec3<i32>, background: f32) -> f32 {
    let c = vec3<u32>(ijk) & vec3<u32>(7u);
    let n = (c.x << 6u) | (c.y << 3u) | c.z;
    if !nanovdb_bit(leaf + NANOVDB_LEAF_VALUE_MASK, n) {
        return background;
    }
    let grid_type = nanovdb_word(NANOVDB_GRID_TYPE);
    if grid_type == NANOVDB_FLOAT {
        return bitcast<f32>(nanovdb_word(leaf + NANOVDB_LEAF_VALUES + 4u * n));
    }
    var bits = 4u << (grid_type - NANOVDB_FP4);
    if grid_type == NANOVDB_FPN {
        bits = 1u << min(nanovdb_word(leaf + NANOVDB_LEAF_FLAGS_WORD) >> 29u, 4u);
    }
    let bit = n * bits;
    let word = nanovdb_word(leaf + NANOVDB_LEAF_VALUES + 4u * (bit >> 5u));
    let code = (word >> (bit & 31u)) & ((1u << bits) - 1u);
    let minimum = bitcast<f32>(nanovdb_word(leaf + NANOVDB_LEAF_MINIMUM));
    let quantum = bitcast<f32>(nanovdb_word(leaf + NANOVDB_LEAF_QUANTUM));
    // The product times a run-time 1 (2 only for a NaN quantum, whose result is NaN anyway)
    // that no constant folding can see (real.wgsl's opaque_one): a compiler that contracts
    // the sum into an fma still rounds the product first, as the CPU does.
    let one = opaque_one(quantum);
    return (f32(code) * quantum) * one + minimum;
}

// Value of voxel `ijk` of the grid, bit for bit as the CPU reader gives it.
fn nanovdb_voxel(ijk: vec3<i32>) -> f32 {
    let root = NANOVDB_TREE + nanovdb_word(NANOVDB_TREE + NANOVDB_ROOT_OFFSET);
    let background = bitcast<f32>(nanovdb_word(root + NANOVDB_ROOT_BACKGROUND));
    var at = nanovdb_root(root, ijk);
    for (var level = 0u; level < 2u && at.kind == NANOVDB_AT_NODE; level += 1u) {
        at = nanovdb_internal(at.at, level, ijk);
    }
    if at.kind == NANOVDB_AT_VALUE {
        return bitcast<f32>(nanovdb_word(at.at));
    }
    if at.kind == NANOVDB_AT_NODE {
        return nanovdb_leaf(at.at, ijk, background);
    }
    return background;
}
