//! Which optical surface applies to a crossing, and what a photon does at a boundary
//! (Geant4's G4OpBoundaryProcess for the surfaces this propagator models).
//!
//! At a boundary from material 1 into material 2:
//! - material 1 without RINDEX: the photon dies there (Geant4's NoRINDEX);
//! - the optical surface is found as Geant4 finds it (border surface of the ordered pair
//!   of physical volumes, else skin surfaces: see [`SurfaceLookup`]); without one the
//!   boundary is a polished dielectric-dielectric one with REFLECTIVITY 1;
//! - `dielectric_dielectric`: the same material on both sides passes straight
//!   (SameMaterial); material 2 without RINDEX kills the photon (NoRINDEX); otherwise one
//!   uniform `u` decides: absorbed when `u > R + T` (then detected with probability
//!   EFFICIENCY), passed straight when `u > R`, else Fresnel reflection or refraction;
//! - `dielectric_metal`: reflected specularly when `u <= R`, else passed straight when
//!   `u <= R + T`, else absorbed (detected with probability EFFICIENCY).

use hytrace_foundry::optics::Boundary;
use hytrace_foundry::UNSET;
use hytrace_volume::Rng;

use super::boundary::{dielectric_dielectric, mirror, Fresnel};
use super::properties::{OpticsTables, Property, SurfaceKind};
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
    /// Reflected back by Fresnel reflection or total internal reflection.
    Reflected,
    /// Reflected by a (metal) surface.
    SurfaceReflected,
    /// Absorbed at the surface (or killed for want of RINDEX).
    Absorbed,
    /// Absorbed and detected.
    Detected,
}

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
/// (`dir . normal < 0`).
pub fn cross(
    tables: &OpticsTables,
    (m1, m2): (u32, u32),
    surface: u32,
    photon: AtBoundary,
    normal: V,
    rng: &mut Rng,
) -> Crossing {
    let e = photon.energy;
    let Some(n1) = tables
        .material(m1)
        .and_then(|m| m.rindex.as_ref())
        .map(|r| r.value(e))
    else {
        return Crossing::Absorbed;
    };
    let s = tables.surface(surface);
    let value = |p: Option<&Property>, default: f64| p.map_or(default, |p| p.value(e));
    let (kind, r, t, eff) = match s {
        Some(s) => (
            s.kind,
            value(s.reflectivity.as_ref(), 1.0),
            value(s.transmittance.as_ref(), 0.0),
            value(s.efficiency.as_ref(), 0.0),
        ),
        None => (SurfaceKind::DielectricDielectric, 1.0, 0.0, 0.0),
    };
    match kind {
        SurfaceKind::DielectricDielectric => {
            if m1 == m2 {
                return Crossing::Transmitted;
            }
            let Some(n2) = tables
                .material(m2)
                .and_then(|m| m.rindex.as_ref())
                .map(|r| r.value(e))
            else {
                return Crossing::Absorbed;
            };
            let u = rng.next_f64();
            if u > r + t {
                return absorb(eff, rng);
            }
            if u > r {
                return Crossing::Transmitted;
            }
            let (what, dir, pol) =
                dielectric_dielectric(*photon.dir, *photon.pol, normal, n1, n2, t, rng.next_f64());
            *photon.dir = dir;
            *photon.pol = pol;
            match what {
                Fresnel::Refracted => Crossing::Transmitted,
                Fresnel::Reflected | Fresnel::TotalInternal => Crossing::Reflected,
            }
        }
        SurfaceKind::DielectricMetal => {
            let u = rng.next_f64();
            if u > r {
                return if u > r + t {
                    absorb(eff, rng)
                } else {
                    Crossing::Transmitted
                };
            }
            *photon.dir = mirror(*photon.dir, normal);
            *photon.pol = -mirror(*photon.pol, normal);
            Crossing::SurfaceReflected
        }
    }
}
