//! A photon scene's physics flattened for the GPU kernel (records of
//! [`crate::gpu::photon_records`]): every property table's rows in one array, each
//! material's and surface's tables by index, and per instance its material, mother, copy
//! number and the optical surfaces of its crossings, found as [`SurfaceLookup::between`]
//! finds them ([`FlatSurfaces::between`] is the twin of the kernel's lookup and is tested
//! against it on every pair of instances).
//!
//! The kernel has the CPU's physics; [`kernel_features`] says which of its optional
//! processes a run needs, so that only those are composed in.

use hytrace_foundry::UNSET;

use super::properties::{Finish, OpticsTables, Property, Roughness, Spectrum, SurfaceKind};
use super::sources::Wavelength;
use super::surfaces::SurfaceLookup;
use super::{Origin, PhotonScene, RunOptions};
use crate::gpu::photon_records::{
    PhotonBorder, PhotonInstance, PhotonMaterial, PhotonSurface, PhotonTable, PHOTON_FINISH_GROUND,
    PHOTON_FINISH_GROUND_BACK_PAINTED, PHOTON_FINISH_GROUND_FRONT_PAINTED, PHOTON_FINISH_POLISHED,
    PHOTON_FINISH_POLISHED_BACK_PAINTED, PHOTON_FINISH_POLISHED_FRONT_PAINTED,
    PHOTON_SURFACE_DIELECTRIC, PHOTON_SURFACE_METAL,
};

/// What the GPU kernel reads of a photon scene.
#[derive(Clone, Debug, Default)]
pub struct GpuTables {
    /// Property tables.
    pub tables: Vec<PhotonTable>,
    /// Their rows, `(energy (MeV), value)`.
    pub rows: Vec<[f32; 2]>,
    /// Materials.
    pub materials: Vec<PhotonMaterial>,
    /// Surfaces (a record for every surface of the scene; those no crossing meets are
    /// left at their defaults, never read).
    pub surfaces: Vec<PhotonSurface>,
    /// The crossings' surfaces.
    pub lookup: FlatSurfaces,
}

/// The optical surface of every crossing, as the kernel looks it up.
#[derive(Clone, Debug, Default)]
pub struct FlatSurfaces {
    /// Per instance.
    pub instances: Vec<PhotonInstance>,
    /// Border surfaces between instances that are not mother and daughter, sorted.
    pub borders: Vec<PhotonBorder>,
}

impl FlatSurfaces {
    /// The lookup of a scene's surfaces.
    pub fn new(lookup: &SurfaceLookup, material: &[u32], mother: &[u32], copy: &[i32]) -> Self {
        let n = material.len() as u32;
        // Per instance, the surfaces towards and from a sibling; the border pairs.
        type Siblings = (Vec<(u32, u32)>, Vec<(u32, u32, u32)>);
        let (sibling, borders): Siblings = match lookup {
            SurfaceLookup::Gdml(v) => (
                (0..n).map(|i| (v.skin(i), v.skin(i))).collect(),
                v.border_pairs(),
            ),
            SurfaceLookup::Boundaries { boundaries, .. } => (
                boundaries
                    .iter()
                    .map(|b| (b.outer_surface, b.inner_surface))
                    .collect(),
                Vec::new(),
            ),
        };
        let related = |a: u32, b: u32| mother[a as usize] == b || mother[b as usize] == a;
        let instances = (0..n)
            .map(|i| {
                let m = mother[i as usize];
                let (enter, leave) = if m == UNSET {
                    (UNSET, UNSET)
                } else {
                    (lookup.between(m, i), lookup.between(i, m))
                };
                PhotonInstance {
                    material: material[i as usize],
                    mother: m,
                    copy: copy[i as usize],
                    enter_surface: enter,
                    leave_surface: leave,
                    sibling_leave: sibling[i as usize].0,
                    sibling_enter: sibling[i as usize].1,
                    pad: 0,
                }
            })
            .collect();
        let borders = borders
            .into_iter()
            .filter(|&(pre, post, _)| !related(pre, post))
            .map(|(pre, post, surface)| PhotonBorder {
                pre,
                post,
                surface,
                pad: 0,
            })
            .collect();
        FlatSurfaces { instances, borders }
    }

