//! Optical property tables of materials and surfaces, looked up as Geant4 looks them up.
//!
//! A GDML `<matrix coldim="2">` holds `(photon energy, value)` rows in Geant4's internal
//! units (energies in MeV, lengths in mm, velocities in mm/ns). A photon of wavelength
//! `lambda` has energy `E = h c / lambda` (`h c = 1239.84198 eV nm`); a table is
//! interpolated linearly in energy between its rows and clamped to its first and last
//! values outside them (G4PhysicsVector::Value).

use hytrace_foundry::optics::{Material, OpticalSurface, Table};
use hytrace_foundry::UNSET;

use hytrace_volume::Rng;

use super::scintillation::Scintillator;
use super::PhotonError;

/// `h c` in eV nm: photon energy (eV) times wavelength (nm).
pub const HC_EV_NM: f64 = 1239.84198;

/// Speed of light in vacuum, mm/ns (CLHEP's `c_light`).
pub const C_LIGHT_MM_PER_NS: f64 = 299.792458;

/// Photon energy in MeV (Geant4's energy unit) of a wavelength in nm.
pub fn energy_of_wavelength(nm: f64) -> f64 {
    HC_EV_NM / nm * 1e-6
}

/// Wavelength in nm of a photon energy in MeV.
pub fn wavelength_of_energy(mev: f64) -> f64 {
    HC_EV_NM / (mev * 1e6)
}

/// A property of photon energy: `(energy, value)` rows, energies not decreasing.
#[derive(Clone, Debug, PartialEq)]
pub struct Property {
    energies: Vec<f64>,
    values: Vec<f64>,
    /// Whether every value is the same finite number, bit for bit (most tables of real scenes:
    /// reflectivities, efficiencies, indices given at two energies): [`Property::value`]
    /// then skips the search and the interpolation, whose answer it knows.
    flat: bool,
}

impl Property {
    /// Checks a two-column table: at least one row, finite numbers, energies positive and
    /// not decreasing, values not negative. `what` names the table in errors.
    pub fn new(table: &Table, what: &str) -> Result<Property, PhotonError> {
        let bad = |problem: String| PhotonError::Table {
            table: what.to_string(),
            problem,
        };
        if table.columns != 2 {
            return Err(bad(format!(
                "has {} columns, expected 2 (photon energy, value)",
                table.columns
            )));
        }
        if table.values.is_empty() || !table.values.len().is_multiple_of(2) {
            return Err(bad(format!(
                "has {} numbers, expected a positive even count",
                table.values.len()
            )));
        }
        let (mut energies, mut values) = (Vec::new(), Vec::new());
        for (row, pair) in table.values.chunks_exact(2).enumerate() {
            let (e, v) = (pair[0], pair[1]);
            if !(e.is_finite() && e > 0.0) {
                return Err(bad(format!("row {row}: photon energy {e} is not positive")));
            }
            if !v.is_finite() || v < 0.0 {
                return Err(bad(format!(
                    "row {row}: value {v} is negative or not finite"
                )));
            }
            if let Some(&last) = energies.last() {
                // Repeated energies are allowed (Geant4 reads such tables: a step in the
                // values); decreasing ones are not.
                if e < last {
                    return Err(bad(format!(
                        "row {row}: photon energy {e:e} MeV decreases (previous row {last:e} MeV)"
                    )));
                }
            }
            energies.push(e);
            values.push(v);
        }
        Ok(Property::of_rows(energies, values))
    }

    /// The property of checked rows.
    fn of_rows(energies: Vec<f64>, values: Vec<f64>) -> Property {
        let flat =
            values[0].is_finite() && values.iter().all(|v| v.to_bits() == values[0].to_bits());
        Property {
            energies,
            values,
            flat,
        }
    }

    /// A constant property (tests, defaults).
    pub fn constant(value: f64) -> Property {
        Property::of_rows(vec![1e-6], vec![value])
    }

    /// The photon energies of the rows (MeV), not decreasing.
    pub fn energies(&self) -> &[f64] {
        &self.energies
    }

