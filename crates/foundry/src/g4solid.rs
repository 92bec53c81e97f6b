//! Geant4 solids as data: each variant holds the parameters of a Geant4 solid exactly as its
//! constructor takes them (lengths in mm, angles in radians, Geant4's half-lengths).
//!
//! The GDML reader produces them, the project's Geant4 oracle writes them as JSON
//! (`{"type": "tubs", "rmin": ..., ...}`), and `hytrace_csg::geant4` maps them onto exact CSG
//! expressions or meshes.

use serde::{Deserialize, Serialize};

/// A Geant4 solid with its constructor's parameters (mm, rad, half-lengths).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "camelCase", deny_unknown_fields)]
#[allow(missing_docs)]
pub enum G4Solid {
    /// G4Box(dx, dy, dz).
    Box { dx: f64, dy: f64, dz: f64 },
    /// G4Orb(r).
    Orb { r: f64 },
    /// G4Sphere(rmin, rmax, sphi, dphi, stheta, dtheta).
    Sphere {
        rmin: f64,
        rmax: f64,
        sphi: f64,
        dphi: f64,
        stheta: f64,
        dtheta: f64,
    },
    /// G4Tubs(rmin, rmax, dz, sphi, dphi).
    Tubs {
        rmin: f64,
        rmax: f64,
        dz: f64,
        sphi: f64,
        dphi: f64,
    },
    /// G4CutTubs(rmin, rmax, dz, sphi, dphi, low normal, high normal).
    CutTubs {
        rmin: f64,
        rmax: f64,
        dz: f64,
        sphi: f64,
        dphi: f64,
        low: [f64; 3],
        high: [f64; 3],
    },
    /// G4Cons(rmin1, rmax1, rmin2, rmax2, dz, sphi, dphi).
    Cons {
        rmin1: f64,
        rmax1: f64,
        rmin2: f64,
        rmax2: f64,
        dz: f64,
        sphi: f64,
        dphi: f64,
    },
    /// G4Torus(rmin, rmax, rtor, sphi, dphi).
    Torus {
        rmin: f64,
        rmax: f64,
        rtor: f64,
        sphi: f64,
        dphi: f64,
    },
    /// G4Trd(dx1, dx2, dy1, dy2, dz).
    Trd {
        dx1: f64,
        dx2: f64,
        dy1: f64,
        dy2: f64,
        dz: f64,
    },
    /// G4Trap(dz, theta, phi, dy1, dx1, dx2, alpha1, dy2, dx3, dx4, alpha2).
    Trap {
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
    },
    /// G4Para(dx, dy, dz, alpha, theta, phi).
    Para {
        dx: f64,
        dy: f64,
        dz: f64,
        alpha: f64,
        theta: f64,
        phi: f64,
    },
    /// G4Polycone(sphi, dphi, z planes, inner radii, outer radii).
    Polycone {
        sphi: f64,
        dphi: f64,
        z: Vec<f64>,
        rmin: Vec<f64>,
        rmax: Vec<f64>,
    },
    /// G4Polyhedra(sphi, dphi, numside, z planes, inner, outer) with radii to the side
    /// planes (the z-plane constructor's convention).
    Polyhedra {
        sphi: f64,
        dphi: f64,
        numside: u32,
        z: Vec<f64>,
        rmin: Vec<f64>,
        rmax: Vec<f64>,
    },
    /// G4Hype(rmin, rmax, stereo_in, stereo_out, dz).
    Hype {
        rmin: f64,
        rmax: f64,
        stereo_in: f64,
        stereo_out: f64,
        dz: f64,
    },
    /// G4Paraboloid(dz, rlo, rhi).
    Paraboloid { dz: f64, rlo: f64, rhi: f64 },
    /// G4Ellipsoid(ax, by, cz, zbottom, ztop).
    Ellipsoid {
        ax: f64,
        by: f64,
        cz: f64,
        zbottom: f64,
        ztop: f64,
    },
    /// G4EllipticalTube(dx, dy, dz).
    Eltube { dx: f64, dy: f64, dz: f64 },
    /// G4EllipticalCone(xsemi, ysemi, zheight, zcut).
    Elcone {
        xsemi: f64,
        ysemi: f64,
        zheight: f64,
        zcut: f64,
    },
    /// G4Tet(anchor, p2, p3, p4).
    Tet {
        anchor: [f64; 3],
        p2: [f64; 3],
        p3: [f64; 3],
        p4: [f64; 3],
    },
    /// G4TwistedBox(twistedangle, dx, dy, dz): a box twisted about z (mesh).
    TwistedBox {
        twistedangle: f64,
        dx: f64,
        dy: f64,
        dz: f64,
    },
    /// G4TwistedTrd(dx1, dx2, dy1, dy2, dz, twistedangle) (mesh).
    TwistedTrd {
        dx1: f64,
        dx2: f64,
        dy1: f64,
        dy2: f64,
        dz: f64,
        twistedangle: f64,
    },
    /// G4TwistedTrap(twistedangle, dz, theta, phi, dy1, dx1, dx2, dy2, dx3, dx4, alpha)
    /// (mesh).
    TwistedTrap {
        twistedangle: f64,
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
    },
    /// G4GenericTrap(dz, 8 xy vertices: four at -dz, four at +dz) (mesh; exact when
    /// untwisted).
    GenericTrap { dz: f64, vertices: Vec<[f64; 2]> },
    /// G4ExtrudedSolid(polygon, z sections) (exact mesh).
    Xtru {
        polygon: Vec<[f64; 2]>,
        sections: Vec<XtruSection>,
    },
    /// G4TessellatedSolid of triangular or quadrangular facets (absolute vertices,
    /// counter-clockwise seen from outside) (exact mesh).
    Tessellated { facets: Vec<Vec<[f64; 3]>> },
    /// G4GenericPolycone(sphi, dphi, r, z): the (r, z) polygon revolved about z.
    GenericPolycone {
        sphi: f64,
        dphi: f64,
        r: Vec<f64>,
        z: Vec<f64>,
    },
    /// G4Polyhedra(sphi, dphi, numside, r, z): the (r, z) corner polygon swept around a
    /// regular polygon (r measured to the polygon's corners, unlike the z-plane form).
    GenericPolyhedra {
        sphi: f64,
        dphi: f64,
        numside: u32,
        r: Vec<f64>,
        z: Vec<f64>,
    },
    /// G4TwistedTubs(twistedangle, endinnerrad, endouterrad, halfzlen, dphi) (mesh).
    TwistedTubs {
        twistedangle: f64,
        endinnerrad: f64,
        endouterrad: f64,
        halfzlen: f64,
        dphi: f64,
    },
    /// G4MultiUnion: the union of placed solids.
    MultiUnion { parts: Vec<PlacedSolid> },
    /// A solid under a general affine map (G4ScaledSolid, G4ReflectedSolid, GDML's
    /// physvol scale folded into the solid).
    Displaced(PlacedSolid),
    /// G4UnionSolid(a, b, transform).
    Union(Boolean),
    /// G4SubtractionSolid(a, b, transform).
    Subtraction(Boolean),
    /// G4IntersectionSolid(a, b, transform).
    Intersection(Boolean),
}

