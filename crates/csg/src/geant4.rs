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
//! | G4Polycone | (union of cones - union of inner cones) * phi cut |
//! | G4Polyhedra | union of convex polyhedra (one per z section and phi half) minus the inner ones |
//! | G4Hype | hyperboloid - inner hyperboloid (or inner double cone) |
//! | G4Paraboloid | paraboloid |
//! | G4Ellipsoid, G4EllipticalTube, G4EllipticalCone | scaled z-cut sphere, cylinder, cone |
//! | G4UnionSolid, G4SubtractionSolid, G4IntersectionSolid | `+`, `-`, `*` |
//!
//! Booleans place their second operand by `p_first = rotation * p_second + translation`
//! (the `G4Transform3D` form: the rotation applies to the solid, not the frame).
//!
//! The JSON form (`{"type": "tubs", "rmin": ..., ...}`) is the one written by the project's
//! Geant4 oracle, `tests/oracle/geant4_oracle.py`.

use std::f64::consts::PI;

use crate::shape::{
    box3, cone, cylinder, halfspace, hyperboloid, paraboloid, phi_cut, polyhedron, sphere,
    theta_cut, torus, tube, zsphere, CsgError, Shape,
};
use crate::tessellate::{ruled_solid, section_stack, signed_area2, Tri};
use hytrace_foundry::Transform64;

pub use hytrace_foundry::g4solid::{Boolean, G4Solid, PlacedSolid, XtruSection};

/// What a Geant4 solid becomes: an exact CSG expression, or a closed triangle mesh where
/// no analytic form exists here (twisted solids, extrusions, tessellated solids).
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

