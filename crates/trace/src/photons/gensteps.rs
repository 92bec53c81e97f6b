//! Gensteps: the steps of charged particles that emit optical photons, handed over by a
//! Geant4 application (as Opticks' users hand theirs over), and the photons emitted along
//! them as G4Scintillation ([`super::scintillation`]) and G4Cerenkov ([`super::cherenkov`])
//! emit them.
//!
//! A genstep file is a float64 `.npy` array of shape `(G, 14)`, one row a step:
//!
//! | column | content |
//! |---|---|
//! | 0 | kind: 1 Cherenkov, 2 scintillation |
//! | 1 | number of photons (a whole number, 0 or more) |
//! | 2 | material index: the material's position in the scene's material table |
//! | 3 | time at the step's start (ns) |
//! | 4-6 | start of the step (mm) |
//! | 7-9 | end of the step (mm) |
//! | 10 | the particle's speed over `c` (beta) at the start |
//! | 11 | beta at the end |
//! | 12 | the particle's charge (units of e) |
//! | 13 | scintillation: 0 (the material's components share the photons as Geant4 shares them) or the component 1-3 that emits them all; Cherenkov: 0 |
//!
//! Photons are numbered through the file in row order: photon `i` of a run draws the
//! stream `(seed, i)`.

use std::path::Path;

use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::read_array;
use hytrace_foundry::optics::Material;
use hytrace_foundry::UNSET;
use hytrace_volume::Rng;

use super::bulk::isotropic;
use super::cherenkov::Cherenkov;
use super::gpu_tables::GpuTables;
use super::properties::C_LIGHT_MM_PER_NS;
use super::scintillation::Scintillator;
use super::{PhotonError, V};
use crate::gpu::photon_records::{
    PhotonGenstep, PHOTON_GENSTEP_CHERENKOV, PHOTON_GENSTEP_SCINTILLATION,
};

/// Columns of a genstep row.
pub const GENSTEP_COLUMNS: usize = 14;

/// Kind code of a Cherenkov genstep (column 0).
pub const CHERENKOV: f64 = 1.0;

/// Kind code of a scintillation genstep (column 0).
pub const SCINTILLATION: f64 = 2.0;

/// What emits a genstep's photons.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kind {
    /// Cherenkov light.
    Cherenkov,
    /// Scintillation light of one component (1-3), or shared among the material's
    /// components (0).
    Scintillation {
        /// Component, 0 for all.
        component: u8,
    },
}

/// One genstep row, checked for what can be checked without the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Genstep {
    /// What emits.
    pub kind: Kind,
    /// Number of photons.
    pub photons: u64,
    /// Material index.
    pub material: u32,
    /// Time at the start (ns).
    pub time: f64,
    /// Start of the step (mm).
    pub start: V,
    /// End of the step (mm).
    pub end: V,
    /// Speed over `c` at the start and the end.
    pub beta: [f64; 2],
    /// Charge (e).
    pub charge: f64,
}

/// The gensteps of a run and where they came from (named in messages).
#[derive(Clone, Debug, PartialEq)]
pub struct GenstepFile {
    /// The file (or other source) they were read from.
    pub source: String,
    /// The rows.
    pub steps: Vec<Genstep>,
}

/// A whole number in `0 ..= max` from a float column.
fn whole(x: f64, max: f64) -> Option<f64> {
    (x >= 0.0 && x.fract() == 0.0 && x <= max).then_some(x)
}

impl GenstepFile {
    /// Reads a genstep file (see the module doc).
    pub fn read(path: &Path) -> Result<GenstepFile, PhotonError> {
        let source = path.display().to_string();
        let array = read_array(path).map_err(|e| PhotonError::Input(e.to_string()))?;
        if array.scalar != Scalar::F64 {
            return Err(PhotonError::Input(format!(
                "{source}: gensteps must be float64, found {}",
                array.scalar.numpy()
            )));
        }
        let values: Vec<f64> = array
            .bytes
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")))
            .collect();
        GenstepFile::from_values(source, &array.shape, &values)
    }

    /// Number of photons the gensteps emit in a scene of `materials` (checked against
    /// them, as a run checks them).
    pub fn photons(&self, materials: &[Material]) -> Result<u64, PhotonError> {
        Ok(Gensteps::new(self, materials)?.photons())
    }

