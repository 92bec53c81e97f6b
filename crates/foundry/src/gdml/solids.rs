//! `<solids>`: every solid tag Geant4 reads, as [`G4Solid`] constructor parameters.

use roxmltree::Node;

use super::reader::{GdmlError, Reader, Vector};
use super::{strip_name, GdmlSolid};
use crate::g4solid::{Boolean, G4Solid, PlacedSolid, XtruSection};

/// `Rz(z) Ry(y) Rx(x)`, the matrix CLHEP builds from GDML rotation angles by
/// `rotateX(x); rotateY(y); rotateZ(z)` (row-major, acting on column vectors).
pub(crate) fn rotation_matrix(angles: Vector) -> [[f64; 3]; 3] {
    let [(sx, cx), (sy, cy), (sz, cz)] = angles.map(f64::sin_cos);
    let rx = [[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]];
    let ry = [[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]];
    let rz = [[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]];
    mul(&rz, &mul(&ry, &rx))
}

/// 3x3 matrix product.
pub(crate) fn mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

/// Transpose (the inverse of a rotation).
pub(crate) fn transpose(a: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| a[j][i]))
}

/// The linear part placing a daughter (or a boolean operand) from GDML angles and scale:
/// the inverse of `Rz Ry Rx`, applied after the scale (Geant4's
/// `G4Transform3D(rot.inverse(), pos) * G4Scale3D(scale)`).
pub(crate) fn placement_matrix(rotation: Vector, scale: Vector) -> [[f64; 3]; 3] {
    let r = transpose(&rotation_matrix(rotation));
    let s = [
        [scale[0], 0.0, 0.0],
        [0.0, scale[1], 0.0],
        [0.0, 0.0, scale[2]],
    ];
    mul(&r, &s)
}

/// Deepest nesting of booleans, multi-unions and displaced solids accepted.
const MAX_SOLID_DEPTH: usize = 256;
/// Most primitive solids one solid may expand into.
const MAX_SOLID_SIZE: usize = 100_000;

/// Nesting depth and number of solids of a solid (its operands were checked when read, so
/// the recursion is bounded).
fn extent(solid: &G4Solid) -> (usize, usize) {
    let combine = |parts: &mut dyn Iterator<Item = &G4Solid>| {
        parts.fold((0usize, 0usize), |(d, n), s| {
            let (sd, sn) = extent(s);
            (d.max(sd), n.saturating_add(sn))
        })
    };
    let (d, n) = match solid {
        G4Solid::Union(b) | G4Solid::Subtraction(b) | G4Solid::Intersection(b) => {
            combine(&mut [&*b.a, &*b.b].into_iter())
        }
        G4Solid::MultiUnion { parts } => combine(&mut parts.iter().map(|p| &*p.solid)),
        G4Solid::Displaced(p) => extent(&p.solid),
        _ => return (1, 1),
    };
    (d + 1, n.saturating_add(1))
}

impl<'a, 'input> Reader<'a, 'input> {
    /// The solid named by a reference element's `ref`.
    pub fn solid_ref(&self, node: Node) -> Result<usize, GdmlError> {
        let name = self.reference(node)?;
        self.solid_index
            .get(&name)
            .copied()
            .ok_or_else(|| self.error(node, format!("unknown solid `{name}`")))
    }

    fn solid_by_attr(&self, node: Node, attr: &str) -> Result<G4Solid, GdmlError> {
        let raw = self.text_attr(node, attr)?;
        let name = self.name(node, raw)?;
        self.solid_index
            .get(&name)
            .map(|&i| self.out.solids[i].solid.clone())
            .ok_or_else(|| self.error(node, format!("unknown solid `{name}`")))
    }

    fn position_attr(&self, node: Node, attr: &str, lunit: f64) -> Result<Vector, GdmlError> {
        let raw = self.text_attr(node, attr)?;
        let name = self.name(node, raw)?;
        self.defines
            .positions
            .get(&name)
            .map(|p| p.map(|v| v * lunit))
            .ok_or_else(|| self.error(node, format!("unknown position `{name}`")))
    }

