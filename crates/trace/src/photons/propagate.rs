//! The propagation loop: photons step through the scene's volumes until they are
//! absorbed, detected or leave the world.
//!
//! Each step, in the volume the photon is in (known from the previous step, as Geant4's
//! tracking navigator keeps it), draws a distance to absorption and to Rayleigh scattering
//! from the material's ABSLENGTH and RAYLEIGH lengths, and asks the CPU tracer (f64, or f32
//! as the GPU kernel's twin: [`super::tracer`]) for
//! the distance to the next boundary: leaving the volume or entering one of its daughters
//! ([`crate::cpu::CpuScene::trace_in`]). The nearest of the three happens. At a boundary the volume on
//! the far side is the daughter entered, or where the photon goes on leaving the volume
//! (a touching sibling, else the mother); the two materials and the optical surface of the
//! crossing decide what the photon does ([`cross`]). In a wavelength shifter a third
//! distance (WLSABSLENGTH) competes; the photons an absorption emits go on from there. In
//! a scene with media ([`super::media`]) the first collision with them within the step
//! competes last; the loop is compiled with that test only for such scenes.

use std::collections::HashMap;
use std::ops::Range;
use std::sync::Arc;
use std::time::Instant;

use hytrace_csg::Ray;
use hytrace_foundry::{Foundry, UNSET};
use hytrace_volume::{CacheStats, Rng, DEFAULT_STORE_BUDGET};
use rayon::prelude::*;

use super::bulk::{isotropic, rayleigh_scatter, sample_distance};
use super::gensteps::{GenstepFile, Gensteps};
use super::media::{collide, PhotonMedia};
use super::output::{
    photon_columns, record_point, sorted_counts, History, HitRow, Label, RecordPoint, HIT_COLUMNS,
    RECORD_COLUMNS,
};
use super::properties::{
    energy_of_wavelength, wavelength_of_energy, OpticsTables, Property, Spectrum, C_LIGHT_MM_PER_NS,
};
use super::sources::{Source, Start, Wavelength};
use super::surfaces::{cross, AtBoundary, Crossing, SurfaceLookup};
use super::tracer::{PhotonTracer, Precision};
use super::{PhotonError, V};
use crate::cpu::Hit;
use crate::scene::VolumeSurfaces;

/// Photons the CPU propagates per parallel batch by default (bounds a run's memory).
pub const BATCH: u64 = 1 << 16;

/// A scene prepared for photons.
pub struct PhotonScene {
    pub(crate) tracer: PhotonTracer,
    pub(crate) tables: OpticsTables,
    /// The scene's materials as read (their tables, for spectra a run draws from).
    materials: Vec<hytrace_foundry::optics::Material>,
    /// Material inside every instance ([`UNSET`] for none).
    pub(crate) material: Vec<u32>,
    pub(crate) mother: Vec<u32>,
    pub(crate) copy: Vec<i32>,
    pub(crate) surfaces: SurfaceLookup,
    pub(crate) hierarchical: bool,
    /// The scene's media, `None` without any.
    pub(crate) media: Option<PhotonMedia>,
}

impl PhotonScene {
    /// Prepares a scene: its tracer, its materials' and used surfaces' property tables
    /// (checked), and the surface lookup (Geant4's for a GDML scene, given `surfaces`).
    pub fn new(f: &Foundry, surfaces: Option<VolumeSurfaces>) -> Result<Self, PhotonError> {
        Self::with_precision(f, surfaces, Precision::F64)
    }

    /// [`PhotonScene::new`] navigating with the CPU tracer in `precision` (f32: the GPU
    /// kernel's twin).
    pub fn with_precision(
        f: &Foundry,
        surfaces: Option<VolumeSurfaces>,
        precision: Precision,
    ) -> Result<Self, PhotonError> {
        Self::with_memory(f, surfaces, precision, DEFAULT_STORE_BUDGET)
    }

