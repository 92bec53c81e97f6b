// Probe of the raw NanoVDB lookup for its twin test (crates/trace/tests/gpu_nanovdb.rs,
// run by crates/trace/src/gpu/nanovdb.rs): per item, the value of one voxel as
// hytrace_volume's NanoGrid::voxel gives it. The grid is the atlas of the volume bindings
// (group 0, its parameters entry 0); the points and values are group 1.
// #import volume/nanovdb

// Per item, 4 integers: i, j, k, 1 unused.
@group(1) @binding(0) var<storage, read> nanovdb_points: array<vec4<i32>>;
// Per item, the f32 value's bits.
@group(1) @binding(1) var<storage, read_write> nanovdb_values: array<u32>;

@compute @workgroup_size(64)
fn nanovdb_probe(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = gid.y * groups.x * 64u + gid.x;
    if i >= arrayLength(&nanovdb_points) {
        return;
    }
    use_volume(0u);
    nanovdb_values[i] = bitcast<u32>(nanovdb_voxel(nanovdb_points[i].xyz));
}
