//! `<structure>`: volumes, physvols, assemblies, replicas, divisions, parameterised
//! volumes, `file=` includes and the border and skin surfaces.

use roxmltree::Node;

use super::reader::{GdmlError, Reader, Section, Vector};
use super::solids::placement_matrix;
use super::{strip_name, GdmlSolid, LogicalSurface, LogicalVolume, Placement, SurfaceLink};
use crate::g4solid::G4Solid;
use crate::records::Transform64;

/// What daughters are read into.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Mother {
    /// A logical volume (index into `Gdml::volumes`).
    Volume(usize),
    /// An assembly (index into the reader's assemblies).
    Assembly(usize),
}

/// What a `volumeref` names.
enum Target {
    Volume(usize),
    Assembly(usize),
}

/// The affine map `p -> matrix * p + translation`.
pub(crate) fn affine(matrix: [[f64; 3]; 3], translation: Vector) -> Transform64 {
    let mut t = Transform64::IDENTITY;
    for i in 0..3 {
        t.rows[i][..3].copy_from_slice(&matrix[i]);
        t.rows[i][3] = translation[i];
    }
    t
}

/// A replication or division axis.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Axis {
    Cartesian(usize),
    Phi,
    Rho,
}

impl<'a, 'input> Reader<'a, 'input> {
    /// Reads one element of `<structure>`.
    pub fn read_structure_element(&mut self, node: Node<'a, 'input>) -> Result<(), GdmlError> {
        match node.tag_name().name() {
            "volume" => self.read_volume(node),
            "assembly" => {
                let name = self.name_attr(node)?;
                let index = self.assemblies.len();
                self.assemblies.push(Vec::new());
                self.assembly_index.entry(name).or_insert(index);
                self.read_section(node, Section::Daughters(Mother::Assembly(index)))
            }
            "bordersurface" => {
                let refs: Vec<Node> = node
                    .children()
                    .filter(|c| c.has_tag_name("physvolref"))
                    .collect();
                if refs.len() != 2 {
                    return Err(
                        self.error(node, format!("needs 2 <physvolref>, got {}", refs.len()))
                    );
                }
                let (a, b) = (self.reference(refs[0])?, self.reference(refs[1])?);
                // Geant4's reader resolves the names among the physical volumes read so far.
                for (r, name) in [(refs[0], &a), (refs[1], &b)] {
                    if !self.physical_volume_exists(name) {
                        let e = self.error(r, format!("unknown physical volume `{name}`"));
                        if !self.options.lenient {
                            return Err(e);
                        }
                        self.out
                            .warnings
                            .push(format!("{e} (the border surface is left out)"));
                        return Ok(());
                    }
                }
                self.logical_surface(node, SurfaceLink::Border(a, b))
            }
            "skinsurface" => {
                let v = node
                    .children()
                    .find(|c| c.has_tag_name("volumeref"))
                    .ok_or_else(|| self.error(node, "no <volumeref>"))?;
                let name = self.reference(v)?;
                let volume = *self
                    .volume_index
                    .get(&name)
                    .ok_or_else(|| self.error(v, format!("unknown volume `{name}`")))?;
                self.logical_surface(node, SurfaceLink::Skin(volume))
            }
            _ => self.unsupported(node, "structure element"),
        }
    }

    /// Whether a physical volume (a placement in a volume or an assembly) named `name` has
    /// been read.
    fn physical_volume_exists(&self, name: &str) -> bool {
        let volumes = self.out.volumes.iter().flat_map(|v| &v.daughters);
        let assemblies = self.assemblies.iter().flatten();
        volumes.chain(assemblies).any(|p| p.name == name)
    }

    fn logical_surface(&mut self, node: Node, link: SurfaceLink) -> Result<(), GdmlError> {
        let name = self.name_attr(node)?;
        let sp = self.text_attr(node, "surfaceproperty")?;
        let sp = self.name(node, sp)?;
        let surface = *self
            .surface_index
            .get(&sp)
            .ok_or_else(|| self.error(node, format!("unknown optical surface `{sp}`")))?;
        self.out.logical_surfaces.push(LogicalSurface {
            name,
            surface,
            link,
        });
        Ok(())
    }

