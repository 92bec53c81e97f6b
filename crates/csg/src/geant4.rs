//! Geant4 solids as CSG expressions over hytrace's primitives.
//!
//! [`G4Solid`] holds the parameters of a Geant4 solid exactly as its constructor takes them
//! (lengths in mm, angles in radians, Geant4's half-lengths), and [`G4Solid::to_shape`]
//! builds the equivalent [`Shape`]:
//!
//! | Geant4 | expression |
//! |---|---|
//! | G4Box, G4Orb | box, sphere |
//! | G4Sphere | (sphere - inner sphere) * theta cut * phi cut |
//! | G4Tubs, G4CutTubs | tube * phi cut (* two half-spaces) |
//! | G4Cons | (cone - inner cone) * phi cut |
//! | G4Torus | torus * phi cut |
//! | G4Trd, G4Trap, G4Para, G4Tet | convex polyhedron |
//! | G4Polycone, G4GenericPolycone | union over z slabs of (cone - inner cone), * phi cut |
//! | G4Polyhedra (both constructors) | union over z slabs of (convex polyhedron - inner one), one per run of sides spanning <= pi |
//! | G4Hype | hyperboloid - inner hyperboloid (or inner double cone) |
//! | G4TwistedTubs | (hyperboloid - inner hyperboloid) * two turned saddles (hyperbolic paraboloid half-spaces) |
//! | G4TwistedBox, G4TwistedTrd, G4TwistedTrap | bounding cylinder * four twisted half-spaces, sheared along (theta, phi) |
//! | G4Paraboloid | paraboloid |
//! | G4Ellipsoid, G4EllipticalTube, G4EllipticalCone | scaled z-cut sphere, cylinder, cone |
//! | G4ExtrudedSolid | union over section pairs and convex pieces of the polygon of convex polyhedra |
//! | G4UnionSolid, G4SubtractionSolid, G4IntersectionSolid | `+`, `-`, `*` |
//!
//! G4Polycone and G4Polyhedra share one construction with their generic (r, z) corner forms:
//! the z-plane form becomes the corner polygon up the outer radii and back down the inner
//! ones; the polygon is cut into slabs at every corner z, where the edges spanning a slab
//! pair up into (inner, outer) boundaries. The rz-corner G4Polyhedra constructor measures
//! radii to the polygon's corners, the z-plane one to its sides (Geant4 scales the latter by
//! 1 / cos(dphi / numside / 2)).
//!
//! G4ExtrudedSolid: between two consecutive sections the cross-section is the polygon
//! scaled and moved linearly in z, so each side face is a planar trapezoid and each convex
//! piece of the polygon sweeps a convex polyhedron. The pieces (Hertel-Mehlhorn merging of
//! an ear-clipping triangulation, see [`crate::tessellate::convex_pieces`]) share whole
//! faces, whose planes are computed once and negated for the other side, so that the
//! union's coincident crossings merge. Standing alone it is still meshed by
//! [`G4Mapping::to_geometry`]: the mesh is exact too and traces about as fast (0.75x to
//! 1.3x the expression's speed, depending on the polygon); the expression makes it a
//! boolean operand.
//!
//! G4GenericTrap and G4TessellatedSolid have no expression here:
//! [`G4Mapping::to_geometry`] meshes them.
//!
//! Booleans place their second operand by `p_first = rotation * p_second + translation`
//! (the `G4Transform3D` form: the rotation applies to the solid, not the frame).
//!
//! The JSON form (`{"type": "tubs", "rmin": ..., ...}`) is the one written by the project's
//! Geant4 oracle, `tests/oracle/geant4_oracle.py`.

use std::f64::consts::PI;

use crate::shape::{
    box3, cone, cylinder, halfspace, hyperboloid, paraboloid, phi_cut, polyhedron, saddle, sphere,
    theta_cut, torus, tube, twisted_halfspace, zsphere, CsgError, Shape,
};
use crate::tessellate::{convex_pieces, ruled_solid, section_stack, simple_polygon, Tri};
use hytrace_foundry::Transform64;

pub use hytrace_foundry::g4solid::{Boolean, G4Solid, PlacedSolid, XtruSection};

/// What a Geant4 solid becomes: an exact CSG expression, or a closed triangle mesh where
/// no analytic form exists here (generic traps, extrusions, tessellated solids).
#[derive(Clone, Debug, PartialEq)]
pub enum G4Geometry {
    /// An exact expression.
    Csg(Shape),
    /// Triangles counter-clockwise seen from outside, in the solid's frame.
    Mesh(Vec<Tri>),
}

fn bad(primitive: &'static str, problem: String) -> CsgError {
    CsgError { primitive, problem }
}

/// `shape * phi_cut(sphi, dphi)` unless the range covers the full circle.
fn with_phi(shape: Shape, sphi: f64, dphi: f64) -> Result<Shape, CsgError> {
    if dphi >= 2.0 * PI {
        Ok(shape)
    } else {
        Ok(shape * phi_cut(sphi, dphi)?)
    }
}

/// The convex hull of a hexahedron given as bottom `v[0..4]` and top `v[4..8]` faces in
/// Geant4's G4Trap vertex order, as a polyhedron of its six face planes.
fn hexahedron(v: &[[f64; 3]; 8]) -> Result<Shape, CsgError> {
    const FACES: [[usize; 4]; 6] = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    faces_to_polyhedron(v, &FACES)
}

/// A convex polyhedron from faces given as vertex indices (see [`face_planes`]).
fn faces_to_polyhedron<const N: usize>(
    v: &[[f64; 3]],
    faces: &[[usize; N]],
) -> Result<Shape, CsgError> {
    polyhedron(&face_planes(v, faces))
}

/// The planes `[n, d]` (`dot(n, x) <= d`, `n` not normalized) of faces given as vertex
/// indices: each from Newell's method, oriented away from the vertices' centroid.
fn face_planes<const N: usize>(v: &[[f64; 3]], faces: &[[usize; N]]) -> Vec<[f64; 4]> {
    let centroid: [f64; 3] =
        std::array::from_fn(|k| v.iter().map(|p| p[k]).sum::<f64>() / v.len() as f64);
    let mut planes = Vec::with_capacity(faces.len());
    for face in faces {
        let mut n = [0.0f64; 3];
        let mut mid = [0.0f64; 3];
        for (i, &a) in face.iter().enumerate() {
            let (p, q) = (v[a], v[face[(i + 1) % N]]);
            n[0] += (p[1] - q[1]) * (p[2] + q[2]);
            n[1] += (p[2] - q[2]) * (p[0] + q[0]);
            n[2] += (p[0] - q[0]) * (p[1] + q[1]);
            for k in 0..3 {
                mid[k] += p[k] / N as f64;
            }
        }
        let d = n[0] * mid[0] + n[1] * mid[1] + n[2] * mid[2];
        let c = n[0] * centroid[0] + n[1] * centroid[1] + n[2] * centroid[2];
        if c > d {
            planes.push([-n[0], -n[1], -n[2], -d]);
        } else {
            planes.push([n[0], n[1], n[2], d]);
        }
    }
    planes
}

#[allow(clippy::too_many_arguments)]
fn trap_vertices(
    dz: f64,
    theta: f64,
    phi: f64,
    dy1: f64,
    dx1: f64,
    dx2: f64,
    alpha1: f64,
    dy2: f64,
    dx3: f64,
    dx4: f64,
    alpha2: f64,
) -> [[f64; 3]; 8] {
    let (tx, ty) = (theta.tan() * phi.cos(), theta.tan() * phi.sin());
    let face = |z: f64, dy: f64, alpha: f64, dxa: f64, dxb: f64| {
        trapezoid(dy, alpha.tan(), dxa, dxb).map(|p| [p[0] + z * tx, p[1] + z * ty, z])
    };
    let (b, t) = (
        face(-dz, dy1, alpha1, dx1, dx2),
        face(dz, dy2, alpha2, dx3, dx4),
    );
    [b[0], b[1], b[2], b[3], t[0], t[1], t[2], t[3]]
}

/// The trapezoid section of G4Trap-like solids in its own plane, in Geant4's vertex order
/// (-x -y, +x -y, -x +y, +x +y): half height `dy`, half widths `dxa` at -dy and `dxb` at
/// +dy, sheared by `tan_alpha`.
fn trapezoid(dy: f64, tan_alpha: f64, dxa: f64, dxb: f64) -> [[f64; 2]; 4] {
    [
        [-dy * tan_alpha - dxa, -dy],
        [-dy * tan_alpha + dxa, -dy],
        [dy * tan_alpha - dxb, dy],
        [dy * tan_alpha + dxb, dy],
    ]
}