    /// [`PhotonScene::with_precision`] with each medium read as stored in a brick store
    /// holding at most `memory` bytes resident: its tables and a cache of the bricks
    /// photons read (`hytrace photons --memory`); a budget too small for a store is refused
    /// naming it and the least it needs. Results do not depend on it.
    pub fn with_memory(
        f: &Foundry,
        surfaces: Option<VolumeSurfaces>,
        precision: Precision,
        memory: u64,
    ) -> Result<Self, PhotonError> {
        let tracer =
            PhotonTracer::new(f, precision).map_err(|e| PhotonError::Scene(format!("{e:#}")))?;
        let boundaries = &f.optics.boundaries;
        let material = f
            .inst
            .iter()
            .map(|i| match i.boundary {
                UNSET => UNSET,
                b => boundaries[b as usize].inner_material,
            })
            .collect();
        let mother: Vec<u32> = f.inst_mother.iter().map(|m| m.index).collect();
        let surfaces = match surfaces {
            Some(v) => SurfaceLookup::Gdml(v),
            None => SurfaceLookup::Boundaries {
                boundaries: f
                    .inst
                    .iter()
                    .map(|i| match i.boundary {
                        UNSET => hytrace_foundry::optics::Boundary {
                            outer_material: UNSET,
                            outer_surface: UNSET,
                            inner_surface: UNSET,
                            inner_material: UNSET,
                        },
                        b => boundaries[b as usize],
                    })
                    .collect(),
                mother: mother.clone(),
            },
        };
        let used = |s: u32| match &surfaces {
            SurfaceLookup::Gdml(v) => v.uses(s),
            SurfaceLookup::Boundaries { boundaries, .. } => boundaries
                .iter()
                .any(|b| b.inner_surface == s || b.outer_surface == s),
        };
        let tables = OpticsTables::new(&f.optics, used)?;
        let media = PhotonMedia::new(f, &tracer, memory)?;
        Ok(PhotonScene {
            media,
            tracer,
            tables,
            materials: f.optics.materials.clone(),
            material,
            hierarchical: mother.iter().any(|&m| m != UNSET),
            mother,
            copy: f.inst.iter().map(|i| i.copy_number).collect(),
            surfaces,
        })
    }

    /// What the brick caches of the media read as stored did so far, summed (`None` when
    /// no medium is read as stored).
    pub fn store_stats(&self) -> Option<CacheStats> {
        self.media.as_ref().and_then(|m| m.open().store_stats())
    }

    /// Resolves where a run's photons come from: a torch source with its wavelength, or
    /// gensteps prepared for the scene's materials.
    pub(crate) fn emitting(&self, origin: &Origin) -> Result<Emitting, PhotonError> {
        match origin {
            Origin::Torch { source, wavelength } => Ok(Emitting::Torch {
                source: *source,
                emission: self.emission(wavelength)?,
            }),
            Origin::Gensteps(file) => Ok(Emitting::Gensteps(Gensteps::new(file, &self.materials)?)),
        }
    }

    /// Resolves a torch run's wavelength: a fixed one checked, a spectrum looked up among
    /// the scene's materials.
    pub(crate) fn emission(&self, wavelength: &Wavelength) -> Result<Emission, PhotonError> {
        match wavelength {
            Wavelength::Fixed(nm) if nm.is_finite() && *nm > 0.0 => Ok(Emission::Fixed {
                energy: energy_of_wavelength(*nm),
                nm: *nm,
            }),
            Wavelength::Fixed(nm) => Err(PhotonError::Input(format!(
                "the wavelength {nm} nm is not a positive number"
            ))),
            Wavelength::Spectrum { material, property } => {
                let names = |v: Vec<&str>| v.join(", ");
                let Some(m) = self.materials.iter().find(|m| &m.name == material) else {
                    return Err(PhotonError::Input(format!(
                        "--wavelength: no material `{material}` in the scene (materials: {})",
                        names(self.materials.iter().map(|m| m.name.as_str()).collect())
                    )));
                };
                let Some((_, table)) = m.properties.iter().find(|(n, _)| n == property) else {
                    return Err(PhotonError::Input(format!(
                        "--wavelength: material `{material}` has no property `{property}` (its properties: {})",
                        names(m.properties.iter().map(|(n, _)| n.as_str()).collect())
                    )));
                };
                let intensity = Property::new(
                    table,
                    &format!("material `{material}`: property {property}"),
                )?;
                Ok(Emission::Spectrum(Spectrum::new(&intensity)))
            }
        }
    }

