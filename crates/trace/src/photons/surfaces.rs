//! Which optical surface applies to a crossing, and what a photon does at a boundary
//! (Geant4's G4OpBoundaryProcess for the surfaces this propagator models).
//!
//! At a boundary from material 1 into material 2:
//! - material 1 without RINDEX: the photon dies there (Geant4's NoRINDEX);
//! - the optical surface is found as Geant4 finds it (border surface of the ordered pair
//!   of physical volumes, else skin surfaces: see [`SurfaceLookup`]); without one the
//!   boundary is a polished dielectric-dielectric one with REFLECTIVITY 1;
//! - a back-painted finish without RINDEX kills the photon;
//! - `dielectric_dielectric`, polished or ground: the same material on both sides passes
//!   straight (SameMaterial); material 2 without RINDEX kills the photon (NoRINDEX);
//! - `dielectric_dielectric` not back-painted: one uniform `u` decides: absorbed when
//!   `u > R + T` (then detected with probability EFFICIENCY), passed straight when
//!   `u > R`, else Fresnel reflection or refraction (polished, ground) or the paint's
//!   reflection (front-painted); back-painted: Fresnel into the gap first
//!   ([`super::surface_models`]);
//! - `dielectric_metal`: reflected when `u <= R` (as the model and finish say), else
//!   passed straight when `u <= R + T`, else absorbed (detected with probability
//!   EFFICIENCY).
//!
//! The photon ends on the side its new direction points to (as Geant4's navigator
//! relocates it), and the reflections are labelled by what they did: specular about the
//! surface normal on a dielectric boundary, specular on a metal, or diffuse.

use hytrace_foundry::optics::Boundary;
use hytrace_foundry::UNSET;
use hytrace_volume::Rng;

use super::boundary::mirror;
use super::properties::{Finish, OpticsTables, Property, Roughness, SurfaceKind};
use super::surface_models::{SurfaceAt, SurfaceEnd};
use super::V;
use crate::scene::VolumeSurfaces;

/// Finds the optical surface of a crossing between two instances.
pub enum SurfaceLookup {
    /// A GDML scene: Geant4's lookup by physical and logical volumes, siblings included.
    Gdml(VolumeSurfaces),
    /// Other scenes: the instances' boundary table. Leaving an instance uses its outer
    /// surface, entering one its inner surface; between siblings the outer surface of the
    /// one left, else the inner surface of the one entered.
    Boundaries {
        /// Boundary of every instance.
        boundaries: Vec<Boundary>,
        /// Mother of every instance ([`UNSET`] for none).
        mother: Vec<u32>,
    },
}

impl SurfaceLookup {
    /// The surface (index, [`UNSET`] for none) of a crossing from `pre` into `post`.
    pub fn between(&self, pre: u32, post: u32) -> u32 {
        match self {
            SurfaceLookup::Gdml(v) => v.between(pre, post),
            SurfaceLookup::Boundaries { boundaries, mother } => {
                if mother[post as usize] == pre {
                    boundaries[post as usize].inner_surface
                } else if mother[pre as usize] == post {
                    boundaries[pre as usize].outer_surface
                } else {
                    match boundaries[pre as usize].outer_surface {
                        UNSET => boundaries[post as usize].inner_surface,
                        s => s,
                    }
                }
            }
        }
    }
}

/// What a photon did at a boundary.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Crossing {
    /// Went on into the far side (refracted, or passed straight).
    Transmitted,
    /// Reflected specularly (about the surface normal) by a dielectric boundary: Fresnel
    /// reflection, total internal reflection, a unified surface's spike or paint.
    Reflected,
    /// Reflected specularly by a (metal) surface.
    SurfaceReflected,
    /// Reflected in any other direction: Lambertian, a lobe or a facet of a rough
    /// surface, backscattered.
    DiffuseReflected,
    /// Absorbed at the surface (or killed for want of RINDEX).
    Absorbed,
    /// Absorbed and detected.
    Detected,
}

/// A reflected direction within this of the mirror image of the incoming one counts as
/// specular.
const SPECULAR_TOLERANCE: f64 = 1e-7;

/// A photon at a boundary: its direction and polarization (changed in place) and energy.
pub struct AtBoundary<'a> {
    /// Unit direction.
    pub dir: &'a mut V,
    /// Unit polarization.
    pub pol: &'a mut V,
    /// Photon energy (MeV).
    pub energy: f64,
}