/// A G4TwistedTrap (G4TwistedBox and G4TwistedTrd are special cases) as an exact
/// expression: at height z the trapezoid interpolated between its end sections, rotated
/// counter-clockwise by `twist * z / (2 dz)`, then shifted along the (theta, phi) axis (the
/// geometry the oracle established against Geant4). Without the shift (a shear, the
/// expression's placement) and the twist, the solid is a trapezoid prism whose lateral
/// faces Geant4 requires to be planar (checked here as Geant4 11.4's
/// `G4VTwistedFaceted` checks it); twisted, each face is a [`twisted_halfspace`] of that
/// plane, capped at `|z| <= dz`. Their intersection, with a cylinder just wider than the
/// corners to bound it, is the solid.
#[allow(clippy::too_many_arguments)]
fn twisted_trap_shape(
    what: &'static str,
    twist: f64,
    dz: f64,
    theta: f64,
    phi: f64,
    dy1: f64,
    dx1: f64,
    dx2: f64,
    dy2: f64,
    dx3: f64,
    dx4: f64,
    alpha: f64,
) -> Result<Shape, CsgError> {
    let lengths = [dz, dy1, dx1, dx2, dy2, dx3, dx4];
    if !lengths.iter().all(|x| x.is_finite() && *x > 0.0) {
        return Err(bad(
            what,
            format!("lengths must be finite and > 0, got {lengths:?}"),
        ));
    }
    if ![twist, theta, phi, alpha].iter().all(|a| a.is_finite()) {
        return Err(bad(
            what,
            format!("angles must be finite, got {twist} {theta} {phi} {alpha}"),
        ));
    }
    // The lateral faces x = ... are planar before the twist only when the bottom and top
    // trapezoids narrow alike: dx1 - dx2 over dy1 as dx3 - dx4 over dy2.
    let narrowing = (dx1 != dx2, dx3 != dx4);
    let planar = match narrowing {
        (true, true) => (dy1 * (dx3 - dx4) / (dx1 - dx2) - dy2).abs() <= CAR_TOLERANCE,
        (false, false) => true,
        _ => false,
    };
    if !planar {
        return Err(bad(
            what,
            format!(
                "its untwisted side faces are not planar (Geant4 needs dy2 = dy1 (dx3 - dx4) / (dx1 - dx2)): {lengths:?}"
            ),
        ));
    }
    let ta = alpha.tan();
    let (bottom, top) = (trapezoid(dy1, ta, dx1, dx2), trapezoid(dy2, ta, dx3, dx4));
    let corner = |t: &[[f64; 2]; 4], k: usize, z: f64| [t[k][0], t[k][1], z];
    let v: [[f64; 3]; 8] = std::array::from_fn(|i| {
        if i < 4 {
            corner(&bottom, i, -dz)
        } else {
            corner(&top, i - 4, dz)
        }
    });
    // Geant4's trapezoid order (-x -y, +x -y, -x +y, +x +y): the -y, +y, -x and +x sides.
    const SIDES: [[usize; 4]; 4] = [[0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    let reach = v.iter().map(|p| p[0].hypot(p[1])).fold(0.0f64, f64::max);
    let mut solid = cylinder(1.01 * reach, -dz, dz)?;
    let rate = twist / (2.0 * dz);
    for [nx, ny, nz, d] in face_planes(&v, &SIDES) {
        let l = (nx * nx + ny * ny + nz * nz).sqrt();
        solid = solid * twisted_halfspace([nx, ny, nz], d / l, rate, dz)?;
    }
    let (tx, ty) = (theta.tan() * phi.cos(), theta.tan() * phi.sin());
    if tx == 0.0 && ty == 0.0 {
        return Ok(solid);
    }
    // x += z tx, y += z ty.
    let mut shear = Transform64::IDENTITY;
    shear.rows[0][2] = tx;
    shear.rows[1][2] = ty;
    Ok(solid.placed(shear))
}

/// Geant4's kCarTolerance (mm): G4GenericTrap takes lengths below it for zero.
const CAR_TOLERANCE: f64 = 1e-9;

/// The bottom and top quadruples of a G4GenericTrap, counter-clockwise seen from +z, after
/// the checks of Geant4 11.4's `G4GenericTrap::CheckParameters` and
/// `ComputeLateralSurfaces`, which refuse the same solids: dz under 2e-9 mm, other than 8
/// vertices, bottom and top running in opposite directions, more than one lateral edge
/// collapsed at both ends, no volume, a non-convex end or a lateral face twisted by more
/// than 90 degrees. Coincident vertices are allowed (an end may collapse to a triangle, a
/// segment or a point); vertices of an end closer than kCarTolerance to the one before
/// are made equal to it, as Geant4 takes them for one.
fn generic_trap_ends(dz: f64, vertices: &[[f64; 2]]) -> Result<[[[f64; 2]; 4]; 2], CsgError> {
    let fail = |problem: String| Err(bad("genericTrap", problem));
    if !(dz.is_finite() && dz >= 2.0 * CAR_TOLERANCE) {
        return fail(format!("dz must be finite and at least 2e-9 mm, got {dz}"));
    }
    if vertices.len() != 8 || !vertices.iter().flatten().all(|v| v.is_finite()) {
        return fail(format!("needs 8 finite vertices, got {vertices:?}"));
    }
    let mut v: [[f64; 2]; 8] = std::array::from_fn(|k| vertices[k]);
    let d = |a: [f64; 2], b: [f64; 2]| [a[0] - b[0], a[1] - b[1]];
    let cross = |a: [f64; 2], b: [f64; 2]| a[0] * b[1] - a[1] * b[0];
    let len = |a: [f64; 2]| a[0].hypot(a[1]);
    // Twice the signed area of each end by its diagonals (> 0: counter-clockwise), zero
    // within Geant4's tolerance, and the longer diagonal.
    let end_area = |v: &[[f64; 2]; 8], o: usize| {
        let (d1, d2) = (d(v[o + 2], v[o]), d(v[o + 3], v[o + 1]));
        let l = len(d1).max(len(d2));
        let z = cross(d1, d2);
        (if z.abs() < l * CAR_TOLERANCE { 0.0 } else { z }, l)
    };
    let ((zbot, lbot), (ztop, ltop)) = (end_area(&v, 0), end_area(&v, 4));
    if zbot * ztop < 0.0 {
        return fail(format!(
            "the bottom and top vertices run in opposite directions: {vertices:?}"
        ));
    }
    // Geant4 lists them clockwise (it re-orders anticlockwise ones, with a warning).
    if zbot > 0.0 || ztop > 0.0 {
        v.swap(1, 3);
        v.swap(5, 7);
    }
    let collapsed = (0..4)
        .filter(|&i| {
            let j = (i + 1) % 4;
            len(d(v[j], v[i])).max(len(d(v[j + 4], v[i + 4]))) < CAR_TOLERANCE
        })
        .count();
    // Geant4's volume formula (clockwise vertices: positive).
    let (a, b) = (d(v[3], v[1]), d(v[2], v[0]));
    let (c, e) = (d(v[7], v[5]), d(v[6], v[4]));
    let volume = ((cross(a, b) + cross(c, e)) / 3.0 + (cross(a, e) + cross(c, b)) / 6.0) * dz;
    if collapsed > 1 || volume.is_nan() || volume < dz * lbot.max(ltop) * CAR_TOLERANCE {
        return fail(format!(
            "degenerate ({collapsed} lateral edges collapsed at both ends, volume {volume} \
             mm^3): {vertices:?}"
        ));
    }
    for o in [0, 4] {
        for i in 0..4 {
            let (j, k) = ((i + 1) % 4, (i + 2) % 4);
            if cross(d(v[o + j], v[o + i]), d(v[o + k], v[o + j])) >= CAR_TOLERANCE {
                return fail(format!(
                    "the bottom and top faces must be convex: {vertices:?}"
                ));
            }
        }
    }
    for i in 0..4 {
        let j = (i + 1) % 4;
        let (eb, et) = (d(v[i], v[j]), d(v[i + 4], v[j + 4]));
        let (lb, lt) = (len(eb), len(et));
        let twisted =
            lb.min(lt) >= CAR_TOLERANCE && cross(eb, et).abs() >= CAR_TOLERANCE * lb.max(lt);
        if twisted && eb[0] * et[0] + eb[1] * et[1] < 0.0 {
            return fail(format!(
                "lateral face {i} is twisted by more than 90 degrees: {vertices:?}"
            ));
        }
    }
    for o in [0, 4] {
        for k in 1..4 {
            if len(d(v[o + k], v[o + k - 1])) < CAR_TOLERANCE {
                v[o + k] = v[o + k - 1];
            }
        }
        if len(d(v[o], v[o + 3])) < CAR_TOLERANCE {
            v[o + 3] = v[o];
        }
    }
    // Clockwise to counter-clockwise, vertex k + 4 still above vertex k.
    let ccw = |o: usize| [v[o], v[o + 3], v[o + 2], v[o + 1]];
    Ok([ccw(0), ccw(4)])
}

/// The union of `parts` (at least one).
fn union_of(parts: Vec<Shape>) -> Shape {
    let mut it = parts.into_iter();
    let first = it.next().expect("at least one part");
    it.fold(first, |a, b| a + b)
}

fn check_planes(what: &'static str, z: &[f64], rmin: &[f64], rmax: &[f64]) -> Result<(), CsgError> {
    if z.len() < 2 || z.len() != rmin.len() || z.len() != rmax.len() {
        return Err(bad(
            what,
            format!(
                "needs at least 2 z planes and as many radii, got {} z, {} rmin, {} rmax",
                z.len(),
                rmin.len(),
                rmax.len()
            ),
        ));
    }
    if z.windows(2).any(|w| w[1] < w[0]) {
        return Err(bad(what, format!("z planes must not decrease, got {z:?}")));
    }
    if rmin.iter().zip(rmax).any(|(a, b)| *a < 0.0 || a > b) {
        return Err(bad(what, "needs 0 <= rmin <= rmax at every z plane".into()));
    }
    Ok(())
}

/// Side planes of one z section of a regular polygon prism frustum over the phi range
/// `[phi_a, phi_b]` of `sides` sides (of the solid's `numside` over `dphi`), with apothems
/// `r1` at `z1` and `r2` at `z2`, closed by radial planes when the range is partial.
#[allow(clippy::too_many_arguments)]
fn polygon_section(
    sphi: f64,
    step: f64,
    sides: std::ops::Range<u32>,
    full: bool,
    z1: f64,
    z2: f64,
    r1: f64,
    r2: f64,
) -> Result<Shape, CsgError> {
    let mut planes = vec![[0.0, 0.0, -1.0, -z1], [0.0, 0.0, 1.0, z2]];
    for j in sides.clone() {
        let phi = sphi + (j as f64 + 0.5) * step;
        let (c, s) = (phi.cos(), phi.sin());
        let n = [c * (z2 - z1), s * (z2 - z1), -(r2 - r1)];
        let d = n[0] * r1 * c + n[1] * r1 * s + n[2] * z1;
        planes.push([n[0], n[1], n[2], d]);
    }
    if !full {
        let (pa, pb) = (
            sphi + sides.start as f64 * step,
            sphi + sides.end as f64 * step,
        );
        planes.push([pa.sin(), -pa.cos(), 0.0, 0.0]);
        planes.push([-pb.sin(), pb.cos(), 0.0, 0.0]);
    }
    polyhedron(&planes)
}

/// The (r, z) corner polygon of a z-plane solid: up the outer radii, back down the inner
/// ones.
fn zplanes_to_rz(z: &[f64], rmin: &[f64], rmax: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let r = rmax.iter().chain(rmin.iter().rev()).copied().collect();
    let z = z.iter().chain(z.iter().rev()).copied().collect();
    (r, z)
}

/// One piece of a revolved (r, z) polygon: the region between the `inner` and `outer`
/// boundary edges over the slab `z1 < z < z2`, with their radii at `z1` and `z2` (an inner
/// boundary on the axis has radii `[0, 0]`).
#[derive(Clone, Copy, Debug, PartialEq)]
struct SlabPiece {
    z1: f64,
    z2: f64,
    inner: [f64; 2],
    outer: [f64; 2],
}

/// Splits a simple (r, z) polygon (corners in either orientation, r >= 0) into slabs at
/// every distinct corner z. Inside a slab the edges spanning it do not cross; sorted by
/// radius they alternate between inner and outer boundaries of the polygon's interior, and
/// each consecutive (inner, outer) pair is one piece.
fn rz_slabs(what: &'static str, r: &[f64], z: &[f64]) -> Result<Vec<SlabPiece>, CsgError> {
    let n = r.len();
    if n != z.len() || n < 3 {
        return Err(bad(
            what,
            format!(
                "needs 3 or more (r, z) corners, got {} r and {} z",
                r.len(),
                z.len()
            ),
        ));
    }
    if !r.iter().chain(z).all(|v| v.is_finite()) {
        return Err(bad(what, "corners must be finite".into()));
    }
    if r.iter().any(|&v| v < 0.0) {
        return Err(bad(what, format!("radii must be >= 0, got {r:?}")));
    }
    let span = |v: &[f64]| {
        let (lo, hi) = v
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
                (lo.min(x), hi.max(x))
            });
        hi - lo
    };
    let size = span(r).max(span(z));
    // Twice the area, about the first corner (no cancellation from far-off z).
    let area2: f64 = (0..n)
        .map(|i| {
            let j = (i + 1) % n;
            (r[i] - r[0]) * (z[j] - z[0]) - (r[j] - r[0]) * (z[i] - z[0])
        })
        .sum();
    if area2.abs() <= 1e-12 * size * size || size == 0.0 {
        return Err(bad(what, "the (r, z) polygon has no area".into()));
    }
    let mut levels = z.to_vec();
    levels.sort_by(f64::total_cmp);
    levels.dedup();
    // Radius of the edge from corner lo to corner hi (z[lo] < z[hi]) at height h, exact at
    // the corners.
    let r_at = |lo: usize, hi: usize, h: f64| {
        if h == z[lo] {
            r[lo]
        } else if h == z[hi] {
            r[hi]
        } else {
            r[lo] + (r[hi] - r[lo]) * ((h - z[lo]) / (z[hi] - z[lo]))
        }
    };
    let mut pieces = Vec::new();
    for w in levels.windows(2) {
        let (za, zb) = (w[0], w[1]);
        let mut cuts: Vec<[f64; 2]> = Vec::new();
        for i in 0..n {
            let j = (i + 1) % n;
            let (lo, hi) = match z[i].total_cmp(&z[j]) {
                std::cmp::Ordering::Less => (i, j),
                std::cmp::Ordering::Greater => (j, i),
                std::cmp::Ordering::Equal => continue,
            };
            if z[lo] <= za && z[hi] >= zb {
                cuts.push([r_at(lo, hi, za), r_at(lo, hi, zb)]);
            }
        }
        cuts.sort_by(|a, b| (a[0] + a[1]).total_cmp(&(b[0] + b[1])));
        let crossing = cuts
            .windows(2)
            .any(|p| p[1][0] < p[0][0] || p[1][1] < p[0][1]);
        if crossing || !cuts.len().is_multiple_of(2) {
            return Err(bad(
                what,
                format!("the (r, z) polygon crosses itself between z = {za} and {zb}"),
            ));
        }
        for pair in cuts.chunks_exact(2) {
            let (inner, outer) = (pair[0], pair[1]);
            if outer[0] + outer[1] <= inner[0] + inner[1] {
                return Err(bad(
                    what,
                    format!("the (r, z) polygon has overlapping edges between z = {za} and {zb}"),
                ));
            }
            pieces.push(SlabPiece {
                z1: za,
                z2: zb,
                inner,
                outer,
            });
        }
    }
    Ok(pieces)
}

