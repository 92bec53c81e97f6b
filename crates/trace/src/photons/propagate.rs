//! The propagation loop: photons step through the scene's volumes until they are
//! absorbed, detected or leave the world.
//!
//! Each step, in the volume the photon is in (known from the previous step, as Geant4's
//! tracking navigator keeps it), draws a distance to absorption and to Rayleigh scattering
//! from the material's ABSLENGTH and RAYLEIGH lengths, and asks the CPU tracer (f64) for
//! the distance to the next boundary: leaving the volume or entering one of its daughters
//! ([`CpuScene::trace_in`]). The nearest of the three happens. At a boundary the volume on
//! the far side is the daughter entered, or where the photon goes on leaving the volume
//! (a touching sibling, else the mother); the two materials and the optical surface of the
//! crossing decide what the photon does ([`cross`]).

use std::time::Instant;

use hytrace_csg::Ray;
use hytrace_foundry::{Foundry, UNSET};
use hytrace_volume::Rng;
use rayon::prelude::*;

use super::bulk::{rayleigh_scatter, sample_distance};
use super::output::{sorted_counts, History, HitRow, Label};
use super::properties::{energy_of_wavelength, OpticsTables, Property, C_LIGHT_MM_PER_NS};
use super::sources::Source;
use super::surfaces::{cross, AtBoundary, Crossing, SurfaceLookup};
use super::{PhotonError, V};
use crate::cpu::{CpuScene, Hit};
use crate::scene::VolumeSurfaces;

/// Photons propagated per parallel batch (bounds the memory of a run without histories).
const BATCH: u64 = 1 << 16;

/// A scene prepared for photons.
pub struct PhotonScene {
    tracer: CpuScene<f64>,
    tables: OpticsTables,
    /// Material inside every instance ([`UNSET`] for none).
    material: Vec<u32>,
    mother: Vec<u32>,
    copy: Vec<i32>,
    surfaces: SurfaceLookup,
    hierarchical: bool,
}

