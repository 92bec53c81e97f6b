//! What a render needs besides geometry: camera, materials, lights, the optical properties
//! of media and the render settings, as a scene file writes them (see `docs/rendering.md`
//! and `docs/scene-files.md`).

use std::collections::BTreeMap;

use crate::error::{bail, ensure};
use hytrace_volume::DEFAULT_STORE_BUDGET;
use serde::Deserialize;

use super::camera::{Camera, CameraSpec};

/// A surface material.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Material {
    /// Lambertian reflection of `colour` (albedo per channel, in [0, 1]).
    Diffuse {
        /// Albedo.
        colour: [f64; 3],
    },
    /// Perfect mirror reflecting `colour` of the light.
    Mirror {
        /// Reflectance.
        colour: [f64; 3],
    },
    /// Smooth dielectric (glass, water, acrylic): Fresnel reflection and refraction; light
    /// inside is attenuated as `exp(-length / absorption_length)` (no attenuation when
    /// absent).
    Dielectric {
        /// Index of refraction inside (outside is 1).
        ior: f64,
        /// Absorption length in mm.
        #[serde(default)]
        absorption_length: Option<f64>,
    },
    /// A surface emitting `radiance` and reflecting nothing.
    Emitter {
        /// Emitted radiance.
        radiance: [f64; 3],
    },
    /// Invisible: rays pass through (a GDML world or an air volume).
    Transparent,
    /// A faint see-through shell (a detector's envelope): it adds `opacity` of its
    /// unlit `colour` (scaled by the cosine to the view direction) and lets the rest of
    /// the light through; it casts no shadow.
    Shell {
        /// Colour, in [0, 1] per channel.
        colour: [f64; 3],
        /// The fraction of the light it stands for, in (0, 1].
        opacity: f64,
    },
}

/// The material of solids that name none.
pub const DEFAULT_MATERIAL: Material = Material::Diffuse {
    colour: [0.7, 0.7, 0.7],
};

impl Material {
    /// Errors on colours outside [0, 1], an index of refraction below 1, or a
    /// non-positive absorption length.
    pub fn validate(&self) -> crate::Result<()> {
        let unit = |c: &[f64; 3]| c.iter().all(|v| (0.0..=1.0).contains(v));
        match self {
            Material::Diffuse { colour } | Material::Mirror { colour } => ensure!(
                unit(colour),
                "colour {colour:?}: every channel must be in [0, 1] (energy is never created)"
            ),
            Material::Dielectric {
                ior,
                absorption_length,
            } => {
                ensure!(
                    ior.is_finite() && *ior >= 1.0,
                    "ior must be finite and >= 1, got {ior}"
                );
                if let Some(l) = absorption_length {
                    ensure!(*l > 0.0, "absorption_length must be > 0, got {l}");
                }
            }
            Material::Emitter { radiance } => ensure!(
                radiance.iter().all(|v| v.is_finite() && *v >= 0.0),
                "radiance {radiance:?} must be finite and >= 0"
            ),
            Material::Shell { colour, opacity } => {
                ensure!(
                    unit(colour),
                    "colour {colour:?}: every channel must be in [0, 1]"
                );
                ensure!(
                    *opacity > 0.0 && *opacity <= 1.0,
                    "shell opacity must be in (0, 1], got {opacity}"
                );
            }
            Material::Transparent => {}
        }
        Ok(())
    }

    /// Whether rays go on past the surface without stopping (transparent or a shell).
    pub fn is_see_through(&self) -> bool {
        matches!(self, Material::Transparent | Material::Shell { .. })
    }

    /// Whether the material reflects or refracts specularly.
    pub fn is_specular(&self) -> bool {
        matches!(self, Material::Mirror { .. } | Material::Dielectric { .. })
    }
}

/// A light.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Light {
    /// A point light: irradiance `intensity / distance^2` facing it.
    Point {
        /// Position (mm).
        position: [f64; 3],
        /// Radiant intensity per channel.
        intensity: [f64; 3],
    },
    /// A distant light whose light travels along `direction`.
    Directional {
        /// Direction the light travels.
        direction: [f64; 3],
        /// Irradiance on a surface facing it.
        irradiance: [f64; 3],
    },
    /// Uniform radiance from every direction no geometry covers (also the background).
    Environment {
        /// Radiance.
        radiance: [f64; 3],
    },
}

impl Light {
    /// Errors on non-finite or negative values and a zero direction.
    pub fn validate(&self) -> crate::Result<()> {
        let finite = |v: &[f64; 3]| v.iter().all(|c| c.is_finite());
        let power = |v: &[f64; 3]| v.iter().all(|c| c.is_finite() && *c >= 0.0);
        match self {
            Light::Point {
                position,
                intensity,
            } => ensure!(
                finite(position) && power(intensity),
                "point light: position must be finite and intensity finite and >= 0"
            ),
            Light::Directional {
                direction,
                irradiance,
            } => ensure!(
                finite(direction) && *direction != [0.0; 3] && power(irradiance),
                "directional light: direction must be finite and non-zero, irradiance finite and >= 0"
            ),
            Light::Environment { radiance } => ensure!(
                power(radiance),
                "environment light: radiance must be finite and >= 0"
            ),
        }
        Ok(())
    }
}