    /// Gensteps from an array's shape and values (row-major); `source` names them in
    /// messages.
    pub fn from_values(
        source: String,
        shape: &[u64],
        values: &[f64],
    ) -> Result<GenstepFile, PhotonError> {
        if shape.len() != 2 || shape[1] != GENSTEP_COLUMNS as u64 {
            return Err(PhotonError::Input(format!(
                "{source}: gensteps must have shape (G, {GENSTEP_COLUMNS}), found {shape:?}"
            )));
        }
        let steps = values
            .chunks_exact(GENSTEP_COLUMNS)
            .enumerate()
            .map(|(r, row)| {
                Genstep::parse(row)
                    .map_err(|problem| PhotonError::Input(format!("{source}: row {r}: {problem}")))
            })
            .collect::<Result<_, _>>()?;
        Ok(GenstepFile { source, steps })
    }
}

impl Genstep {
    /// Checks and reads one row.
    fn parse(row: &[f64]) -> Result<Genstep, String> {
        if let Some(c) = row.iter().position(|x| !x.is_finite()) {
            return Err(format!("column {c} is {}, not a finite number", row[c]));
        }
        let photons = whole(row[1], 2f64.powi(53)).ok_or_else(|| {
            format!(
                "the number of photons (column 1) is {}, not a whole number >= 0",
                row[1]
            )
        })?;
        let material = whole(row[2], f64::from(u32::MAX - 1)).ok_or_else(|| {
            format!(
                "the material index (column 2) is {}, not a whole number >= 0",
                row[2]
            )
        })?;
        for (c, b) in [(10, row[10]), (11, row[11])] {
            if !(b > 0.0 && b <= 1.0) {
                return Err(format!("beta (column {c}) is {b}, not in (0, 1]"));
            }
        }
        let component = row[13];
        let kind = match row[0] {
            CHERENKOV => {
                if component != 0.0 {
                    return Err(format!(
                        "column 13 is {component}: a Cherenkov step has no component (0)"
                    ));
                }
                if row[12] == 0.0 {
                    return Err("a Cherenkov step needs a charged particle (column 12 is 0)".into());
                }
                if row[4..7] == row[7..10] {
                    return Err(
                        "a Cherenkov step needs a length: its start and end are the same point"
                            .into(),
                    );
                }
                Kind::Cherenkov
            }
            SCINTILLATION => match whole(component, 3.0) {
                Some(k) => Kind::Scintillation { component: k as u8 },
                None => {
                    return Err(format!(
                        "the scintillation component (column 13) is {component}, not 0, 1, 2 or 3"
                    ))
                }
            },
            k => {
                return Err(format!(
                    "unknown kind {k} in column 0 (1: Cherenkov, 2: scintillation)"
                ))
            }
        };
        Ok(Genstep {
            kind,
            photons: photons as u64,
            material: material as u32,
            time: row[3],
            start: V::new(row[4], row[5], row[6]),
            end: V::new(row[7], row[8], row[9]),
            beta: [row[10], row[11]],
            charge: row[12],
        })
    }

    /// Where along the step a photon starts (the fraction `u` of the way) and when: the
    /// particle's time there, its speed taken as linear in `u` on the way as Geant4
    /// takes it.
    fn along(&self, u: f64) -> (V, f64) {
        let (v0, v1) = (
            self.beta[0] * C_LIGHT_MM_PER_NS,
            self.beta[1] * C_LIGHT_MM_PER_NS,
        );
        let step = self.end - self.start;
        let dt = u * step.length() / (v0 + u * (v1 - v0) / 2.0);
        (self.start + step * u, self.time + dt)
    }
}

/// A photon emitted by a genstep: where, when, which way, its polarization and energy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Emitted {
    /// Position (mm).
    pub position: V,
    /// Time (ns).
    pub time: f64,
    /// Unit direction.
    pub direction: V,
    /// Unit polarization, perpendicular to the direction.
    pub polarization: V,
    /// Energy (MeV).
    pub energy: f64,
}