impl PhotonScene {
    /// Prepares a scene: its tracer, its materials' and used surfaces' property tables
    /// (checked), and the surface lookup (Geant4's for a GDML scene, given `surfaces`).
    pub fn new(f: &Foundry, surfaces: Option<VolumeSurfaces>) -> Result<Self, PhotonError> {
        let tracer = CpuScene::new(f).map_err(|e| PhotonError::Scene(format!("{e:#}")))?;
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
        Ok(PhotonScene {
            tracer,
            tables,
            material,
            hierarchical: mother.iter().any(|&m| m != UNSET),
            mother,
            copy: f.inst.iter().map(|i| i.copy_number).collect(),
            surfaces,
        })
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
            let h = self
                .tracer
                .trace_in(&ray, Some(current), tmin, f64::INFINITY)?;
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

    /// Propagates photon `index` to its end: its history, and its hit row when detected.
    fn photon(&self, index: u64, run: &RunOptions, energy: f64) -> (History, Option<HitRow>) {
        let mut rng = Rng::new(run.seed, index as u32, (index >> 32) as u32);
        let start = run.source.sample(&mut rng);
        let (mut pos, mut dir, mut pol) = (start.position, start.direction, start.polarization);
        let mut time = 0.0;
        let mut history = History::default();
        history.push(Label::To);
        let Some(mut current) = self.tracer.locate_point(pos.to_f64()) else {
            history.push(Label::Mi);
            return (history, None);
        };
        for steps in 1..=run.max_steps {
            let m = self.material[current as usize];
            let mat = self.tables.material(m);
            let draw = |p: Option<&Property>, rng: &mut Rng| {
                p.map_or(f64::INFINITY, |p| {
                    sample_distance(p.value(energy), rng.next_f64())
                })
            };
            let d_abs = draw(mat.and_then(|m| m.abslength.as_ref()), &mut rng);
            let d_sc = draw(mat.and_then(|m| m.rayleigh.as_ref()), &mut rng);
            let hit = self.next_boundary(pos, dir, current);
            let t_b = hit.map_or(f64::INFINITY, |h| h.t);
            let step = t_b.min(d_abs).min(d_sc);
            if !step.is_finite() {
                history.push(Label::Mi);
                return (history, None);
            }
            pos = pos + dir * step;
            time += step / mat.map_or(C_LIGHT_MM_PER_NS, |m| m.velocity(energy));
            if d_abs == step && d_abs < t_b {
                history.push(Label::Ab);
                return (history, None);
            }
            if d_sc == step && d_sc < t_b {
                (dir, pol) = rayleigh_scatter(dir, pol, &mut rng);
                history.push(Label::Sc);
                continue;
            }
            let hit = hit.expect("a finite step that is no interaction is a boundary");
            let Some(post) = self.next_volume(pos, dir, current, &hit) else {
                history.push(Label::Mi);
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
            match cross(&self.tables, materials, surface, photon, normal, &mut rng) {
                Crossing::Transmitted => {
                    history.push(Label::Bt);
                    current = post;
                }
                Crossing::Reflected => history.push(Label::Br),
                Crossing::SurfaceReflected => history.push(Label::Sr),
                Crossing::DiffuseReflected => history.push(Label::Dr),
                Crossing::Absorbed => {
                    history.push(Label::Sa);
                    return (history, None);
                }
                Crossing::Detected => {
                    history.push(Label::Sd);
                    let row = HitRow([
                        pos.x,
                        pos.y,
                        pos.z,
                        time,
                        dir.x,
                        dir.y,
                        dir.z,
                        run.wavelength_nm,
                        pol.x,
                        pol.y,
                        pol.z,
                        f64::from(hit.instance),
                        f64::from(self.copy[hit.instance as usize]),
                        index as f64,
                        f64::from(history.mask),
                        f64::from(steps),
                    ]);
                    return (history, Some(row));
                }
            }
        }
        history.push(Label::Tr);
        (history, None)
    }
}

/// What to propagate.
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Where photons start.
    pub source: Source,
    /// Wavelength of every photon (nm).
    pub wavelength_nm: f64,
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
}

/// What a run gives back.
#[derive(Clone, Debug)]
pub struct PhotonRun {
    /// One row per detected photon, in photon order.
    pub hits: Vec<HitRow>,
    /// Packed history of every photon (empty unless asked for).
    pub histories: Vec<u64>,
    /// Count of each history, most frequent first.
    pub counts: Vec<(String, u64)>,
    /// Seconds spent propagating.
    pub propagate_s: f64,
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
    if run.photons == 0 {
        return Err(PhotonError::Input(
            "the number of photons (-n) must be at least 1".into(),
        ));
    }
    if !(run.wavelength_nm.is_finite() && run.wavelength_nm > 0.0) {
        return Err(PhotonError::Input(format!(
            "the wavelength {} nm is not a positive number",
            run.wavelength_nm
        )));
    }
    let Some(end) = run.first.checked_add(run.photons) else {
        return Err(PhotonError::Input(format!(
            "photons {} .. {} + {}: past the last photon index",
            run.first, run.first, run.photons
        )));
    };
    if run.max_steps == 0 {
        return Err(PhotonError::Input(
            "the step limit must be at least 1".into(),
        ));
    }
    let origin = match run.source {
        Source::Point { position } => position,
        Source::Beam { centre, .. } => centre,
    };
    if scene.tracer.locate_point(origin.to_f64()).is_none() {
        return Err(PhotonError::Input(format!(
            "the source at ({}, {}, {}) mm lies outside the world",
            origin.x, origin.y, origin.z
        )));
    }
    let energy = energy_of_wavelength(run.wavelength_nm);
    let start = Instant::now();
    let mut hits = Vec::new();
    let mut histories = Vec::new();
    let mut codes: std::collections::HashMap<u64, u64> = Default::default();
    let mut first = run.first;
    while first < end {
        let last = first.saturating_add(BATCH).min(end);
        let batch: Vec<(History, Option<HitRow>)> = (first..last)
            .into_par_iter()
            .map(|i| scene.photon(i, run, energy))
            .collect();
        for (h, hit) in batch {
            *codes.entry(h.code).or_default() += 1;
            if run.keep_histories {
                histories.push(h.code);
            }
            hits.extend(hit);
        }
        first = last;
        progress(first - run.first);
    }
    let propagate_s = start.elapsed().as_secs_f64();
    let counts = sorted_counts(codes);
    Ok(PhotonRun {
        hits,
        histories,
        counts,
        propagate_s,
    })
}