    /// The next boundary from `pos` along `dir` inside instance `current`. A crossing of
    /// the surface the photon sits on, found again at a rounding distance with the wrong
    /// orientation (entering the volume it is leaving, or leaving a daughter it is outside
    /// of), is skipped.
    fn next_boundary(&self, pos: V, dir: V, current: u32) -> Option<Hit<f64>> {
        let ray = Ray {
            origin: pos,
            direction: dir,
        };
        let eps = 1e-7 * pos.max_abs().max(1.0);
        let mut tmin = 0.0;
        let mut found = None;
        for _ in 0..8 {
            let h = self.tracer.trace_in(&ray, current, tmin)?;
            let leaving = h.instance == current;
            let outward = h.normal.dot(dir) > 0.0;
            if leaving == outward || h.t > eps {
                return Some(h);
            }
            tmin = h.t;
            found = Some(h);
        }
        found
    }

    /// The instance on the far side of the boundary `hit` at `pos`: the daughter entered,
    /// else the volume found just past the surface (a touching sibling), else the mother;
    /// `None` outside the world.
    fn next_volume(&self, pos: V, dir: V, current: u32, hit: &Hit<f64>) -> Option<u32> {
        if self.hierarchical && hit.instance != current {
            return Some(hit.instance);
        }
        let probe = pos + dir * (1e-6 * pos.max_abs().max(1.0));
        match self.tracer.locate_point(probe.to_f64()) {
            Some(c) if c != current => Some(c),
            _ => {
                let m = self.mother[current as usize];
                (m != UNSET).then_some(m)
            }
        }
    }

    /// Propagates photon `index` to its end: the histories of its lineages (the photon
    /// itself first, then the further photons its wavelength-shifting absorptions
    /// emitted) and the hit rows of those detected.
    pub(crate) fn photon(&self, index: u64, run: &RunOptions, emitting: &Emitting) -> PhotonEnd {
        let mut rng = Rng::new(run.seed, index as u32, (index >> 32) as u32);
        let (start, time, energy, wavelength_nm) = match emitting {
            Emitting::Torch { source, emission } => {
                let start = source.sample(&mut rng);
                let (energy, nm) = match emission {
                    Emission::Fixed { energy, nm } => (*energy, *nm),
                    Emission::Spectrum(s) => {
                        let e = s.sample(&mut rng);
                        (e, wavelength_of_energy(e))
                    }
                };
                (start, 0.0, energy, nm)
            }
            Emitting::Gensteps(g) => {
                let e = g.emit(index, &mut rng);
                let start = Start {
                    position: e.position,
                    direction: e.direction,
                    polarization: e.polarization,
                };
                (start, e.time, e.energy, wavelength_of_energy(e.energy))
            }
        };
        let mut history = History::default();
        let mut record = Vec::with_capacity(run.records as usize);
        let mut mark = |history: &mut History, label: Label| {
            history.push(label);
            if record.len() < run.records as usize {
                let (p, d, e) = (start.position, start.direction, start.polarization);
                record.push(record_point(label, p, time, d, e, wavelength_nm));
            }
        };
        mark(&mut history, Label::To);
        let Some(current) = self.tracer.locate_point(start.position.to_f64()) else {
            mark(&mut history, Label::Mi);
            return PhotonEnd {
                own: (history, None),
                further: Vec::new(),
                record: padded(record, run.records),
            };
        };
        let photon = Lineage {
            pos: start.position,
            dir: start.direction,
            pol: start.polarization,
            time,
            energy,
            wavelength_nm,
            current,
            history,
        };
        // The photon's own lineage first; the vectors allocate only when a wavelength
        // shifter emits more than one photon.
        let mut pending = Vec::new();
        let lineage = match self.media {
            Some(_) => Self::lineage::<true>,
            None => Self::lineage::<false>,
        };
        let own = lineage(
            self,
            photon,
            index,
            run,
            &mut rng,
            &mut pending,
            Some(&mut record),
        );
        let mut further = Vec::new();
        while let Some(photon) = pending.pop() {
            let end = lineage(self, photon, index, run, &mut rng, &mut pending, None);
            further.push(end);
        }
        PhotonEnd {
            own,
            further,
            record: padded(record, run.records),
        }
    }