    fn read_volume(&mut self, node: Node<'a, 'input>) -> Result<(), GdmlError> {
        let name = self.name_attr(node)?;
        let (mut solid, mut material) = (None, None);
        let mut auxiliary = Vec::new();
        for c in node.children().filter(|c| c.is_element()) {
            match c.tag_name().name() {
                "solidref" => solid = Some(self.solid_ref(c)?),
                "materialref" => material = Some(self.material_ref(c)?),
                "auxiliary" => auxiliary.push((
                    c.attribute("auxtype").unwrap_or("").to_string(),
                    c.attribute("auxvalue").unwrap_or("").to_string(),
                )),
                _ => {}
            }
        }
        let solid = solid.ok_or_else(|| self.error(node, "no <solidref>"))?;
        let index = self.out.volumes.len();
        self.out.volumes.push(LogicalVolume {
            name: strip_name(&name).to_string(),
            solid,
            material,
            daughters: Vec::new(),
            auxiliary,
        });
        self.read_section(node, Section::Daughters(Mother::Volume(index)))?;
        // Registered after its daughters, so a volume cannot contain itself; the first
        // volume of a name is the one references find (Geant4's store lookup).
        self.volume_index.entry(name).or_insert(index);
        Ok(())
    }

    /// Reads one child of a volume or assembly.
    pub fn read_daughter(
        &mut self,
        node: Node<'a, 'input>,
        mother: Mother,
    ) -> Result<(), GdmlError> {
        match (node.tag_name().name(), mother) {
            ("physvol", _) => self.read_physvol(node, mother),
            ("solidref" | "materialref" | "auxiliary" | "colorref", Mother::Volume(_)) => Ok(()),
            ("replicavol", Mother::Volume(m)) => self.read_replica(node, m),
            ("divisionvol", Mother::Volume(m)) => self.read_division(node, m),
            ("paramvol", Mother::Volume(m)) => self.read_paramvol(node, m),
            _ => self.unsupported(node, "volume content"),
        }
    }

    fn target(&mut self, node: Node<'a, 'input>) -> Result<Target, GdmlError> {
        if let Some(f) = node.children().find(|c| c.has_tag_name("file")) {
            return self.include(f).map(Target::Volume);
        }
        let r = node
            .children()
            .find(|c| c.has_tag_name("volumeref"))
            .ok_or_else(|| self.error(node, "no <volumeref> or <file>"))?;
        let name = self.reference(r)?;
        if let Some(&v) = self.volume_index.get(&name) {
            Ok(Target::Volume(v))
        } else if let Some(&a) = self.assembly_index.get(&name) {
            Ok(Target::Assembly(a))
        } else {
            Err(self.error(r, format!("unknown volume `{name}`")))
        }
    }

    /// Pushes a placement into a volume or assembly.
    fn place(&mut self, mother: Mother, p: Placement) {
        match mother {
            Mother::Volume(m) => self.out.volumes[m].daughters.push(p),
            Mother::Assembly(a) => self.assemblies[a].push(p),
        }
    }

