//! What a hit needs to know beyond geometry: materials with their optical property tables,
//! optical surfaces, the boundary table and the names of the placed volumes.
//!
//! Every instance has a boundary (index into [`Optics::boundaries`]): the materials on the
//! two sides of its surface and the optical surfaces that apply when it is crossed, as
//! Opticks' `(omat, osur, isur, imat)` quadruplets. Saved as `optics.json` beside the
//! arrays.

use serde::{Deserialize, Serialize};

use crate::error::{FoundryError, Result};
use crate::store::UNSET;

/// A property table: rows of `columns` numbers (e.g. photon energy, value).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Table {
    /// Number of columns.
    pub columns: usize,
    /// Values, row-major.
    pub values: Vec<f64>,
}

/// A material and its optical property tables (RINDEX, ABSLENGTH, RAYLEIGH, ...).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// Name.
    pub name: String,
    /// `(property name, table)`.
    pub properties: Vec<(String, Table)>,
}

/// An optical surface (Geant4's G4OpticalSurface).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OpticalSurface {
    /// Name.
    pub name: String,
    /// Model (`glisur`, `unified`, ...).
    pub model: String,
    /// Finish (`polished`, `ground`, ...).
    pub finish: String,
    /// Type (`dielectric_metal`, `dielectric_dielectric`, ...).
    pub kind: String,
    /// Roughness parameter.
    pub value: f64,
    /// Property tables (REFLECTIVITY, EFFICIENCY, ...).
    pub properties: Vec<(String, Table)>,
}

/// One boundary: indices into materials and surfaces, [`UNSET`] for none.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Boundary {
    /// Material outside the instance's surface (its mother's).
    pub outer_material: u32,
    /// Surface applying to crossings from inside to outside.
    pub outer_surface: u32,
    /// Surface applying to crossings from outside to inside.
    pub inner_surface: u32,
    /// Material inside the instance's surface.
    pub inner_material: u32,
}

/// Materials, surfaces, boundaries and volume names of a Foundry.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Optics {
    /// Materials.
    pub materials: Vec<Material>,
    /// Optical surfaces.
    pub surfaces: Vec<OpticalSurface>,
    /// Boundaries; [`crate::Instance::boundary`] indexes them.
    pub boundaries: Vec<Boundary>,
    /// Names of placed volumes; [`crate::Instance::identity`] indexes them when set.
    pub volumes: Vec<String>,
    /// The participating medium of every volume prim: where its voxels come from and how
    /// dense it is (absent in files written before media existed).
    #[serde(default)]
    pub media: Vec<Medium>,
}

/// A participating medium: the voxel grid behind a volume prim's bricks.
///
/// The Foundry keeps the bricks (bounds and majorants, what acceleration structures need);
/// the voxels stay in their source, which tracers open again.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Medium {
    /// The volume prim (index into the prim array).
    pub prim: u32,
    /// A .nvdb or .vdb path, or a procedural grid (`sphere:...`, `box:...`).
    pub source: String,
    /// Grid name inside the source (`None`: the first grid).
    pub grid: Option<String>,
    /// Extinction per unit length of the scene per unit of grid value.
    pub density_scale: f64,
    /// Texel format of the bricked grid the bricks were built from (`f32`, `f16`,
    /// `unorm16`, `unorm8`, `bc4`).
    pub format: String,
    /// Single-scattering albedo, scattering over extinction, in [0, 1]: the chance that a
    /// photon's collision with the medium scatters rather than absorbs it (0, a pure
    /// absorber, in files written before photons met media).
    #[serde(default)]
    pub albedo: f64,
    /// Henyey-Greenstein asymmetry of its scattering, in (-1, 1): above 0 forward.
    #[serde(default)]
    pub g: f64,
}

impl Optics {
    /// Checks every index of the boundary table.
    pub fn validate(&self) -> Result<()> {
        for (i, b) in self.boundaries.iter().enumerate() {
            let check = |field: &str, v: u32, n: usize| {
                if v != UNSET && v as usize >= n {
                    Err(FoundryError::File {
                        path: "optics.json".into(),
                        problem: format!(
                            "boundary {i}: {field} is {v}, but the table has {n} (indices \
                             0..{n}, or {UNSET} for none)"
                        ),
                    })
                } else {
                    Ok(())
                }
            };
            check("outer_material", b.outer_material, self.materials.len())?;
            check("inner_material", b.inner_material, self.materials.len())?;
            check("outer_surface", b.outer_surface, self.surfaces.len())?;
            check("inner_surface", b.inner_surface, self.surfaces.len())?;
        }
        for (i, m) in self.media.iter().enumerate() {
            if !(m.density_scale.is_finite() && m.density_scale >= 0.0) {
                return Err(FoundryError::File {
                    path: "optics.json".into(),
                    problem: format!(
                        "medium {i}: density scale {} is not finite and >= 0",
                        m.density_scale
                    ),
                });
            }
            if !(0.0..=1.0).contains(&m.albedo) {
                return Err(FoundryError::File {
                    path: "optics.json".into(),
                    problem: format!("medium {i}: albedo {} is not in [0, 1]", m.albedo),
                });
            }
            if !(m.g.is_finite() && m.g.abs() < 1.0) {
                return Err(FoundryError::File {
                    path: "optics.json".into(),
                    problem: format!("medium {i}: phase asymmetry g {} is not in (-1, 1)", m.g),
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with_medium(albedo: f64, g: f64) -> Optics {
        Optics {
            media: vec![Medium {
                source: "box:4,4,4".into(),
                density_scale: 0.1,
                format: "f32".into(),
                albedo,
                g,
                ..Medium::default()
            }],
            ..Optics::default()
        }
    }

    /// A medium's albedo outside [0, 1] or `g` outside (-1, 1) is refused naming the file
    /// and the medium; a record written before media had them reads them as 0.
    #[test]
    fn media_scattering_is_checked_and_defaults_to_a_pure_absorber() {
        assert!(with_medium(0.5, -0.9).validate().is_ok());
        for (albedo, g, why) in [
            (1.5, 0.0, "albedo 1.5"),
            (-0.1, 0.0, "albedo -0.1"),
            (0.5, 1.0, "g 1"),
            (0.5, f64::NAN, "g NaN"),
        ] {
            let e = with_medium(albedo, g).validate().unwrap_err().to_string();
            assert!(
                e.contains("optics.json") && e.contains("medium 0") && e.contains(why),
                "{e}"
            );
        }
        let old = r#"{"prim": 3, "source": "fog.nvdb", "grid": null, "density_scale": 0.2, "format": "f16"}"#;
        let m: Medium = serde_json::from_str(old).unwrap();
        assert_eq!((m.albedo, m.g), (0.0, 0.0));
    }
}