    /// Propagates one photon to its end; photons emitted by wavelength-shifting
    /// absorptions beyond the one that carries on are pushed onto `pending`. With `record`,
    /// each step point is appended to it until it holds `run.records`. `MEDIA`: the scene
    /// has media (a scene without runs the loop with their test compiled out).
    fn lineage<const MEDIA: bool>(
        &self,
        photon: Lineage,
        index: u64,
        run: &RunOptions,
        rng: &mut Rng,
        pending: &mut Vec<Lineage>,
        mut record: Option<&mut Vec<RecordPoint>>,
    ) -> (History, Option<HitRow>) {
        let Lineage {
            mut pos,
            mut dir,
            mut pol,
            mut time,
            mut energy,
            mut wavelength_nm,
            mut current,
            mut history,
        } = photon;
        // Labels a step and records its point: where the photon is and how it leaves.
        macro_rules! mark {
            ($label:expr) => {{
                history.push($label);
                if let Some(r) = record
                    .as_deref_mut()
                    .filter(|r| r.len() < run.records as usize)
                {
                    r.push(record_point($label, pos, time, dir, pol, wavelength_nm));
                }
            }};
        }
        for steps in 1..=run.max_steps {
            let m = self.material[current as usize];
            let mat = self.tables.material(m);
            let draw = |p: Option<&Property>, rng: &mut Rng| {
                p.map_or(f64::INFINITY, |p| {
                    sample_distance(p.value(energy), rng.next_f64())
                })
            };
            let d_abs = draw(mat.and_then(|m| m.abslength.as_ref()), rng);
            let d_sc = draw(mat.and_then(|m| m.rayleigh.as_ref()), rng);
            let d_wls = draw(mat.and_then(|m| m.wlsabslength.as_ref()), rng);
            let hit = self.next_boundary(pos, dir, current);
            let t_b = hit.map_or(f64::INFINITY, |h| h.t);
            let step = t_b.min(d_abs).min(d_sc).min(d_wls);
            if !step.is_finite() {
                mark!(Label::Mi);
                return (history, None);
            }
            if let (true, Some(media)) = (MEDIA, &self.media) {
                if let Some(c) = media.collision(&self.tracer, pos, dir, step, rng) {
                    pos = pos + dir * c.t;
                    time += c.t / mat.map_or(C_LIGHT_MM_PER_NS, |m| m.velocity(energy));
                    let Some((d, p)) = collide(c.scattering, dir, pol, rng) else {
                        mark!(Label::Ab);
                        return (history, None);
                    };
                    (dir, pol) = (d, p);
                    mark!(Label::Sc);
                    continue;
                }
            }
            pos = pos + dir * step;
            time += step / mat.map_or(C_LIGHT_MM_PER_NS, |m| m.velocity(energy));
            if d_abs == step && d_abs < t_b {
                // A scintillator may emit again what it absorbed (REEMISSIONPROB).
                let reemission = mat.and_then(|m| m.reemission.as_ref());
                if let Some(k) = reemission.and_then(|r| r.reemits(energy, rng)) {
                    let scintillator = &reemission.expect("checked above").scintillator;
                    energy = scintillator.energy(k, rng);
                    wavelength_nm = wavelength_of_energy(energy);
                    time += scintillator.delay(k, rng);
                    (dir, pol) = isotropic(rng);
                    mark!(Label::Re);
                    continue;
                }
                mark!(Label::Ab);
                return (history, None);
            }
            if d_sc == step && d_sc < t_b {
                (dir, pol) = rayleigh_scatter(dir, pol, rng);
                mark!(Label::Sc);
                continue;
            }
            if d_wls == step && d_wls < t_b {
                // Absorbed by the shifter; what it emits starts here, isotropic, with a
                // random transverse polarization, after the material's delay.
                let Some(wls) = mat.and_then(|m| m.wls.as_ref()) else {
                    mark!(Label::Ab);
                    return (history, None);
                };
                let count = wls.sample_count(rng);
                let energies: Vec<f64> = (0..count)
                    .filter_map(|_| wls.sample_energy(energy, rng))
                    .collect();
                let Some((&first, rest)) = energies.split_first() else {
                    mark!(Label::Ab);
                    return (history, None);
                };
                time += wls.time_constant;
                let mut emitted = history;
                emitted.push(Label::Re);
                for &e in rest.iter().rev() {
                    let (d, p) = isotropic(rng);
                    pending.push(Lineage {
                        pos,
                        dir: d,
                        pol: p,
                        time,
                        energy: e,
                        wavelength_nm: wavelength_of_energy(e),
                        current,
                        history: emitted,
                    });
                }
                (dir, pol) = isotropic(rng);
                energy = first;
                wavelength_nm = wavelength_of_energy(first);
                mark!(Label::Re);
                continue;
            }
            let hit = hit.expect("a finite step that is no interaction is a boundary");
            let Some(post) = self.next_volume(pos, dir, current, &hit) else {
                mark!(Label::Mi);
                return (history, None);
            };
            let normal = if hit.normal.dot(dir) > 0.0 {
                -hit.normal
            } else {
                hit.normal
            };
            let surface = self.surfaces.between(current, post);
            let photon = AtBoundary {
                dir: &mut dir,
                pol: &mut pol,
                energy,
            };
            let materials = (m, self.material[post as usize]);
            match cross(&self.tables, materials, surface, photon, normal, rng) {
                Crossing::Transmitted => {
                    mark!(Label::Bt);
                    current = post;
                }
                Crossing::Reflected => mark!(Label::Br),
                Crossing::SurfaceReflected => mark!(Label::Sr),
                Crossing::DiffuseReflected => mark!(Label::Dr),
                Crossing::Absorbed => {
                    mark!(Label::Sa);
                    return (history, None);
                }
                Crossing::Detected => {
                    mark!(Label::Sd);
                    let mut row = [0.0; HIT_COLUMNS.len()];
                    row[..11].copy_from_slice(&photon_columns(pos, time, dir, wavelength_nm, pol));
                    row[11..].copy_from_slice(&[
                        f64::from(hit.instance),
                        f64::from(self.copy[hit.instance as usize]),
                        index as f64,
                        f64::from(history.mask),
                        f64::from(steps),
                    ]);
                    let row = HitRow(row);
                    return (history, Some(row));
                }
            }
        }
        mark!(Label::Tr);
        (history, None)
    }
}

