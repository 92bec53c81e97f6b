// The prepared meshes (hytrace_csg::gpu_layout::mesh::MeshArrays), group 1 bindings 4-6
// (bindings 0-3 hold the CSG trees). A node's `first` is relative to its mesh's
// `node_offset` (children) or `triangle_offset` (a leaf's triangles).
// #import trace_records

@group(1) @binding(4) var<storage, read> mesh_nodes: array<MeshNode>;
@group(1) @binding(5) var<storage, read> mesh_triangles: array<MeshTriangle>;
@group(1) @binding(6) var<storage, read> meshes: array<MeshRecord>;