    /// The largest value of the table.
    pub fn max_value(&self) -> f64 {
        self.values
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// The `(energy, value)` rows.
    pub fn rows(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.energies
            .iter()
            .copied()
            .zip(self.values.iter().copied())
    }

    /// The value at photon energy `e` (MeV): linear between rows, the first or last value
    /// outside them.
    pub fn value(&self, e: f64) -> f64 {
        let (es, vs) = (&self.energies, &self.values);
        let last = es.len() - 1;
        if e <= es[0] {
            return vs[0];
        }
        if e >= es[last] {
            return vs[last];
        }
        if self.flat {
            // What the interpolation below gives between equal values `v`: `v + 0 * r`
            // with `r` finite and not negative, that is `v + 0.0` (which turns -0 into 0).
            return vs[0] + 0.0;
        }
        // First row above e: e lies in [es[i - 1], es[i]).
        let i = es.partition_point(|&x| x <= e);
        let (e0, e1, v0, v1) = (es[i - 1], es[i], vs[i - 1], vs[i]);
        v0 + (v1 - v0) * (e - e0) / (e1 - e0)
    }
}

/// The looked-up optical properties of a material.
#[derive(Clone, Debug, Default)]
pub struct MaterialOptics {
    /// Name (for messages).
    pub name: String,
    /// Refractive index; without it photons die at the material's boundaries.
    pub rindex: Option<Property>,
    /// Absorption length (mm); none: no absorption.
    pub abslength: Option<Property>,
    /// Rayleigh scattering length (mm); none: no Rayleigh scattering.
    pub rayleigh: Option<Property>,
    /// Group velocity (mm/ns): Geant4's, from RINDEX ([`group_velocity`]) unless the
    /// material gives GROUPVEL after RINDEX; none without either.
    pub groupvel: Option<Property>,
    /// Absorption length of wavelength shifting (WLSABSLENGTH, mm); none: no shifting.
    pub wlsabslength: Option<Property>,
    /// What a wavelength-shifting absorption emits (WLSCOMPONENT and its constants); none:
    /// the absorbed photon ends there.
    pub wls: Option<Wls>,
    /// Re-emission of absorbed photons by a scintillator (REEMISSIONPROB); none: an
    /// absorption ends the photon.
    pub reemission: Option<Reemission>,
}

/// Re-emission in the Opticks/JUNO convention: a photon absorbed in the bulk (ABSLENGTH)
/// of a material with REEMISSIONPROB is emitted again with that probability at its energy,
/// isotropic with a random polarization, at an energy drawn from the spectrum of one of the
/// material's scintillation components (chosen in proportion to their yields), delayed by
/// a time drawn from that component's profile. Geant4 11 has no such process.
#[derive(Clone, Debug)]
pub struct Reemission {
    /// REEMISSIONPROB.
    pub probability: Property,
    /// The material's scintillation, which the re-emitted photon follows.
    pub scintillator: Scintillator,
}

impl Reemission {
    /// Whether a photon of energy `energy` (MeV) absorbed here is emitted again, and from
    /// which scintillation component.
    pub fn reemits(&self, energy: f64, rng: &mut Rng) -> Option<usize> {
        (rng.next_f64() < self.probability.value(energy)).then(|| self.scintillator.pick(rng))
    }
}

/// An emission spectrum to draw photon energies from, as Geant4 draws its scintillation and
/// wavelength-shifting spectra: the trapezoid integral of the intensity over photon energy,
/// inverted linearly between rows (G4PhysicsVector::GetEnergy).
#[derive(Clone, Debug)]
pub struct Spectrum {
    /// `(energy, integral)` rows, the integral not decreasing.
    energies: Vec<f64>,
    cumulative: Vec<f64>,
}

impl Spectrum {
    /// The spectrum of an intensity table (intensity per photon energy).
    pub fn new(intensity: &Property) -> Self {
        let (es, vs) = (&intensity.energies, &intensity.values);
        let mut cumulative = vec![0.0];
        for i in 1..es.len() {
            let last = cumulative[i - 1];
            cumulative.push(last + 0.5 * (es[i] - es[i - 1]) * (vs[i - 1] + vs[i]));
        }
        Spectrum {
            energies: es.clone(),
            cumulative,
        }
    }

    /// The energy at which the cumulative integral reaches `c`.
    fn energy_at(&self, c: f64) -> f64 {
        let (es, cs) = (&self.energies, &self.cumulative);
        let last = cs.len() - 1;
        if last == 0 || c <= cs[0] {
            return es[0];
        }
        if c >= cs[last] {
            return es[last];
        }
        // The row below the first value not below c.
        let i = cs.partition_point(|&x| x < c) - 1;
        let del = cs[i + 1] - cs[i];
        if del > 0.0 {
            es[i] + (c - cs[i]) * (es[i + 1] - es[i]) / del
        } else {
            es[i]
        }
    }

    /// Its rows: `(energy (MeV), integral of the intensity up to it)`, the integral not
    /// decreasing (what the GPU kernel inverts).
    pub fn rows(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.energies
            .iter()
            .copied()
            .zip(self.cumulative.iter().copied())
    }