    /// The surface of a crossing from `pre` into `post` ([`UNSET`] for none): the twin of
    /// `surface_between` in `shaders/photons/surfaces.wgsl`.
    pub fn between(&self, pre: u32, post: u32) -> u32 {
        let (a, b) = (
            &self.instances[pre as usize],
            &self.instances[post as usize],
        );
        if b.mother == pre {
            return b.enter_surface;
        }
        if a.mother == post {
            return a.leave_surface;
        }
        let found = self
            .borders
            .binary_search_by(|x| (x.pre, x.post).cmp(&(pre, post)));
        if let Ok(k) = found {
            return self.borders[k].surface;
        }
        if a.sibling_leave != UNSET {
            a.sibling_leave
        } else {
            b.sibling_enter
        }
    }
}

/// Appends `(energy, value)` rows as a table, returning its index.
fn push_rows(
    tables: &mut Vec<PhotonTable>,
    rows: &mut Vec<[f32; 2]>,
    new: impl Iterator<Item = (f64, f64)>,
) -> u32 {
    let first = rows.len() as u32;
    rows.extend(new.map(|(e, v)| [e as f32, v as f32]));
    tables.push(PhotonTable {
        first,
        count: rows.len() as u32 - first,
    });
    tables.len() as u32 - 1
}

/// Appends a property's rows as a table, returning its index ([`UNSET`] for none).
fn push_table(
    tables: &mut Vec<PhotonTable>,
    rows: &mut Vec<[f32; 2]>,
    p: Option<&Property>,
) -> u32 {
    p.map_or(UNSET, |p| push_rows(tables, rows, p.rows()))
}

/// Appends a spectrum's `(energy, integral)` rows as a table, returning its index.
fn push_spectrum(tables: &mut Vec<PhotonTable>, rows: &mut Vec<[f32; 2]>, s: &Spectrum) -> u32 {
    push_rows(tables, rows, s.rows())
}

/// The kernel's composition features for the physics of a scene with `tables` (the
/// `// #if` blocks of `shaders/photons/`): `rough_surfaces` when an optical surface has
/// a finish other than polished (facets, the unified model's reflection types, paint),
/// `reemission` when a material re-emits what it absorbs (REEMISSIONPROB), `wls` when one
/// shifts wavelengths (WLSABSLENGTH), `media` when the scene places `media` (its volumes,
/// [`super::media`]), `spectrum`
/// when `run`'s torch draws its photons' energies from a spectrum, `gensteps` when its
/// photons come from gensteps, `records` when it writes step points.
pub fn kernel_features(tables: &OpticsTables, media: bool, run: &RunOptions) -> Vec<&'static str> {
    let rough = (tables.surfaces.iter().flatten()).any(|s| s.finish != Finish::Polished);
    let reemission = tables.materials.iter().any(|m| m.reemission.is_some());
    let wls = tables.materials.iter().any(|m| m.wlsabslength.is_some());
    let spectrum = matches!(
        run.origin,
        Origin::Torch {
            wavelength: Wavelength::Spectrum { .. },
            ..
        }
    );
    let gensteps = matches!(run.origin, Origin::Gensteps(_));
    [
        (gensteps, "gensteps"),
        (run.records > 0, "records"),
        (rough, "rough_surfaces"),
        (reemission, "reemission"),
        (wls, "wls"),
        (media, "media"),
        (spectrum, "spectrum"),
    ]
    .into_iter()
    .filter_map(|(on, name)| on.then_some(name))
    .collect()
}

/// A finish as the kernel numbers it (`PHOTON_FINISH_*`).
fn finish_code(finish: Finish) -> u32 {
    match finish {
        Finish::Polished => PHOTON_FINISH_POLISHED,
        Finish::PolishedFrontPainted => PHOTON_FINISH_POLISHED_FRONT_PAINTED,
        Finish::PolishedBackPainted => PHOTON_FINISH_POLISHED_BACK_PAINTED,
        Finish::Ground => PHOTON_FINISH_GROUND,
        Finish::GroundFrontPainted => PHOTON_FINISH_GROUND_FRONT_PAINTED,
        Finish::GroundBackPainted => PHOTON_FINISH_GROUND_BACK_PAINTED,
    }
}