    fn read_physvol(&mut self, node: Node<'a, 'input>, mother: Mother) -> Result<(), GdmlError> {
        let copy = self.num(node, "copynumber", 0.0)?;
        if copy.fract() != 0.0 || copy.abs() > i32::MAX as f64 {
            return Err(self.error(
                node,
                format!("copynumber must be a 32-bit integer, got {copy}"),
            ));
        }
        let (position, rotation, scale) = self.placement_parts(node, "")?;
        if scale.contains(&0.0) {
            return Err(self.error(node, format!("scale {scale:?} is singular")));
        }
        let transform = affine(placement_matrix(rotation, scale), position);
        match self.target(node)? {
            Target::Volume(volume) => {
                let name = match node.attribute("name") {
                    Some(n) => self.name(node, n)?,
                    None => format!("{}_PV", self.out.volumes[volume].name),
                };
                self.place(
                    mother,
                    Placement {
                        name,
                        volume,
                        transform,
                        copy_number: copy as i32,
                    },
                );
            }
            Target::Assembly(a) => {
                // G4AssemblyVolume::MakeImprint: members numbered after the mother's
                // existing daughters.
                let base = match mother {
                    Mother::Volume(m) => self.out.volumes[m].daughters.len(),
                    Mother::Assembly(m) => self.assemblies[m].len(),
                };
                let members = self.assemblies[a].clone();
                for (k, member) in members.into_iter().enumerate() {
                    let name = format!(
                        "av_{}_impr_{}_{}_pv_{k}",
                        a + 1,
                        base + 1,
                        self.out.volumes[member.volume].name
                    );
                    self.place(
                        mother,
                        Placement {
                            name,
                            volume: member.volume,
                            transform: transform.compose(&member.transform),
                            copy_number: (base + k) as i32,
                        },
                    );
                }
            }
        }
        Ok(())
    }

    /// The world volume of another GDML file, its contents appended to this one.
    fn include(&mut self, f: Node<'a, 'input>) -> Result<usize, GdmlError> {
        let file = self.text_attr(f, "name")?;
        let path = self.dir.join(file);
        let sub = super::reader::read_file(&path, self.options, self.include_depth + 1)
            .map_err(|e| self.error(f, format!("in included file: {e}")))?;
        let (solids0, volumes0, materials0, surfaces0) = (
            self.out.solids.len(),
            self.out.volumes.len(),
            self.out.materials.len(),
            self.out.surfaces.len(),
        );
        let world = match f.attribute("volname") {
            Some(v) => sub
                .volumes
                .iter()
                .position(|lv| lv.name == v)
                .ok_or_else(|| self.error(f, format!("{file} has no volume `{v}`")))?,
            None => sub.world,
        };
        self.out.solids.extend(sub.solids);
        self.out.materials.extend(sub.materials);
        self.out.surfaces.extend(sub.surfaces);
        for mut lv in sub.volumes {
            lv.solid += solids0;
            lv.material = lv.material.map(|m| m + materials0);
            for d in &mut lv.daughters {
                d.volume += volumes0;
            }
            self.out.volumes.push(lv);
        }
        for mut s in sub.logical_surfaces {
            s.surface += surfaces0;
            if let SurfaceLink::Skin(v) = &mut s.link {
                *v += volumes0;
            }
            self.out.logical_surfaces.push(s);
        }
        self.out.warnings.extend(sub.warnings);
        Ok(world + volumes0)
    }

    fn axis_of(&self, node: Node, text: &str) -> Result<Axis, GdmlError> {
        Ok(match text {
            "kXAxis" => Axis::Cartesian(0),
            "kYAxis" => Axis::Cartesian(1),
            "kZAxis" => Axis::Cartesian(2),
            "kRho" => Axis::Rho,
            "kPhi" => Axis::Phi,
            _ => return Err(self.error(node, format!("unknown axis `{text}`"))),
        })
    }

    /// Copy `i` of a replica or division: translated along a Cartesian axis by `along`, or
    /// rotated about z by `along` radians.
    fn axis_transform(axis: Axis, along: f64) -> Transform64 {
        match axis {
            Axis::Cartesian(k) => {
                let mut t = [0.0; 3];
                t[k] = along;
                Transform64::translation(t)
            }
            _ => Transform64::rotation([0.0, 0.0, 1.0], along),
        }
    }

    fn volume_ref_child(&self, node: Node) -> Result<usize, GdmlError> {
        let r = node
            .children()
            .find(|c| c.has_tag_name("volumeref"))
            .ok_or_else(|| self.error(node, "no <volumeref>"))?;
        let name = self.reference(r)?;
        self.volume_index
            .get(&name)
            .copied()
            .ok_or_else(|| self.error(r, format!("unknown volume `{name}`")))
    }

