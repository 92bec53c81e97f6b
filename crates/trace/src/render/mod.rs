//! Rendering of scenes that mix CSG solids, GDML detectors, meshes and sparse volumes,
//! simulating only the effects a scene calls for.
//!
//! A [`RenderSpec`] (camera, materials, lights, media optics, settings) comes with the
//! scene ([`crate::scene::load_render_scene`]); [`Effects::of`] decides from it and the
//! Foundry which effects the scene needs, and [`Renderer::render`] runs the CPU path
//! compiled for exactly that set (see the module `integrator`). Pixel `(i, j)`'s sample `s` draws
//! the random stream `(seed, j * width + i, s)` of [`hytrace_volume::Rng`]; with one
//! sample per pixel the ray goes through the pixel centre.

pub mod camera;
pub mod cutaway;
pub mod detector;
mod integrator;
mod legend_image;
mod media;
pub mod optics;
pub mod output;
pub mod run;
pub mod spec;
mod views;

use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{bail, ensure, Context};
use glam::DVec3;
use hytrace_foundry::{Foundry, PrimKind, UNSET};
use hytrace_volume::{Estimator, Rng, TransmittanceParams};
use rayon::prelude::*;

use crate::cpu::media::SceneMedia;
use crate::cpu::{CpuScene, Hit};
use camera::{Camera, CameraSpec};
use integrator::{EMISSION_ABSORPTION, MULTIPLE_SCATTERING, NO_VOLUMES, SINGLE_SCATTERING};
use media::Media;
pub use output::{write_image, ExrPrecision, Image, IMAGE_EXTENSIONS};
use spec::{Light, Material, MediumOptics, RenderSettings, RenderSpec, View, VolumeMode};
pub use views::id_colour;

/// Why a build without the `media` feature refuses a render with media.
const NO_MEDIA_BUILD: &str =
    "this build renders no media: it was built without the `media` feature (on by default)";

/// The effects a render simulates: each only when the scene calls for it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Effects {
    /// What the image shows (a geometry view needs nothing below).
    pub view: View,
    /// Direct light and hard shadows on diffuse surfaces (the scene has lights and diffuse
    /// surfaces).
    pub shading: bool,
    /// Mirror and dielectric surfaces (a placed solid is made of one).
    pub specular: bool,
    /// Media (the scene places a medium and does not turn them off), rendered in this mode.
    pub volumes: Option<VolumeMode>,
}

impl Effects {
    /// The effects `spec` calls for in the scene `f`.
    pub fn of(f: &Foundry, spec: &RenderSpec) -> Effects {
        let settings = &spec.settings;
        if settings.view != View::Shaded {
            return Effects {
                view: settings.view,
                shading: false,
                specular: false,
                volumes: None,
            };
        }
        // Placed solids with surfaces (a volume-only solid is a medium, not a surface).
        let volume_only = 1u32 << PrimKind::Volume as u32;
        let placed: Vec<usize> = {
            let mut s: Vec<usize> = f
                .inst
                .iter()
                .map(|i| i.solid as usize)
                .filter(|&s| f.solid[s].content & !volume_only != 0)
                .collect();
            s.sort_unstable();
            s.dedup();
            s
        };
        let material_of = |solid: usize| solid_material(f, spec, solid);
        let has_media = !f.optics.media.is_empty() && !f.brick.is_empty();
        let scatters = spec.media.values().any(|m| m.albedo > 0.0);
        Effects {
            view: View::Shaded,
            shading: placed
                .iter()
                .any(|&s| matches!(material_of(s), Material::Diffuse { .. })),
            specular: placed.iter().any(|&s| material_of(s).is_specular()),
            volumes: match settings.volumes {
                _ if !has_media => None,
                Some(VolumeMode::Off) => None,
                Some(mode) => Some(mode),
                None if scatters => Some(VolumeMode::MultipleScattering),
                None => Some(VolumeMode::EmissionAbsorption),
            },
        }
    }

