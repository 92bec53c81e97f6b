//! The GDML document walk: errors with file, line and element path; `<define>`;
//! expression evaluation; `<loop>`; the top-level sections.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use roxmltree::{Document, Node};

use super::expr::{self, Scope};
use super::{Gdml, GdmlOptions};

/// Nesting of `file=` includes beyond which a file is assumed to include itself.
const MAX_INCLUDE_DEPTH: usize = 16;
/// Nesting of `<loop>` elements accepted.
const MAX_LOOP_DEPTH: usize = 8;
/// Iterations of all loops of a file together: a million (about a second of reading; real
/// detector files loop thousands of times). Ten million took 20 s and 3 GB.
const MAX_LOOP_ITERATIONS: usize = 1_000_000;

/// A GDML file that cannot be read as Geant4 would.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}:{line}: {element}: {message}")]
pub struct GdmlError {
    /// The file.
    pub file: String,
    /// 1-based line of the element (0 when the file could not be parsed at all).
    pub line: u32,
    /// Element path, e.g. `gdml/solids/tube[name=T1]`.
    pub element: String,
    /// What is wrong.
    pub message: String,
}

/// A named 3-vector of `<define>`.
pub(crate) type Vector = [f64; 3];

/// A matrix of `<define>`.
#[derive(Clone, Debug)]
pub(crate) struct Matrix {
    pub columns: usize,
    pub values: Vec<f64>,
}

/// Everything `<define>` names, and the loop variables.
#[derive(Default)]
pub(crate) struct Defines {
    scalars: HashMap<String, f64>,
    variables: HashSet<String>,
    pub positions: HashMap<String, Vector>,
    pub rotations: HashMap<String, Vector>,
    pub scales: HashMap<String, Vector>,
    pub matrices: HashMap<String, Matrix>,
}

impl Scope for Defines {
    fn scalar(&self, name: &str) -> Option<f64> {
        self.scalars.get(name).copied()
    }
    fn matrix(&self, name: &str) -> Option<(&[f64], usize, usize)> {
        self.matrices
            .get(name)
            .map(|m| (&m.values[..], m.values.len() / m.columns, m.columns))
    }
}

/// The reading state of one file.
pub(crate) struct Reader<'a, 'input> {
    pub file: String,
    pub dir: PathBuf,
    /// The document whose nodes the reader is handed.
    document: std::marker::PhantomData<&'a Document<'input>>,
    pub options: &'a GdmlOptions,
    pub defines: Defines,
    pub out: Gdml,
    pub solid_index: HashMap<String, usize>,
    pub volume_index: HashMap<String, usize>,
    pub assembly_index: HashMap<String, usize>,
    pub assemblies: Vec<Vec<super::Placement>>,
    pub material_index: HashMap<String, usize>,
    pub surface_index: HashMap<String, usize>,
    pub include_depth: usize,
    loop_depth: usize,
    loop_iterations: usize,
    /// Byte offset of the start of every line of the text after the first: a node's line
    /// by binary search (roxmltree's own lookup scans the text from its start, which made
    /// reading a file with a message origin per volume quadratic).
    line_starts: Vec<usize>,
}

/// Reads a file, `depth` includes deep.
pub(crate) fn read_file(
    path: &Path,
    options: &GdmlOptions,
    depth: usize,
) -> Result<Gdml, GdmlError> {
    let file = path.display().to_string();
    let fail = |message: String| GdmlError {
        file: file.clone(),
        line: 0,
        element: "file".into(),
        message,
    };
    if depth > MAX_INCLUDE_DEPTH {
        return Err(fail(format!(
            "`file=` includes nest deeper than {MAX_INCLUDE_DEPTH} (a file including itself?)"
        )));
    }
    let bytes = std::fs::read(path).map_err(|e| fail(format!("cannot read: {e}")))?;
    let text = String::from_utf8(bytes).map_err(|e| fail(format!("not UTF-8 text: {e}")))?;
    let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    read_text(&text, &file, &dir, options, depth)
}