    fn copies(&self, node: Node, attr: &str) -> Result<usize, GdmlError> {
        let n = self.required(node, attr)?;
        if !(1.0..=1e7).contains(&n) || n.fract() != 0.0 {
            return Err(self.error(
                node,
                format!("`{attr}` must be a whole number >= 1, got {n}"),
            ));
        }
        Ok(n as usize)
    }

    /// `<replicavol number>`: copies along x, y, z (centred on the mother) or in phi
    /// (G4ReplicaNavigation's transformations).
    fn read_replica(&mut self, node: Node<'a, 'input>, mother: usize) -> Result<(), GdmlError> {
        let number = self.copies(node, "number")?;
        let volume = self.volume_ref_child(node)?;
        let along = node
            .children()
            .find(|c| c.has_tag_name("replicate_along_axis"))
            .ok_or_else(|| self.error(node, "no <replicate_along_axis>"))?;
        let (mut axis, mut width, mut offset) = (None, 0.0, 0.0);
        for c in along.children().filter(|c| c.is_element()) {
            match c.tag_name().name() {
                "direction" => {
                    for (attr, a) in [
                        ("x", Axis::Cartesian(0)),
                        ("y", Axis::Cartesian(1)),
                        ("z", Axis::Cartesian(2)),
                        ("rho", Axis::Rho),
                        ("phi", Axis::Phi),
                    ] {
                        if self.num(c, attr, 0.0)? == 1.0 {
                            axis = Some(a);
                        }
                    }
                }
                "width" => width = self.required(c, "value")? * self.unit(c, "unit", 1.0)?,
                "offset" => offset = self.required(c, "value")? * self.unit(c, "unit", 1.0)?,
                _ => {}
            }
        }
        let axis = axis.ok_or_else(|| self.error(along, "no replication direction"))?;
        if axis == Axis::Rho {
            return self.unsupported(node, "radial replica");
        }
        for i in 0..number {
            let along = match axis {
                Axis::Cartesian(_) => -width * 0.5 * (number as f64 - 1.0) + width * i as f64,
                _ => offset + width * (i as f64 + 0.5),
            };
            let name = format!("{}_replica", self.out.volumes[volume].name);
            self.out.volumes[mother].daughters.push(Placement {
                name,
                volume,
                transform: Self::axis_transform(axis, along),
                copy_number: i as i32,
            });
        }
        Ok(())
    }

    /// A copy of logical volume `volume` whose solid is `solid` (divisions and
    /// parameterised volumes change the dimensions per copy).
    fn volume_with_solid(&mut self, node: Node, volume: usize, solid: G4Solid) -> usize {
        let lv = &self.out.volumes[volume];
        let name = lv.name.clone();
        let copy = LogicalVolume {
            name: name.clone(),
            solid: self.out.solids.len(),
            material: lv.material,
            daughters: lv.daughters.clone(),
            auxiliary: lv.auxiliary.clone(),
        };
        let origin = self.origin(node);
        self.out.solids.push(GdmlSolid {
            name: format!("{name}_param"),
            solid,
            origin,
        });
        self.out.volumes.push(copy);
        self.out.volumes.len() - 1
    }

