// The planes of convex polyhedra, (nx, ny, nz, d) with inside dot(n, x) <= d, as the CPU's
// prepared trees hold them (rounded from the Foundry's double-precision planes).

// Read through `csg_plane`; above the device's binding limit split over bindings 0 and 20
// to 22 (crates/trace/src/gpu/chunks.rs).
// #chunked csg_planes vec4<f32> 1 0 20 csg_plane