    /// One photon energy (MeV) drawn from the spectrum.
    pub fn sample(&self, rng: &mut Rng) -> f64 {
        self.energy_at(rng.next_f64() * self.cumulative[self.cumulative.len() - 1])
    }
}

/// Re-emission by a wavelength shifter (Geant4's G4OpWLS): how many photons, at which
/// energies, after which delay.
#[derive(Clone, Debug)]
pub struct Wls {
    /// WLSCOMPONENT.
    spectrum: Spectrum,
    /// WLSTIMECONSTANT (ns): the delay of every re-emitted photon (Geant4's default
    /// `delta` time profile).
    pub time_constant: f64,
    /// WLSMEANNUMBERPHOTONS: photons emitted per absorption, Poisson distributed with
    /// this mean; none: exactly one.
    pub mean_photons: Option<f64>,
}

/// Draws past which the Poisson sampler stops counting (the tail beyond is below f64's
/// resolution for the means Geant4 samples this way).
const POISSON_MAX: u32 = 1000;

impl Wls {
    /// The re-emission of a material with WLSCOMPONENT `component`.
    fn new(component: &Property, time_constant: f64, mean_photons: Option<f64>) -> Self {
        Wls {
            spectrum: Spectrum::new(component),
            time_constant,
            mean_photons,
        }
    }

    /// WLSCOMPONENT, the spectrum re-emitted photons are drawn from.
    pub fn spectrum(&self) -> &Spectrum {
        &self.spectrum
    }

    /// The energy of one re-emitted photon, no higher than `primary` (MeV): up to 100
    /// draws from the spectrum, as Geant4 tries; `None` when none is low enough.
    pub fn sample_energy(&self, primary: f64, rng: &mut Rng) -> Option<f64> {
        (0..100)
            .map(|_| self.spectrum.sample(rng))
            .find(|&e| e <= primary)
    }

    /// The number of photons one absorption emits (G4Poisson for WLSMEANNUMBERPHOTONS:
    /// inversion up to a mean of 16, a rounded Gaussian above).
    pub fn sample_count(&self, rng: &mut Rng) -> u32 {
        let Some(mean) = self.mean_photons else {
            return 1;
        };
        if mean <= 16.0 {
            let u = rng.next_f64();
            let mut term = (-mean).exp();
            let mut sum = term;
            let mut n = 0;
            while sum <= u && n < POISSON_MAX {
                n += 1;
                term *= mean / f64::from(n);
                sum += term;
            }
            return n;
        }
        let t = (-2.0 * (1.0 - rng.next_f64()).ln()).sqrt()
            * (std::f64::consts::TAU * rng.next_f64()).cos();
        let value = mean + t * mean.sqrt() + 0.5;
        if value <= 0.0 {
            0
        } else {
            value.min(f64::from(u32::MAX)) as u32
        }
    }
}

/// Looks up a named constant property (a one-value GDML matrix), checked.
pub(super) fn constant(
    list: &[(String, Table)],
    name: &str,
    owner: &str,
) -> Result<Option<f64>, PhotonError> {
    let Some((_, t)) = list.iter().find(|(n, _)| n == name) else {
        return Ok(None);
    };
    match t.values.as_slice() {
        [v] if t.columns == 1 && v.is_finite() && *v >= 0.0 => Ok(Some(*v)),
        _ => Err(PhotonError::Table {
            table: format!("{owner}: property {name}"),
            problem: "must be one constant, finite and not negative (a matrix with coldim=\"1\" and one value)".into(),
        }),
    }
}

/// Material properties of processes this propagator does not model; a material with one
/// is refused rather than propagated without it.
const UNMODELLED_MATERIAL_PROPERTIES: [&str; 3] = ["WLSABSLENGTH2", "WLSCOMPONENT2", "MIEHG"];

/// Looks up a named two-column property of a list, checked.
pub(super) fn property(
    list: &[(String, Table)],
    name: &str,
    owner: &str,
) -> Result<Option<Property>, PhotonError> {
    list.iter()
        .find(|(n, _)| n == name)
        .map(|(_, t)| Property::new(t, &format!("{owner}: property {name}")))
        .transpose()
}

impl MaterialOptics {
    /// The optical properties of a material of the scene.
    pub fn new(m: &Material) -> Result<Self, PhotonError> {
        let owner = format!("material `{}`", m.name);
        let rindex = property(&m.properties, "RINDEX", &owner)?;
        // Geant4 computes GROUPVEL whenever RINDEX is added (replacing a GROUPVEL given
        // before it); a GROUPVEL given after RINDEX replaces the computed one.
        let position = |name: &str| m.properties.iter().position(|(n, _)| n == name);
        let groupvel = match (position("GROUPVEL"), position("RINDEX"), &rindex) {
            (Some(g), Some(r), _) if g > r => property(&m.properties, "GROUPVEL", &owner)?,
            (Some(_), None, _) => property(&m.properties, "GROUPVEL", &owner)?,
            (_, _, Some(n)) => Some(group_velocity(n)),
            _ => None,
        };
        if let Some((name, _)) = m
            .properties
            .iter()
            .find(|(n, _)| UNMODELLED_MATERIAL_PROPERTIES.contains(&n.as_str()))
        {
            return Err(PhotonError::Unsupported {
                what: format!("{owner}: property `{name}`"),
            });
        }
        let wls = match property(&m.properties, "WLSCOMPONENT", &owner)? {
            None => None,
            Some(component) => {
                // Geant4 stops with a fatal error at the first re-emission without it.
                let Some(tau) = constant(&m.properties, "WLSTIMECONSTANT", &owner)? else {
                    return Err(PhotonError::Table {
                        table: format!("{owner}: property WLSCOMPONENT"),
                        problem: "needs the constant WLSTIMECONSTANT (the re-emission delay)"
                            .into(),
                    });
                };
                let mean = constant(&m.properties, "WLSMEANNUMBERPHOTONS", &owner)?;
                Some(Wls::new(&component, tau, mean))
            }
        };
        Ok(MaterialOptics {
            name: m.name.clone(),
            rindex,
            abslength: property(&m.properties, "ABSLENGTH", &owner)?,
            rayleigh: property(&m.properties, "RAYLEIGH", &owner)?,
            groupvel,
            wlsabslength: property(&m.properties, "WLSABSLENGTH", &owner)?,
            wls,
            reemission: match property(&m.properties, "REEMISSIONPROB", &owner)? {
                // Zero everywhere (as in files written for Geant4, which has no such
                // process): nothing is re-emitted and the scintillation is not needed.
                Some(p) if p.max_value() == 0.0 => None,
                None => None,
                Some(probability) => {
                    if probability.max_value() > 1.0 {
                        return Err(PhotonError::Table {
                            table: format!("{owner}: property REEMISSIONPROB"),
                            problem: format!("a probability above 1 ({})", probability.max_value()),
                        });
                    }
                    let scintillator = Scintillator::new(m).map_err(|e| PhotonError::Table {
                        table: format!("{owner}: property REEMISSIONPROB"),
                        problem: format!("re-emits as the material scintillates, but {e}"),
                    })?;
                    Some(Reemission {
                        probability,
                        scintillator,
                    })
                }
            },
        })
    }