/// How one photon ended: its own lineage's history and hit, then those of the further
/// photons its wavelength-shifting absorptions emitted, and its own lineage's first step
/// points (`RunOptions::records` of them, zero past its end; none when not asked for).
pub(crate) struct PhotonEnd {
    pub(crate) own: (History, Option<HitRow>),
    pub(crate) further: Vec<(History, Option<HitRow>)>,
    pub(crate) record: Vec<RecordPoint>,
}

/// A batch's photons as they ended, in photon order: what [`drive_batches`] tallies and
/// hands on.
#[derive(Default)]
pub(crate) struct BatchEnds {
    /// Each photon's own lineage's packed history.
    pub(crate) histories: Vec<u64>,
    /// The packed histories of the further lineages (counted, not kept).
    pub(crate) further: Vec<u64>,
    /// The hit rows, in photon order (a photon's own lineage's first).
    pub(crate) hits: Vec<HitRow>,
    /// Each photon's step points, [`RunOptions::records`] a photon.
    pub(crate) records: Vec<RecordPoint>,
}

impl BatchEnds {
    /// The ends of photons propagated one by one, in photon order.
    pub(crate) fn of(ends: Vec<PhotonEnd>) -> BatchEnds {
        let mut out = BatchEnds {
            histories: Vec::with_capacity(ends.len()),
            ..BatchEnds::default()
        };
        for end in ends {
            let own = out.add_lineages(end);
            out.histories.push(own);
        }
        out
    }

