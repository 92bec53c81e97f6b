//! Scintillation light as Geant4 11's G4Scintillation emits it: a material's one to three
//! components (SCINTILLATIONCOMPONENTk spectra with their SCINTILLATIONTIMECONSTANTk decay
//! times, SCINTILLATIONRISETIMEk rise times and SCINTILLATIONYIELDk weights), each photon
//! isotropic with a random linear polarization, its energy drawn from its component's
//! spectrum and its delay from the component's time profile. Used by scintillation
//! gensteps ([`super::gensteps`]) and by re-emission (REEMISSIONPROB).

use hytrace_foundry::optics::Material;
use hytrace_volume::Rng;

use super::properties::{constant, property, Spectrum};
use super::PhotonError;

/// One scintillation component.
#[derive(Clone, Debug)]
struct Component {
    /// SCINTILLATIONCOMPONENTk: intensity per photon energy.
    spectrum: Spectrum,
    /// SCINTILLATIONTIMECONSTANTk (ns).
    decay: f64,
    /// SCINTILLATIONRISETIMEk (ns); 0: an instant rise.
    rise: f64,
    /// SCINTILLATIONYIELDk: the component's share of the photons.
    weight: f64,
}

/// A material's scintillation components.
#[derive(Clone, Debug)]
pub struct Scintillator {
    components: Vec<Component>,
}

impl Scintillator {
    /// The scintillation of material `m`: as many components as the highest
    /// SCINTILLATIONCOMPONENTk it has (Geant4 counts them so), each needing its spectrum
    /// and its SCINTILLATIONTIMECONSTANTk; yields default to 1 for the first component and
    /// 0 for the others, as in Geant4.
    pub fn new(m: &Material) -> Result<Scintillator, PhotonError> {
        let owner = format!("material `{}`", m.name);
        let has = |k: usize| {
            m.properties
                .iter()
                .any(|(n, _)| *n == format!("SCINTILLATIONCOMPONENT{k}"))
        };
        let Some(count) = (1..=3).rev().find(|&k| has(k)) else {
            return Err(PhotonError::Input(format!(
                "{owner} has no SCINTILLATIONCOMPONENT1: it cannot scintillate"
            )));
        };
        let mut components = Vec::new();
        for k in 1..=count {
            let name = format!("SCINTILLATIONCOMPONENT{k}");
            let Some(intensity) = property(&m.properties, &name, &owner)? else {
                return Err(PhotonError::Input(format!(
                    "{owner} has SCINTILLATIONCOMPONENT{count} but no {name}"
                )));
            };
            let decay_name = format!("SCINTILLATIONTIMECONSTANT{k}");
            let Some(decay) = constant(&m.properties, &decay_name, &owner)? else {
                return Err(PhotonError::Input(format!(
                    "{owner}: {name} needs the constant {decay_name} (its decay time)"
                )));
            };
            let rise = constant(&m.properties, &format!("SCINTILLATIONRISETIME{k}"), &owner)?;
            let weight = constant(&m.properties, &format!("SCINTILLATIONYIELD{k}"), &owner)?;
            components.push(Component {
                spectrum: Spectrum::new(&intensity),
                decay,
                rise: rise.unwrap_or(0.0),
                weight: weight.unwrap_or(if k == 1 { 1.0 } else { 0.0 }),
            });
        }
        if count > 1 && components.iter().map(|c| c.weight).sum::<f64>() <= 0.0 {
            return Err(PhotonError::Input(format!(
                "{owner}: the yields SCINTILLATIONYIELD1..{count} add up to 0"
            )));
        }
        Ok(Scintillator { components })
    }

    /// Number of components (1 to 3).
    pub fn components(&self) -> usize {
        self.components.len()
    }

    /// How G4Scintillation divides `n` photons among the components: all to a single one;
    /// of two, the first `floor(n y1 / (y1 + y2))` and the rest to the second; of three,
    /// `floor(n yk / sum)` each (so up to two photons of `n` are not emitted, as in Geant4).
    pub fn split(&self, n: u64) -> [u64; 3] {
        let sum: f64 = self.components.iter().map(|c| c.weight).sum();
        let share = |k: usize| (self.components[k].weight / sum * n as f64) as u64;
        match self.components.len() {
            1 => [n, 0, 0],
            2 => [share(0), n - share(0), 0],
            _ => [share(0), share(1), share(2)],
        }
    }

    /// Component `k`'s spectrum, decay time, rise time (0: none) and yield.
    pub fn component(&self, k: usize) -> (&Spectrum, f64, f64, f64) {
        let c = &self.components[k];
        (&c.spectrum, c.decay, c.rise, c.weight)
    }

    /// A component drawn in proportion to the yields (for single re-emitted photons).
    pub fn pick(&self, rng: &mut Rng) -> usize {
        let sum: f64 = self.components.iter().map(|c| c.weight).sum();
        let mut u = rng.next_f64() * sum;
        for (k, c) in self.components.iter().enumerate() {
            if u < c.weight {
                return k;
            }
            u -= c.weight;
        }
        self.components.len() - 1
    }