/// The (r, z) polygon revolved about z over `[sphi, sphi + dphi]` (G4Polycone,
/// G4GenericPolycone): the union over its slab pieces of `cone(outer) - cone(inner)`, cut
/// in phi.
fn revolved_polygon(
    what: &'static str,
    r: &[f64],
    z: &[f64],
    sphi: f64,
    dphi: f64,
) -> Result<Shape, CsgError> {
    let mut parts = Vec::new();
    for p in rz_slabs(what, r, z)? {
        let mut s = cone(p.outer[0], p.z1, p.outer[1], p.z2)?;
        if p.inner[0] > 0.0 || p.inner[1] > 0.0 {
            s = s - cone(p.inner[0], p.z1, p.inner[1], p.z2)?;
        }
        parts.push(s);
    }
    with_phi(union_of(parts), sphi, dphi)
}

/// The (r, z) polygon swept around a regular polygon of `numside` sides over
/// `[sphi, sphi + dphi]` (G4Polyhedra); a corner's radius times `apothem` is the distance
/// of the sides from the axis there. Each slab piece becomes convex polyhedra (one per run
/// of sides spanning at most pi when the range is partial), minus the inner ones.
fn swept_polygon(
    what: &'static str,
    r: &[f64],
    z: &[f64],
    sphi: f64,
    dphi: f64,
    numside: u32,
    apothem: f64,
) -> Result<Shape, CsgError> {
    if numside == 0 || (numside < 3 && dphi >= 2.0 * PI) {
        return Err(bad(
            what,
            format!("needs 3 or more sides (1 or more for a partial phi range), got {numside}"),
        ));
    }
    if !(sphi.is_finite() && dphi > 0.0 && dphi.is_finite()) {
        return Err(bad(
            what,
            format!("needs a finite phi range with dphi > 0, got {sphi} {dphi}"),
        ));
    }
    if apothem.is_nan() || apothem <= 0.0 {
        return Err(bad(
            what,
            format!("sides of {numside} over {dphi} rad must each span less than pi"),
        ));
    }
    let full = dphi >= 2.0 * PI;
    let dphi = dphi.min(2.0 * PI);
    let step = dphi / f64::from(numside);
    // A partial range is cut into runs of sides spanning at most pi each, so every piece
    // (closed by its radial planes) is convex.
    let per = if full {
        numside
    } else {
        ((PI / step).floor() as u32).clamp(1, numside)
    };
    let runs: Vec<std::ops::Range<u32>> = (0..numside)
        .step_by(per as usize)
        .map(|a| a..(a + per).min(numside))
        .collect();
    let scaled: Vec<f64> = r.iter().map(|v| v * apothem).collect();
    let mut parts = Vec::new();
    for p in rz_slabs(what, &scaled, z)? {
        for h in &runs {
            let section = |radii: [f64; 2]| {
                polygon_section(sphi, step, h.clone(), full, p.z1, p.z2, radii[0], radii[1])
            };
            let mut s = section(p.outer)?;
            if p.inner[0] > 0.0 || p.inner[1] > 0.0 {
                s = s - section(p.inner)?;
            }
            parts.push(s);
        }
    }
    Ok(union_of(parts))
}