    /// One line per effect and the CPU path and GPU modules it brings in, as
    /// `hytrace render --explain` prints them.
    pub fn explain(&self) -> Vec<String> {
        if self.view != View::Shaded {
            return vec![format!(
                "view {:?}: first hits only (scan kernel and camera rays); no shading, no media",
                self.view
            )
            .to_lowercase()];
        }
        let yes_no = |b: bool| if b { "yes" } else { "no (not compiled in)" };
        vec![
            "view shaded: light transport".to_string(),
            format!(
                "direct light and hard shadows on diffuse surfaces: {}",
                yes_no(self.shading)
            ),
            format!(
                "mirror and dielectric surfaces (Fresnel): {}",
                yes_no(self.specular)
            ),
            match self.volumes {
                None | Some(VolumeMode::Off) => "media: no (not compiled in)".to_string(),
                Some(VolumeMode::EmissionAbsorption) => {
                    "media: emission-absorption (marched emission and transmittance)".into()
                }
                Some(VolumeMode::SingleScattering) => {
                    "media: single scattering (delta tracking, ratio-tracked shadow rays)".into()
                }
                Some(VolumeMode::MultipleScattering) => {
                    "media: multiple scattering (delta tracking with local majorants, ratio-tracked shadow rays)".into()
                }
            },
        ]
    }
}

/// The material of `solid` under `spec` (a named material, transparent, or the default).
fn solid_material(f: &Foundry, spec: &RenderSpec, solid: usize) -> Material {
    let name = f.solid_names.get(solid).map(String::as_str).unwrap_or("");
    if spec.transparent_solids.iter().any(|s| s == name) {
        return Material::Transparent;
    }
    spec.solid_materials
        .get(name)
        .and_then(|m| spec.materials.get(m))
        .copied()
        .unwrap_or(spec::DEFAULT_MATERIAL)
}

/// [`Renderer::covering`]: per instance, the outermost of itself and its ancestors drawn
/// solid; all `UNSET` in a flat scene.
fn covering_instances(f: &Foundry, materials: &[Material]) -> Vec<u32> {
    let mut covering = vec![UNSET; f.inst.len()];
    if f.inst_mother.iter().all(|m| m.index == UNSET) {
        return covering;
    }
    // Mothers come before their daughters.
    for i in 0..f.inst.len() {
        let mother = f.inst_mother[i].index;
        covering[i] = match mother {
            UNSET => UNSET,
            m => covering[m as usize],
        };
        if covering[i] == UNSET && !materials[i].is_see_through() {
            covering[i] = i as u32;
        }
    }
    covering
}

/// How many times the median diagonal of a detector view's solid volumes a volume may span
/// and still count in the automatic camera's framing.
const FRAMING_OUTLIER: f64 = 20.0;

/// How many times the diagonal of the solid volumes' box a shell (an envelope) may span and
/// still count in the automatic camera's framing.
const FRAMING_SHELLS: f64 = 3.0;

/// How many times the volume of the solid volumes' box the box with those shells must hold
/// for the shells to count in the framing (the contents are then a sliver of the view).
const FRAMING_SLIVER: f64 = 20.0;

/// The median box diagonal of the instances `keep` accepts (infinite without any).
fn median_diagonal(scene: &CpuScene<f32>, keep: impl Fn(usize) -> bool) -> f64 {
    let mut d: Vec<f64> = (0..scene.instances())
        .filter(|&i| keep(i))
        .map(|i| {
            let [lo, hi] = scene.instance_bounds(i);
            (DVec3::from(hi) - DVec3::from(lo)).length()
        })
        .collect();
    if d.is_empty() {
        return f64::INFINITY;
    }
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

/// A scene prepared for rendering with one set of effects.
pub struct Renderer<'a> {
    pub(crate) scene: &'a CpuScene<f32>,
    pub(crate) media: Option<Media<'a>>,
    pub(crate) camera: Camera,
    /// Material, solid and boundary of each instance.
    pub(crate) instance_material: Vec<Material>,
    /// Per instance of a hierarchical scene: the outermost instance among itself and its
    /// ancestors that is drawn solid (not see-through), `UNSET` for none. A ray that has
    /// just passed a see-through surface and finds itself inside such an instance entered
    /// it at that surface (their faces coincide): it shows that instance there.
    pub(crate) covering: Vec<u32>,
    pub(crate) instance_solid: Vec<u32>,
    pub(crate) instance_boundary: Vec<u32>,
    /// Point and directional lights (the environment is kept apart).
    pub(crate) lights: Vec<Light>,
    pub(crate) environment: DVec3,
    /// Whether some surface lets shadow rays through (transparent or dielectric).
    pub(crate) see_through: bool,
    /// Depth view: distances mapped from white (near) to black (far).
    pub(crate) depth_range: [f64; 2],
    pub(crate) settings: RenderSettings,
    pub(crate) effects: Effects,
    /// Cut planes.
    pub(crate) cutaway: cutaway::Cutaway,
}

