//! `<materials>` (names and optical property tables) and optical surfaces.

use roxmltree::Node;

use super::reader::{GdmlError, Reader};
use super::{strip_name, Material, OpticalSurface, Table};

impl<'a, 'input> Reader<'a, 'input> {
    /// Reads one element of `<materials>`; only materials matter for ray tracing (their
    /// names and property tables), isotopes and elements are skipped.
    pub fn read_material_element(&mut self, node: Node<'a, 'input>) -> Result<(), GdmlError> {
        match node.tag_name().name() {
            "material" => {
                let name = self.name_attr(node)?;
                if name.is_empty() {
                    return Err(self.error(node, "a material needs a name"));
                }
                let properties = self.properties(node)?;
                let material = Material {
                    name: strip_name(&name).to_string(),
                    properties,
                };
                // The first material of a name is the one references find.
                self.material_index
                    .entry(name)
                    .or_insert(self.out.materials.len());
                self.out.materials.push(material);
                Ok(())
            }
            "isotope" | "element" | "define" => Ok(()),
            _ => self.unsupported(node, "material element"),
        }
    }

    /// The `<property name ref>` children of a node, each a `<define>` matrix.
    fn properties(&self, node: Node) -> Result<Vec<(String, Table)>, GdmlError> {
        let mut out = Vec::new();
        for p in node.children().filter(|c| c.has_tag_name("property")) {
            let name = self.text_attr(p, "name")?.to_string();
            if p.attribute("ref").is_none() {
                // A constant property written as `value=` (not Geant4's own dialect).
                let value = self.required(p, "value")?;
                let values = vec![value];
                out.push((name, Table { columns: 1, values }));
                continue;
            }
            let matrix = self.reference(p)?;
            let m = self
                .defines
                .matrices
                .get(&matrix)
                .ok_or_else(|| self.error(p, format!("unknown matrix `{matrix}`")))?;
            out.push((
                name,
                Table {
                    columns: m.columns,
                    values: m.values.clone(),
                },
            ));
        }
        Ok(out)
    }

    /// The material named by a `materialref`; Geant4's NIST materials (`G4_...`) need no
    /// definition in the file.
    pub fn material_ref(&mut self, node: Node) -> Result<usize, GdmlError> {
        let name = self.reference(node)?;
        if let Some(&i) = self.material_index.get(&name) {
            return Ok(i);
        }
        if !name.starts_with("G4_") {
            return Err(self.error(node, format!("unknown material `{name}`")));
        }
        let i = self.out.materials.len();
        self.out.materials.push(Material {
            name: strip_name(&name).to_string(),
            properties: Vec::new(),
        });
        self.material_index.insert(name, i);
        Ok(i)
    }

    /// `<opticalsurface name model finish type value>` (in `<solids>`).
    pub fn read_optical_surface(&mut self, node: Node) -> Result<(), GdmlError> {
        let name = self.name_attr(node)?;
        let text = |attr: &str| node.attribute(attr).unwrap_or("").trim().to_string();
        // Geant4 strips the names of materials, solids and volumes, not of surfaces.
        let surface = OpticalSurface {
            name: name.clone(),
            model: text("model"),
            finish: text("finish"),
            kind: text("type"),
            // Geant4's GDML reader: 0 when absent (glisur's polish, unified's sigma_alpha).
            value: self.num(node, "value", 0.0)?,
            properties: self.properties(node)?,
        };
        self.surface_index
            .entry(name)
            .or_insert(self.out.surfaces.len());
        self.out.surfaces.push(surface);
        Ok(())
    }
}