/// Optical properties of a medium (a scene file's `[volumes.NAME]` entry), on top of its
/// extinction `density_scale * grid value`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MediumOptics {
    /// Single-scattering albedo: scattering over extinction, in [0, 1].
    pub albedo: f64,
    /// Henyey-Greenstein asymmetry in (-1, 1): > 0 scatters forward.
    pub g: f64,
    /// Emission colour: the medium emits `extinction * grid value * emission` per unit
    /// length (an emission-absorption transfer function: the denser, the brighter).
    pub emission: [f64; 3],
}

impl Default for MediumOptics {
    fn default() -> Self {
        MediumOptics {
            albedo: 0.0,
            g: 0.0,
            emission: [0.0; 3],
        }
    }
}

impl MediumOptics {
    /// Errors on an albedo outside [0, 1], `|g| >= 1` or a negative emission.
    pub fn validate(&self) -> crate::Result<()> {
        ensure!(
            (0.0..=1.0).contains(&self.albedo),
            "albedo must be in [0, 1], got {}",
            self.albedo
        );
        ensure!(
            self.g.is_finite() && self.g.abs() < 1.0,
            "g must be in (-1, 1), got {}",
            self.g
        );
        ensure!(
            self.emission.iter().all(|c| c.is_finite() && *c >= 0.0),
            "emission {:?} must be finite and >= 0",
            self.emission
        );
        Ok(())
    }
}

/// What the image shows.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum View {
    /// Light transport: materials, lights, media.
    #[default]
    Shaded,
    /// Distance to the first surface, near white to far black.
    Depth,
    /// Outward normal of the first surface, `0.5 (n + 1)` as RGB.
    Normal,
    /// A colour per solid.
    Solid,
    /// A colour per prim.
    Prim,
    /// A colour per instance (placement).
    Instance,
    /// A colour per boundary (GDML's material pairs and optical surfaces).
    Boundary,
}

crate::choice::named!(View {
    (View::Shaded, "shaded", [], "Light transport: materials, lights, media"),
    (View::Depth, "depth", [], "Distance to the first surface, near white to far black"),
    (View::Normal, "normal", [], "Outward normal of the first surface, `0.5 (n + 1)` as RGB"),
    (View::Solid, "solid", [], "A colour per solid"),
    (View::Prim, "prim", [], "A colour per prim"),
    (View::Instance, "instance", [], "A colour per instance (placement)"),
    (View::Boundary, "boundary", [], "A colour per boundary (GDML's material pairs and optical surfaces)"),
});

/// How media are rendered.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum VolumeMode {
    /// Media are left out: the render sees the surfaces only.
    Off,
    /// Emission and absorption only (no scattering): exact transmittance, marched emission.
    EmissionAbsorption,
    /// Light scattered once toward the lights (transmittance to them by ratio tracking).
    SingleScattering,
    /// Light scattered any number of times (delta tracking with the local majorants).
    MultipleScattering,
}

crate::choice::named!(VolumeMode {
    (VolumeMode::Off, "off", [], "Media are left out: the render sees the surfaces only"),
    (VolumeMode::EmissionAbsorption, "emission-absorption", [], "Emission and absorption only (no scattering): exact transmittance, marched emission"),
    (VolumeMode::SingleScattering, "single-scattering", [], "Light scattered once toward the lights (transmittance to them by ratio tracking)"),
    (VolumeMode::MultipleScattering, "multiple-scattering", [], "Light scattered any number of times (delta tracking with the local majorants)"),
});

/// The `[render]` table of a scene file; command-line options override it.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RenderSettings {
    /// What the image shows.
    #[serde(default)]
    pub view: View,
    /// How media are rendered (default: multiple scattering when a medium scatters, else
    /// emission-absorption).
    #[serde(default)]
    pub volumes: Option<VolumeMode>,
    /// Width and height in pixels.
    #[serde(default = "default_size")]
    pub size: [u32; 2],
    /// Samples per pixel (1: the pixel centre, deterministic for deterministic effects).
    #[serde(default = "default_spp")]
    pub spp: u32,
    /// Longest path: surface and medium scattering events.
    #[serde(default = "default_bounces")]
    pub max_bounces: u32,
    /// Emission-absorption march step, in voxels of each medium.
    #[serde(default = "default_step")]
    pub step: f64,
    /// Seed of the random streams.
    #[serde(default)]
    pub seed: u32,
    /// Bytes each medium read as stored in a brick store may hold resident: its tables and
    /// a cache of the bricks read on demand.
    #[serde(default = "default_memory")]
    pub memory: u64,
}