    /// A photon energy (MeV) from component `k`'s spectrum.
    pub fn energy(&self, k: usize, rng: &mut Rng) -> f64 {
        self.components[k].spectrum.sample(rng)
    }

    /// A delay (ns) after the deposit from component `k`'s time profile: exponential with
    /// the decay time `d`, or with a rise time `r` G4Scintillation's profile
    /// `(r + d) / d^2 exp(-t/d) (1 - exp(-t/r))`, sampled as it samples it (an exponential
    /// envelope of the decay time and rejection).
    pub fn delay(&self, k: usize, rng: &mut Rng) -> f64 {
        let Component { decay, rise, .. } = self.components[k];
        if rise == 0.0 {
            return -decay * (1.0 - rng.next_f64()).ln();
        }
        // The envelope (r + d) / d^2 exp(-t/d) lies above the profile everywhere; their
        // ratio is 1 - exp(-t/r).
        loop {
            let t = -decay * (1.0 - rng.next_f64()).ln();
            if rng.next_f64() <= 1.0 - (-t / rise).exp() {
                return t;
            }
        }
    }
}

/// Materials for the tests of the photon sources.
#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use hytrace_foundry::optics::Table;

    /// A table: a constant for one value, else `(energy, value)` rows.
    fn table(values: &[f64]) -> Table {
        Table {
            columns: if values.len() == 1 { 1 } else { 2 },
            values: values.to_vec(),
        }
    }

    /// A material named `name` with the given named tables.
    pub(crate) fn material(name: &str, props: &[(&str, &[f64])]) -> Material {
        Material {
            name: name.into(),
            properties: props
                .iter()
                .map(|(n, v)| (n.to_string(), table(v)))
                .collect(),
        }
    }

    const SPECTRUM: &[f64] = &[2e-6, 1.0, 3e-6, 1.0];

    #[test]
    fn photons_divide_among_components_as_geant4_divides_them() {
        let two = Scintillator::new(&material(
            "Scint",
            &[
                ("SCINTILLATIONCOMPONENT1", SPECTRUM),
                ("SCINTILLATIONCOMPONENT2", SPECTRUM),
                ("SCINTILLATIONTIMECONSTANT1", &[6.0]),
                ("SCINTILLATIONTIMECONSTANT2", &[1500.0]),
                ("SCINTILLATIONYIELD1", &[0.3]),
                ("SCINTILLATIONYIELD2", &[0.7]),
            ],
        ))
        .unwrap();
        // floor(10 * 0.3) = 3 (0.3 / 1.0 * 10 is 2.9999999999999996 in f64, as in Geant4).
        assert_eq!(two.split(10)[0] + two.split(10)[1], 10);
        assert_eq!(two.split(1000), [300, 700, 0]);
        let three = Scintillator::new(&material(
            "Scint",
            &[
                ("SCINTILLATIONCOMPONENT1", SPECTRUM),
                ("SCINTILLATIONCOMPONENT2", SPECTRUM),
                ("SCINTILLATIONCOMPONENT3", SPECTRUM),
                ("SCINTILLATIONTIMECONSTANT1", &[1.0]),
                ("SCINTILLATIONTIMECONSTANT2", &[2.0]),
                ("SCINTILLATIONTIMECONSTANT3", &[3.0]),
                ("SCINTILLATIONYIELD1", &[1.0]),
                ("SCINTILLATIONYIELD2", &[1.0]),
                ("SCINTILLATIONYIELD3", &[1.0]),
            ],
        ))
        .unwrap();
        assert_eq!(three.split(10), [3, 3, 3]);
        // Drawn in proportion to the yields: a third each.
        let mut rng = Rng::new(5, 0, 0);
        let mut seen = [0u32; 3];
        for _ in 0..30_000 {
            seen[three.pick(&mut rng)] += 1;
        }
        for s in seen {
            assert!((f64::from(s) - 10_000.0).abs() < 4.0 * 81.6, "{seen:?}");
        }
    }

    #[test]
    fn materials_that_cannot_scintillate_are_refused_by_name() {
        for (props, needle) in [
            (vec![], "no SCINTILLATIONCOMPONENT1"),
            (
                vec![("SCINTILLATIONCOMPONENT1", SPECTRUM)],
                "SCINTILLATIONTIMECONSTANT1",
            ),
            (
                vec![
                    ("SCINTILLATIONCOMPONENT2", SPECTRUM),
                    ("SCINTILLATIONTIMECONSTANT2", &[1.0][..]),
                ],
                "no SCINTILLATIONCOMPONENT1",
            ),
        ] {
            let e = Scintillator::new(&material("Scint", &props))
                .unwrap_err()
                .to_string();
            assert!(e.contains("`Scint`") && e.contains(needle), "{e}");
        }
    }
}
