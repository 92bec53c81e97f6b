// The tracer's scene arrays, group 1 bindings 7-13 (bindings 0-3 hold the CSG trees,
// shaders/csg/tree_bindings.wgsl, and 4-6 the meshes, shaders/mesh/bindings.wgsl). Filled
// by hytrace_trace::cpu::gpu_export from the prepared f32 scene.
// #import generated/trace_records

// Each array is read through its accessor; above the device's binding limit it is split over
// its binding and three more (35 to 55, in the order below).
// #chunked box_nodes BoxNode 1 7 35 box_node
// #chunked box_items u32 1 8 38 box_item
// #chunked placements Placement 1 9 41 placement
// #chunked groups SearchList 1 10 44 group_list
// #chunked group_members u32 1 11 47 group_member
// #chunked solids SearchList 1 12 50 solid_list
// #chunked surface_prims SurfacePrim 1 13 53 surface_prim