/// How a prepared genstep emits.
#[derive(Clone, Debug)]
enum Emitter {
    /// Along the step's direction at the mean beta; photons placed along the step in
    /// proportion to the yields at its two ends.
    Cherenkov {
        material: usize,
        axis: V,
        beta: f64,
        yields: [f64; 2],
    },
    /// The photons of each component in turn: `counts[k]` of component `k`.
    Scintillation { material: usize, counts: [u64; 3] },
}

/// Gensteps prepared for a scene's materials: photon `i` of the file is found by its
/// genstep and drawn there.
#[derive(Clone, Debug)]
pub struct Gensteps {
    steps: Vec<(Genstep, Emitter)>,
    /// Photons emitted by the gensteps up to and including each.
    ends: Vec<u64>,
    cherenkov: Vec<Option<Cherenkov>>,
    scintillators: Vec<Option<Scintillator>>,
}

impl Gensteps {
    /// Prepares `file`'s gensteps for `materials` (the scene's material table), checking
    /// that each material can emit as asked.
    pub fn new(file: &GenstepFile, materials: &[Material]) -> Result<Gensteps, PhotonError> {
        let mut cherenkov: Vec<Option<Cherenkov>> = vec![None; materials.len()];
        let mut scintillators: Vec<Option<Scintillator>> = vec![None; materials.len()];
        let mut steps = Vec::with_capacity(file.steps.len());
        let mut ends = Vec::with_capacity(file.steps.len());
        let mut total = 0u64;
        for (r, g) in file.steps.iter().enumerate() {
            let bad = |problem: String| {
                PhotonError::Input(format!("{}: row {r}: {problem}", file.source))
            };
            let m = g.material as usize;
            let Some(material) = materials.get(m) else {
                let list: Vec<String> = materials
                    .iter()
                    .enumerate()
                    .map(|(i, m)| format!("{i} {}", m.name))
                    .collect();
                return Err(bad(format!(
                    "material index {m} out of range (the scene's materials: {})",
                    list.join(", ")
                )));
            };
            let emitter = match g.kind {
                Kind::Cherenkov => {
                    if cherenkov[m].is_none() {
                        cherenkov[m] =
                            Some(Cherenkov::new(material).map_err(|e| bad(e.to_string()))?);
                    }
                    let c = cherenkov[m].as_ref().expect("prepared above");
                    let beta = 0.5 * (g.beta[0] + g.beta[1]);
                    if g.photons > 0 && beta * c.max_index() <= 1.0 {
                        return Err(bad(format!(
                            "beta {beta} is below the Cherenkov threshold of `{}` (1 / {} = {})",
                            material.name,
                            c.max_index(),
                            1.0 / c.max_index()
                        )));
                    }
                    Emitter::Cherenkov {
                        material: m,
                        axis: (g.end - g.start).normalized(),
                        beta,
                        yields: g.beta.map(|b| c.relative_yield(b)),
                    }
                }
                Kind::Scintillation { component } => {
                    if scintillators[m].is_none() {
                        scintillators[m] =
                            Some(Scintillator::new(material).map_err(|e| bad(e.to_string()))?);
                    }
                    let s = scintillators[m].as_ref().expect("prepared above");
                    let counts = match component {
                        0 => s.split(g.photons),
                        k if usize::from(k) <= s.components() => {
                            let mut c = [0; 3];
                            c[usize::from(k) - 1] = g.photons;
                            c
                        }
                        k => {
                            return Err(bad(format!(
                                "scintillation component {k}: material `{}` has {}",
                                material.name,
                                s.components()
                            )))
                        }
                    };
                    Emitter::Scintillation {
                        material: m,
                        counts,
                    }
                }
            };
            total = total
                .checked_add(match &emitter {
                    Emitter::Scintillation { counts, .. } => counts.iter().sum(),
                    Emitter::Cherenkov { .. } => g.photons,
                })
                .ok_or_else(|| bad("the photon count overflows".into()))?;
            steps.push((*g, emitter));
            ends.push(total);
        }
        Ok(Gensteps {
            steps,
            ends,
            cherenkov,
            scintillators,
        })
    }

    /// Number of photons the gensteps emit.
    pub fn photons(&self) -> u64 {
        self.ends.last().copied().unwrap_or(0)
    }