/// Reads GDML text; `dir` resolves `file=` includes.
pub(crate) fn read_text(
    text: &str,
    file: &str,
    dir: &Path,
    options: &GdmlOptions,
    depth: usize,
) -> Result<Gdml, GdmlError> {
    let parse_options = roxmltree::ParsingOptions {
        allow_dtd: true,
        nodes_limit: 50_000_000,
        ..Default::default()
    };
    let doc = Document::parse_with_options(text, parse_options).map_err(|e| GdmlError {
        file: file.to_string(),
        line: e.pos().row,
        element: "xml".into(),
        message: format!("malformed XML: {e}"),
    })?;
    let mut reader = Reader {
        file: file.to_string(),
        dir: dir.to_path_buf(),
        document: std::marker::PhantomData,
        options,
        defines: Defines::default(),
        out: Gdml::default(),
        solid_index: HashMap::new(),
        volume_index: HashMap::new(),
        assembly_index: HashMap::new(),
        assemblies: Vec::new(),
        material_index: HashMap::new(),
        surface_index: HashMap::new(),
        include_depth: depth,
        loop_depth: 0,
        loop_iterations: 0,
        line_starts: text
            .bytes()
            .enumerate()
            .filter(|(_, b)| *b == b'\n')
            .map(|(i, _)| i + 1)
            .collect(),
    };
    reader.read_root(doc.root_element())?;
    Ok(reader.out)
}

/// The section readers a `<loop>` can repeat.
#[derive(Clone, Copy)]
pub(crate) enum Section {
    Define,
    Materials,
    Solids,
    Structure,
    /// The daughters of a volume or assembly (index into volumes or assemblies).
    Daughters(super::structure::Mother),
}

impl<'a, 'input> Reader<'a, 'input> {
    /// An error at `node`.
    pub fn error(&self, node: Node, message: impl Into<String>) -> GdmlError {
        let mut parts: Vec<String> = node
            .ancestors()
            .filter(|n| n.is_element())
            .map(|n| match n.attribute("name") {
                Some(name) => format!("{}[name={name}]", n.tag_name().name()),
                None => n.tag_name().name().to_string(),
            })
            .collect();
        parts.reverse();
        GdmlError {
            file: self.file.clone(),
            line: self.line(node),
            element: parts.join("/"),
            message: message.into(),
        }
    }

    /// The line (from 1) where `node` starts.
    fn line(&self, node: Node) -> u32 {
        let at = node.range().start;
        (self.line_starts.partition_point(|&start| start <= at) + 1) as u32
    }

    /// `file:line` of a node.
    pub fn origin(&self, node: Node) -> String {
        format!("{}:{}", self.file, self.line(node))
    }

    /// Fails on an unsupported element, or skips it with a warning when lenient.
    pub fn unsupported(&mut self, node: Node, what: &str) -> Result<(), GdmlError> {
        let e = self.error(
            node,
            format!("unsupported {what} <{}>", node.tag_name().name()),
        );
        if self.options.lenient {
            self.out.warnings.push(e.to_string());
            Ok(())
        } else {
            Err(e)
        }
    }

    /// Evaluates an expression written in `node`.
    pub fn eval(&self, node: Node, text: &str) -> Result<f64, GdmlError> {
        expr::evaluate(text, &self.defines).map_err(|e| self.error(node, e.to_string()))
    }

    /// Evaluates attribute `attr`, or gives `default` when it is absent.
    pub fn num(&self, node: Node, attr: &str, default: f64) -> Result<f64, GdmlError> {
        match node.attribute(attr) {
            // Geant4 reads an empty attribute as zero.
            Some(text) if text.trim().is_empty() => Ok(0.0),
            Some(text) => self.eval(node, text).map_err(|e| GdmlError {
                message: format!("attribute `{attr}`: {}", e.message),
                ..e
            }),
            None => Ok(default),
        }
    }

