// The prepared meshes (hytrace_csg::gpu_layout::mesh::MeshArrays), group 1 bindings 4-6
// (bindings 0-3 hold the CSG trees). A node's `first` is relative to its mesh's
// `node_offset` (children) or `triangle_offset` (a leaf's triangles).
// #import generated/trace_records

// Nodes, triangles and mesh records are read through `mesh_node`, `mesh_triangle` and
// `mesh_record`; above the device's binding limit each is split over its binding and three
// more (14 to 16, 17 to 19, 32 to 34).
// #chunked mesh_nodes MeshNode 1 4 14 mesh_node
// #chunked mesh_triangles MeshTriangle 1 5 17 mesh_triangle
// #chunked meshes MeshRecord 1 6 32 mesh_record
