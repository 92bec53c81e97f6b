// The arrays of prepared CSG trees (hytrace_csg::gpu_layout::tree::CsgArrays): group 1 holds
// the polyhedron planes (binding 0, csg/planes), the slots and list members of every tree
// (binding 1), the leaves' frames (binding 2) and one record per tree (binding 3).
// #import trace_records
// #import csg/planes

@group(1) @binding(1) var<storage, read> csg_nodes: array<CsgNode>;
@group(1) @binding(2) var<storage, read> csg_frames: array<FrameRecord>;
@group(1) @binding(3) var<storage, read> csg_trees: array<CsgTree>;