/// A G4TwistedTubs (twist angle `twist` from -dz to +dz, end radii `end_inner` and
/// `end_outer`, half length `dz`, opening `dphi`) as an exact expression. With
/// `kappa = tan(twist / 2) / dz`, the solid is the image of the box `|a| <= dphi / 2`,
/// `r_in <= x <= r_out`, `|z| <= dz` under `(a, x, z) -> R_z(a) (x, kappa x z, z)`, where
/// `r_in, r_out` are the end radii times `cos(twist / 2)` (the waists): the geometry the
/// oracle established against Geant4. Its cross-section at height z is the annular sector
/// between the hyperboloids `r = r_in/out sqrt(1 + (kappa z)^2)` over the phi range
/// `atan(kappa z) +- dphi / 2`. Each side face `a = +-dphi / 2` lies on the hyperbolic
/// paraboloid `y = kappa x z` of a frame turned by `a`, and for `dphi <= pi` the sector is the
/// intersection of the two half-planes its sides bound: so the solid is
/// `(outer hyperboloid - inner hyperboloid) * saddle turned by dphi / 2 * saddle turned by
/// pi - dphi / 2` (the half-turn takes `y - kappa x z` to its negative: the other side).
fn twisted_tubs_shape(
    twist: f64,
    end_inner: f64,
    end_outer: f64,
    dz: f64,
    dphi: f64,
) -> Result<Shape, CsgError> {
    let what = "twistedTubs";
    if ![twist, end_inner, end_outer, dz, dphi]
        .iter()
        .all(|v| v.is_finite())
    {
        return Err(bad(what, "parameters must be finite".into()));
    }
    if !(end_inner > 0.0 && end_inner < end_outer && dz > 0.0) {
        return Err(bad(
            what,
            format!("needs 0 < endinnerrad < endouterrad and halfzlen > 0, got {end_inner} {end_outer} {dz}"),
        ));
    }
    // Geant4 (11.4) classifies points by both side surfaces at once, so a wider segment
    // behaves as the 2 pi - dphi one: only dphi <= pi is a solid of opening dphi.
    if !(dphi > 0.0 && dphi <= PI && twist.abs() < PI) {
        return Err(bad(
            what,
            format!("needs 0 < dphi <= pi and |twistedangle| < pi, got {dphi} {twist}"),
        ));
    }
    let half_twist = 0.5 * twist;
    let (r_in, r_out) = (end_inner * half_twist.cos(), end_outer * half_twist.cos());
    let kappa = half_twist.tan() / dz;
    let wall = hyperboloid(r_out, r_out * kappa.abs(), -dz, dz)?
        - hyperboloid(r_in, r_in * kappa.abs(), -dz, dz)?;
    let z = [0.0, 0.0, 1.0];
    let end_side = saddle(kappa)?.rotate(z, 0.5 * dphi);
    let start_side = saddle(kappa)?.rotate(z, PI - 0.5 * dphi);
    Ok(wall * end_side * start_side)
}

/// Most corners of one convex piece of a G4ExtrudedSolid: bounds the cost of checking the
/// piece's polyhedron (its vertex enumeration is quartic in the plane count).
const XTRU_MAX_PIECE_CORNERS: usize = 32;

/// A G4ExtrudedSolid's checked polygon: counter-clockwise, without repeated corners or
/// corners in line with their neighbours (as Geant4 keeps it); checks the sections too.
fn xtru_polygon(polygon: &[[f64; 2]], sections: &[XtruSection]) -> Result<Vec<[f64; 2]>, CsgError> {
    if sections.len() < 2
        || !sections.iter().all(|s| s.z.is_finite())
        || sections
            .windows(2)
            .any(|w| w[0].z.partial_cmp(&w[1].z) != Some(std::cmp::Ordering::Less))
    {
        return Err(bad(
            "xtru",
            "needs 2 or more sections with finite, increasing z".into(),
        ));
    }
    if sections
        .iter()
        .any(|s| !(s.scale.is_finite() && s.scale > 0.0 && s.offset.iter().all(|v| v.is_finite())))
    {
        return Err(bad(
            "xtru",
            "section scales must be finite and > 0, offsets finite".into(),
        ));
    }
    simple_polygon(polygon).map_err(|e| bad("xtru", e.problem))
}

/// Polygon point `p` in section `s`.
fn xtru_corner(s: &XtruSection, p: [f64; 2]) -> [f64; 3] {
    [
        s.scale * p[0] + s.offset[0],
        s.scale * p[1] + s.offset[1],
        s.z,
    ]
}

/// The sections that bound the solid's pieces: a section whose scale and offset are the
/// linear interpolation (in z, within 1e-12 of the solid's size) between its neighbours
/// kept on either side adds no edge and is dropped.
fn xtru_kept_sections<'a>(poly: &[[f64; 2]], sections: &'a [XtruSection]) -> Vec<&'a XtruSection> {
    let radius = poly
        .iter()
        .fold(0.0f64, |m, p| m.max(p[0].abs()).max(p[1].abs()));
    let size = sections.iter().fold(0.0f64, |m, s| {
        m.max(s.scale * radius + s.offset[0].abs() + s.offset[1].abs())
    });
    // Whether section `m` lies on the straight path from `a` to `b`.
    let between = |a: &XtruSection, m: &XtruSection, b: &XtruSection| {
        let f = (m.z - a.z) / (b.z - a.z);
        let lerp = |x: f64, y: f64| x + f * (y - x);
        (lerp(a.scale, b.scale) - m.scale).abs() * radius
            + (lerp(a.offset[0], b.offset[0]) - m.offset[0]).abs()
            + (lerp(a.offset[1], b.offset[1]) - m.offset[1]).abs()
            <= 1e-12 * size
    };
    let mut kept = vec![&sections[0]];
    let mut last = 0;
    for k in 1..sections.len() - 1 {
        // Keep k unless every section from the last kept one up to k lies on the path
        // from the last kept one to k + 1.
        let next = &sections[k + 1];
        if !(last + 1..=k).all(|m| between(&sections[last], &sections[m], next)) {
            kept.push(&sections[k]);
            last = k;
        }
    }
    kept.push(&sections[sections.len() - 1]);
    kept
}

/// The outer side of the face swept by polygon edge `i -> j` (to its right: outward for a
/// counter-clockwise piece) from section `a` to section `b`, `dot(n, x) <= d`. Between two
/// scaled and offset copies of the polygon the face is a planar trapezoid. The plane of
/// `j -> i` is computed as the exact negation of that of `i -> j`, so that two pieces
/// sharing a face see one plane from either side.
fn xtru_side_plane(
    poly: &[[f64; 2]],
    i: usize,
    j: usize,
    a: &XtruSection,
    b: &XtruSection,
) -> [f64; 4] {
    let (p, q) = (poly[i.min(j)], poly[i.max(j)]);
    // Outward normal of p -> q in the polygon's plane and its offset: m . x <= c inside.
    let m = [q[1] - p[1], p[0] - q[0]];
    let c = 0.5 * (m[0] * (p[0] + q[0]) + m[1] * (p[1] + q[1]));
    // At height z the section is s(z) poly + o(z), with s and o linear in z: a point x is
    // inside the edge's half-plane when m . (x - o(z)) <= c s(z), i.e. (times h)
    // h m . x - k z <= const.
    let h = b.z - a.z;
    let k = m[0] * (b.offset[0] - a.offset[0])
        + m[1] * (b.offset[1] - a.offset[1])
        + c * (b.scale - a.scale);
    let n = [h * m[0], h * m[1], -k];
    let d = [
        xtru_corner(a, p),
        xtru_corner(a, q),
        xtru_corner(b, p),
        xtru_corner(b, q),
    ]
    .iter()
    .map(|v| n[0] * v[0] + n[1] * v[1] + n[2] * v[2])
    .sum::<f64>()
        / 4.0;
    let plane = [n[0], n[1], n[2], d];
    if i < j {
        plane
    } else {
        plane.map(|v| -v)
    }
}

