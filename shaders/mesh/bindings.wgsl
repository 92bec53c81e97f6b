// The prepared meshes (hytrace_csg::gpu_layout::mesh::MeshArrays), group 1 bindings 4-6
// (bindings 0-3 hold the CSG trees). A node's `first` is relative to its mesh's
// `node_offset` (children) or `triangle_offset` (a leaf's triangles).
// #import trace_records

// Nodes and triangles are read through `mesh_node` and `mesh_triangle`; above the device's
// binding limit they are split over bindings 4 and 14 to 16, 5 and 17 to 19.
// #chunked mesh_nodes MeshNode 1 4 14 mesh_node
// #chunked mesh_triangles MeshTriangle 1 5 17 mesh_triangle
@group(1) @binding(6) var<storage, read> meshes: array<MeshRecord>;
