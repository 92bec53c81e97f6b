// The Foundry's eight arrays, group 0 of every kernel (binding order of
// hytrace_foundry::gpu_arrays()).
// #import generated/foundry

@group(0) @binding(0) var<storage, read> solid: array<Solid>;
@group(0) @binding(1) var<storage, read> prim: array<Prim>;
@group(0) @binding(2) var<storage, read> node: array<Node>;
@group(0) @binding(3) var<storage, read> plan: array<Plane>;
@group(0) @binding(4) var<storage, read> itra: array<Transform>;
@group(0) @binding(5) var<storage, read> inst: array<Instance>;
@group(0) @binding(6) var<storage, read> tri: array<Triangle>;
@group(0) @binding(7) var<storage, read> brick: array<Brick>;