/// A camera looking at the scene's bounds from the front right, above (the default when a
/// scene file has no `[camera]`).
pub fn auto_camera(bounds: Option<[[f64; 3]; 2]>) -> CameraSpec {
    let [lo, hi] = bounds.unwrap_or([[-1.0; 3], [1.0; 3]]);
    let centre: [f64; 3] = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
    let radius = (0..3)
        .map(|k| (hi[k] - lo[k]).powi(2))
        .sum::<f64>()
        .sqrt()
        .max(1e-3)
        * 0.5;
    let fov: f64 = 40.0;
    let distance = radius / (0.5 * fov.to_radians()).sin();
    let dir = DVec3::new(0.55, -0.75, 0.45).normalize();
    CameraSpec {
        eye: (DVec3::from(centre) + distance * dir).into(),
        target: centre,
        up: [0.0, 0.0, 1.0],
        fov: Some(fov),
        orthographic: None,
    }
}

/// Which pixels a render computes.
enum Pixels<'p> {
    /// The whole image, by rows; the callback gets the rows finished so far.
    All(&'p (dyn Fn(u64) + Sync)),
    /// These, by row-major index.
    Some(&'p [u32]),
}

impl<'a> Renderer<'a> {
    /// Prepares a render of `f` (traced through `scene`, prepared from it) under `spec`.
    pub fn new(scene: &'a CpuScene<f32>, f: &Foundry, spec: &RenderSpec) -> crate::Result<Self> {
        spec.validate()?;
        let settings = spec.settings.clone();
        let effects = Effects::of(f, spec);
        crate::error::ensure!(
            cfg!(feature = "media") || effects.volumes.is_none(),
            "{NO_MEDIA_BUILD}"
        );
        ensure!(
            spec.instance_materials.is_empty() || spec.instance_materials.len() == f.inst.len(),
            "{} instance materials for {} instances",
            spec.instance_materials.len(),
            f.inst.len()
        );
        // A solid made transparent wins over a detector view's material.
        let instance_material: Vec<Material> = f
            .inst
            .iter()
            .enumerate()
            .map(|(k, i)| match spec.instance_materials.get(k) {
                Some(&m) if solid_material(f, spec, i.solid as usize) != Material::Transparent => m,
                _ => solid_material(f, spec, i.solid as usize),
            })
            .collect();
        let covering = covering_instances(f, &instance_material);
        // What is seen: the surfaces drawn solid (a detector view's contents), and the
        // shells (envelopes) around them up to a few times their size when the contents are
        // a sliver of what those show (simple-cms.gdml: nested envelopes around one thin
        // beam pipe); else every surface drawn. Transparent instances (a GDML world, hidden
        // volumes) never count. A detector view leaves out what is far larger than its
        // typical solid volume (beam pipes tens of metres long around a detector of a few).
        let solid = |i: usize| !instance_material[i].is_see_through();
        let typical = if spec.instance_materials.is_empty() {
            f64::INFINITY
        } else {
            FRAMING_OUTLIER * median_diagonal(scene, solid)
        };
        let diagonal = |i: usize| {
            let [lo, hi] = scene.instance_bounds(i);
            (DVec3::from(hi) - DVec3::from(lo)).length()
        };
        let contents = scene.bounds_of(|i| solid(i) && diagonal(i) <= typical);
        let volume =
            |[lo, hi]: [[f64; 3]; 2]| (DVec3::from(hi) - DVec3::from(lo)).element_product();
        let bounds = match contents {
            Some([lo, hi]) => {
                let largest = FRAMING_SHELLS * (DVec3::from(hi) - DVec3::from(lo)).length();
                let with_shells = scene.bounds_of(|i| {
                    let shell = matches!(instance_material[i], Material::Shell { .. });
                    (solid(i) && diagonal(i) <= typical) || (shell && diagonal(i) <= largest)
                });
                with_shells
                    .filter(|&b| FRAMING_SLIVER * volume([lo, hi]) < volume(b))
                    .or(contents)
            }
            None => scene.bounds_of(|i| instance_material[i] != Material::Transparent),
        }
        .or_else(|| scene.world_bounds());
        let camera_spec = spec.camera.clone().unwrap_or_else(|| auto_camera(bounds));
        let camera = Camera::new(&camera_spec, settings.size)?;
        let mut lights = Vec::new();
        let mut environment = DVec3::ZERO;
        for l in spec.lights_or_default() {
            match l {
                Light::Environment { radiance } => environment += DVec3::from(radiance),
                other => lights.push(other),
            }
        }
        let see_through = instance_material
            .iter()
            .any(|m| m.is_see_through() || matches!(m, Material::Dielectric { .. }));
        let media = match effects.volumes {
            None => None,
            Some(mode) => {
                // Shadow rays ratio-track scattering media; emission-absorption marches them
                // (Media::transmittance), so the estimator serves the trackers only.
                let mut params = TransmittanceParams::new(Estimator::Ratio);
                params.seed = settings.seed;
                let scene_media = SceneMedia::with_memory(scene, f, &params, settings.memory)?;
                let optics = f
                    .optics
                    .media
                    .iter()
                    .map(|m| {
                        let solid = f
                            .solid
                            .iter()
                            .position(|s| {
                                (s.prim_offset..s.prim_offset + s.num_prim).contains(&m.prim)
                            })
                            .context("a medium's prim belongs to no solid")?;
                        let name = &f.solid_names[solid];
                        Ok(spec.media.get(name).copied().unwrap_or_default())
                    })
                    .collect::<crate::Result<Vec<MediumOptics>>>()?;
                Some(Media {
                    scene: scene_media,
                    optics,
                    step: settings.step,
                    march: mode == VolumeMode::EmissionAbsorption,
                })
            }
        };
        let depth_range = match bounds {
            None => [0.0, 1.0],
            Some([lo, hi]) => {
                let centre = 0.5 * (DVec3::from(lo) + DVec3::from(hi));
                let radius = 0.5 * (DVec3::from(hi) - DVec3::from(lo)).length();
                let d = (centre - camera.eye).length();
                [(d - radius).max(0.0), (d + radius).max(1e-9)]
            }
        };
        Ok(Renderer {
            scene,
            media,
            camera,
            instance_material,
            covering,
            instance_solid: f.inst.iter().map(|i| i.solid).collect(),
            instance_boundary: f.inst.iter().map(|i| i.boundary).collect(),
            lights,
            environment,
            see_through,
            depth_range,
            settings,
            effects,
            cutaway: spec.cutaway.clone(),
        })
    }

    /// The effects this render simulates.
    pub fn effects(&self) -> Effects {
        self.effects
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    fn material(&self, hit: &Hit<f32>) -> Material {
        self.instance_material[hit.instance as usize]
    }

    /// The camera ray of pixel `(i, j)`'s sample drawn from `rng`.
    fn camera_ray(&self, i: u32, j: u32, rng: &mut Rng) -> (DVec3, DVec3) {
        let offset = if self.settings.spp == 1 {
            [0.5, 0.5]
        } else {
            [rng.next_f64(), rng.next_f64()]
        };
        self.camera.ray(i, j, offset)
    }

    /// Renders the image on the CPU (rayon over rows); `progress` is called with the
    /// number of rows finished so far. Errors name the pixel that failed.
    pub fn render(&self, progress: &(dyn Fn(u64) + Sync)) -> crate::Result<Image> {
        let [width, height] = self.settings.size;
        Ok(Image {
            width,
            height,
            pixels: self.shade(Pixels::All(progress))?,
        })
    }

    /// The values of some pixels of the image (row-major indices below width x height),
    /// each as [`Renderer::render`] gives it: the same samples of the same streams.
    pub fn render_pixels(&self, pixels: &[u32]) -> crate::Result<Vec<[f32; 3]>> {
        let [width, height] = self.settings.size;
        if let Some(p) = pixels
            .iter()
            .find(|&&p| p as u64 >= width as u64 * height as u64)
        {
            bail!("pixel {p} is outside the {width}x{height} image");
        }
        self.shade(Pixels::Some(pixels))
    }

    /// The values of `pixels` under this render's effects.
    fn shade(&self, pixels: Pixels<'_>) -> crate::Result<Vec<[f32; 3]>> {
        let fx = self.effects;
        let vm = match fx.volumes {
            None | Some(VolumeMode::Off) => NO_VOLUMES,
            Some(VolumeMode::EmissionAbsorption) => EMISSION_ABSORPTION,
            Some(VolumeMode::SingleScattering) => SINGLE_SCATTERING,
            Some(VolumeMode::MultipleScattering) => MULTIPLE_SCATTERING,
        };
        if fx.view != View::Shaded {
            return self.render_with(pixels, |o, d, _| Ok(self.geometry_view(o, d)));
        }
        // One instantiation per effect set; those with media only in builds with the
        // `media` feature (on by default), so a build without it holds no media code.
        macro_rules! shaded {
            (always: $($s:literal, $p:literal, $v:ident);* ; media: $($ms:literal, $mp:literal, $mv:ident);* $(;)?) => {
                match (fx.shading, fx.specular, vm) {
                    $(($s, $p, $v) => self.render_with(pixels, |o, d, rng| {
                        self.radiance::<$s, $p, $v>(o, d, rng)
                    }),)*
                    $(#[cfg(feature = "media")]
                    ($ms, $mp, $mv) => self.render_with(pixels, |o, d, rng| {
                        self.radiance::<$ms, $mp, $mv>(o, d, rng)
                    }),)*
                    _ => crate::error::bail!("{NO_MEDIA_BUILD}"),
                }
            };
        }
        shaded!(
            always:
            false, false, NO_VOLUMES; false, true, NO_VOLUMES;
            true, false, NO_VOLUMES; true, true, NO_VOLUMES;
            media:
            false, false, EMISSION_ABSORPTION; false, false, SINGLE_SCATTERING;
            false, false, MULTIPLE_SCATTERING; false, true, EMISSION_ABSORPTION;
            false, true, SINGLE_SCATTERING; false, true, MULTIPLE_SCATTERING;
            true, false, EMISSION_ABSORPTION; true, false, SINGLE_SCATTERING;
            true, false, MULTIPLE_SCATTERING; true, true, EMISSION_ABSORPTION;
            true, true, SINGLE_SCATTERING; true, true, MULTIPLE_SCATTERING;
        )
    }

    /// The values of `pixels`, each the mean of its samples that `sample` gives.
    fn render_with<F>(&self, pixels: Pixels<'_>, sample: F) -> crate::Result<Vec<[f32; 3]>>
    where
        F: Fn(DVec3, DVec3, &mut Rng) -> crate::Result<DVec3> + Sync,
    {
        let [width, height] = self.settings.size;
        ensure!(
            (width as u64) * (height as u64) <= u32::MAX as u64,
            "{width}x{height} pixels: at most 2^32 - 1"
        );
        let pixel = |i: u32, j: u32| -> crate::Result<[f32; 3]> {
            let mut sum = DVec3::ZERO;
            for s in 0..self.settings.spp {
                let mut rng = Rng::new(self.settings.seed, j * width + i, s);
                let (o, d) = self.camera_ray(i, j, &mut rng);
                sum += sample(o, d, &mut rng)
                    .with_context(|| format!("pixel ({i}, {j}), sample {s}"))?;
            }
            Ok((sum / self.settings.spp as f64).as_vec3().to_array())
        };
        match pixels {
            Pixels::Some(list) => list
                .par_iter()
                .map(|&p| pixel(p % width, p / width))
                .collect(),
            Pixels::All(progress) => {
                let done = AtomicU64::new(0);
                let rows: Vec<Vec<[f32; 3]>> = (0..height)
                    .into_par_iter()
                    .map(|j| {
                        let row = (0..width)
                            .map(|i| pixel(i, j))
                            .collect::<crate::Result<Vec<_>>>()?;
                        progress(done.fetch_add(1, Ordering::Relaxed) + 1);
                        Ok(row)
                    })
                    .collect::<crate::Result<_>>()?;
                Ok(rows.into_iter().flatten().collect())
            }
        }
    }

    /// Solid, boundary (or `UNSET`) of an instance.
    fn identity(&self, instance: u32) -> (u32, u32) {
        let i = instance as usize;
        (
            self.instance_solid.get(i).copied().unwrap_or(UNSET),
            self.instance_boundary.get(i).copied().unwrap_or(UNSET),
        )
    }
}