/// Absorption at a surface, detected with probability `efficiency`.
fn absorb(efficiency: f64, rng: &mut Rng) -> Crossing {
    if rng.next_f64() < efficiency {
        Crossing::Detected
    } else {
        Crossing::Absorbed
    }
}

/// The boundary process at a crossing from material `m1` into `m2` through `surface`
/// (indices; [`UNSET`] for none). `normal` is the unit normal facing the photon
/// (`dir . normal < 0`). The photon ends on the side its new direction points to.
pub fn cross(
    tables: &OpticsTables,
    (m1, m2): (u32, u32),
    surface: u32,
    photon: AtBoundary,
    normal: V,
    rng: &mut Rng,
) -> Crossing {
    let e = photon.energy;
    let rindex = |m: u32| {
        tables
            .material(m)
            .and_then(|m| m.rindex.as_ref())
            .map(|r| r.value(e))
    };
    let Some(n1) = rindex(m1) else {
        return Crossing::Absorbed;
    };
    let s = tables.surface(surface);
    let value = |p: Option<&Property>, default: f64| p.map_or(default, |p| p.value(e));
    let at = match s {
        Some(s) => SurfaceAt {
            finish: s.finish,
            roughness: s.roughness,
            reflectivity: value(s.reflectivity.as_ref(), 1.0),
            transmittance: value(s.transmittance.as_ref(), 0.0),
            spike: value(s.spike.as_ref(), 0.0),
            lobe: value(s.lobe.as_ref(), 0.0),
            backscatter: value(s.backscatter.as_ref(), 0.0),
        },
        None => SurfaceAt {
            finish: Finish::Polished,
            roughness: Roughness::Glisur { polish: 1.0 },
            reflectivity: 1.0,
            transmittance: 0.0,
            spike: 0.0,
            lobe: 0.0,
            backscatter: 0.0,
        },
    };
    let efficiency = s.map_or(0.0, |s| value(s.efficiency.as_ref(), 0.0));
    let kind = s.map_or(SurfaceKind::DielectricDielectric, |s| s.kind);
    // Back-painted finishes fill the gap with the surface's RINDEX; without it the
    // photon dies there (Geant4's NoRINDEX).
    let gap = match s.filter(|s| s.finish.back_painted()) {
        Some(s) => match s.rindex.as_ref() {
            Some(r) => Some(r.value(e)),
            None => return Crossing::Absorbed,
        },
        None => None,
    };
    let incoming = *photon.dir;
    let (dir, pol) = (photon.dir, photon.pol);
    let end = match kind {
        SurfaceKind::DielectricDielectric => {
            let plain = matches!(at.finish, Finish::Polished | Finish::Ground);
            let n2 = if plain {
                if m1 == m2 {
                    return Crossing::Transmitted;
                }
                match rindex(m2) {
                    Some(n2) => n2,
                    None => return Crossing::Absorbed,
                }
            } else {
                gap.unwrap_or(n1)
            };
            if at.finish.back_painted() {
                at.dielectric(dir, pol, normal, (n1, n2), rng)
            } else {
                let u = rng.next_f64();
                if u > at.reflectivity + at.transmittance {
                    return absorb(efficiency, rng);
                }
                if u > at.reflectivity {
                    return Crossing::Transmitted;
                }
                if plain {
                    at.dielectric(dir, pol, normal, (n1, n2), rng)
                } else {
                    at.paint_reflection(dir, pol, normal, rng);
                    SurfaceEnd::Left
                }
            }
        }
        SurfaceKind::DielectricMetal => {
            let u = rng.next_f64();
            if u > at.reflectivity {
                return if u > at.reflectivity + at.transmittance {
                    absorb(efficiency, rng)
                } else {
                    Crossing::Transmitted
                };
            }
            at.metal_reflection(dir, pol, normal, rng);
            SurfaceEnd::Left
        }
    };
    if end == SurfaceEnd::Absorbed {
        return absorb(efficiency, rng);
    }
    if dir.dot(normal) < 0.0 {
        Crossing::Transmitted
    } else if (*dir - mirror(incoming, normal)).length() > SPECULAR_TOLERANCE {
        Crossing::DiffuseReflected
    } else if kind == SurfaceKind::DielectricMetal {
        Crossing::SurfaceReflected
    } else {
        Crossing::Reflected
    }
}
