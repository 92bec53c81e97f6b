// The bricked grid and its range mips as the volume kernels read them (uploaded by
// crates/trace/src/gpu/volume.rs): group 0, bindings 0 to 4.
// #import trace_records

@group(0) @binding(0) var<storage, read> vparams: VolumeParams;
// (min, max) of every block of every mip level, level after level (VolumeParams.level_dims.w).
@group(0) @binding(1) var<storage, read> ranges: array<vec2<f32>>;
// Brick-table index of every brick of the indirection box (x fastest), or VOLUME_NO_BRICK.
@group(0) @binding(2) var<storage, read> indirection: array<u32>;
@group(0) @binding(3) var<storage, read> bricks: array<BrickEntry>;
// The atlas bytes as little-endian words.
@group(0) @binding(4) var<storage, read> atlas: array<u32>;