/// A convex polyhedron from faces given as vertex indices; each face's plane comes from
/// Newell's method and is oriented away from the centroid.
fn faces_to_polyhedron<const N: usize>(
    v: &[[f64; 3]],
    faces: &[[usize; N]],
) -> Result<Shape, CsgError> {
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
    polyhedron(&planes)
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

/// The mesh of a G4TwistedTrap (G4TwistedBox and G4TwistedTrd are special cases): at
/// height z the trapezoid interpolated between its end sections, rotated counter-clockwise
/// by `twist * z / (2 dz)`, then shifted along the (theta, phi) axis (the geometry the
/// oracle established against Geant4).
#[allow(clippy::too_many_arguments)]
fn twisted_trap_mesh(
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
    tolerance: f64,
) -> Result<Vec<Tri>, CsgError> {
    let lengths = [dz, dy1, dx1, dx2, dy2, dx3, dx4];
    if !lengths.iter().all(|x| x.is_finite() && *x > 0.0) {
        return Err(bad(
            what,
            format!("lengths must be finite and > 0, got {lengths:?}"),
        ));
    }
    let (tx, ty) = (theta.tan() * phi.cos(), theta.tan() * phi.sin());
    let ta = alpha.tan();
    let section = |z: f64| {
        let f = (z + dz) / (2.0 * dz);
        let t = trapezoid(
            dy1 + f * (dy2 - dy1),
            ta,
            dx1 + f * (dx3 - dx1),
            dx2 + f * (dx4 - dx2),
        );
        let (s, c) = (twist * z / (2.0 * dz)).sin_cos();
        // Counter-clockwise corner order for the section stack.
        [t[0], t[1], t[3], t[2]]
            .map(|p| {
                [
                    c * p[0] - s * p[1] + z * tx,
                    s * p[0] + c * p[1] + z * ty,
                    z,
                ]
            })
            .to_vec()
    };
    ruled_solid(&section, -dz, dz, tolerance)
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
                let (mut outer, mut inner) = (Vec::new(), Vec::new());
                for i in 0..z.len() - 1 {
                    if z[i + 1] == z[i] {
                        continue;
                    }
                    outer.push(cone(rmax[i], z[i], rmax[i + 1], z[i + 1])?);
                    if rmin[i] > 0.0 || rmin[i + 1] > 0.0 {
                        inner.push(cone(rmin[i], z[i], rmin[i + 1], z[i + 1])?);
                    }
                }
                if outer.is_empty() {
                    return Err(bad("polycone", "all sections have zero height".into()));
                }
                let mut s = union_of(outer);
                if !inner.is_empty() {
                    s = s - union_of(inner);
                }
                with_phi(s, *sphi, *dphi)
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
                if *numside < 3 && *dphi >= 2.0 * PI {
                    return Err(bad(
                        "polyhedra",
                        format!("needs 3 or more sides, got {numside}"),
                    ));
                }
                if *numside == 0 {
                    return Err(bad("polyhedra", "needs at least one side".into()));
                }
                let full = *dphi >= 2.0 * PI;
                let dphi = dphi.min(2.0 * PI);
                let step = dphi / *numside as f64;
                // Partial ranges wider than pi are split so every piece is convex.
                let split = if full || dphi <= PI || *numside < 2 {
                    *numside
                } else {
                    numside / 2
                };
                let halves: Vec<std::ops::Range<u32>> = [0..split, split..*numside]
                    .into_iter()
                    .filter(|r| !r.is_empty())
                    .collect();
                let (mut outer, mut inner) = (Vec::new(), Vec::new());
                for i in 0..z.len() - 1 {
                    if z[i + 1] == z[i] {
                        continue;
                    }
                    for h in &halves {
                        let (z1, z2) = (z[i], z[i + 1]);
                        outer.push(polygon_section(
                            *sphi,
                            step,
                            h.clone(),
                            full,
                            z1,
                            z2,
                            rmax[i],
                            rmax[i + 1],
                        )?);
                        if rmin[i] > 0.0 || rmin[i + 1] > 0.0 {
                            inner.push(polygon_section(
                                *sphi,
                                step,
                                h.clone(),
                                full,
                                z1,
                                z2,
                                rmin[i],
                                rmin[i + 1],
                            )?);
                        }
                    }
                }
                if outer.is_empty() {
                    return Err(bad("polyhedra", "all sections have zero height".into()));
                }
                let s = union_of(outer);
                Ok(if inner.is_empty() {
                    s
                } else {
                    s - union_of(inner)
                })
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
            G4Solid::TwistedBox { .. }
            | G4Solid::TwistedTrd { .. }
            | G4Solid::TwistedTrap { .. }
            | G4Solid::GenericTrap { .. }
            | G4Solid::Xtru { .. }
            | G4Solid::Tessellated { .. }
            | G4Solid::TwistedTubs { .. } => Err(bad(
                "geant4",
                format!(
                    "{} has no analytic form: it is a mesh (see to_geometry)",
                    self.kind()
                ),
            )),
            G4Solid::GenericPolycone { .. } | G4Solid::GenericPolyhedra { .. } => Err(bad(
                "geant4",
                format!("{} is not mapped yet", self.kind()),
            )),
            G4Solid::MultiUnion { parts } => {
                if parts.is_empty() {
                    return Err(bad("multiUnion", "has no solids".into()));
                }
                let shapes = parts.iter().map(placed_shape).collect::<Result<Vec<_>, _>>()?;
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
            &G4Solid::TwistedBox {
                twistedangle,
                dx,
                dy,
                dz,
            } => mesh(twisted_trap_mesh(
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
                tolerance,
            )?),
            &G4Solid::TwistedTrd {
                dx1,
                dx2,
                dy1,
                dy2,
                dz,
                twistedangle,
            } => mesh(twisted_trap_mesh(
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
                tolerance,
            )?),
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
            } => mesh(twisted_trap_mesh(
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
                tolerance,
            )?),
            G4Solid::GenericTrap { dz, vertices } => {
                let dz = *dz;
                if dz.is_nan() || dz <= 0.0 || dz.is_infinite() {
                    return Err(bad(
                        "genericTrap",
                        format!("dz must be finite and > 0, got {dz}"),
                    ));
                }
                if vertices.len() != 8 || !vertices.iter().flatten().all(|v| v.is_finite()) {
                    return Err(bad(
                        "genericTrap",
                        format!("needs 8 finite vertices, got {}", vertices.len()),
                    ));
                }
                let (mut bottom, mut top) = (vertices[..4].to_vec(), vertices[4..].to_vec());
                // Geant4 lists the vertices clockwise; sections run counter-clockwise.
                let area = signed_area2(&bottom) + signed_area2(&top);
                if area < 0.0 {
                    bottom.reverse();
                    top.reverse();
                } else if area == 0.0 {
                    return Err(bad("genericTrap", "the faces have no area".into()));
                }
                let section = |z: f64| {
                    let f = (z + dz) / (2.0 * dz);
                    (0..4)
                        .map(|k| {
                            let (b, t) = (bottom[k], top[k]);
                            [b[0] + f * (t[0] - b[0]), b[1] + f * (t[1] - b[1]), z]
                        })
                        .collect()
                };
                mesh(ruled_solid(&section, -dz, dz, tolerance)?)
            }
            G4Solid::Xtru { polygon, sections } => {
                if sections.len() < 2
                    || sections
                        .windows(2)
                        .any(|w| w[0].z.partial_cmp(&w[1].z) != Some(std::cmp::Ordering::Less))
                {
                    return Err(bad(
                        "xtru",
                        "needs 2 or more sections with increasing z".into(),
                    ));
                }
                if sections.iter().any(|s| {
                    s.scale.is_nan() || s.scale <= 0.0 || !s.offset.iter().all(|v| v.is_finite())
                }) {
                    return Err(bad(
                        "xtru",
                        "section scales must be > 0 and offsets finite".into(),
                    ));
                }
                let mut poly = polygon.clone();
                if signed_area2(&poly) < 0.0 {
                    poly.reverse();
                }
                let levels: Vec<Vec<[f64; 3]>> = sections
                    .iter()
                    .map(|s| {
                        poly.iter()
                            .map(|p| {
                                [
                                    s.scale * p[0] + s.offset[0],
                                    s.scale * p[1] + s.offset[1],
                                    s.z,
                                ]
                            })
                            .collect()
                    })
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
    Ok(b.b.to_shape()?.placed(affine(&b.rotation, &b.translation, "boolean")?))
}

/// A placed solid's expression in the outer frame.
fn placed_shape(p: &PlacedSolid) -> Result<Shape, CsgError> {
    Ok(p.solid.to_shape()?.placed(affine(&p.matrix, &p.translation, "displaced")?))
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