fn default_size() -> [u32; 2] {
    [640, 360]
}
fn default_spp() -> u32 {
    16
}
fn default_bounces() -> u32 {
    32
}
fn default_step() -> f64 {
    0.125
}
fn default_memory() -> u64 {
    DEFAULT_STORE_BUDGET
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            view: View::default(),
            volumes: None,
            size: default_size(),
            spp: default_spp(),
            max_bounces: default_bounces(),
            step: default_step(),
            seed: 0,
            memory: default_memory(),
        }
    }
}

/// Largest image side.
pub const MAX_IMAGE_SIDE: u32 = 16384;

impl RenderSettings {
    /// Errors on impossible sizes, sample counts or steps.
    pub fn validate(&self) -> crate::Result<()> {
        let [w, h] = self.size;
        ensure!(
            (1..=MAX_IMAGE_SIDE).contains(&w) && (1..=MAX_IMAGE_SIDE).contains(&h),
            "size {w}x{h}: each side must be in 1..={MAX_IMAGE_SIDE}"
        );
        ensure!(
            (1..=1 << 20).contains(&self.spp),
            "spp must be in 1..=1048576, got {}",
            self.spp
        );
        ensure!(
            self.max_bounces <= 4096,
            "max_bounces must be at most 4096, got {}",
            self.max_bounces
        );
        ensure!(
            self.step.is_finite() && self.step > 0.0,
            "step must be finite and > 0 voxels, got {}",
            self.step
        );
        Ok(())
    }
}

/// Everything a render needs besides the Foundry.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RenderSpec {
    /// The camera (`None`: framed automatically around the scene).
    pub camera: Option<CameraSpec>,
    /// Named materials.
    pub materials: BTreeMap<String, Material>,
    /// Material name of each solid, by solid name (others get [`DEFAULT_MATERIAL`]).
    pub solid_materials: BTreeMap<String, String>,
    /// Lights (none: one directional light from above and a dim environment).
    pub lights: Vec<Light>,
    /// Optical properties of each medium, by its solid (volume) name.
    pub media: BTreeMap<String, MediumOptics>,
    /// Settings.
    pub settings: RenderSettings,
    /// Solids rendered transparent because the scene says so (a GDML world).
    pub transparent_solids: Vec<String>,
    /// One material per instance, overriding the solids' (empty: by solid): a detector
    /// view's styling ([`crate::render::detector`]).
    pub instance_materials: Vec<Material>,
    /// What a detector view knows of each placed volume (empty for flat scenes).
    pub volumes: Vec<VolumeLabel>,
    /// Cut planes (none: nothing is cut away).
    pub cutaway: super::cutaway::Cutaway,
}

/// The names and file attributes of one placed volume of a hierarchical scene.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VolumeLabel {
    /// Physical volume name (stripped).
    pub physical: String,
    /// Logical volume name (stripped; the solid's name when the scene keeps none).
    pub logical: String,
    /// Material name (empty when none).
    pub material: String,
    /// Colour the file gives the volume (GDML's auxiliary `Color`), linear RGB.
    pub colour: Option<[f64; 3]>,
    /// Visibility the file gives the volume (GDML's auxiliary `Visibility`).
    pub visible: Option<bool>,
}

impl RenderSpec {
    /// Checks every material, light and medium, the settings, and that every material a
    /// solid names exists.
    pub fn validate(&self) -> crate::Result<()> {
        self.cutaway.validate().map_err(crate::Error::Invalid)?;
        for (name, m) in &self.materials {
            m.validate()
                .map_err(|e| e.context(format!("material `{name}`")))?;
        }
        for (solid, name) in &self.solid_materials {
            if !self.materials.contains_key(name) {
                bail!("solid `{solid}`: unknown material `{name}`");
            }
        }
        for (k, m) in self.instance_materials.iter().enumerate() {
            m.validate()
                .map_err(|e| e.context(format!("material of instance {k}")))?;
        }
        for (k, l) in self.lights.iter().enumerate() {
            l.validate().map_err(|e| e.context(format!("light {k}")))?;
        }
        for (name, m) in &self.media {
            m.validate()
                .map_err(|e| e.context(format!("volume `{name}`")))?;
        }
        self.settings.validate()?;
        if let Some(camera) = &self.camera {
            Camera::new(camera, self.settings.size)?;
        }
        Ok(())
    }

    /// The lights, or the default ones when the scene names none: sunlight from above
    /// and a dim sky.
    pub fn lights_or_default(&self) -> Vec<Light> {
        if !self.lights.is_empty() {
            return self.lights.clone();
        }
        vec![
            Light::Directional {
                direction: [-0.3, 0.4, -1.0],
                irradiance: [2.0, 2.0, 2.0],
            },
            Light::Environment {
                radiance: [0.15, 0.15, 0.18],
            },
        ]
    }
}
