//! Photon runs on a scene read from a file: preparing it and propagating, errors naming
//! the file (what `hytrace photons` and the Python package call).

use std::path::Path;

use crate::error::Context;
use hytrace_foundry::Foundry;

use super::tracer::Precision;
use super::{
    propagate_batches, propagate_reporting, Batch, PhotonError, PhotonRun, PhotonScene, RunOptions,
    RunSummary,
};
use crate::scene::VolumeSurfaces;

/// Prepares the scene `f` read from `path` for photons, navigating in `precision`, each
/// medium read as stored holding at most `memory` bytes resident
/// ([`PhotonScene::with_memory`]); errors name the file.
pub fn prepare(
    f: &Foundry,
    surfaces: Option<VolumeSurfaces>,
    path: &Path,
    precision: Precision,
    memory: u64,
) -> crate::Result<PhotonScene> {
    PhotonScene::with_memory(f, surfaces, precision, memory)
        .with_context(|| format!("{}: preparing for photons", path.display()))
}

/// Propagates photons through the scene read from `path` ([`propagate_reporting`]), errors
/// naming the file; `progress` hears the photons done after each batch.
pub fn propagate_in(
    scene: &PhotonScene,
    path: &Path,
    run: &RunOptions,
    progress: &dyn Fn(u64),
) -> crate::Result<PhotonRun> {
    propagate_reporting(scene, run, progress)
        .with_context(|| format!("{}: propagating photons", path.display()))
}

/// Propagates photons through the scene read from `path` `batch` at a time, handing each
/// batch to `sink` ([`propagate_batches`]), errors naming the file.
pub fn propagate_batches_in(
    scene: &PhotonScene,
    path: &Path,
    run: &RunOptions,
    batch: u64,
    sink: &mut dyn FnMut(Batch) -> Result<(), PhotonError>,
    progress: &dyn Fn(u64),
) -> crate::Result<RunSummary> {
    propagate_batches(scene, run, batch, sink, progress)
        .with_context(|| format!("{}: propagating photons", path.display()))
}
