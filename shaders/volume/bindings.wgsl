// The bricked grids and their range mips as the volume kernels read them (uploaded by
// crates/trace/src/gpu/volume.rs): group 0, bindings 0 to 4 (5 to 7 for a split atlas, 8
// for texels in a 3D texture). Several grids share the arrays (the renderer's media); each
// has its parameters, with its first entries in them.
// #import trace_records

@group(0) @binding(0) var<storage, read> volume_params: array<VolumeParams>;
// (min, max) of every block of every mip level, level after level (VolumeParams.level_dims.w).
@group(0) @binding(1) var<storage, read> ranges: array<vec2<f32>>;
// Brick-table index of every brick of each grid's indirection box (x fastest), or
// VOLUME_NO_BRICK.
@group(0) @binding(2) var<storage, read> indirection: array<u32>;
@group(0) @binding(3) var<storage, read> bricks: array<BrickEntry>;
// The atlas bytes as little-endian words (brick texels, or raw NanoVDB grids), read
// through `atlas_word`; above the device's binding limit split over bindings 4 to 7.
// #chunked atlas u32 0 4 5 atlas_word
// #if atlas_texture
// A bricked grid's texels as a 3D texture instead (crates/trace/src/gpu/texels.rs): the 8^3
// texels of atlas slot s at brick (s % bx, s / bx % by, s / (bx by)) of its bx x by x bz
// bricks, in the format's own texture format.
@group(0) @binding(8) var atlas_texture: texture_3d<f32>;
// #endif
// The parameters of the grid the walks and lookups read (`use_volume`), and their entry.
var<private> vparams: VolumeParams;
var<private> vparams_entry: u32 = 0xffffffffu;

// Makes entry `i` of the volume parameters the grid read. A private copy: reads of its
// fields are then plain loads on every driver, where indexed storage reads gather per
// lane on CPU drivers.
fn use_volume(i: u32) {
    if i != vparams_entry {
        vparams = volume_params[i];
        vparams_entry = i;
    }
}