    /// Evaluates attribute `attr`, which must be present.
    pub fn required(&self, node: Node, attr: &str) -> Result<f64, GdmlError> {
        if node.attribute(attr).is_none() {
            return Err(self.error(node, format!("missing attribute `{attr}`")));
        }
        self.num(node, attr, 0.0)
    }

    /// The value of a unit attribute (`lunit`, `aunit`, `unit`), `default` when absent.
    pub fn unit(&self, node: Node, attr: &str, default: f64) -> Result<f64, GdmlError> {
        self.num(node, attr, default)
    }

    /// Attribute text that must be present.
    pub fn text_attr<'n>(&self, node: Node<'n, 'input>, attr: &str) -> Result<&'n str, GdmlError>
    where
        'input: 'n,
    {
        node.attribute(attr)
            .ok_or_else(|| self.error(node, format!("missing attribute `{attr}`")))
    }

    /// A name as Geant4 generates it while reading: `[expr]` groups solved inside loops.
    /// References resolve by these full names; the `0x` suffixes are stripped only from
    /// the names the result reports (as Geant4 strips after reading).
    pub fn name(&self, node: Node, raw: &str) -> Result<String, GdmlError> {
        if self.loop_depth > 0 {
            self.solve_brackets(node, raw)
        } else {
            Ok(raw.to_string())
        }
    }

    /// The element's `name` attribute as Geant4 generates it (empty when absent).
    pub fn name_attr(&self, node: Node) -> Result<String, GdmlError> {
        self.name(node, node.attribute("name").unwrap_or(""))
    }

    /// The `ref` attribute of a reference element, as a generated name.
    pub fn reference(&self, node: Node) -> Result<String, GdmlError> {
        let raw = self.text_attr(node, "ref")?;
        self.name(node, raw)
    }

    /// Replaces `name[e1,e2]` groups of a name inside a loop by `name_v1_v2` with the
    /// 1-based indices made 0-based, as Geant4's `SolveBrackets` does.
    fn solve_brackets(&self, node: Node, text: &str) -> Result<String, GdmlError> {
        let mut out = String::with_capacity(text.len());
        let mut rest = text;
        while let Some(open) = rest.find('[') {
            let close = rest[open..]
                .find(']')
                .map(|c| open + c)
                .ok_or_else(|| self.error(node, format!("unbalanced `[` in \"{text}\"")))?;
            out.push_str(&rest[..open]);
            for part in rest[open + 1..close].split(',') {
                let v = expr::evaluate(part, &self.defines)
                    .map_err(|e| self.error(node, e.to_string()))?;
                if v.fract() != 0.0 || v.abs() > 1e15 {
                    return Err(self.error(node, format!("index `{part}` = {v} is not an integer")));
                }
                out.push_str(&format!("_{}", v as i64 - 1));
            }
            rest = &rest[close + 1..];
        }
        out.push_str(rest);
        Ok(out)
    }

    fn read_root(&mut self, root: Node<'a, 'input>) -> Result<(), GdmlError> {
        let tag = root.tag_name().name();
        if tag != "gdml" && tag != "gdml_simple_extension" {
            return Err(self.error(root, format!("root element must be <gdml>, got <{tag}>")));
        }
        let mut world = None;
        for child in root.children().filter(|n| n.is_element()) {
            match child.tag_name().name() {
                "define" => self.read_section(child, Section::Define)?,
                "materials" => self.read_section(child, Section::Materials)?,
                "solids" => self.read_section(child, Section::Solids)?,
                "structure" => self.read_section(child, Section::Structure)?,
                "setup" => {
                    if world.is_none() {
                        let w = child
                            .children()
                            .find(|n| n.has_tag_name("world"))
                            .ok_or_else(|| self.error(child, "no <world ref=...>"))?;
                        world = Some(w);
                    }
                }
                "userinfo" | "extension" => {}
                _ => self.unsupported(child, "section")?,
            }
        }
        let w = world.ok_or_else(|| self.error(root, "no <setup> with a <world>"))?;
        let name = self.reference(w)?;
        self.out.world = *self
            .volume_index
            .get(&name)
            .ok_or_else(|| self.error(w, format!("unknown world volume `{name}`")))?;
        Ok(())
    }