    /// `<divisionvol axis number width offset unit>` of a box mother (Geant4's
    /// G4ParameterisationBox*: slices of the box, each a box of the slice's width).
    fn read_division(&mut self, node: Node<'a, 'input>, mother: usize) -> Result<(), GdmlError> {
        let unit = self.unit(node, "unit", 1.0)?;
        let axis_text = self.text_attr(node, "axis")?;
        let axis = self.axis_of(node, axis_text)?;
        let number = self.num(node, "number", 0.0)?;
        let width = self.num(node, "width", 0.0)? * unit;
        let offset = self.num(node, "offset", 0.0)? * unit;
        let volume = self.volume_ref_child(node)?;
        let mother_solid = self.out.solids[self.out.volumes[mother].solid]
            .solid
            .clone();
        let (G4Solid::Box { dx, dy, dz }, Axis::Cartesian(k)) = (&mother_solid, axis) else {
            return self.unsupported(node, "division (only of boxes along x, y or z)");
        };
        let half = [*dx, *dy, *dz];
        let extent = 2.0 * half[k] - offset;
        let (count, width) = match (number > 0.0, width > 0.0) {
            (true, true) => (number, width),
            (true, false) => (number, extent / number),
            (false, true) => ((extent / width).floor(), width),
            (false, false) => return Err(self.error(node, "needs a number or a width > 0")),
        };
        if !(1.0..=1e7).contains(&count) || count.fract() != 0.0 || width.is_nan() || width <= 0.0 {
            return Err(self.error(
                node,
                format!("impossible division: {count} slices of width {width}"),
            ));
        }
        let mut slice = half;
        slice[k] = width / 2.0;
        let sliced = self.volume_with_solid(
            node,
            volume,
            G4Solid::Box {
                dx: slice[0],
                dy: slice[1],
                dz: slice[2],
            },
        );
        for i in 0..count as usize {
            let along = -half[k] + offset + (i as f64 + 0.5) * width;
            let name = format!("{}_div", self.out.volumes[volume].name);
            self.out.volumes[mother].daughters.push(Placement {
                name,
                volume: sliced,
                transform: Self::axis_transform(axis, along),
                copy_number: i as i32,
            });
        }
        Ok(())
    }

    /// `<paramvol ncopies>` with `<parameterised_position_size>`: each copy placed like a
    /// physvol, with the dimensions its `*_dimensions` element gives.
    fn read_paramvol(&mut self, node: Node<'a, 'input>, mother: usize) -> Result<(), GdmlError> {
        let volume = self.volume_ref_child(node)?;
        let sizes = node
            .children()
            .find(|c| c.has_tag_name("parameterised_position_size"))
            .ok_or_else(|| self.error(node, "no <parameterised_position_size>"))?;
        for (i, p) in sizes
            .children()
            .filter(|c| c.has_tag_name("parameters"))
            .enumerate()
        {
            let (position, rotation, _) = self.placement_parts(p, "")?;
            let mut solid = None;
            for d in p.children().filter(|c| c.is_element()) {
                let l = self.unit(d, "lunit", 1.0)?;
                let a = self.unit(d, "aunit", 1.0)?;
                let len = |attr: &str| Ok::<f64, GdmlError>(self.num(d, attr, 0.0)? * l);
                let ang = |attr: &str| Ok::<f64, GdmlError>(self.num(d, attr, 0.0)? * a);
                solid = match d.tag_name().name() {
                    "box_dimensions" => Some(G4Solid::Box {
                        dx: len("x")? / 2.0,
                        dy: len("y")? / 2.0,
                        dz: len("z")? / 2.0,
                    }),
                    "tube_dimensions" => Some(G4Solid::Tubs {
                        rmin: len("InR")?,
                        rmax: len("OutR")?,
                        dz: len("hz")? / 2.0,
                        sphi: ang("StartPhi")?,
                        dphi: ang("DeltaPhi")?,
                    }),
                    "position" | "rotation" | "positionref" | "rotationref" => continue,
                    _ => {
                        self.unsupported(d, "parameterisation")?;
                        continue;
                    }
                };
            }
            let Some(solid) = solid else {
                return Err(self.error(p, "no dimensions element"));
            };
            let copy = self.volume_with_solid(p, volume, solid);
            let name = format!("{}_param", self.out.volumes[volume].name);
            self.out.volumes[mother].daughters.push(Placement {
                name,
                volume: copy,
                transform: affine(placement_matrix(rotation, [1.0; 3]), position),
                copy_number: i as i32,
            });
        }
        Ok(())
    }
}
