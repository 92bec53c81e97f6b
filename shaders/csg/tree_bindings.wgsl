// The arrays of prepared CSG trees (hytrace_csg::gpu_layout::tree::CsgArrays): group 1 holds
// the polyhedron planes (binding 0, csg/planes), the slots and list members of every tree
// (binding 1), the leaves' frames (binding 2) and one record per tree (binding 3).
// #import generated/trace_records
// #import csg/planes

// Read through `csg_node`, `csg_frame` and `csg_tree`; above the device's binding limit each
// is split over its binding and three more (23 to 31).
// #chunked csg_nodes CsgNode 1 1 23 csg_node
// #chunked csg_frames FrameRecord 1 2 26 csg_frame
// #chunked csg_trees CsgTree 1 3 29 csg_tree