    /// The gensteps as the GPU kernel emits photons from them (`shaders/photons/gensteps.wgsl`,
    /// the twin of [`Gensteps::emit`]), their scintillation spectra appended to `tables`.
    /// A step of 2^32 photons or more is refused, naming its row.
    pub fn gpu_records(&self, tables: &mut GpuTables) -> Result<Vec<PhotonGenstep>, String> {
        let mut spectra: Vec<Option<[u32; 3]>> = vec![None; self.scintillators.len()];
        let mut before = 0;
        let mut records = Vec::with_capacity(self.steps.len());
        for (row, ((step, emitter), &end)) in self.steps.iter().zip(&self.ends).enumerate() {
            if end - before > u64::from(u32::MAX) {
                return Err(format!(
                    "row {row}: {} photons from one step (the GPU kernel counts them in 32 bits)",
                    end - before
                ));
            }
            before = end;
            let f = |v: V| v.to_f64().map(|c| c as f32);
            let mut r = PhotonGenstep {
                material: step.material,
                end_index: [end as u32, (end >> 32) as u32],
                start: f(step.start),
                time: step.time as f32,
                end: f(step.end),
                charge: step.charge as f32,
                beta: step.beta.map(|b| b as f32),
                ..Default::default()
            };
            match *emitter {
                Emitter::Cherenkov {
                    material,
                    axis,
                    beta,
                    yields,
                } => {
                    let c = self.cherenkov[material].as_ref().expect("prepared");
                    let max_cos = 1.0 / (beta * c.max_index());
                    r.kind = PHOTON_GENSTEP_CHERENKOV;
                    r.mean_beta = beta as f32;
                    r.max_sin2 = ((1.0 - max_cos) * (1.0 + max_cos)) as f32;
                    r.axis = f(axis);
                    r.yields = yields.map(|y| y as f32);
                }
                Emitter::Scintillation { material, counts } => {
                    let s = self.scintillators[material].as_ref().expect("prepared");
                    r.kind = PHOTON_GENSTEP_SCINTILLATION;
                    r.counts = counts.map(|c| c as u32);
                    r.spectrum = *spectra[material].get_or_insert_with(|| {
                        let mut t = [UNSET; 3];
                        for (k, t) in t.iter_mut().enumerate().take(s.components()) {
                            *t = tables.push_spectrum(s.component(k).0);
                        }
                        t
                    });
                    for k in 0..s.components() {
                        let (_, decay, rise, _) = s.component(k);
                        r.decay[k] = decay as f32;
                        r.rise[k] = rise as f32;
                    }
                }
            }
            records.push(r);
        }
        Ok(records)
    }