impl GpuTables {
    /// Appends a torch run's spectrum as a table, returning its index
    /// ([`PhotonParams::spectrum`](crate::gpu::photon_records::PhotonParams::spectrum)).
    pub fn push_spectrum(&mut self, s: &Spectrum) -> u32 {
        push_spectrum(&mut self.tables, &mut self.rows, s)
    }

    /// Flattens `scene`'s physics for the kernel.
    pub fn new(scene: &PhotonScene) -> Self {
        let (mut tables, mut rows) = (Vec::new(), Vec::new());
        let t = &scene.tables;
        let materials = t
            .materials
            .iter()
            .map(|m| {
                let mut flat = PhotonMaterial {
                    rindex: push_table(&mut tables, &mut rows, m.rindex.as_ref()),
                    abslength: push_table(&mut tables, &mut rows, m.abslength.as_ref()),
                    rayleigh: push_table(&mut tables, &mut rows, m.rayleigh.as_ref()),
                    groupvel: push_table(&mut tables, &mut rows, m.groupvel.as_ref()),
                    reemission: UNSET,
                    spectrum: [UNSET; 3],
                    wlsabslength: push_table(&mut tables, &mut rows, m.wlsabslength.as_ref()),
                    wls_spectrum: UNSET,
                    wls_mean: -1.0,
                    ..Default::default()
                };
                if let Some(w) = &m.wls {
                    flat.wls_spectrum = push_spectrum(&mut tables, &mut rows, w.spectrum());
                    flat.wls_delay = w.time_constant as f32;
                    flat.wls_mean = w.mean_photons.map_or(-1.0, |m| m as f32);
                }
                if let Some(r) = &m.reemission {
                    flat.reemission = push_table(&mut tables, &mut rows, Some(&r.probability));
                    flat.components = r.scintillator.components() as u32;
                    for k in 0..r.scintillator.components() {
                        let (spectrum, decay, rise, weight) = r.scintillator.component(k);
                        flat.spectrum[k] = push_spectrum(&mut tables, &mut rows, spectrum);
                        flat.decay[k] = decay as f32;
                        flat.rise[k] = rise as f32;
                        flat.weight[k] = weight as f32;
                    }
                }
                flat
            })
            .collect();
        let surfaces = t
            .surfaces
            .iter()
            .map(|s| match s {
                None => PhotonSurface::default(),
                Some(s) => {
                    let mut table =
                        |p: &Option<Property>| push_table(&mut tables, &mut rows, p.as_ref());
                    let (unified, roughness) = match s.roughness {
                        Roughness::Glisur { polish } => (0, polish),
                        Roughness::Unified { sigma_alpha } => (1, sigma_alpha),
                    };
                    PhotonSurface {
                        kind: match s.kind {
                            SurfaceKind::DielectricMetal => PHOTON_SURFACE_METAL,
                            SurfaceKind::DielectricDielectric => PHOTON_SURFACE_DIELECTRIC,
                        },
                        reflectivity: table(&s.reflectivity),
                        efficiency: table(&s.efficiency),
                        transmittance: table(&s.transmittance),
                        finish: finish_code(s.finish),
                        unified,
                        roughness: roughness as f32,
                        rindex: table(&s.rindex),
                        spike: table(&s.spike),
                        lobe: table(&s.lobe),
                        backscatter: table(&s.backscatter),
                        pad: 0,
                    }
                }
            })
            .collect();
        GpuTables {
            tables,
            rows,
            materials,
            surfaces,
            lookup: FlatSurfaces::new(&scene.surfaces, &scene.material, &scene.mother, &scene.copy),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photons::load_photon_scene;
    use hytrace_foundry::gdml::GdmlOptions;

    /// The kernel's lookup finds the surface Geant4's lookup finds for every ordered pair
    /// of instances (siblings, mothers and daughters, and farther apart), on files with
    /// skin surfaces, border surfaces between mothers and daughters, and many border
    /// surfaces between siblings (pfRICH).
    #[test]
    fn flat_lookup_agrees_with_the_surface_lookup_on_every_pair() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let mut sibling_borders = 0;
        for file in [
            "tests/data/photons/every_process.gdml",
            "tests/data/photons/rough_surfaces.gdml",
            "../shared/gdml/eic-opticks/opticks_raindrop.gdml",
            "../shared/gdml/eic-opticks/8x8SiPM_w_CSI_optial_grease.gdml",
            "../shared/gdml/eic-opticks/pfrich_min_FINAL.gdml",
            "../shared/gdml/eic-opticks/basic_detector.gdml",
            "../shared/gdml/geant4/opticalsurfaces.gdml",
        ] {
            let (f, surfaces) = load_photon_scene(&root.join(file), &GdmlOptions::default())
                .unwrap_or_else(|e| panic!("{file}: {e:#}"));
            let scene = PhotonScene::new(&f, surfaces).unwrap();
            let flat =
                FlatSurfaces::new(&scene.surfaces, &scene.material, &scene.mother, &scene.copy);
            sibling_borders += flat.borders.len();
            let n = scene.material.len() as u32;
            let mut surfaced = 0;
            for pre in 0..n {
                for post in (0..n).filter(|&p| p != pre) {
                    let s = scene.surfaces.between(pre, post);
                    assert_eq!(flat.between(pre, post), s, "{file}: {pre} -> {post}");
                    surfaced += usize::from(s != UNSET);
                }
            }
            assert!(surfaced > 0, "{file}: no crossing has a surface");
        }
        assert!(
            sibling_borders > 0,
            "no file has border surfaces between siblings"
        );
    }

    /// A run composes in the processes its scene, photons and outputs call for, only
    /// those.
    #[test]
    fn the_kernel_composes_what_the_run_needs() {
        use crate::photons::gensteps::GenstepFile;
        use crate::photons::sources::Source;
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let tables = |file: &str| {
            let (f, surfaces) =
                load_photon_scene(&root.join(file), &GdmlOptions::default()).unwrap();
            PhotonScene::new(&f, surfaces).unwrap().tables
        };
        let torch = RunOptions {
            origin: Origin::Torch {
                source: Source::parse("point:0,0,0").unwrap(),
                wavelength: Wavelength::Fixed(420.0),
            },
            photons: 10,
            first: 0,
            seed: 0,
            max_steps: 100,
            keep_histories: false,
            records: 0,
        };
        let spectrum = RunOptions {
            origin: Origin::Torch {
                source: Source::parse("point:0,0,0").unwrap(),
                wavelength: Wavelength::Spectrum {
                    material: "Liquid".into(),
                    property: "SCINTILLATIONCOMPONENT1".into(),
                },
            },
            ..torch.clone()
        };
        let every = tables("tests/data/photons/every_process.gdml");
        let rough = tables("tests/data/photons/rough_surfaces.gdml");
        let scintillator = tables("tests/data/photons/scintillator.gdml");
        let shifter = tables("tests/data/photons/wavelength_shifter.gdml");
        for (tables, run, features) in [
            (&every, &torch, &[][..]),
            (&every, &spectrum, &["spectrum"][..]),
            (&rough, &torch, &["rough_surfaces"][..]),
            (&scintillator, &torch, &["reemission"][..]),
            (&shifter, &torch, &["wls"][..]),
        ] {
            assert_eq!(kernel_features(tables, false, run), features);
        }
        let gensteps = RunOptions {
            origin: Origin::Gensteps(std::sync::Arc::new(GenstepFile {
                source: "g.npy".into(),
                steps: Vec::new(),
            })),
            ..torch.clone()
        };
        let records = RunOptions {
            records: 4,
            ..torch.clone()
        };
        assert_eq!(kernel_features(&every, false, &records), ["records"]);
        assert_eq!(kernel_features(&every, false, &gensteps), ["gensteps"]);
        assert_eq!(kernel_features(&shifter, true, &torch), ["wls", "media"]);
    }
}
