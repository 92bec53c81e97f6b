//! GDML, the geometry format of Geant4 users, read with Geant4's own semantics.
//!
//! [`read_gdml`] parses a file (no schema download, no network) into a [`Gdml`]: the
//! solids as [`G4Solid`] constructor parameters, the logical volumes with their daughters
//! (assemblies, replicas, divisions and parameterised volumes already expanded into plain
//! placements), materials with their property tables, and optical surfaces. What Geant4
//! does, this reader does:
//!
//! - expressions with the CLHEP unit table and math functions ([`expr`]), `<define>`
//!   constants, variables, quantities, expressions, positions, rotations, scales and
//!   matrices (1-based `m[i,j]` element access), `<loop>` in every section with `[i]` in
//!   names replaced by `_<value>`;
//! - `lunit` and `aunit` default to mm and rad; box, tube, cone, trd, trap, para, hype,
//!   twisted solids take full lengths, eltube, paraboloid and arb8 half lengths, polycone
//!   z planes are absolute;
//! - a physvol's rotation angles (x, y, z) place the daughter by the inverse of
//!   `Rz(z) Ry(y) Rx(x)`; a scale (possibly a reflection) applies before the rotation;
//! - names of materials, solids and volumes lose their `0x...` pointer suffixes (Geant4's
//!   name stripping, after reading: references use the full names), optical surfaces keep
//!   theirs; the first definition of a name is the one references find.
//!
//! Every error names the file, the line and the element path.

pub mod expr;
mod materials;
mod reader;
mod solids;
mod structure;

use std::path::Path;

use crate::g4solid::G4Solid;
use crate::records::Transform64;

pub use crate::optics::{Material, OpticalSurface, Table};
pub use reader::GdmlError;

/// Options of [`read_gdml`].
#[derive(Clone, Debug, Default)]
pub struct GdmlOptions {
    /// Skip unsupported elements with a warning instead of failing.
    pub lenient: bool,
}

/// A solid of the file.
#[derive(Clone, Debug, PartialEq)]
pub struct GdmlSolid {
    /// Name, stripped.
    pub name: String,
    /// Geant4 constructor parameters.
    pub solid: G4Solid,
    /// Where it is defined (`file:line`), for errors found when it is built.
    pub origin: String,
}

/// A logical volume: one solid of one material, with daughters.
#[derive(Clone, Debug, PartialEq)]
pub struct LogicalVolume {
    /// Name, stripped.
    pub name: String,
    /// Index into [`Gdml::solids`].
    pub solid: usize,
    /// Index into [`Gdml::materials`] (Geant4 accepts volumes without a material).
    pub material: Option<usize>,
    /// Placements inside this volume.
    pub daughters: Vec<Placement>,
    /// `<auxiliary auxtype auxvalue>` pairs.
    pub auxiliary: Vec<(String, String)>,
}

/// One physical volume: a logical volume placed in its mother.
#[derive(Clone, Debug, PartialEq)]
pub struct Placement {
    /// Physical volume name as written (not stripped: border surfaces refer to it).
    pub name: String,
    /// Index into [`Gdml::volumes`].
    pub volume: usize,
    /// Daughter-to-mother affine transform (may include a reflection).
    pub transform: Transform64,
    /// Geant4's copy number.
    pub copy_number: i32,
}

/// Where an optical surface applies.
#[derive(Clone, Debug, PartialEq)]
pub enum SurfaceLink {
    /// A G4LogicalBorderSurface: crossings from the first physical volume into the second
    /// (physical volume names as written).
    Border(String, String),
    /// A G4LogicalSkinSurface: every crossing of a logical volume's surface.
    Skin(usize),
}

/// A border or skin surface.
#[derive(Clone, Debug, PartialEq)]
pub struct LogicalSurface {
    /// Name (not stripped, as in Geant4).
    pub name: String,
    /// Index into [`Gdml::surfaces`].
    pub surface: usize,
    /// Where it applies.
    pub link: SurfaceLink,
}

/// A GDML file as Geant4 reads it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gdml {
    /// Solids.
    pub solids: Vec<GdmlSolid>,
    /// Logical volumes.
    pub volumes: Vec<LogicalVolume>,
    /// The world's logical volume.
    pub world: usize,
    /// Materials.
    pub materials: Vec<Material>,
    /// Optical surfaces.
    pub surfaces: Vec<OpticalSurface>,
    /// Border and skin surfaces.
    pub logical_surfaces: Vec<LogicalSurface>,
    /// What `lenient` skipped.
    pub warnings: Vec<String>,
}

/// Reads a GDML file.
pub fn read_gdml(path: &Path, options: &GdmlOptions) -> Result<Gdml, GdmlError> {
    reader::read_file(path, options, 0)
}

/// Reads GDML from text; `source` names it in errors and `file=` includes resolve against
/// the current directory.
pub fn parse_gdml(text: &str, source: &str, options: &GdmlOptions) -> Result<Gdml, GdmlError> {
    reader::read_text(text, source, Path::new("."), options, 0)
}

/// Geant4's name stripping: everything from the first `0x` on is a pointer suffix.
pub fn strip_name(name: &str) -> &str {
    match name.find("0x") {
        Some(i) if i > 0 => &name[..i],
        _ => name,
    }
}