    /// Speed of a photon of energy `e` (mm/ns): the group velocity, `c` in a material
    /// without RINDEX (as Geant4's optical photons).
    pub fn velocity(&self, e: f64) -> f64 {
        self.groupvel
            .as_ref()
            .map_or(C_LIGHT_MM_PER_NS, |g| g.value(e))
    }
}

/// The group velocity Geant4 derives from a RINDEX table
/// (G4MaterialPropertiesTable::CalculateGROUPVEL): `c / (n + dn / d ln E)` by finite
/// differences, at the first and last energies and at the midpoints between the rows in
/// between, and `c / n` wherever that formula gives a negative or faster-than-`c / n`
/// speed (anomalous dispersion).
pub fn group_velocity(rindex: &Property) -> Property {
    let (es, ns) = (&rindex.energies, &rindex.values);
    let c = C_LIGHT_MM_PER_NS;
    if es.len() < 2 {
        return Property::of_rows(es.clone(), vec![c / ns[0]]);
    }
    let bounded = |vg: f64, n: f64| if vg < 0.0 || vg > c / n { c / n } else { vg };
    let slope = |i: usize| (ns[i + 1] - ns[i]) / (es[i + 1] / es[i]).ln();
    let mut energies = vec![es[0]];
    let mut values = vec![bounded(c / (ns[0] + slope(0)), ns[0])];
    for i in 0..es.len() - 2 {
        let n = 0.5 * (ns[i] + ns[i + 1]);
        energies.push(0.5 * (es[i] + es[i + 1]));
        values.push(bounded(c / (n + slope(i)), n));
    }
    let last = es.len() - 1;
    energies.push(es[last]);
    values.push(bounded(c / (ns[last] + slope(last - 1)), ns[last]));
    Property::of_rows(energies, values)
}

/// Geant4's surface types this propagator models.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SurfaceKind {
    /// `dielectric_metal`: reflect with REFLECTIVITY, else absorb (detect with EFFICIENCY).
    DielectricMetal,
    /// `dielectric_dielectric`: absorb with 1 - REFLECTIVITY - TRANSMITTANCE, pass with
    /// TRANSMITTANCE, else Fresnel.
    DielectricDielectric,
}

/// Geant4's surface finishes this propagator models (G4OpticalSurfaceFinish's first six).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Finish {
    /// Smooth.
    Polished,
    /// Smooth, with paint on the surface (reflection spike, no refraction).
    PolishedFrontPainted,
    /// Smooth, with paint behind a gap of the surface's RINDEX (specular paint).
    PolishedBackPainted,
    /// Rough: facets drawn per crossing.
    Ground,
    /// Rough, with paint on the surface (Lambertian reflection).
    GroundFrontPainted,
    /// Rough, with paint behind a gap of the surface's RINDEX (Lambertian paint).
    GroundBackPainted,
}

impl Finish {
    /// Painted behind a gap (the surface's RINDEX fills it).
    pub fn back_painted(self) -> bool {
        matches!(
            self,
            Finish::PolishedBackPainted | Finish::GroundBackPainted
        )
    }
}