/// A G4ExtrudedSolid exactly: the polygon cut into convex pieces, each swept between two
/// consecutive (kept) sections into a convex polyhedron (two caps and one side plane per
/// piece edge); the solid is their union. Neighbouring pieces share whole faces, whose
/// planes are exact negations of each other.
fn xtru_shape(polygon: &[[f64; 2]], sections: &[XtruSection]) -> Result<Shape, CsgError> {
    let poly = xtru_polygon(polygon, sections)?;
    let pieces =
        convex_pieces(&poly, XTRU_MAX_PIECE_CORNERS).map_err(|e| bad("xtru", e.problem))?;
    let mut parts = Vec::new();
    for pair in xtru_kept_sections(&poly, sections).windows(2) {
        let (a, b) = (pair[0], pair[1]);
        for piece in &pieces {
            let mut planes = vec![[0.0, 0.0, -1.0, -a.z], [0.0, 0.0, 1.0, b.z]];
            planes.extend(
                (0..piece.len())
                    .map(|k| xtru_side_plane(&poly, piece[k], piece[(k + 1) % piece.len()], a, b)),
            );
            parts.push(polyhedron(&planes).map_err(|e| bad("xtru", e.problem))?);
        }
    }
    Ok(union_of(parts))
}

/// How a [`G4Solid`] becomes hytrace geometry.
pub trait G4Mapping {
    /// The equivalent CSG expression; impossible parameters give an error naming the solid.
    fn to_shape(&self) -> Result<Shape, CsgError>;
    /// The solid as an exact expression, or as a closed mesh within `tolerance` mm of the
    /// true surface for the solids with no analytic form here.
    fn to_geometry(&self, tolerance: f64) -> Result<G4Geometry, CsgError>;
}

