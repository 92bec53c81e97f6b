// The tracer's scene arrays, group 1 bindings 7-13 (bindings 0-3 hold the CSG trees,
// shaders/csg/tree_bindings.wgsl, and 4-6 the meshes, shaders/mesh/bindings.wgsl). Filled
// by hytrace_trace::cpu::gpu_export from the prepared f32 scene.
// #import trace_records

@group(1) @binding(7) var<storage, read> box_nodes: array<BoxNode>;
@group(1) @binding(8) var<storage, read> box_items: array<u32>;
@group(1) @binding(9) var<storage, read> placements: array<Placement>;
@group(1) @binding(10) var<storage, read> groups: array<SearchList>;
@group(1) @binding(11) var<storage, read> group_members: array<u32>;
@group(1) @binding(12) var<storage, read> solids: array<SearchList>;
@group(1) @binding(13) var<storage, read> surface_prims: array<SurfacePrim>;