/// How a surface's facets are drawn (G4OpticalSurfaceModel with the surface's `value`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Roughness {
    /// The glisur model: facet normals are the normal plus `1 - polish` times a point
    /// uniform in the unit ball; polish 1 is smooth.
    Glisur {
        /// `value` of the surface.
        polish: f64,
    },
    /// The unified model: facet normals at an angle drawn from a Gaussian of standard
    /// deviation `sigma_alpha` (radians) times its sine; 0 is smooth.
    Unified {
        /// `value` of the surface.
        sigma_alpha: f64,
    },
}

/// The looked-up properties of an optical surface.
#[derive(Clone, Debug)]
pub struct SurfaceOptics {
    /// Name (for messages).
    pub name: String,
    /// Type.
    pub kind: SurfaceKind,
    /// Finish.
    pub finish: Finish,
    /// Model and its roughness parameter.
    pub roughness: Roughness,
    /// REFLECTIVITY (Geant4's default without the table: 1).
    pub reflectivity: Option<Property>,
    /// EFFICIENCY (default 0).
    pub efficiency: Option<Property>,
    /// TRANSMITTANCE (default 0).
    pub transmittance: Option<Property>,
    /// RINDEX of the gap behind back-painted finishes (without it photons die there).
    pub rindex: Option<Property>,
    /// The unified model's SPECULARSPIKECONSTANT, SPECULARLOBECONSTANT and
    /// BACKSCATTERCONSTANT (default 0 each; the rest of the reflections are Lambertian).
    pub spike: Option<Property>,
    /// SPECULARLOBECONSTANT.
    pub lobe: Option<Property>,
    /// BACKSCATTERCONSTANT.
    pub backscatter: Option<Property>,
}

/// A GDML enumeration attribute: a name or Geant4's enumerator value.
fn enumerated<'a>(text: &str, names: &[&'a str]) -> Option<&'a str> {
    let t = text.trim();
    names
        .iter()
        .enumerate()
        .find(|(i, n)| t == **n || t.parse::<usize>() == Ok(*i))
        .map(|(_, n)| *n)
}

/// Properties of surfaces that change the physics in ways this propagator does not model.
const UNMODELLED_SURFACE_PROPERTIES: [&str; 3] =
    ["REALRINDEX", "IMAGINARYRINDEX", "SURFACEROUGHNESS"];

impl SurfaceOptics {
    /// The properties of a surface, which must be a `dielectric_metal` or
    /// `dielectric_dielectric` surface of the glisur or unified model with one of the six
    /// plain finishes (the surface models of this propagator).
    pub fn new(s: &OpticalSurface) -> Result<Self, PhotonError> {
        let owner = format!("optical surface `{}`", s.name);
        let unsupported = |what: &str, value: &str| PhotonError::Unsupported {
            what: format!("{owner}: {what} `{value}`"),
        };
        // G4SurfaceType, G4OpticalSurfaceFinish and G4OpticalSurfaceModel, in enumerator
        // order (GDML gives either the name or the number).
        let kind = match enumerated(
            &s.kind,
            &[
                "dielectric_metal",
                "dielectric_dielectric",
                "dielectric_LUT",
            ],
        ) {
            Some("dielectric_metal") => SurfaceKind::DielectricMetal,
            Some("dielectric_dielectric") => SurfaceKind::DielectricDielectric,
            _ => return Err(unsupported("type", &s.kind)),
        };
        let finishes = [
            "polished",
            "polishedfrontpainted",
            "polishedbackpainted",
            "ground",
            "groundfrontpainted",
            "groundbackpainted",
        ];
        // Geant4's default finish is polished.
        let finish = match s.finish.trim() {
            "" => Finish::Polished,
            f => match enumerated(f, &finishes) {
                Some("polished") => Finish::Polished,
                Some("polishedfrontpainted") => Finish::PolishedFrontPainted,
                Some("polishedbackpainted") => Finish::PolishedBackPainted,
                Some("ground") => Finish::Ground,
                Some("groundfrontpainted") => Finish::GroundFrontPainted,
                Some("groundbackpainted") => Finish::GroundBackPainted,
                _ => return Err(unsupported("finish", &s.finish)),
            },
        };
        if !s.value.is_finite() {
            return Err(PhotonError::Input(format!(
                "{owner}: value {} is not a finite number",
                s.value
            )));
        }
        let roughness = match s.model.trim() {
            "" => Roughness::Glisur { polish: s.value },
            m => match enumerated(m, &["glisur", "unified"]) {
                Some("glisur") => Roughness::Glisur { polish: s.value },
                Some("unified") if s.value < 0.0 => {
                    return Err(PhotonError::Input(format!(
                        "{owner}: sigma_alpha (value) {} is negative",
                        s.value
                    )))
                }
                Some("unified") => Roughness::Unified {
                    sigma_alpha: s.value,
                },
                _ => return Err(unsupported("model", &s.model)),
            },
        };
        if let Some((name, _)) = s
            .properties
            .iter()
            .find(|(n, _)| UNMODELLED_SURFACE_PROPERTIES.contains(&n.as_str()))
        {
            return Err(unsupported("property", name));
        }
        let get = |name: &str| property(&s.properties, name, &owner);
        Ok(SurfaceOptics {
            name: s.name.clone(),
            kind,
            finish,
            roughness,
            reflectivity: get("REFLECTIVITY")?,
            efficiency: get("EFFICIENCY")?,
            transmittance: get("TRANSMITTANCE")?,
            rindex: get("RINDEX")?,
            spike: get("SPECULARSPIKECONSTANT")?,
            lobe: get("SPECULARLOBECONSTANT")?,
            backscatter: get("BACKSCATTERCONSTANT")?,
        })
    }
}