impl G4Mapping for G4Solid {
    fn to_shape(&self) -> Result<Shape, CsgError> {
        match self {
            &G4Solid::Box { dx, dy, dz } => box3(2.0 * dx, 2.0 * dy, 2.0 * dz),
            &G4Solid::Orb { r } => sphere(r),
            &G4Solid::Sphere {
                rmin,
                rmax,
                sphi,
                dphi,
                stheta,
                dtheta,
            } => {
                let mut s = sphere(rmax)?;
                if rmin > 0.0 {
                    s = s - sphere(rmin)?;
                }
                let theta1 = (stheta + dtheta).min(PI);
                if stheta > 0.0 || theta1 < PI {
                    s = s * theta_cut(stheta, theta1)?;
                }
                with_phi(s, sphi, dphi)
            }
            &G4Solid::Tubs {
                rmin,
                rmax,
                dz,
                sphi,
                dphi,
            } => with_phi(tube(rmin, rmax, -dz, dz)?, sphi, dphi),
            &G4Solid::CutTubs {
                rmin,
                rmax,
                dz,
                sphi,
                dphi,
                low,
                high,
            } => {
                // The tube must reach past both tilted cut planes everywhere inside rmax.
                let reach = |n: [f64; 3]| rmax * (n[0] * n[0] + n[1] * n[1]).sqrt() / n[2].abs();
                if !(low[2] < 0.0 && high[2] > 0.0) {
                    return Err(bad(
                        "cutTubs",
                        format!("low normal needs z < 0 and high z > 0, got {low:?} {high:?}"),
                    ));
                }
                let h = dz + reach(low).max(reach(high)) + 1.0;
                let s = tube(rmin, rmax, -h, h)?
                    * halfspace(low, -dz * low[2])?
                    * halfspace(high, dz * high[2])?;
                with_phi(s, sphi, dphi)
            }
            &G4Solid::Cons {
                rmin1,
                rmax1,
                rmin2,
                rmax2,
                dz,
                sphi,
                dphi,
            } => {
                let mut s = cone(rmax1, -dz, rmax2, dz)?;
                if rmin1 > 0.0 || rmin2 > 0.0 {
                    s = s - cone(rmin1, -dz, rmin2, dz)?;
                }
                with_phi(s, sphi, dphi)
            }
            &G4Solid::Torus {
                rmin,
                rmax,
                rtor,
                sphi,
                dphi,
            } => with_phi(torus(rmin, rmax, rtor)?, sphi, dphi),
            &G4Solid::Trd {
                dx1,
                dx2,
                dy1,
                dy2,
                dz,
            } => hexahedron(&trap_vertices(
                dz, 0.0, 0.0, dy1, dx1, dx1, 0.0, dy2, dx2, dx2, 0.0,
            )),
            &G4Solid::Trap {
                dz,
                theta,
                phi,
                dy1,
                dx1,
                dx2,
                alpha1,
                dy2,
                dx3,
                dx4,
                alpha2,
            } => hexahedron(&trap_vertices(
                dz, theta, phi, dy1, dx1, dx2, alpha1, dy2, dx3, dx4, alpha2,
            )),
            &G4Solid::Para {
                dx,
                dy,
                dz,
                alpha,
                theta,
                phi,
            } => hexahedron(&trap_vertices(
                dz, theta, phi, dy, dx, dx, alpha, dy, dx, dx, alpha,
            )),
            G4Solid::Tet { anchor, p2, p3, p4 } => {
                let v = [*anchor, *p2, *p3, *p4];
                faces_to_polyhedron(&v, &[[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])
            }
            G4Solid::Polycone {
                sphi,
                dphi,
                z,
                rmin,
                rmax,
            } => {
                check_planes("polycone", z, rmin, rmax)?;
                let (r, z) = zplanes_to_rz(z, rmin, rmax);
                revolved_polygon("polycone", &r, &z, *sphi, *dphi)
            }
            G4Solid::GenericPolycone { sphi, dphi, r, z } => {
                revolved_polygon("genericPolycone", r, z, *sphi, *dphi)
            }
            G4Solid::Polyhedra {
                sphi,
                dphi,
                numside,
                z,
                rmin,
                rmax,
            } => {
                check_planes("polyhedra", z, rmin, rmax)?;
                let (r, z) = zplanes_to_rz(z, rmin, rmax);
                swept_polygon("polyhedra", &r, &z, *sphi, *dphi, *numside, 1.0)
            }
            G4Solid::GenericPolyhedra {
                sphi,
                dphi,
                numside,
                r,
                z,
            } => {
                // The rz-corner constructor's radii reach the polygon's corners (the z-plane
                // one's reach its sides): the sides lie at r cos(step / 2).
                let step = dphi.min(2.0 * PI) / f64::from(*numside);
                swept_polygon(
                    "genericPolyhedra",
                    r,
                    z,
                    *sphi,
                    *dphi,
                    *numside,
                    (0.5 * step).cos(),
                )
            }
            &G4Solid::Hype {
                rmin,
                rmax,
                stereo_in,
                stereo_out,
                dz,
            } => {
                let outer = hyperboloid(rmax, stereo_out.tan(), -dz, dz)?;
                if rmin > 0.0 {
                    Ok(outer - hyperboloid(rmin, stereo_in.tan(), -dz, dz)?)
                } else if stereo_in != 0.0 {
                    // A zero inner radius with a stereo angle is a double cone.
                    let r = dz * stereo_in.tan();
                    Ok(outer - (cone(r, -dz, 0.0, 0.0)? + cone(0.0, 0.0, r, dz)?))
                } else {
                    Ok(outer)
                }
            }
            &G4Solid::Paraboloid { dz, rlo, rhi } => paraboloid(rlo, rhi, dz),
            &G4Solid::Ellipsoid {
                ax,
                by,
                cz,
                zbottom,
                ztop,
            } => {
                if ax.is_nan() || by.is_nan() || ax <= 0.0 || by <= 0.0 {
                    return Err(bad(
                        "ellipsoid",
                        format!("semi-axes must be > 0, got {ax} {by}"),
                    ));
                }
                // G4Ellipsoid's constructor: both cuts zero means no cut; cuts beyond the
                // ellipsoid are clamped to it.
                let (zbottom, ztop) = if zbottom == 0.0 && ztop == 0.0 {
                    (-cz, cz)
                } else {
                    (zbottom.max(-cz), ztop.min(cz))
                };
                Ok(zsphere(cz, zbottom, ztop)?.scale(ax / cz, by / cz, 1.0))
            }
            &G4Solid::Eltube { dx, dy, dz } => {
                if dx.is_nan() || dx <= 0.0 {
                    return Err(bad("eltube", format!("dx must be > 0, got {dx}")));
                }
                Ok(cylinder(dy, -dz, dz)?.scale(dx / dy, 1.0, 1.0))
            }
            &G4Solid::Elcone {
                xsemi,
                ysemi,
                zheight,
                zcut,
            } => {
                if !(xsemi > 0.0 && ysemi > 0.0 && zcut > 0.0 && zcut < zheight) {
                    return Err(bad(
                        "elcone",
                        format!("needs semi-axes > 0 and 0 < zcut < zheight, got {xsemi} {ysemi} {zheight} {zcut}"),
                    ));
                }
                Ok(cone(zheight + zcut, -zcut, zheight - zcut, zcut)?.scale(xsemi, ysemi, 1.0))
            }
            G4Solid::GenericTrap { .. } | G4Solid::Tessellated { .. } => Err(bad(
                "geant4",
                format!(
                    "{} has no analytic form: it is a mesh (see to_geometry)",
                    self.kind()
                ),
            )),
            &G4Solid::TwistedBox {
                twistedangle,
                dx,
                dy,
                dz,
            } => twisted_trap_shape(
                "twistedBox",
                twistedangle,
                dz,
                0.0,
                0.0,
                dy,
                dx,
                dx,
                dy,
                dx,
                dx,
                0.0,
            ),
            &G4Solid::TwistedTrd {
                dx1,
                dx2,
                dy1,
                dy2,
                dz,
                twistedangle,
            } => twisted_trap_shape(
                "twistedTrd",
                twistedangle,
                dz,
                0.0,
                0.0,
                dy1,
                dx1,
                dx1,
                dy2,
                dx2,
                dx2,
                0.0,
            ),
            &G4Solid::TwistedTrap {
                twistedangle,
                dz,
                theta,
                phi,
                dy1,
                dx1,
                dx2,
                dy2,
                dx3,
                dx4,
                alpha,
            } => twisted_trap_shape(
                "twistedTrap",
                twistedangle,
                dz,
                theta,
                phi,
                dy1,
                dx1,
                dx2,
                dy2,
                dx3,
                dx4,
                alpha,
            ),
            &G4Solid::TwistedTubs {
                twistedangle,
                endinnerrad,
                endouterrad,
                halfzlen,
                dphi,
            } => twisted_tubs_shape(twistedangle, endinnerrad, endouterrad, halfzlen, dphi),
            G4Solid::Xtru { polygon, sections } => xtru_shape(polygon, sections),
            G4Solid::MultiUnion { parts } => {
                if parts.is_empty() {
                    return Err(bad("multiUnion", "has no solids".into()));
                }
                let shapes = parts
                    .iter()
                    .map(placed_shape)
                    .collect::<Result<Vec<_>, _>>()?;
                Ok(union_of(shapes))
            }
            G4Solid::Displaced(p) => placed_shape(p),
            G4Solid::Union(b) => Ok(b.a.to_shape()? + boolean_b(b)?),
            G4Solid::Subtraction(b) => Ok(b.a.to_shape()? - boolean_b(b)?),
            G4Solid::Intersection(b) => Ok(b.a.to_shape()? * boolean_b(b)?),
        }
    }

    fn to_geometry(&self, tolerance: f64) -> Result<G4Geometry, CsgError> {
        let mesh = |tris: Vec<Tri>| Ok(G4Geometry::Mesh(tris));
        match self {
            G4Solid::GenericTrap { dz, vertices } => {
                let dz = *dz;
                let [bottom, top] = generic_trap_ends(dz, vertices)?;
                let section = |z: f64| {
                    let f = (z + dz) / (2.0 * dz);
                    // Exactly the given vertices at the ends, so that coincident ones stay
                    // coincident at every height.
                    let at = |b: f64, t: f64| {
                        if f <= 0.0 {
                            b
                        } else if f >= 1.0 {
                            t
                        } else {
                            b + f * (t - b)
                        }
                    };
                    (0..4)
                        .map(|k| {
                            let (b, t) = (bottom[k], top[k]);
                            [at(b[0], t[0]), at(b[1], t[1]), z]
                        })
                        .collect()
                };
                mesh(ruled_solid(&section, -dz, dz, tolerance)?)
            }
            G4Solid::Xtru { polygon, sections } => {
                let poly = xtru_polygon(polygon, sections)?;
                let levels: Vec<Vec<[f64; 3]>> = sections
                    .iter()
                    .map(|s| poly.iter().map(|&p| xtru_corner(s, p)).collect())
                    .collect();
                let corners: Vec<usize> = (0..poly.len()).collect();
                mesh(section_stack(&levels, &corners)?)
            }
            G4Solid::Tessellated { facets } => {
                let mut tris: Vec<Tri> = Vec::with_capacity(facets.len());
                for (i, f) in facets.iter().enumerate() {
                    if !(f.len() == 3 || f.len() == 4) || !f.iter().flatten().all(|v| v.is_finite())
                    {
                        return Err(bad(
                            "tessellated",
                            format!("facet {i}: needs 3 or 4 finite vertices, got {}", f.len()),
                        ));
                    }
                    tris.push([f[0], f[1], f[2]]);
                    if f.len() == 4 {
                        tris.push([f[0], f[2], f[3]]);
                    }
                }
                mesh(tris)
            }
            G4Solid::Displaced(p) => match p.solid.to_geometry(tolerance)? {
                G4Geometry::Csg(_) => self.to_shape().map(G4Geometry::Csg),
                G4Geometry::Mesh(tris) => {
                    let m = affine(&p.matrix, &p.translation, "displaced")?;
                    let mirrored = m.linear_determinant() < 0.0;
                    mesh(
                        tris.iter()
                            .map(|t| {
                                let mut v = t.map(|q| m.apply_point(q));
                                // A reflection turns counter-clockwise faces clockwise.
                                if mirrored {
                                    v.swap(1, 2);
                                }
                                v
                            })
                            .collect(),
                    )
                }
            },
            other => other.to_shape().map(G4Geometry::Csg),
        }
    }
}

/// The affine map `p -> matrix * p + translation`, checked to be finite and invertible.
fn affine(
    matrix: &[[f64; 3]; 3],
    translation: &[f64; 3],
    what: &'static str,
) -> Result<Transform64, CsgError> {
    let (r, t) = (matrix, translation);
    let m = Transform64 {
        rows: [
            [r[0][0], r[0][1], r[0][2], t[0]],
            [r[1][0], r[1][1], r[1][2], t[1]],
            [r[2][0], r[2][1], r[2][2], t[2]],
            [0.0, 0.0, 0.0, 1.0],
        ],
    };
    if !m.is_affine() || m.inverse().is_none() {
        return Err(bad(
            what,
            format!("singular or non-finite placement {r:?} {t:?}"),
        ));
    }
    Ok(m)
}

/// A boolean's second operand in the first one's frame.
fn boolean_b(b: &Boolean) -> Result<Shape, CsgError> {
    Ok(b.b
        .to_shape()?
        .placed(affine(&b.rotation, &b.translation, "boolean")?))
}

/// A placed solid's expression in the outer frame.
fn placed_shape(p: &PlacedSolid) -> Result<Shape, CsgError> {
    Ok(p.solid
        .to_shape()?
        .placed(affine(&p.matrix, &p.translation, "displaced")?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::Primitive;

    #[test]
    fn json_round_trip_of_a_boolean() {
        let j = r#"{"type":"subtraction","a":{"type":"box","dx":1,"dy":2,"dz":3},
            "b":{"type":"tubs","rmin":0,"rmax":1,"dz":5,"sphi":0,"dphi":7},
            "rotation":[[1,0,0],[0,1,0],[0,0,1]],"translation":[0,0,1]}"#;
        let s: G4Solid = serde_json::from_str(j).unwrap();
        assert!(matches!(s, G4Solid::Subtraction(_)));
        assert!(s.to_shape().is_ok());
        let bad: Result<G4Solid, _> = serde_json::from_str(r#"{"type":"box","dx":1}"#);
        assert!(bad.is_err());
        let unknown: Result<G4Solid, _> = serde_json::from_str(r#"{"type":"twistedBox"}"#);
        assert!(unknown.is_err());
    }

    #[test]
    fn impossible_parameters_are_errors_not_panics() {
        let cases = [
            G4Solid::Box {
                dx: 0.0,
                dy: 1.0,
                dz: 1.0,
            },
            G4Solid::Tubs {
                rmin: 2.0,
                rmax: 1.0,
                dz: 1.0,
                sphi: 0.0,
                dphi: 1.0,
            },
            G4Solid::Torus {
                rmin: 0.0,
                rmax: 2.0,
                rtor: 1.0,
                sphi: 0.0,
                dphi: 7.0,
            },
            G4Solid::Polycone {
                sphi: 0.0,
                dphi: 7.0,
                z: vec![0.0],
                rmin: vec![0.0],
                rmax: vec![1.0],
            },
            G4Solid::Tubs {
                rmin: 0.0,
                rmax: 1.0,
                dz: 1.0,
                sphi: 0.0,
                dphi: 0.0,
            },
        ];
        for c in cases {
            assert!(c.to_shape().is_err(), "{c:?}");
        }
    }
    fn generic_polycone(r: &[f64], z: &[f64]) -> G4Solid {
        G4Solid::GenericPolycone {
            sphi: 0.0,
            dphi: 7.0,
            r: r.to_vec(),
            z: z.to_vec(),
        }
    }

    fn generic_polyhedra(numside: u32, r: &[f64], z: &[f64]) -> G4Solid {
        G4Solid::GenericPolyhedra {
            sphi: 0.0,
            dphi: 7.0,
            numside,
            r: r.to_vec(),
            z: z.to_vec(),
        }
    }

    #[test]
    fn invalid_rz_polygons_are_errors_not_panics() {
        let nan = f64::NAN;
        let cases: [(&[f64], &[f64]); 8] = [
            // fewer than 3 corners, or mismatched lengths
            (&[1.0, 2.0], &[0.0, 1.0]),
            (&[1.0, 2.0, 2.0], &[0.0, 1.0]),
            // NaN, infinite, negative radius
            (&[1.0, nan, 2.0], &[0.0, 1.0, 2.0]),
            (&[1.0, 2.0, 2.0], &[0.0, f64::INFINITY, 2.0]),
            (&[1.0, -2.0, 2.0], &[0.0, 1.0, 2.0]),
            // zero area: collinear corners, all at one z
            (&[0.0, 1.0, 2.0], &[0.0, 1.0, 2.0]),
            (&[0.0, 1.0, 2.0, 3.0], &[5.0, 5.0, 5.0, 5.0]),
            // a bow tie: its edges cross
            (&[1.0, 3.0, 3.0, 1.0], &[0.0, 2.0, 0.0, 2.0]),
        ];
        for (r, z) in cases {
            let e = generic_polycone(r, z).to_shape().unwrap_err();
            assert_eq!(e.primitive, "genericPolycone", "{r:?} {z:?}: {e}");
            let e = generic_polyhedra(6, r, z).to_shape().unwrap_err();
            assert_eq!(e.primitive, "genericPolyhedra", "{r:?} {z:?}: {e}");
        }
        // Too few sides, a zero or NaN phi range.
        let square = ([1.0, 2.0, 2.0, 1.0], [0.0, 0.0, 1.0, 1.0]);
        assert!(generic_polyhedra(2, &square.0, &square.1)
            .to_shape()
            .is_err());
        assert!(generic_polyhedra(0, &square.0, &square.1)
            .to_shape()
            .is_err());
        for dphi in [0.0, -1.0, nan] {
            let s = G4Solid::GenericPolyhedra {
                sphi: 0.0,
                dphi,
                numside: 4,
                r: square.0.to_vec(),
                z: square.1.to_vec(),
            };
            assert!(s.to_shape().is_err(), "{dphi}");
            let s = G4Solid::GenericPolycone {
                sphi: 0.0,
                dphi,
                r: square.0.to_vec(),
                z: square.1.to_vec(),
            };
            assert!(s.to_shape().is_err(), "{dphi}");
        }
        // One side spanning more than pi has no convex polyhedron.
        let wide = G4Solid::GenericPolyhedra {
            sphi: 0.0,
            dphi: 4.0,
            numside: 1,
            r: square.0.to_vec(),
            z: square.1.to_vec(),
        };
        assert!(wide.to_shape().is_err());
    }

    #[test]
    fn twisted_tubs_parameters_are_checked() {
        let ok = G4Solid::TwistedTubs {
            twistedangle: 0.6,
            endinnerrad: 2.0,
            endouterrad: 5.0,
            halfzlen: 4.0,
            dphi: 1.0,
        };
        // An exact expression whatever the tessellation tolerance.
        assert!(matches!(ok.to_geometry(1e-2), Ok(G4Geometry::Csg(_))));
        assert!(ok.to_shape().is_ok());
        // (parameter index, bad value) in (twistedangle, endinnerrad, endouterrad,
        // halfzlen, dphi).
        let bad_cases = [
            (0, 3.5),      // twist beyond pi
            (0, f64::NAN), // NaN twist
            (1, 0.0),      // no inner radius (Geant4 needs one)
            (1, 6.0),      // inner beyond outer
            (2, f64::NAN),
            (3, 0.0), // no length
            (3, f64::INFINITY),
            (4, 0.0), // no opening
            (4, 4.0), // wider than pi
        ];
        for (i, v) in bad_cases {
            let mut p = [0.6, 2.0, 5.0, 4.0, 1.0];
            p[i] = v;
            let s = G4Solid::TwistedTubs {
                twistedangle: p[0],
                endinnerrad: p[1],
                endouterrad: p[2],
                halfzlen: p[3],
                dphi: p[4],
            };
            assert!(s.to_geometry(1e-2).is_err(), "{s:?}");
            assert!(s.to_shape().is_err(), "{s:?}");
        }
    }

    #[test]
    fn zplane_and_corner_forms_are_one_construction() {
        // A z-plane polycone equals its corner polygon (up the outer radii, down the inner).
        let zp = G4Solid::Polycone {
            sphi: 0.5,
            dphi: 2.0,
            z: vec![-3.0, 0.0, 0.0, 4.0],
            rmin: vec![0.0, 1.0, 2.0, 1.0],
            rmax: vec![2.0, 3.0, 4.0, 5.0],
        };
        let rz = G4Solid::GenericPolycone {
            sphi: 0.5,
            dphi: 2.0,
            r: vec![2.0, 3.0, 4.0, 5.0, 1.0, 2.0, 1.0, 0.0],
            z: vec![-3.0, 0.0, 0.0, 4.0, 4.0, 0.0, 0.0, -3.0],
        };
        assert_eq!(zp.to_shape().unwrap(), rz.to_shape().unwrap());
        // Reversed corner order, another starting corner: the same solid.
        let mut r: Vec<f64> = vec![2.0, 3.0, 4.0, 5.0, 1.0, 2.0, 1.0, 0.0];
        let mut z: Vec<f64> = vec![-3.0, 0.0, 0.0, 4.0, 4.0, 0.0, 0.0, -3.0];
        r.reverse();
        z.reverse();
        r.rotate_left(3);
        z.rotate_left(3);
        let again = G4Solid::GenericPolycone {
            sphi: 0.5,
            dphi: 2.0,
            r,
            z,
        };
        assert_eq!(again.to_shape().unwrap(), rz.to_shape().unwrap());
        // The rz-corner polyhedra's radii reach the corners: scaled by cos(pi / 6) they
        // are the z-plane form's side distances.
        let c = (PI / 6.0).cos();
        let sides = G4Solid::Polyhedra {
            sphi: 0.0,
            dphi: 7.0,
            numside: 6,
            z: vec![-1.0, 1.0],
            rmin: vec![0.0, 0.0],
            rmax: vec![2.0 * c, 3.0 * c],
        };
        let corners = generic_polyhedra(6, &[0.0, 2.0, 3.0, 0.0], &[-1.0, -1.0, 1.0, 1.0]);
        let (a, b) = (sides.to_shape().unwrap(), corners.to_shape().unwrap());
        let probe = |s: &Shape, p: [f64; 3]| {
            crate::PrimTree::<f64>::from_shape(s)
                .unwrap()
                .contains(crate::V3::from_f64(p))
        };
        // Just inside and just outside a corner (phi = 0) and a side centre (phi = pi/6).
        for (p, inside) in [
            ([2.49, 0.0, 0.0], true),
            ([2.51, 0.0, 0.0], false),
            ([2.49 * c * c, 2.49 * c * 0.5, 0.0], true),
            ([2.51 * c * c, 2.51 * c * 0.5, 0.0], false),
        ] {
            assert_eq!(probe(&a, p), inside, "{p:?}");
            assert_eq!(probe(&b, p), inside, "{p:?}");
        }
    }

    fn xtru(polygon: &[[f64; 2]], sections: &[(f64, [f64; 2], f64)]) -> G4Solid {
        G4Solid::Xtru {
            polygon: polygon.to_vec(),
            sections: sections
                .iter()
                .map(|&(z, offset, scale)| XtruSection { z, offset, scale })
                .collect(),
        }
    }

    /// The convex polyhedra of an expression.
    fn polyhedra(s: &Shape) -> usize {
        match s {
            Shape::Leaf(Primitive::Polyhedron { .. }) => 1,
            Shape::Leaf(_) => 0,
            Shape::Op(_, a, b) => polyhedra(a) + polyhedra(b),
            Shape::Placed(_, a) | Shape::Complement(a) => polyhedra(a),
        }
    }

    const U_SHAPE: [[f64; 2]; 8] = [
        [-300.0, -300.0],
        [-300.0, 300.0],
        [300.0, 300.0],
        [300.0, -300.0],
        [150.0, -300.0],
        [150.0, 150.0],
        [-150.0, 150.0],
        [-150.0, -300.0],
    ];

    #[test]
    fn xtru_is_a_union_of_convex_polyhedra() {
        let l = [
            [0.0, 0.0],
            [20.0, 0.0],
            [20.0, 10.0],
            [10.0, 10.0],
            [10.0, 20.0],
            [0.0, 20.0],
        ];
        let prism = [(-5.0, [0.0, 0.0], 1.0), (5.0, [0.0, 0.0], 1.0)];
        assert_eq!(polyhedra(&xtru(&l, &prism).to_shape().unwrap()), 2);
        // Sections on one straight path (here: identical) add no pieces.
        let stacked = [
            (-5.0, [0.0, 0.0], 1.0),
            (-1.0, [0.0, 0.0], 1.0),
            (5.0, [0.0, 0.0], 1.0),
        ];
        assert_eq!(polyhedra(&xtru(&l, &stacked).to_shape().unwrap()), 2);
        let tapered = [
            (-5.0, [0.0, 0.0], 1.0),
            (0.0, [1.0, -2.0], 0.75),
            (5.0, [2.0, -4.0], 0.5),
        ];
        assert_eq!(polyhedra(&xtru(&l, &tapered).to_shape().unwrap()), 2);
        // GDML's scaledSolids "Xtru1S": a U, clockwise, three corners on y = -300, four
        // sections on no straight path: 3 pieces in each of 3 slabs.
        let u = xtru(
            &U_SHAPE,
            &[
                (-400.0, [-200.0, 100.0], 1.5),
                (100.0, [0.0, 0.0], 0.5),
                (150.0, [0.0, 0.0], 0.7),
                (400.0, [200.0, 200.0], 0.9),
            ],
        );
        let shape = u.to_shape().unwrap();
        assert_eq!(polyhedra(&shape), 9);
        // It is a valid operand: a union of two of them builds.
        let b = Boolean {
            a: Box::new(u.clone()),
            b: Box::new(u),
            rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            translation: [10.0, 0.0, 0.0],
        };
        let union = G4Solid::Union(b);
        assert!(matches!(union.to_geometry(1e-2), Ok(G4Geometry::Csg(_))));
        assert!(crate::PrimTree::<f32>::from_shape(&union.to_shape().unwrap()).is_ok());
        // Standing alone it stays an exact mesh.
        assert!(matches!(
            xtru(&l, &prism).to_geometry(1e-2),
            Ok(G4Geometry::Mesh(_))
        ));
    }

    #[test]
    fn xtru_inside_test_follows_the_sections() {
        let sections = [
            (-400.0, [-200.0, 100.0], 1.5),
            (100.0, [0.0, 0.0], 0.5),
            (150.0, [0.0, 0.0], 0.7),
            (400.0, [200.0, 200.0], 0.9),
        ];
        let tree =
            crate::PrimTree::<f64>::from_shape(&xtru(&U_SHAPE, &sections).to_shape().unwrap())
                .unwrap();
        // Even-odd test of the section at z.
        let inside = |p: [f64; 3]| {
            let Some(k) = sections
                .windows(2)
                .position(|w| w[0].0 <= p[2] && p[2] <= w[1].0)
            else {
                return false;
            };
            let (a, b) = (sections[k], sections[k + 1]);
            let f = (p[2] - a.0) / (b.0 - a.0);
            let s = a.2 + f * (b.2 - a.2);
            let q = [0, 1].map(|i| (p[i] - (a.1[i] + f * (b.1[i] - a.1[i]))) / s);
            let mut odd = false;
            for i in 0..U_SHAPE.len() {
                let (u, v) = (U_SHAPE[i], U_SHAPE[(i + 1) % U_SHAPE.len()]);
                if (u[1] > q[1]) != (v[1] > q[1])
                    && q[0] < u[0] + (v[0] - u[0]) * (q[1] - u[1]) / (v[1] - u[1])
                {
                    odd = !odd;
                }
            }
            odd
        };
        let mut seed = 777u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut count = 0;
        for _ in 0..20000 {
            let p = [
                -700.0 + 1200.0 * next(),
                -500.0 + 1000.0 * next(),
                -450.0 + 900.0 * next(),
            ];
            let want = inside(p);
            assert_eq!(tree.contains(crate::V3::from_f64(p)), want, "{p:?}");
            count += want as usize;
        }
        assert!(count > 2000, "{count}");
    }

    #[test]
    fn impossible_xtru_parameters_are_errors_not_panics() {
        let square = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let ok = [(0.0, [0.0, 0.0], 1.0), (1.0, [0.0, 0.0], 1.0)];
        let nan = f64::NAN;
        let cases = [
            // self-crossing (a bow tie), touching itself, no area, too few corners
            xtru(&[[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]], &ok),
            xtru(
                &[
                    [0.0, 0.0],
                    [4.0, 0.0],
                    [4.0, 2.0],
                    [2.0, 2.0],
                    [3.0, 3.0],
                    [1.0, 3.0],
                    [2.0, 2.0],
                    [0.0, 2.0],
                ],
                &ok,
            ),
            xtru(&[[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]], &ok),
            xtru(&[[0.0, 0.0], [1.0, 1.0]], &ok),
            xtru(&[[0.0, 0.0], [1.0, nan], [0.0, 1.0]], &ok),
            // sections: one, not increasing, repeated, NaN or infinite z, bad scales
            xtru(&square, &ok[..1]),
            xtru(&square, &[ok[1], ok[0]]),
            xtru(&square, &[ok[0], ok[0]]),
            xtru(&square, &[ok[0], (nan, [0.0, 0.0], 1.0)]),
            xtru(&square, &[ok[0], (f64::INFINITY, [0.0, 0.0], 1.0)]),
            xtru(&square, &[ok[0], (1.0, [0.0, 0.0], 0.0)]),
            xtru(&square, &[ok[0], (1.0, [0.0, 0.0], -1.0)]),
            xtru(&square, &[ok[0], (1.0, [0.0, 0.0], nan)]),
            xtru(&square, &[ok[0], (1.0, [nan, 0.0], 1.0)]),
        ];
        for c in cases {
            let e = c.to_shape().unwrap_err();
            assert_eq!(e.primitive, "xtru", "{c:?}: {e}");
            assert!(c.to_geometry(1e-2).is_err(), "{c:?}");
            // As a boolean operand the error comes through.
            let u = G4Solid::Union(Boolean {
                a: Box::new(G4Solid::Box {
                    dx: 1.0,
                    dy: 1.0,
                    dz: 1.0,
                }),
                b: Box::new(c),
                rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                translation: [0.0; 3],
            });
            assert!(u.to_shape().is_err());
        }
    }

    /// Even-odd point-in-polygon test in the (r, z) half-plane.
    fn in_rz(r: &[f64], z: &[f64], pr: f64, pz: f64) -> bool {
        let n = r.len();
        let mut inside = false;
        for i in 0..n {
            let j = (i + 1) % n;
            if (z[i] > pz) != (z[j] > pz) {
                let x = r[i] + (r[j] - r[i]) * (pz - z[i]) / (z[j] - z[i]);
                if pr < x {
                    inside = !inside;
                }
            }
        }
        inside
    }

    #[test]
    fn non_convex_rz_polygons_revolve_exactly() {
        // A "C" opening outwards with an overhang (the edge from (2, 1) down to (7, 0)) and
        // corners on the axis: slabs with two (inner, outer) pairs and pieces without an
        // inner boundary.
        let r = [0.0, 6.0, 6.0, 2.0, 2.0, 7.0, 5.0, 0.0, 0.0];
        let z = [-5.0, -5.0, -3.0, -2.0, 1.0, 0.0, 6.0, 4.0, 1.0];
        let sphi = -0.4;
        let dphi = 4.0;
        let cone_solid = G4Solid::GenericPolycone {
            sphi,
            dphi,
            r: r.to_vec(),
            z: z.to_vec(),
        };
        let numside = 5u32;
        let poly_solid = G4Solid::GenericPolyhedra {
            sphi,
            dphi,
            numside,
            r: r.to_vec(),
            z: z.to_vec(),
        };
        let step = dphi / f64::from(numside);
        let trees = [cone_solid, poly_solid]
            .map(|s| crate::PrimTree::<f64>::from_shape(&s.to_shape().unwrap()).unwrap());
        let mut seed = 12345u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut inside_count = [0usize; 2];
        for _ in 0..20000 {
            let p = [
                -8.0 + 16.0 * next(),
                -8.0 + 16.0 * next(),
                -6.0 + 13.0 * next(),
            ];
            let phi = (p[1].atan2(p[0]) - sphi).rem_euclid(2.0 * PI);
            let rho = p[0].hypot(p[1]);
            let in_phi = phi < dphi;
            // The polygon sweep: the distance to the side plane of the point's sector,
            // over the apothem factor, is the corner-polygon radius.
            let side = ((phi / step).floor() + 0.5) * step + sphi;
            let rho_poly = (p[0] * side.cos() + p[1] * side.sin()) / (0.5 * step).cos();
            let want = [
                in_phi && in_rz(&r, &z, rho, p[2]),
                in_phi && in_rz(&r, &z, rho_poly, p[2]),
            ];
            for (k, tree) in trees.iter().enumerate() {
                let got = tree.contains(crate::V3::from_f64(p));
                assert_eq!(got, want[k], "solid {k} at {p:?}");
                inside_count[k] += got as usize;
            }
        }
        assert!(inside_count.iter().all(|&c| c > 1000), "{inside_count:?}");
    }

    /// G4Ellipsoid's constructor reads zero cuts at both ends as no cut (testG4Ellipsoid
    /// builds one so), and clamps cuts beyond the ellipsoid to it.
    #[test]
    fn ellipsoid_cuts_read_as_geant4_reads_them() {
        let ellipsoid = |zbottom, ztop| G4Solid::Ellipsoid {
            ax: 11.0,
            by: 8.0,
            cz: 10.0,
            zbottom,
            ztop,
        };
        let whole = ellipsoid(-10.0, 10.0).to_shape().unwrap();
        assert_eq!(ellipsoid(0.0, 0.0).to_shape().unwrap(), whole);
        assert_eq!(ellipsoid(-20.0, 30.0).to_shape().unwrap(), whole);
        assert_ne!(ellipsoid(0.0, 5.0).to_shape().unwrap(), whole);
    }
}