    /// Adds the hits, step points and further histories of the next photon's `end`;
    /// returns its own history, for the caller to place.
    pub(crate) fn add_lineages(&mut self, end: PhotonEnd) -> u64 {
        self.records.extend(end.record);
        self.hits.extend(end.own.1);
        for (h, hit) in end.further {
            self.further.push(h.code);
            self.hits.extend(hit);
        }
        end.own.0.code
    }
}

/// `record` filled to `k` points with zero points (label 0).
fn padded(mut record: Vec<RecordPoint>, k: u32) -> Vec<RecordPoint> {
    record.resize(k as usize, [0.0; RECORD_COLUMNS]);
    record
}

/// Where a run's photons come from, resolved for the scene.
pub(crate) enum Emitting {
    Torch { source: Source, emission: Emission },
    Gensteps(Gensteps),
}

/// The wavelength of a torch run, resolved: fixed (energy in MeV and nm) or a spectrum.
pub(crate) enum Emission {
    Fixed { energy: f64, nm: f64 },
    Spectrum(Spectrum),
}

/// A photon on its way: where, which way, its polarization, time (ns), energy (MeV) and
/// wavelength (nm), the instance it is in and its history so far.
struct Lineage {
    pos: V,
    dir: V,
    pol: V,
    time: f64,
    energy: f64,
    wavelength_nm: f64,
    current: u32,
    history: History,
}

/// Where a run's photons come from.
#[derive(Clone, Debug)]
pub enum Origin {
    /// A torch source: every photon starts at time 0 with this wavelength.
    Torch {
        /// Where photons start and which way.
        source: Source,
        /// Their wavelength: fixed or drawn from a material's spectrum.
        wavelength: Wavelength,
    },
    /// Gensteps: photon `i` of the run is photon `i` of the file (numbered through its rows
    /// in order).
    Gensteps(Arc<GenstepFile>),
}

/// What to propagate.
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Where photons come from.
    pub origin: Origin,
    /// Number of photons.
    pub photons: u64,
    /// Index of the first photon: the run propagates photons `first .. first + photons`,
    /// each drawing its own stream `(seed, index)`, so runs over consecutive ranges give
    /// together exactly what one run over their union gives.
    pub first: u64,
    /// Seed of the random streams.
    pub seed: u32,
    /// Steps after which a photon is stopped (label TR).
    pub max_steps: u32,
    /// Keep every photon's packed history in [`PhotonRun::histories`].
    pub keep_histories: bool,
    /// Step points to record of each photon ([`PhotonRun::records`]; 0: none).
    pub records: u32,
}

/// What a run gives back.
#[derive(Clone, Debug)]
pub struct PhotonRun {
    /// One row per detected photon, in photon order.
    pub hits: Vec<HitRow>,
    /// Packed history of every photon (empty unless asked for): its own lineage, through
    /// any re-emissions.
    pub histories: Vec<u64>,
    /// Count of each history, most frequent first, over every lineage (photons emitted by
    /// a wavelength shifter beyond the first count as lineages of their own).
    pub counts: Vec<(String, u64)>,
    /// Seconds spent propagating.
    pub propagate_s: f64,
    /// The first `records` step points of every photon's own lineage, `records` a photon
    /// (zero points past its end), when asked for.
    pub records: Vec<RecordPoint>,
}

