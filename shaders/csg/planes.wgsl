// The planes of convex polyhedra, (nx, ny, nz, d) with inside dot(n, x) <= d, as the CPU's
// prepared trees hold them (rounded from the Foundry's double-precision planes).

@group(1) @binding(0) var<storage, read> csg_planes: array<vec4<f32>>;
