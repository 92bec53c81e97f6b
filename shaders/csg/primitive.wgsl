// Primitive dispatch by typecode: the spans of a ray inside a primitive and the signed
// distance to it, in the primitive's own frame. Twin of
// hytrace_csg::kernel::{primitive_spans, primitive_sdf}.
//
// Each typecode's branch sits in a `#if FAMILY` block so that a composer can leave out the
// primitives a scene does not use; unknown codes give no spans and an infinite distance.
// #import generated/foundry
// #import csg/spans
// #import csg/quadric
// #import csg/planar
// #import csg/cuts
// #if torus
// #import csg/torus
// #endif
// #if twisted
// #import csg/twisted
// #endif

// The spans of the ray start + t d, solved from start + shift d and given as parameters from
// there (capped quadrics meet their z caps from start itself).
fn primitive_spans(code: u32, p: array<f32, 6>, plane_first: u32, plane_count: u32, start: vec3<f32>, d: vec3<f32>, shift: f32) -> Spans {
    let o = start + d * shift;
    // #if sphere
    if code == CSG_SPHERE { return sphere_spans(p, o, d); }
    // #endif
    // #if zsphere
    if code == CSG_ZSPHERE { return zsphere_spans(p, start, d, shift); }
    // #endif
    // #if cylinder
    if code == CSG_CYLINDER { return cylinder_spans(p, start, d, shift); }
    // #endif
    // #if tube
    if code == CSG_DISC { return tube_spans(p, start, d, shift); }
    // #endif
    // #if cone
    if code == CSG_CONE { return cone_spans(p, start, d, shift); }
    // #endif
    // #if hyperboloid
    if code == CSG_HYPERBOLOID { return hyperboloid_spans(p, start, d, shift); }
    // #endif
    // #if paraboloid
    if code == CSG_PARABOLOID { return paraboloid_spans(p, start, d, shift); }
    // #endif
    // #if torus
    if code == CSG_TORUS { return torus_spans(p, o, d); }
    // #endif
    // #if box
    if code == CSG_BOX3 { return box_spans(p, o, d); }
    // #endif
    // #if polyhedron
    if code == CSG_CONVEX_POLYHEDRON { return polyhedron_spans(plane_first, plane_count, o, d); }
    // #endif
    // #if halfspace
    if code == CSG_HALFSPACE { return halfspace_spans(p, o, d); }
    // #endif
    // #if slab
    if code == CSG_SLAB { return slab_spans(p, o, d); }
    // #endif
    // #if phicut
    if code == CSG_PHICUT { return phicut_spans(p, o, d); }
    // #endif
    // #if thetacut
    if code == CSG_THETACUT { return thetacut_spans(p, o, d); }
    // #endif
    // #if saddle
    if code == CSG_SADDLE { return saddle_spans(p, o, d); }
    // #endif
    // #if twisted
    if code == CSG_TWISTED_HALFSPACE { return twisted_spans(p, start, d, shift); }
    // #endif
    return spans_empty();
}

fn primitive_sdf(code: u32, p: array<f32, 6>, plane_first: u32, plane_count: u32, x: vec3<f32>) -> f32 {
    // #if sphere
    if code == CSG_SPHERE { return sphere_sdf(p, x); }
    // #endif
    // #if zsphere
    if code == CSG_ZSPHERE { return zsphere_sdf(p, x); }
    // #endif
    // #if cylinder
    if code == CSG_CYLINDER { return cylinder_sdf(p, x); }
    // #endif
    // #if tube
    if code == CSG_DISC { return tube_sdf(p, x); }
    // #endif
    // #if cone
    if code == CSG_CONE { return cone_sdf(p, x); }
    // #endif
    // #if hyperboloid
    if code == CSG_HYPERBOLOID { return hyperboloid_sdf(p, x); }
    // #endif
    // #if paraboloid
    if code == CSG_PARABOLOID { return paraboloid_sdf(p, x); }
    // #endif
    // #if torus
    if code == CSG_TORUS { return torus_prim_sdf(p, x); }
    // #endif
    // #if box
    if code == CSG_BOX3 { return box_sdf(p, x); }
    // #endif
    // #if polyhedron
    if code == CSG_CONVEX_POLYHEDRON { return polyhedron_sdf(plane_first, plane_count, x); }
    // #endif
    // #if halfspace
    if code == CSG_HALFSPACE { return halfspace_sdf(p, x); }
    // #endif
    // #if slab
    if code == CSG_SLAB { return slab_sdf(p, x); }
    // #endif
    // #if phicut
    if code == CSG_PHICUT { return phicut_sdf(p, x); }
    // #endif
    // #if thetacut
    if code == CSG_THETACUT { return thetacut_sdf(p, x); }
    // #endif
    // #if saddle
    if code == CSG_SADDLE { return saddle_sdf(p, x); }
    // #endif
    // #if twisted
    if code == CSG_TWISTED_HALFSPACE { return twisted_sdf(p, x); }
    // #endif
    return INF;
}