/// The results of one batch of photons, in photon order.
#[derive(Clone, Debug, Default)]
pub struct Batch {
    /// Hit rows.
    pub hits: Vec<HitRow>,
    /// Packed histories, when asked for.
    pub histories: Vec<u64>,
    /// Step points, [`RunOptions::records`] a photon, when asked for.
    pub records: Vec<RecordPoint>,
}

impl Batch {
    /// Appends `b`'s results to these.
    pub fn gather(&mut self, b: Batch) -> Result<(), PhotonError> {
        self.hits.extend(b.hits);
        self.histories.extend(b.histories);
        self.records.extend(b.records);
        Ok(())
    }
}

impl PhotonRun {
    /// A run's results gathered from all its batches, and its summary.
    pub fn of(all: Batch, summary: RunSummary) -> PhotonRun {
        PhotonRun {
            hits: all.hits,
            histories: all.histories,
            counts: summary.counts,
            propagate_s: summary.propagate_s,
            records: all.records,
        }
    }
}

/// What a run handed over batch by batch adds up to.
#[derive(Clone, Debug)]
pub struct RunSummary {
    /// Hits.
    pub hits: u64,
    /// Count of each history, as [`PhotonRun::counts`].
    pub counts: Vec<(String, u64)>,
    /// Seconds spent propagating (the sink's time included).
    pub propagate_s: f64,
    /// Of those, seconds counting histories and gathering each batch's results.
    pub tally_s: f64,
    /// Of those, seconds in the sink (writing the outputs).
    pub write_s: f64,
}

/// Propagates photons `run.first .. run.first + run.photons` through `scene`, in parallel
/// over photons.
pub fn propagate(scene: &PhotonScene, run: &RunOptions) -> Result<PhotonRun, PhotonError> {
    propagate_reporting(scene, run, &|_| ())
}

/// [`propagate`], calling `progress` with the number of photons done after each batch.
pub fn propagate_reporting(
    scene: &PhotonScene,
    run: &RunOptions,
    progress: &dyn Fn(u64),
) -> Result<PhotonRun, PhotonError> {
    let mut all = Batch::default();
    let summary = propagate_batches(scene, run, BATCH, &mut |b| all.gather(b), progress)?;
    Ok(PhotonRun::of(all, summary))
}

/// Propagates photons `run.first .. run.first + run.photons` through `scene`, `batch` at a
/// time (in parallel over each batch's photons), handing each batch's results to `sink`
/// in photon order as it finishes (so a run's memory is bounded by its batch), then
/// calling `progress` with the number of photons done. The results do not depend on
/// `batch`.
pub fn propagate_batches(
    scene: &PhotonScene,
    run: &RunOptions,
    batch: u64,
    sink: &mut dyn FnMut(Batch) -> Result<(), PhotonError>,
    progress: &dyn Fn(u64),
) -> Result<RunSummary, PhotonError> {
    let mut on_cpu = |photons: Range<u64>, _: Option<Range<u64>>, emitting: &Emitting| {
        let ends = BatchEnds::of(
            photons
                .into_par_iter()
                .map(|i| scene.photon(i, run, emitting))
                .collect(),
        );
        if let Some(media) = &scene.media {
            media.check_reads(&scene.tracer)?;
        }
        Ok::<_, PhotonError>(ends)
    };
    drive_batches(scene, run, batch, &mut on_cpu, sink, progress)
}

/// A batch of photons propagated: the ends of photons `range`, given the range of the
/// batch asked for next (`None` after the last), which the GPU starts on before the
/// host works through this one's results.
pub(crate) type BatchFn<'a, E> =
    dyn FnMut(Range<u64>, Option<Range<u64>>, &Emitting) -> Result<BatchEnds, E> + 'a;