    /// Photon `index` (below [`Gensteps::photons`]), drawn from `rng`.
    pub fn emit(&self, index: u64, rng: &mut Rng) -> Emitted {
        let g = self.ends.partition_point(|&e| e <= index);
        let local = index - if g == 0 { 0 } else { self.ends[g - 1] };
        let (step, emitter) = &self.steps[g];
        match *emitter {
            Emitter::Cherenkov {
                material,
                axis,
                beta,
                yields: [y0, y1],
            } => {
                let c = self.cherenkov[material].as_ref().expect("prepared");
                let (direction, polarization, energy) = c.sample(beta, axis, rng);
                // The fraction of the way, with density linear from y0 to y1 (G4Cerenkov's
                // rejection on the photon numbers at the two ends).
                let u = loop {
                    let u = rng.next_f64();
                    if rng.next_f64() * y0.max(y1) <= y0 - u * (y0 - y1) {
                        break u;
                    }
                };
                let (position, time) = step.along(u);
                Emitted {
                    position,
                    time,
                    direction,
                    polarization,
                    energy,
                }
            }
            Emitter::Scintillation { material, counts } => {
                let s = self.scintillators[material].as_ref().expect("prepared");
                let mut k = 0;
                let mut first = counts[0];
                while local >= first {
                    k += 1;
                    first += counts[k];
                }
                let energy = s.energy(k, rng);
                let (direction, polarization) = isotropic(rng);
                // A neutral particle's photons start at the step's end, as in Geant4.
                let u = if step.charge == 0.0 {
                    1.0
                } else {
                    rng.next_f64()
                };
                let (position, time) = step.along(u);
                Emitted {
                    position,
                    time: time + s.delay(k, rng),
                    direction,
                    polarization,
                    energy,
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photons::scintillation::tests::material;

    /// Material 0 a vacuum (no optical tables), material 1 a scintillator with two
    /// components (the second with a rise time) and a RINDEX for Cherenkov light.
    fn materials() -> Vec<Material> {
        vec![
            material("Vacuum", &[]),
            material(
                "Scint",
                &[
                    ("RINDEX", &[2.0e-6, 1.45, 3.5e-6, 1.50]),
                    (
                        "SCINTILLATIONCOMPONENT1",
                        &[2.0e-6, 0.0, 2.8e-6, 1.0, 3.5e-6, 0.0],
                    ),
                    ("SCINTILLATIONCOMPONENT2", &[2.0e-6, 1.0, 3.5e-6, 1.0]),
                    ("SCINTILLATIONTIMECONSTANT1", &[5.0]),
                    ("SCINTILLATIONTIMECONSTANT2", &[40.0]),
                    ("SCINTILLATIONRISETIME2", &[3.0]),
                    ("SCINTILLATIONYIELD1", &[0.75]),
                    ("SCINTILLATIONYIELD2", &[0.25]),
                ],
            ),
        ]
    }

    /// A row of the layout.
    #[allow(clippy::too_many_arguments)]
    fn row(
        kind: f64,
        n: f64,
        m: f64,
        t0: f64,
        a: [f64; 3],
        b: [f64; 3],
        beta: [f64; 2],
        q: f64,
        k: f64,
    ) -> Vec<f64> {
        let mut r = vec![kind, n, m, t0];
        r.extend(a);
        r.extend(b);
        r.extend([beta[0], beta[1], q, k]);
        r
    }

    fn file(rows: &[Vec<f64>]) -> Result<GenstepFile, PhotonError> {
        let values: Vec<f64> = rows.concat();
        GenstepFile::from_values("g.npy".into(), &[rows.len() as u64, 14], &values)
    }

    /// Kolmogorov-Smirnov distance between a sample and a CDF.
    fn ks(mut x: Vec<f64>, cdf: impl Fn(f64) -> f64) -> f64 {
        x.sort_by(f64::total_cmp);
        let n = x.len() as f64;
        x.iter()
            .enumerate()
            .map(|(i, &v)| {
                let f = cdf(v);
                (f - i as f64 / n).abs().max((f - (i + 1) as f64 / n).abs())
            })
            .fold(0.0, f64::max)
    }

    /// The KS distance above which a sample of `n` is rejected at p = 0.001.
    fn ks_limit(n: usize) -> f64 {
        1.95 / (n as f64).sqrt()
    }

    /// Where along its step, as a fraction, and after which delay past the particle's
    /// passage a photon was emitted.
    fn along_and_delay(g: &Genstep, e: &Emitted) -> (f64, f64) {
        let step = g.end - g.start;
        let u = (e.position - g.start).length() / step.length();
        let (_, t) = g.along(u);
        (u, e.time - t)
    }

    /// The kernel's records: ends counted through the steps in 64 bits, each component's
    /// photons, the spectra appended once per material; a step of 2^32 photons refused by
    /// its row.
    #[test]
    fn gpu_records_number_the_photons_and_refuse_steps_past_32_bits() {
        let scint = |n: f64| {
            row(
                2.0,
                n,
                1.0,
                0.0,
                [0.0; 3],
                [1.0, 0.0, 0.0],
                [0.5, 0.5],
                -1.0,
                0.0,
            )
        };
        let cherenkov = row(
            1.0,
            10.0,
            1.0,
            0.0,
            [0.0; 3],
            [0.0, 0.0, 5.0],
            [0.9, 0.9],
            -1.0,
            0.0,
        );
        let f = file(&[scint(4e9), scint(100.0), cherenkov.clone()]).unwrap();
        let g = Gensteps::new(&f, &materials()).unwrap();
        let mut tables = GpuTables::default();
        let r = g.gpu_records(&mut tables).unwrap();
        let end = |r: &PhotonGenstep| u64::from(r.end_index[0]) | (u64::from(r.end_index[1]) << 32);
        assert_eq!(
            r.iter().map(end).collect::<Vec<_>>(),
            [4_000_000_000, 4_000_000_100, 4_000_000_110]
        );
        assert_eq!(r[1].counts, [75, 25, 0]);
        assert_eq!((r[0].spectrum, tables.tables.len()), (r[1].spectrum, 2));
        assert_eq!(r[2].kind, PHOTON_GENSTEP_CHERENKOV);
        assert!(r[2].max_sin2 > 0.0 && r[2].axis == [0.0, 0.0, 1.0]);
        let f = file(&[cherenkov, scint(5e9)]).unwrap();
        let why = Gensteps::new(&f, &materials())
            .unwrap()
            .gpu_records(&mut tables)
            .unwrap_err();
        assert!(why.starts_with("row 1: 5000000000 photons"), "{why}");
    }

    #[test]
    fn scintillation_times_positions_and_components_follow_geant4s_distributions() {
        let beta = [0.9, 0.5];
        let f = file(&[row(
            2.0,
            40_000.0,
            1.0,
            7.0,
            [0.0, 0.0, 0.0],
            [3.0, 4.0, 0.0],
            beta,
            -1.0,
            0.0,
        )])
        .unwrap();
        let g = Gensteps::new(&f, &materials()).unwrap();
        // G4Scintillation's split of two components: floor(0.75 n) and the rest.
        assert_eq!(g.photons(), 40_000);
        let step = f.steps[0];
        let (mut us, mut fast, mut slow) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..g.photons() {
            let mut rng = Rng::new(1, i as u32, 0);
            let e = g.emit(i, &mut rng);
            assert!(e.direction.dot(e.polarization).abs() < 1e-12);
            // On the step.
            let off = e.position - step.start;
            assert!(off.cross(step.end - step.start).length() < 1e-9);
            let (u, delay) = along_and_delay(&step, &e);
            assert!((0.0..=1.0).contains(&u) && delay >= 0.0);
            us.push(u);
            if i < 30_000 {
                fast.push(delay)
            } else {
                slow.push(delay)
            }
        }
        // Uniform along the step.
        assert!(ks(us, |u| u) < ks_limit(40_000));
        // Component 1: exponential, 5 ns.
        let exp = |t: f64| 1.0 - (-t / 5.0).exp();
        assert!(ks(fast.clone(), exp) < ks_limit(30_000));
        // Component 2: G4Scintillation's profile with d = 40, r = 3 ns, whose CDF is
        // (d + r) / d (1 - exp(-t/d)) - r / d (1 - exp(-t (d + r) / (d r))).
        let (d, r) = (40.0, 3.0);
        let bi = |t: f64| {
            (d + r) / d * (1.0 - (-t / d).exp()) - r / d * (1.0 - (-t * (d + r) / (d * r)).exp())
        };
        assert!(ks(slow.clone(), bi) < ks_limit(10_000));
        // Each rejected against the other's profile.
        assert!(ks(slow, |t| 1.0 - (-t / d).exp()) > ks_limit(10_000));
        assert!(ks(fast, |t| 1.0 - (-t / 40.0).exp()) > ks_limit(30_000));
    }

    #[test]
    fn cherenkov_photons_follow_the_yield_along_the_step_and_the_particle_in_time() {
        // A slowing particle: fewer photons towards the end.
        let beta = [0.99, 0.75];
        let f = file(&[row(
            1.0,
            30_000.0,
            1.0,
            2.0,
            [0.0, 0.0, -5.0],
            [0.0, 0.0, 5.0],
            beta,
            1.0,
            0.0,
        )])
        .unwrap();
        let g = Gensteps::new(&f, &materials()).unwrap();
        let c = Cherenkov::new(&materials()[1]).unwrap();
        let (y0, y1) = (c.relative_yield(0.99), c.relative_yield(0.75));
        assert!(y1 < 0.5 * y0);
        let mut us = Vec::new();
        for i in 0..g.photons() {
            let mut rng = Rng::new(2, i as u32, 0);
            let e = g.emit(i, &mut rng);
            let (u, delay) = along_and_delay(&f.steps[0], &e);
            // The particle's time at the emission point, no delay.
            assert!(delay.abs() < 1e-9, "{delay}");
            // On the cone of the mean beta: cos theta = 1 / (beta n).
            let beta = 0.5 * (0.99 + 0.75);
            assert!(e.direction.z > 0.0);
            let n = 1.0 / (beta * e.direction.z);
            assert!((1.45 - 1e-9..=1.5 + 1e-9).contains(&n), "{n}");
            us.push(u);
        }
        // Density linear from y0 to y1: CDF (y0 u + (y1 - y0) u^2 / 2) / ((y0 + y1) / 2).
        let cdf = |u: f64| (y0 * u + (y1 - y0) * u * u / 2.0) / ((y0 + y1) / 2.0);
        assert!(ks(us.clone(), cdf) < ks_limit(30_000));
        assert!(ks(us, |u| u) > ks_limit(30_000));
    }

    #[test]
    fn photons_are_numbered_through_the_gensteps_in_order() {
        let (a, b) = ([0.0; 3], [1.0, 0.0, 0.0]);
        let f = file(&[
            row(2.0, 3.0, 1.0, 0.0, a, b, [1.0, 1.0], 1.0, 1.0),
            row(2.0, 0.0, 1.0, 100.0, a, b, [1.0, 1.0], 1.0, 1.0),
            row(1.0, 5.0, 1.0, 1000.0, a, b, [1.0, 1.0], 1.0, 0.0),
        ])
        .unwrap();
        let g = Gensteps::new(&f, &materials()).unwrap();
        assert_eq!(g.photons(), 8);
        for i in 0..8 {
            let t = g.emit(i, &mut Rng::new(0, i as u32, 0)).time;
            // The first three photons scintillate after t0 = 0, the rest are Cherenkov
            // photons of the third step, within its 3.3 ps.
            assert_eq!(t >= 1000.0, i >= 3, "photon {i}: {t}");
        }
    }

    #[test]
    fn bad_gensteps_are_refused_naming_the_row_and_the_problem() {
        let (a, b) = ([0.0; 3], [1.0, 0.0, 0.0]);
        let ok = row(2.0, 10.0, 1.0, 0.0, a, b, [1.0, 1.0], 1.0, 0.0);
        let with = |c: usize, v: f64| {
            let mut r = ok.clone();
            r[c] = v;
            r
        };
        for (bad, needle) in [
            (with(0, 3.0), "unknown kind 3"),
            (with(1, -1.0), "number of photons (column 1) is -1"),
            (with(1, 2.5), "not a whole number"),
            (with(3, f64::NAN), "column 3 is NaN"),
            (with(10, 0.0), "beta (column 10) is 0"),
            (with(11, 1.5), "beta (column 11) is 1.5"),
            (with(13, 4.0), "component (column 13) is 4"),
            (with(2, -2.0), "material index (column 2) is -2"),
            (
                row(1.0, 10.0, 1.0, 0.0, a, a, [1.0, 1.0], 1.0, 0.0),
                "the same point",
            ),
            (
                row(1.0, 10.0, 1.0, 0.0, a, b, [1.0, 1.0], 0.0, 0.0),
                "charged particle",
            ),
        ] {
            let e = file(&[ok.clone(), bad]).unwrap_err().to_string();
            assert!(e.contains("g.npy: row 1: ") && e.contains(needle), "{e}");
        }
        let e = GenstepFile::from_values("g.npy".into(), &[1, 13], &[0.0; 13]).unwrap_err();
        assert!(e.to_string().contains("shape (G, 14)"), "{e}");
        // Against the scene's materials.
        for (bad, needle) in [
            (
                with(2, 7.0),
                "material index 7 out of range (the scene's materials: 0 Vacuum, 1 Scint)",
            ),
            (
                with(2, 0.0),
                "material `Vacuum` has no SCINTILLATIONCOMPONENT1",
            ),
            (with(13, 3.0), "component 3: material `Scint` has 2"),
            (
                row(1.0, 10.0, 0.0, 0.0, a, b, [1.0, 1.0], 1.0, 0.0),
                "`Vacuum` has no RINDEX",
            ),
            (
                row(1.0, 10.0, 1.0, 0.0, a, b, [0.6, 0.6], 1.0, 0.0),
                "below the Cherenkov threshold",
            ),
        ] {
            let f = file(&[ok.clone(), bad]).unwrap();
            let e = Gensteps::new(&f, &materials()).unwrap_err().to_string();
            assert!(e.contains("g.npy: row 1: ") && e.contains(needle), "{e}");
        }
    }
}