    /// Reads the children of a section element (or of a loop inside one).
    pub fn read_section(
        &mut self,
        node: Node<'a, 'input>,
        section: Section,
    ) -> Result<(), GdmlError> {
        for child in node.children().filter(|n| n.is_element()) {
            if child.has_tag_name("loop") {
                self.read_loop(child, section)?;
                continue;
            }
            match section {
                Section::Define => self.read_define(child)?,
                Section::Materials => self.read_material_element(child)?,
                Section::Solids => self.read_solid(child)?,
                Section::Structure => self.read_structure_element(child)?,
                Section::Daughters(mother) => self.read_daughter(child, mother)?,
            }
        }
        Ok(())
    }

    /// `<loop for from to step>`: the body read once per value of the variable.
    fn read_loop(&mut self, node: Node<'a, 'input>, section: Section) -> Result<(), GdmlError> {
        if self.loop_depth >= MAX_LOOP_DEPTH {
            return Err(self.error(node, format!("loops nest deeper than {MAX_LOOP_DEPTH}")));
        }
        let var = self.text_attr(node, "for")?.trim().to_string();
        if !self.defines.variables.contains(&var) {
            return Err(self.error(node, format!("loop variable `{var}` is not a <variable>")));
        }
        let integer = |r: &Self, attr: &str, default: f64| -> Result<i64, GdmlError> {
            let v = r.num(node, attr, default)?;
            if v.abs() > 1e15 {
                return Err(r.error(node, format!("`{attr}` = {v} is out of range")));
            }
            Ok(v as i64)
        };
        let current = self.defines.scalars[&var];
        let from = integer(self, "from", current)?;
        let to = integer(self, "to", 0.0)?;
        let step = integer(self, "step", 0.0)?;
        if step <= 0 {
            return Err(self.error(node, format!("loop step must be > 0, got {step}")));
        }
        if from > to {
            return Err(self.error(node, format!("loop runs from {from} past {to}")));
        }
        let count = ((to - from) / step + 1) as usize;
        self.loop_iterations = self.loop_iterations.saturating_add(count);
        if self.loop_iterations > MAX_LOOP_ITERATIONS {
            return Err(self.error(
                node,
                format!("loops run more than {MAX_LOOP_ITERATIONS} iterations in all"),
            ));
        }
        self.loop_depth += 1;
        let mut value = from;
        let mut result = Ok(());
        while value <= to {
            self.defines.scalars.insert(var.clone(), value as f64);
            result = self.read_section(node, section);
            if result.is_err() {
                break;
            }
            value += step;
        }
        self.loop_depth -= 1;
        result
    }

    fn define_scalar(&mut self, node: Node, name: String, value: f64) -> Result<(), GdmlError> {
        if !value.is_finite() {
            return Err(self.error(node, format!("`{name}` evaluates to {value}")));
        }
        self.defines.scalars.insert(name, value);
        Ok(())
    }

    /// A `(x, y, z)` vector element scaled by its `unit` attribute (default `default_unit`).
    pub fn vector(&self, node: Node, default_unit: f64) -> Result<Vector, GdmlError> {
        let unit = self.unit(node, "unit", default_unit)?;
        Ok([
            self.num(node, "x", 0.0)? * unit,
            self.num(node, "y", 0.0)? * unit,
            self.num(node, "z", 0.0)? * unit,
        ])
    }