/// Checks a run, then propagates its photons in batches of `size` with `batch` (the CPU's
/// or the GPU's), handing each batch's hits, histories and step points to `sink` as it
/// finishes, and counts the histories.
pub(crate) fn drive_batches<E: From<PhotonError>>(
    scene: &PhotonScene,
    run: &RunOptions,
    size: u64,
    batch: &mut BatchFn<E>,
    sink: &mut dyn FnMut(Batch) -> Result<(), PhotonError>,
    progress: &dyn Fn(u64),
) -> Result<RunSummary, E> {
    if run.photons == 0 {
        return Err(
            PhotonError::Input("the number of photons (-n) must be at least 1".into()).into(),
        );
    }
    if size == 0 {
        return Err(PhotonError::Input("the batch size must be at least 1".into()).into());
    }
    let emitting = scene.emitting(&run.origin)?;
    let Some(end) = run.first.checked_add(run.photons) else {
        return Err(PhotonError::Input(format!(
            "photons {} .. {} + {}: past the last photon index",
            run.first, run.first, run.photons
        ))
        .into());
    };
    if run.max_steps == 0 {
        return Err(PhotonError::Input("the step limit must be at least 1".into()).into());
    }
    match &emitting {
        Emitting::Torch { source, .. } => {
            let origin = match *source {
                Source::Point { position } => position,
                Source::Beam { centre, .. } | Source::Sphere { centre, .. } => centre,
            };
            if scene.tracer.locate_point(origin.to_f64()).is_none() {
                return Err(PhotonError::Input(format!(
                    "the source at ({}, {}, {}) mm lies outside the world",
                    origin.x, origin.y, origin.z
                ))
                .into());
            }
        }
        Emitting::Gensteps(g) if end > g.photons() => {
            return Err(PhotonError::Input(format!(
                "photons {} .. {end}: the gensteps emit {} photons",
                run.first,
                g.photons()
            ))
            .into());
        }
        Emitting::Gensteps(_) => {}
    }
    let start = Instant::now();
    let (mut hits, mut tally_s, mut write_s) = (0, 0.0, 0.0);
    let mut codes = HashMap::new();
    let range = |first: u64| first..first.saturating_add(size).min(end);
    let mut first = run.first;
    while first < end {
        let this = range(first);
        let next = (this.end < end).then(|| range(this.end));
        let ends = batch(this.clone(), next, &emitting)?;
        let t = Instant::now();
        tally(&mut codes, &ends.histories);
        tally(&mut codes, &ends.further);
        let out = Batch {
            hits: ends.hits,
            histories: if run.keep_histories {
                ends.histories
            } else {
                Vec::new()
            },
            records: ends.records,
        };
        hits += out.hits.len() as u64;
        let t_sink = Instant::now();
        tally_s += (t_sink - t).as_secs_f64();
        sink(out).map_err(E::from)?;
        write_s += t_sink.elapsed().as_secs_f64();
        first = this.end;
        progress(first - run.first);
    }
    Ok(RunSummary {
        hits,
        counts: sorted_counts(codes),
        propagate_s: start.elapsed().as_secs_f64(),
        tally_s,
        write_s,
    })
}

/// Adds the packed histories `codes` to the `counts` of each (in parallel: a GPU batch
/// holds a million).
fn tally(counts: &mut HashMap<u64, u64>, codes: &[u64]) {
    let counted = codes
        .par_chunks(1 << 14)
        .map(|chunk| {
            let mut counts = HashMap::<u64, u64>::new();
            for &c in chunk {
                *counts.entry(c).or_default() += 1;
            }
            counts
        })
        .reduce(HashMap::new, |mut a, b| {
            for (c, n) in b {
                *a.entry(c).or_default() += n;
            }
            a
        });
    for (c, n) in counted {
        *counts.entry(c).or_default() += n;
    }
}
