//! Optical photon propagation on the CPU, with Geant4's optical physics (`hytrace
//! photons`): torch sources ([`sources`]), gensteps ([`gensteps`]) emitting Cherenkov
//! ([`cherenkov`]) and scintillation ([`scintillation`]) light, material and surface property tables
//! ([`properties`]), Fresnel reflection and refraction ([`boundary`]), bulk absorption and
//! Rayleigh scattering ([`bulk`]), a scene's sparse volumes as absorbing and scattering
//! media ([`media`]), optical surfaces ([`surfaces`]) and their rough and painted
//! models ([`surface_models`]), the propagation loop
//! through the scene's navigator ([`propagate()`]), the outputs ([`output`]) and what a run
//! calls for ([`explain`]).
//!
//! Photon `i` draws every random number from the counter-based stream `(seed, i)`
//! ([`hytrace_volume::Rng`]), so a run's results do not depend on threads or batches.
//! See `docs/photons.md` for the physics, the output layouts and the comparison with
//! Geant4.

pub mod backend;
pub mod boundary;
pub mod bulk;
pub mod cherenkov;
pub mod explain;
pub mod gensteps;
pub mod gpu_tables;
pub mod media;
pub mod output;
pub mod propagate;
pub mod properties;
pub mod run;
pub mod scintillation;
pub mod sources;
pub mod surface_models;
pub mod surfaces;
pub mod tracer;

use std::path::Path;

use crate::error::Context;
use hytrace_csg::V3;
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_foundry::Foundry;

use crate::scene::{load_gdml_scene_with_surfaces, load_scene, VolumeSurfaces};

pub use propagate::{
    propagate, propagate_batches, propagate_reporting, Batch, Origin, PhotonRun, PhotonScene,
    RunOptions, RunSummary,
};

/// Vectors of the propagator: f64 throughout.
pub type V = V3<f64>;

/// Errors of photon propagation.
#[derive(Debug, thiserror::Error)]
pub enum PhotonError {
    /// A property table is malformed.
    #[error("{table}: {problem}")]
    Table {
        /// Which table (owner and property).
        table: String,
        /// What is wrong.
        problem: String,
    },
    /// A source specification is malformed.
    #[error("source `{spec}`: {problem}")]
    Source {
        /// The specification.
        spec: String,
        /// What is wrong.
        problem: String,
    },
    /// The scene asks for physics this propagator does not model.
    #[error("{what}: not modelled by the photon propagator")]
    Unsupported {
        /// What (surface, model, finish).
        what: String,
    },
    /// A run parameter is out of range.
    #[error("{0}")]
    Input(String),
    /// The scene cannot be traced.
    #[error("preparing the scene: {0}")]
    Scene(String),
    /// An output file could not be written.
    #[error("{0}")]
    Output(String),
}

/// Loads a scene for photons: a GDML file with what finds the optical surface of every
/// crossing (Geant4's lookup, siblings included), any other scene with its boundary table
/// only.
pub fn load_photon_scene(
    path: &Path,
    options: &GdmlOptions,
) -> crate::Result<(Foundry, Option<VolumeSurfaces>)> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gdml"))
    {
        let (f, s) = load_gdml_scene_with_surfaces(path, options)?;
        return Ok((f, Some(s)));
    }
    let f =
        load_scene(Some(path), options).with_context(|| format!("loading {}", path.display()))?;
    Ok((f, None))
}