    /// Reads one element of `<solids>`.
    pub fn read_solid(&mut self, node: Node<'a, 'input>) -> Result<(), GdmlError> {
        let tag = node.tag_name().name();
        if tag == "opticalsurface" {
            return self.read_optical_surface(node);
        }
        let Some(solid) = self.solid_from(node)? else {
            return self.unsupported(node, "solid");
        };
        let name = self.name_attr(node)?;
        if name.is_empty() {
            return Err(self.error(node, "a solid needs a name"));
        }
        let (depth, size) = extent(&solid);
        if depth > MAX_SOLID_DEPTH || size > MAX_SOLID_SIZE {
            return Err(self.error(
                node,
                format!(
                    "booleans nest {depth} deep over {size} solids (at most {MAX_SOLID_DEPTH} and {MAX_SOLID_SIZE})"
                ),
            ));
        }
        let index = self.out.solids.len();
        self.out.solids.push(GdmlSolid {
            name: strip_name(&name).to_string(),
            solid,
            origin: self.origin(node),
        });
        // References resolve to the first solid of a name, as Geant4's store lookup does.
        self.solid_index.entry(name).or_insert(index);
        Ok(())
    }

    /// The solid of a solid element, `None` for an unknown tag.
    fn solid_from(&self, n: Node) -> Result<Option<G4Solid>, GdmlError> {
        let l = self.unit(n, "lunit", 1.0)?;
        let a = self.unit(n, "aunit", 1.0)?;
        let len = |attr: &str| Ok::<f64, GdmlError>(self.num(n, attr, 0.0)? * l);
        let half = |attr: &str| Ok::<f64, GdmlError>(self.num(n, attr, 0.0)? * 0.5 * l);
        let ang = |attr: &str| Ok::<f64, GdmlError>(self.num(n, attr, 0.0)? * a);
        let solid = match n.tag_name().name() {
            "box" => G4Solid::Box {
                dx: half("x")?,
                dy: half("y")?,
                dz: half("z")?,
            },
            "orb" => G4Solid::Orb { r: len("r")? },
            "sphere" => G4Solid::Sphere {
                rmin: len("rmin")?,
                rmax: len("rmax")?,
                sphi: ang("startphi")?,
                dphi: ang("deltaphi")?,
                stheta: ang("starttheta")?,
                dtheta: ang("deltatheta")?,
            },
            "tube" => G4Solid::Tubs {
                rmin: len("rmin")?,
                rmax: len("rmax")?,
                dz: half("z")?,
                sphi: ang("startphi")?,
                dphi: ang("deltaphi")?,
            },
            "cutTube" => G4Solid::CutTubs {
                rmin: len("rmin")?,
                rmax: len("rmax")?,
                dz: half("z")?,
                sphi: ang("startphi")?,
                dphi: ang("deltaphi")?,
                low: [
                    self.num(n, "lowX", 0.0)?,
                    self.num(n, "lowY", 0.0)?,
                    self.num(n, "lowZ", 0.0)?,
                ],
                high: [
                    self.num(n, "highX", 0.0)?,
                    self.num(n, "highY", 0.0)?,
                    self.num(n, "highZ", 0.0)?,
                ],
            },
            "cone" => G4Solid::Cons {
                rmin1: len("rmin1")?,
                rmax1: len("rmax1")?,
                rmin2: len("rmin2")?,
                rmax2: len("rmax2")?,
                dz: half("z")?,
                sphi: ang("startphi")?,
                dphi: ang("deltaphi")?,
            },
            "torus" => G4Solid::Torus {
                rmin: len("rmin")?,
                rmax: len("rmax")?,
                rtor: len("rtor")?,
                sphi: ang("startphi")?,
                dphi: ang("deltaphi")?,
            },
            "trd" => G4Solid::Trd {
                dx1: half("x1")?,
                dx2: half("x2")?,
                dy1: half("y1")?,
                dy2: half("y2")?,
                dz: half("z")?,
            },
            "trap" => G4Solid::Trap {
                dz: half("z")?,
                theta: ang("theta")?,
                phi: ang("phi")?,
                dy1: half("y1")?,
                dx1: half("x1")?,
                dx2: half("x2")?,
                alpha1: ang("alpha1")?,
                dy2: half("y2")?,
                dx3: half("x3")?,
                dx4: half("x4")?,
                alpha2: ang("alpha2")?,
            },
            "para" => G4Solid::Para {
                dx: half("x")?,
                dy: half("y")?,
                dz: half("z")?,
                alpha: ang("alpha")?,
                theta: ang("theta")?,
                phi: ang("phi")?,
            },
            "hype" => G4Solid::Hype {
                rmin: len("rmin")?,
                rmax: len("rmax")?,
                stereo_in: ang("inst")?,
                stereo_out: ang("outst")?,
                dz: half("z")?,
            },
            "paraboloid" => G4Solid::Paraboloid {
                dz: len("dz")?,
                rlo: len("rlo")?,
                rhi: len("rhi")?,
            },
            "ellipsoid" => {
                let cz = len("cz")?;
                let (mut zbottom, mut ztop) = (len("zcut1")?, len("zcut2")?);
                // G4Ellipsoid: both cuts zero means no cut.
                if zbottom == 0.0 && ztop == 0.0 {
                    (zbottom, ztop) = (-cz, cz);
                }
                G4Solid::Ellipsoid {
                    ax: len("ax")?,
                    by: len("by")?,
                    cz,
                    zbottom: zbottom.max(-cz),
                    ztop: ztop.min(cz),
                }
            }
            "eltube" => G4Solid::Eltube {
                dx: len("dx")?,
                dy: len("dy")?,
                dz: len("dz")?,
            },
            "elcone" => G4Solid::Elcone {
                xsemi: self.num(n, "dx", 0.0)?,
                ysemi: self.num(n, "dy", 0.0)?,
                zheight: len("zmax")?,
                zcut: len("zcut")?,
            },
            "tet" => G4Solid::Tet {
                anchor: self.position_attr(n, "vertex1", l)?,
                p2: self.position_attr(n, "vertex2", l)?,
                p3: self.position_attr(n, "vertex3", l)?,
                p4: self.position_attr(n, "vertex4", l)?,
            },
            "polycone" | "polyhedra" => {
                let (mut z, mut rmin, mut rmax) = (Vec::new(), Vec::new(), Vec::new());
                for p in n.children().filter(|c| c.has_tag_name("zplane")) {
                    z.push(self.num(p, "z", 0.0)? * l);
                    rmin.push(self.num(p, "rmin", 0.0)? * l);
                    rmax.push(self.num(p, "rmax", 0.0)? * l);
                }
                let (sphi, dphi) = (ang("startphi")?, ang("deltaphi")?);
                if n.has_tag_name("polycone") {
                    G4Solid::Polycone {
                        sphi,
                        dphi,
                        z,
                        rmin,
                        rmax,
                    }
                } else {
                    G4Solid::Polyhedra {
                        sphi,
                        dphi,
                        numside: self.count(n, "numsides")?,
                        z,
                        rmin,
                        rmax,
                    }
                }
            }
            "genericPolycone" | "genericPolyhedra" => {
                let (mut r, mut z) = (Vec::new(), Vec::new());
                for p in n.children().filter(|c| c.has_tag_name("rzpoint")) {
                    r.push(self.num(p, "r", 0.0)? * l);
                    z.push(self.num(p, "z", 0.0)? * l);
                }
                let (sphi, dphi) = (ang("startphi")?, ang("deltaphi")?);
                if n.has_tag_name("genericPolycone") {
                    G4Solid::GenericPolycone { sphi, dphi, r, z }
                } else {
                    G4Solid::GenericPolyhedra {
                        sphi,
                        dphi,
                        numside: self.count(n, "numsides")?,
                        r,
                        z,
                    }
                }
            }
            "arb8" => {
                let mut vertices = Vec::with_capacity(8);
                for k in 1..=8 {
                    vertices.push([len(&format!("v{k}x"))?, len(&format!("v{k}y"))?]);
                }
                G4Solid::GenericTrap {
                    dz: len("dz")?,
                    vertices,
                }
            }
            "xtru" => {
                let mut polygon = Vec::new();
                let mut sections = Vec::new();
                for c in n.children().filter(|c| c.is_element()) {
                    match c.tag_name().name() {
                        "twoDimVertex" => {
                            polygon.push([self.num(c, "x", 0.0)? * l, self.num(c, "y", 0.0)? * l])
                        }
                        "section" => sections.push(XtruSection {
                            z: self.num(c, "zPosition", 0.0)? * l,
                            offset: [
                                self.num(c, "xOffset", 0.0)? * l,
                                self.num(c, "yOffset", 0.0)? * l,
                            ],
                            scale: self.num(c, "scalingFactor", 1.0)?,
                        }),
                        _ => {}
                    }
                }
                G4Solid::Xtru { polygon, sections }
            }
            "tessellated" => {
                let mut facets = Vec::new();
                for c in n.children().filter(|c| c.is_element()) {
                    let corners = match c.tag_name().name() {
                        "triangular" => 3,
                        "quadrangular" => 4,
                        _ => continue,
                    };
                    let relative = c.attribute("type") == Some("RELATIVE");
                    let mut facet: Vec<[f64; 3]> = Vec::with_capacity(corners);
                    for k in 1..=corners {
                        let mut v = self.position_attr(c, &format!("vertex{k}"), l)?;
                        if relative && k > 1 {
                            v = std::array::from_fn(|i| v[i] + facet[0][i]);
                        }
                        facet.push(v);
                    }
                    facets.push(facet);
                }
                G4Solid::Tessellated { facets }
            }
            "twistedbox" => G4Solid::TwistedBox {
                twistedangle: ang("PhiTwist")?,
                dx: half("x")?,
                dy: half("y")?,
                dz: half("z")?,
            },
            "twistedtrd" => G4Solid::TwistedTrd {
                dx1: half("x1")?,
                dx2: half("x2")?,
                dy1: half("y1")?,
                dy2: half("y2")?,
                dz: half("z")?,
                twistedangle: ang("PhiTwist")?,
            },
            "twistedtrap" => G4Solid::TwistedTrap {
                twistedangle: ang("PhiTwist")?,
                dz: half("z")?,
                theta: ang("Theta")?,
                phi: ang("Phi")?,
                dy1: half("y1")?,
                dx1: half("x1")?,
                dx2: half("x2")?,
                dy2: half("y2")?,
                dx3: half("x3")?,
                dx4: half("x4")?,
                alpha: ang("Alph")?,
            },
            "twistedtubs" => {
                if n.attribute("nseg").is_some() || n.attribute("midinnerrad").is_some() {
                    return Err(self.error(
                        n,
                        "twistedtubs with nseg/totphi or mid radii is not supported; give twistedangle, endinnerrad, endouterrad, zlen, phi",
                    ));
                }
                G4Solid::TwistedTubs {
                    twistedangle: ang("twistedangle")?,
                    endinnerrad: len("endinnerrad")?,
                    endouterrad: len("endouterrad")?,
                    halfzlen: half("zlen")?,
                    dphi: ang("phi")?,
                }
            }
            tag @ ("union" | "subtraction" | "intersection") => {
                let mut first = None;
                let mut second = None;
                for c in n.children().filter(|c| c.is_element()) {
                    match c.tag_name().name() {
                        "first" => first = Some(self.solid_ref(c)?),
                        "second" => second = Some(self.solid_ref(c)?),
                        _ => {}
                    }
                }
                let first = first.ok_or_else(|| self.error(n, "no <first> solid"))?;
                let second = second.ok_or_else(|| self.error(n, "no <second> solid"))?;
                let (position, rotation, _) = self.placement_parts(n, "")?;
                let (first_position, first_rotation, _) = self.placement_parts(n, "first")?;
                let mut a = self.out.solids[first].solid.clone();
                if first_position != [0.0; 3] || first_rotation != [0.0; 3] {
                    a = G4Solid::Displaced(PlacedSolid {
                        solid: Box::new(a),
                        matrix: rotation_matrix(first_rotation),
                        translation: first_position,
                    });
                }
                let boolean = Boolean {
                    a: Box::new(a),
                    b: Box::new(self.out.solids[second].solid.clone()),
                    rotation: rotation_matrix(rotation),
                    translation: position,
                };
                match tag {
                    "union" => G4Solid::Union(boolean),
                    "subtraction" => G4Solid::Subtraction(boolean),
                    _ => G4Solid::Intersection(boolean),
                }
            }
            "multiUnion" => {
                let mut parts = Vec::new();
                for node in n.children().filter(|c| c.has_tag_name("multiUnionNode")) {
                    let solid = node
                        .children()
                        .find(|c| c.has_tag_name("solid"))
                        .ok_or_else(|| self.error(node, "no <solid ref=...>"))?;
                    let solid = self.solid_ref(solid)?;
                    let (position, rotation, _) = self.placement_parts(node, "")?;
                    parts.push(PlacedSolid {
                        solid: Box::new(self.out.solids[solid].solid.clone()),
                        matrix: rotation_matrix(rotation),
                        translation: position,
                    });
                }
                G4Solid::MultiUnion { parts }
            }
            "scaledSolid" => {
                let solid = n
                    .children()
                    .find(|c| c.has_tag_name("solidref"))
                    .ok_or_else(|| self.error(n, "no <solidref>"))?;
                let solid = self.solid_ref(solid)?;
                let (_, _, scale) = self.placement_parts(n, "")?;
                G4Solid::Displaced(PlacedSolid {
                    solid: Box::new(self.out.solids[solid].solid.clone()),
                    matrix: placement_matrix([0.0; 3], scale),
                    translation: [0.0; 3],
                })
            }
            "reflectedSolid" => {
                let solid = self.solid_by_attr(n, "solid")?;
                let scale = [
                    self.num(n, "sx", 1.0)?,
                    self.num(n, "sy", 1.0)?,
                    self.num(n, "sz", 1.0)?,
                ];
                let rotation = [ang("rx")?, ang("ry")?, ang("rz")?];
                let translation = [len("dx")?, len("dy")?, len("dz")?];
                // G4ReflectedSolid(solid, T) with T = G4Transform3D(rot, d) * G4Scale3D(s)
                // maps the reflected solid's points into the constituent's frame
                // (its Inside(p) asks the constituent about T p), so the constituent is
                // placed by the inverse of T.
                let s = [
                    [scale[0], 0.0, 0.0],
                    [0.0, scale[1], 0.0],
                    [0.0, 0.0, scale[2]],
                ];
                let t = crate::gdml::structure::affine(
                    mul(&rotation_matrix(rotation), &s),
                    translation,
                );
                let inverse = t
                    .inverse()
                    .ok_or_else(|| self.error(n, format!("singular reflection scale {scale:?}")))?;
                let r = &inverse.rows;
                G4Solid::Displaced(PlacedSolid {
                    solid: Box::new(solid),
                    matrix: std::array::from_fn(|i| [r[i][0], r[i][1], r[i][2]]),
                    translation: [r[0][3], r[1][3], r[2][3]],
                })
            }
            _ => return Ok(None),
        };
        Ok(Some(solid))
    }

    /// A non-negative integer attribute.
    fn count(&self, node: Node, attr: &str) -> Result<u32, GdmlError> {
        let v = self.required(node, attr)?;
        if !(0.0..=1e6).contains(&v) || v.fract() != 0.0 {
            return Err(self.error(
                node,
                format!("`{attr}` must be a whole number >= 0, got {v}"),
            ));
        }
        Ok(v as u32)
    }
}