/// The optical properties of every material and surface of a scene (index as the Foundry's
/// optics); surfaces that no crossing uses are not checked.
pub struct OpticsTables {
    /// Materials.
    pub materials: Vec<MaterialOptics>,
    /// Surfaces: `None` for those no crossing of this propagator can meet.
    pub surfaces: Vec<Option<SurfaceOptics>>,
}

impl OpticsTables {
    /// Builds the tables; `used(s)` says whether surface `s` can be met.
    pub fn new(
        optics: &hytrace_foundry::optics::Optics,
        used: impl Fn(u32) -> bool,
    ) -> Result<Self, PhotonError> {
        let materials = optics
            .materials
            .iter()
            .map(MaterialOptics::new)
            .collect::<Result<_, _>>()?;
        let surfaces = optics
            .surfaces
            .iter()
            .enumerate()
            .map(|(i, s)| used(i as u32).then(|| SurfaceOptics::new(s)).transpose())
            .collect::<Result<_, _>>()?;
        Ok(OpticsTables {
            materials,
            surfaces,
        })
    }

    /// Material `m`, `None` for [`UNSET`].
    pub fn material(&self, m: u32) -> Option<&MaterialOptics> {
        (m != UNSET).then(|| &self.materials[m as usize])
    }

    /// Surface `s`, `None` for [`UNSET`].
    pub fn surface(&self, s: u32) -> Option<&SurfaceOptics> {
        if s == UNSET {
            return None;
        }
        self.surfaces[s as usize].as_ref()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(values: &[f64]) -> Table {
        Table {
            columns: 2,
            values: values.to_vec(),
        }
    }

    #[test]
    fn values_interpolate_linearly_and_clamp_outside() {
        let p = Property::new(&table(&[1e-6, 1.0, 3e-6, 2.0, 4e-6, 4.0]), "t").unwrap();
        assert_eq!(p.value(0.5e-6), 1.0);
        assert_eq!(p.value(1e-6), 1.0);
        assert!((p.value(2e-6) - 1.5).abs() < 1e-12);
        assert!((p.value(3.5e-6) - 3.0).abs() < 1e-12);
        assert_eq!(p.value(4e-6), 4.0);
        assert_eq!(p.value(9e-6), 4.0);
    }

    /// Tables of one value everywhere answer without searching; what they answer is, bit
    /// for bit, the linear interpolation between the rows bracketing the energy, found
    /// here by a scan (the sign of a zero included: between rows of -0 it is +0).
    #[test]
    fn flat_tables_answer_what_the_interpolation_gives_bit_for_bit() {
        let interpolated = |rows: &[f64], e: f64| {
            let pairs: Vec<(f64, f64)> = rows.chunks(2).map(|r| (r[0], r[1])).collect();
            let (first, last) = (pairs[0], pairs[pairs.len() - 1]);
            if e <= first.0 {
                return first.1;
            }
            if e >= last.0 {
                return last.1;
            }
            let k = pairs.iter().position(|&(x, _)| x > e).unwrap();
            let ((e0, v0), (e1, v1)) = (pairs[k - 1], pairs[k]);
            v0 + (v1 - v0) * (e - e0) / (e1 - e0)
        };
        let flat = [
            vec![
                1.512e-6, 0.0, 1.6e-6, 0.0, 2.0e-6, 0.0, 2.0e-6, 0.0, 2.0664e-5, 0.0,
            ],
            vec![1e-6, 0.98, 4e-6, 0.98],
            vec![1e-6, -0.0, 2e-6, -0.0, 4e-6, -0.0],
            vec![1.55e-6, 299.792, 1.55e-5, 299.792],
            vec![3e-6, 7.5],
        ];
        let sloped = [
            vec![1e-6, 0.98, 4e-6, 0.99],
            vec![1e-6, 1.0, 2e-6, 1.0, 3e-6, 1.5],
        ];
        for rows in flat.iter().chain(&sloped) {
            let p = Property::new(&table(rows), "t").unwrap();
            assert_eq!(p.flat, flat.contains(rows), "{rows:?}");
            for k in 0..=400 {
                let e = 0.9e-6 + 2.2e-5 * f64::from(k) / 400.0;
                let (got, want) = (p.value(e), interpolated(rows, e));
                assert_eq!(
                    got.to_bits(),
                    want.to_bits(),
                    "{rows:?} at {e:e}: {got} vs {want}"
                );
            }
        }
    }

    #[test]
    fn bad_tables_are_errors_naming_the_row() {
        let unsorted = Property::new(&table(&[2e-6, 1.0, 1e-6, 2.0]), "m: RINDEX");
        let msg = unsorted.unwrap_err().to_string();
        assert!(msg.contains("m: RINDEX") && msg.contains("row 1"), "{msg}");
        let negative = Property::new(&table(&[1e-6, -1.0]), "m: ABSLENGTH");
        assert!(negative.unwrap_err().to_string().contains("row 0"));
        assert!(Property::new(&table(&[]), "x").is_err());
        let three = Table {
            columns: 3,
            values: vec![1.0; 3],
        };
        assert!(Property::new(&three, "x").is_err());
    }

    #[test]
    fn group_velocity_follows_dispersion() {
        // n = a + b ln E: dn/dlnE = b, so v = c / (n + b) at every point.
        let (a, b) = (1.3, 0.05);
        let es = [1e-6, 2e-6, 3e-6, 4e-6];
        let values: Vec<f64> = es
            .iter()
            .flat_map(|&e: &f64| [e, a + b * (e * 1e6).ln()])
            .collect();
        let g = group_velocity(&Property::new(&table(&values), "n").unwrap());
        for (e, v) in g.energies.iter().zip(&g.values) {
            // The midpoints' n is the mean of the neighbours'.
            let n = if es.contains(e) {
                a + b * (e * 1e6).ln()
            } else {
                let i = es.iter().position(|x| x > e).unwrap();
                0.5 * (a + b * (es[i - 1] * 1e6).ln() + a + b * (es[i] * 1e6).ln())
            };
            assert!((v - C_LIGHT_MM_PER_NS / (n + b)).abs() < 1e-9, "{e}: {v}");
        }
        // First and last energies and the midpoints of all but the last interval.
        assert_eq!(g.energies.len(), 4);
        // Anomalous dispersion (n falling with E) gives c / n.
        let falling = Property::new(&table(&[1e-6, 1.5, 2e-6, 1.4]), "n").unwrap();
        let g = group_velocity(&falling);
        assert!((g.values[0] - C_LIGHT_MM_PER_NS / 1.5).abs() < 1e-12);
    }

    #[test]
    fn energy_and_wavelength_convert_with_hc() {
        // 1239.84198 eV nm: 420 nm is 2.952 eV.
        assert!((energy_of_wavelength(420.0) - 2.95200471e-6).abs() < 1e-13);
        assert!((wavelength_of_energy(energy_of_wavelength(420.0)) - 420.0).abs() < 1e-9);
    }

    fn optical_surface(model: &str, finish: &str, value: f64) -> OpticalSurface {
        OpticalSurface {
            name: "skin".into(),
            model: model.into(),
            finish: finish.into(),
            kind: "dielectric_dielectric".into(),
            value,
            properties: vec![],
        }
    }

    #[test]
    fn surface_models_and_finishes_read_as_geant4_names_them() {
        let s = SurfaceOptics::new(&optical_surface("1", "5", 0.25)).unwrap();
        assert_eq!(s.finish, Finish::GroundBackPainted);
        assert_eq!(s.roughness, Roughness::Unified { sigma_alpha: 0.25 });
        let s = SurfaceOptics::new(&optical_surface("", "", 0.0)).unwrap();
        assert_eq!(s.finish, Finish::Polished);
        assert_eq!(s.roughness, Roughness::Glisur { polish: 0.0 });
    }

    #[test]
    fn unmodelled_or_impossible_surfaces_are_refused_by_name() {
        let refused = |s: OpticalSurface, needle: &str| {
            let e = SurfaceOptics::new(&s).expect_err("refused").to_string();
            assert!(e.contains("`skin`") && e.contains(needle), "{e}");
        };
        refused(optical_surface("LUT", "polished", 0.0), "model `LUT`");
        refused(
            optical_surface("unified", "polishedlumirrorair", 0.1),
            "finish",
        );
        refused(optical_surface("unified", "ground", -0.1), "negative");
        refused(optical_surface("unified", "ground", f64::NAN), "finite");
        let mut s = optical_surface("unified", "ground", 0.1);
        s.properties = vec![(
            "SURFACEROUGHNESS".into(),
            Table {
                columns: 1,
                values: vec![1e-6],
            },
        )];
        refused(s, "SURFACEROUGHNESS");
    }

    fn shifter(mean_photons: Option<f64>) -> Wls {
        // Intensity 0, 1, 1, 0 at 2, 2.5, 3, 3.5 eV: integral 0, 0.25, 0.75, 1.0 (x 1e-6).
        let c = Property::new(
            &table(&[2e-6, 0.0, 2.5e-6, 1.0, 3e-6, 1.0, 3.5e-6, 0.0]),
            "w",
        )
        .unwrap();
        Wls::new(&c, 1.5, mean_photons)
    }

    #[test]
    fn re_emitted_energies_follow_the_integral_of_the_spectrum() {
        let w = shifter(None);
        let mut rng = Rng::new(8, 0, 0);
        let n = 100_000;
        let energies: Vec<f64> = (0..n)
            .map(|_| w.sample_energy(1.0, &mut rng).unwrap())
            .collect();
        for (edge, expected) in [(2.5e-6, 0.25), (3e-6, 0.75)] {
            let below = energies.iter().filter(|&&e| e < edge).count() as f64 / n as f64;
            let sigma = (expected * (1.0 - expected) / n as f64).sqrt();
            assert!((below - expected).abs() < 4.0 * sigma, "{edge}: {below}");
        }
        // Never above the absorbed photon's energy; none when the spectrum lies above it.
        assert!((0..10_000).all(|_| w.sample_energy(2.6e-6, &mut rng).unwrap() <= 2.6e-6));
        assert_eq!(w.sample_energy(1.9e-6, &mut rng), None);
    }

    #[test]
    fn photons_per_absorption_are_one_or_poisson() {
        let mut rng = Rng::new(9, 0, 0);
        assert!((0..100).all(|_| shifter(None).sample_count(&mut rng) == 1));
        for mean in [2.0, 30.0] {
            let w = shifter(Some(mean));
            let n = 100_000;
            let counts: Vec<f64> = (0..n)
                .map(|_| f64::from(w.sample_count(&mut rng)))
                .collect();
            let m = counts.iter().sum::<f64>() / n as f64;
            let var = counts.iter().map(|c| (c - m).powi(2)).sum::<f64>() / n as f64;
            assert!(
                (m - mean).abs() < 4.0 * (mean / n as f64).sqrt(),
                "{mean}: mean {m}"
            );
            assert!((var / mean - 1.0).abs() < 0.03, "{mean}: variance {var}");
        }
    }

    #[test]
    fn shifters_need_their_delay_and_unmodelled_processes_are_refused() {
        let material = |props: &[(&str, Table)]| Material {
            name: "plastic".into(),
            properties: props
                .iter()
                .map(|(n, t)| (n.to_string(), t.clone()))
                .collect(),
        };
        let spectrum = table(&[2e-6, 1.0, 3e-6, 1.0]);
        let e = MaterialOptics::new(&material(&[("WLSCOMPONENT", spectrum.clone())]))
            .expect_err("no delay")
            .to_string();
        assert!(
            e.contains("`plastic`") && e.contains("WLSTIMECONSTANT"),
            "{e}"
        );
        let e = MaterialOptics::new(&material(&[
            ("WLSCOMPONENT", spectrum),
            ("WLSTIMECONSTANT", table(&[1e-6, 2.0])),
        ]))
        .expect_err("a table, not a constant")
        .to_string();
        assert!(
            e.contains("WLSTIMECONSTANT") && e.contains("constant"),
            "{e}"
        );
        let e = MaterialOptics::new(&material(&[("MIEHG", table(&[2e-6, 1.0]))]))
            .expect_err("Mie")
            .to_string();
        assert!(e.contains("MIEHG") && e.contains("not modelled"), "{e}");
    }

    #[test]
    fn re_emission_needs_a_scintillator_and_a_probability() {
        let material = |props: Vec<(&str, Table)>| Material {
            name: "LS".into(),
            properties: props.into_iter().map(|(n, t)| (n.to_string(), t)).collect(),
        };
        let prob = |p: f64| ("REEMISSIONPROB", table(&[2e-6, p, 3e-6, p]));
        let scint = || {
            vec![
                ("SCINTILLATIONCOMPONENT1", table(&[2e-6, 1.0, 3e-6, 1.0])),
                (
                    "SCINTILLATIONTIMECONSTANT1",
                    Table {
                        columns: 1,
                        values: vec![4.0],
                    },
                ),
            ]
        };
        let ok = MaterialOptics::new(&material([scint(), vec![prob(0.3)]].concat())).unwrap();
        let r = ok.reemission.expect("re-emits");
        assert_eq!(r.probability.value(2.5e-6), 0.3);
        // A probability of zero re-emits nothing and needs no scintillation.
        let zero = MaterialOptics::new(&material(vec![prob(0.0)])).unwrap();
        assert!(zero.reemission.is_none());
        for (props, needle) in [
            (vec![prob(0.3)], "no SCINTILLATIONCOMPONENT1"),
            ([scint(), vec![prob(1.5)]].concat(), "above 1"),
        ] {
            let e = MaterialOptics::new(&material(props))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("`LS`: property REEMISSIONPROB") && e.contains(needle),
                "{e}"
            );
        }
    }
}