/// One z section of a G4ExtrudedSolid: the polygon scaled by `scale` and moved by
/// `offset` at height `z`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct XtruSection {
    /// Height.
    pub z: f64,
    /// xy offset of the polygon.
    pub offset: [f64; 2],
    /// Scale of the polygon.
    pub scale: f64,
}

/// A solid placed by `p_outer = matrix * p_solid + translation` (`matrix` may scale or
/// reflect).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlacedSolid {
    /// The solid.
    pub solid: Box<G4Solid>,
    /// Linear part, row-major.
    pub matrix: [[f64; 3]; 3],
    /// Translation.
    pub translation: [f64; 3],
}

/// The operands of a Geant4 boolean solid: `b` is placed in `a`'s frame by
/// `p_a = rotation * p_b + translation`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Boolean {
    /// First operand.
    pub a: Box<G4Solid>,
    /// Second operand.
    pub b: Box<G4Solid>,
    /// Rotation matrix, row-major.
    pub rotation: [[f64; 3]; 3],
    /// Translation.
    pub translation: [f64; 3],
}

impl G4Solid {
    /// The solid's JSON `type` name.
    pub fn kind(&self) -> &'static str {
        match self {
            G4Solid::Box { .. } => "box",
            G4Solid::Orb { .. } => "orb",
            G4Solid::Sphere { .. } => "sphere",
            G4Solid::Tubs { .. } => "tubs",
            G4Solid::CutTubs { .. } => "cutTubs",
            G4Solid::Cons { .. } => "cons",
            G4Solid::Torus { .. } => "torus",
            G4Solid::Trd { .. } => "trd",
            G4Solid::Trap { .. } => "trap",
            G4Solid::Para { .. } => "para",
            G4Solid::Polycone { .. } => "polycone",
            G4Solid::Polyhedra { .. } => "polyhedra",
            G4Solid::Hype { .. } => "hype",
            G4Solid::Paraboloid { .. } => "paraboloid",
            G4Solid::Ellipsoid { .. } => "ellipsoid",
            G4Solid::Eltube { .. } => "eltube",
            G4Solid::Elcone { .. } => "elcone",
            G4Solid::Tet { .. } => "tet",
            G4Solid::TwistedBox { .. } => "twistedBox",
            G4Solid::TwistedTrd { .. } => "twistedTrd",
            G4Solid::TwistedTrap { .. } => "twistedTrap",
            G4Solid::GenericTrap { .. } => "genericTrap",
            G4Solid::Xtru { .. } => "xtru",
            G4Solid::Tessellated { .. } => "tessellated",
            G4Solid::GenericPolycone { .. } => "genericPolycone",
            G4Solid::GenericPolyhedra { .. } => "genericPolyhedra",
            G4Solid::TwistedTubs { .. } => "twistedTubs",
            G4Solid::MultiUnion { .. } => "multiUnion",
            G4Solid::Displaced(_) => "displaced",
            G4Solid::Union(_) => "union",
            G4Solid::Subtraction(_) => "subtraction",
            G4Solid::Intersection(_) => "intersection",
        }
    }
}