    fn read_define(&mut self, node: Node<'a, 'input>) -> Result<(), GdmlError> {
        let name = self.name_attr(node)?;
        match node.tag_name().name() {
            "constant" => {
                let v = self.required(node, "value")?;
                self.define_scalar(node, name, v)
            }
            "variable" => {
                let v = self.required(node, "value")?;
                self.defines.variables.insert(name.clone());
                self.define_scalar(node, name, v)
            }
            "quantity" => {
                let v = self.required(node, "value")? * self.unit(node, "unit", 1.0)?;
                self.define_scalar(node, name, v)
            }
            "expression" => {
                let text = node.text().unwrap_or("").to_string();
                let v = self.eval(node, &text)?;
                self.define_scalar(node, name, v)
            }
            "position" => {
                let v = self.vector(node, 1.0)?;
                self.defines.positions.insert(name, v);
                Ok(())
            }
            "rotation" => {
                let v = self.vector(node, 1.0)?;
                self.defines.rotations.insert(name, v);
                Ok(())
            }
            "scale" => {
                let v = [
                    self.num(node, "x", 1.0)?,
                    self.num(node, "y", 1.0)?,
                    self.num(node, "z", 1.0)?,
                ];
                self.defines.scales.insert(name, v);
                Ok(())
            }
            "matrix" => {
                let columns = self.required(node, "coldim")?;
                if !(1.0..=1e6).contains(&columns) || columns.fract() != 0.0 {
                    return Err(self.error(
                        node,
                        format!("coldim must be a positive integer, got {columns}"),
                    ));
                }
                let columns = columns as usize;
                // Geant4 reads a matrix without `values` as empty.
                let values = node
                    .attribute("values")
                    .unwrap_or("")
                    .split_whitespace()
                    .map(|t| self.eval(node, t))
                    .collect::<Result<Vec<f64>, _>>()?;
                if values.len() % columns != 0 {
                    return Err(self.error(
                        node,
                        format!(
                            "{} values do not fill rows of {columns} columns",
                            values.len()
                        ),
                    ));
                }
                self.defines
                    .matrices
                    .insert(name, Matrix { columns, values });
                Ok(())
            }
            _ => self.unsupported(node, "define"),
        }
    }

    /// A named position, rotation or scale of `<define>`.
    pub fn defined(
        &self,
        node: Node,
        kind: &str,
        table: &HashMap<String, Vector>,
    ) -> Result<Vector, GdmlError> {
        let name = self.reference(node)?;
        table
            .get(&name)
            .copied()
            .ok_or_else(|| self.error(node, format!("unknown {kind} `{name}`")))
    }

    /// The position, rotation and scale given by the children of a placing element
    /// (`position`/`positionref`, `rotation`/`rotationref`, `scale`/`scaleref`, and the
    /// `first...` forms when `prefix` is `first`).
    pub fn placement_parts(
        &self,
        node: Node,
        prefix: &str,
    ) -> Result<(Vector, Vector, Vector), GdmlError> {
        let (mut position, mut rotation, mut scale) = ([0.0; 3], [0.0; 3], [1.0; 3]);
        for child in node.children().filter(|n| n.is_element()) {
            let tag = child.tag_name().name();
            let Some(base) = tag.strip_prefix(prefix) else {
                continue;
            };
            match base {
                "position" => position = self.vector(child, 1.0)?,
                "positionref" => {
                    position = self.defined(child, "position", &self.defines.positions)?
                }
                "rotation" => rotation = self.vector(child, 1.0)?,
                "rotationref" => {
                    rotation = self.defined(child, "rotation", &self.defines.rotations)?
                }
                "scale" => {
                    scale = [
                        self.num(child, "x", 1.0)?,
                        self.num(child, "y", 1.0)?,
                        self.num(child, "z", 1.0)?,
                    ]
                }
                "scaleref" => scale = self.defined(child, "scale", &self.defines.scales)?,
                _ => {}
            }
        }
        Ok((position, rotation, scale))
    }
}
