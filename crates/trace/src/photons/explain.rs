//! What a photon run calls for (`hytrace photons --explain`): the processes its scene's
//! materials and surfaces, its source and its outputs need, each with the materials or
//! surfaces that need it and where it runs (the CPU propagator and the GPU kernel have
//! every one; the GPU streams a medium read as stored in a brick store through its brick
//! pool when it is the scene's only medium), then what the GPU kernel is composed of.

use std::collections::BTreeSet;

use hytrace_foundry::UNSET;

use super::gpu_tables::kernel_features;
use super::properties::{MaterialOptics, Roughness, SurfaceKind};
use super::sources::{Source, Wavelength};
use super::{Origin, PhotonScene, RunOptions};

/// Where a process runs.
const BOTH: &str = "cpu, gpu";
/// Wavelength shifting: an absorption emitting several photons is propagated on the CPU.
const WLS_ON: &str = "cpu, gpu; an absorption emitting several photons: cpu";

/// Media: the GPU streams a brick store read as stored through its brick pool, when it is
/// the scene's only medium.
const MEDIA_ON: &str =
    "cpu, gpu; a brick store read as stored: streamed through the GPU's brick pool, alone";

/// Whether a material needs a process.
type Needs = dyn Fn(&MaterialOptics) -> bool;

/// The lines of `--explain` for `run` through `scene`: one per process the run calls for
/// (`process: who needs it [where it runs]`), then the GPU kernel's composition.
pub fn explain(scene: &PhotonScene, run: &RunOptions) -> Vec<String> {
    let mut lines = Vec::new();
    let mut line = |what: &str, who: String, on: &str| {
        lines.push(format!("{what}: {who} [{on}]"));
    };
    match &run.origin {
        Origin::Torch { source, wavelength } => {
            let at = |v: super::V| format!("({}, {}, {}) mm", v.x, v.y, v.z);
            let what = match *source {
                Source::Point { position } => format!("point at {}", at(position)),
                Source::Beam { centre, radius, .. } => {
                    format!("beam from a disk of radius {radius} mm at {}", at(centre))
                }
                Source::Sphere {
                    centre,
                    radius,
                    inward,
                } => format!(
                    "sphere of radius {radius} mm at {}, {}",
                    at(centre),
                    if inward { "inward" } else { "outward" }
                ),
            };
            line("torch source", what, BOTH);
            match wavelength {
                Wavelength::Fixed(nm) => line("wavelength", format!("{nm} nm"), BOTH),
                Wavelength::Spectrum { material, property } => line(
                    "wavelength drawn from a spectrum",
                    format!("material `{material}`: {property}"),
                    BOTH,
                ),
            }
        }
        Origin::Gensteps(file) => line(
            "gensteps (Cherenkov and scintillation photons)",
            format!("{} ({} steps)", file.source, file.steps.len()),
            BOTH,
        ),
    }
    // The materials some instance is made of.
    let present: BTreeSet<u32> = scene
        .material
        .iter()
        .copied()
        .filter(|&m| m != UNSET)
        .collect();
    let materials: Vec<&MaterialOptics> = present
        .iter()
        .filter_map(|&m| scene.tables.material(m))
        .collect();
    let names = |has: &Needs| {
        let named: Vec<String> = (materials.iter())
            .filter(|m| has(m))
            .map(|m| format!("`{}`", m.name))
            .collect();
        (!named.is_empty()).then(|| format!("materials {}", named.join(", ")))
    };
    let bulk: [(&str, &Needs, &str); 6] = [
        ("Fresnel boundaries (RINDEX)", &|m| m.rindex.is_some(), BOTH),
        (
            "killed at boundaries (no RINDEX)",
            &|m| m.rindex.is_none(),
            BOTH,
        ),
        ("absorption (ABSLENGTH)", &|m| m.abslength.is_some(), BOTH),
        (
            "Rayleigh scattering (RAYLEIGH)",
            &|m| m.rayleigh.is_some(),
            BOTH,
        ),
        (
            "re-emission (REEMISSIONPROB)",
            &|m| m.reemission.is_some(),
            BOTH,
        ),
        (
            "wavelength shifting (WLSABSLENGTH)",
            &|m| m.wlsabslength.is_some(),
            WLS_ON,
        ),
    ];
    for (what, has, on) in bulk {
        if let Some(who) = names(has) {
            line(what, who, on);
        }
    }
    for medium in scene.media.iter().flat_map(|m| m.describe()) {
        line(
            "medium: delta-tracked absorption (AB) and Henyey-Greenstein scattering (SC)",
            medium,
            MEDIA_ON,
        );
    }
    for s in scene.tables.surfaces.iter().flatten() {
        let kind = match s.kind {
            SurfaceKind::DielectricMetal => "dielectric_metal",
            SurfaceKind::DielectricDielectric => "dielectric_dielectric",
        };
        let model = match s.roughness {
            Roughness::Glisur { polish } => format!("glisur, polish {polish}"),
            Roughness::Unified { sigma_alpha } => format!("unified, sigma_alpha {sigma_alpha}"),
        };
        line(
            "optical surface",
            format!("`{}` ({kind}, {:?}, {model})", s.name, s.finish),
            BOTH,
        );
    }
    if run.records > 0 {
        line("step points", format!("--records {}", run.records), BOTH);
    }
    lines.push(format!(
        "gpu kernel: composed with the physics features [{}] (besides the geometry's)",
        kernel_features(&scene.tables, scene.media.is_some(), run).join(", ")
    ));
    lines
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photons::load_photon_scene;
    use hytrace_foundry::gdml::GdmlOptions;

    fn lines(file: &str, wavelength: Wavelength) -> Vec<String> {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let (f, surfaces) = load_photon_scene(&root.join(file), &GdmlOptions::default()).unwrap();
        let scene = PhotonScene::new(&f, surfaces).unwrap();
        let run = RunOptions {
            origin: Origin::Torch {
                source: Source::parse("point:0,0,0").unwrap(),
                wavelength,
            },
            photons: 1,
            first: 0,
            seed: 0,
            max_steps: 10,
            keep_histories: false,
            records: 3,
        };
        explain(&scene, &run)
    }

    fn has(lines: &[String], needle: &str) -> bool {
        lines.iter().any(|l| l.contains(needle))
    }

    /// The processes each test scene's GDML file defines are listed with where they run,
    /// and the kernel's composition or refusal follows.
    #[test]
    fn explain_lists_the_processes_the_scene_calls_for() {
        let rough = lines(
            "tests/data/photons/rough_surfaces.gdml",
            Wavelength::Fixed(420.0),
        );
        assert!(
            has(&rough, "optical surface: `UnifiedGroundSurface`"),
            "{rough:?}"
        );
        assert!(
            has(&rough, "Ground, unified, sigma_alpha 0.2) [cpu, gpu]"),
            "{rough:?}"
        );
        assert!(
            has(&rough, "step points: --records 3 [cpu, gpu]"),
            "{rough:?}"
        );
        assert!(has(&rough, "[records, rough_surfaces]"), "{rough:?}");
        assert!(!has(&rough, "Rayleigh"), "{rough:?}");
        let every = lines(
            "tests/data/photons/every_process.gdml",
            Wavelength::Spectrum {
                material: "Liquid".into(),
                property: "SCINTILLATIONCOMPONENT1".into(),
            },
        );
        for needle in [
            "wavelength drawn from a spectrum: material `Liquid`",
            "Rayleigh scattering (RAYLEIGH): materials",
            "absorption (ABSLENGTH)",
            "killed at boundaries (no RINDEX)",
            "[records, spectrum]",
        ] {
            assert!(has(&every, needle), "{needle}: {every:?}");
        }
        let scintillator = lines(
            "tests/data/photons/scintillator.gdml",
            Wavelength::Fixed(400.0),
        );
        assert!(has(
            &scintillator,
            "re-emission (REEMISSIONPROB): materials `LS` [cpu, gpu]"
        ));
        let shifter = lines(
            "tests/data/photons/wavelength_shifter.gdml",
            Wavelength::Fixed(420.0),
        );
        assert!(has(
            &shifter,
            "wavelength shifting (WLSABSLENGTH): materials"
        ));
        assert!(has(&shifter, "several photons: cpu]"), "{shifter:?}");
        assert!(has(&shifter, "features [records, wls]"), "{shifter:?}");
    }
}
