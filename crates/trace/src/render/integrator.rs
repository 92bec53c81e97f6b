//! Light transport for the shaded view, compiled once per set of effects: a scene that
//! calls for no media, no specular surfaces or no lights runs code without them (the
//! effect flags are constants, so the unused branches vanish from the instantiation).
//!
//! A path starts at the camera. Media along each straight piece are handled first
//! (emission-absorption: their light is added and the path attenuated; scattering: a real
//! collision is sampled by delta tracking and, if one happens before the surface, the path
//! scatters there). At a surface: emitters end the path with their radiance; diffuse
//! surfaces end it with their direct light (point and directional lights, and one
//! cosine-distributed direction toward the environment; hard shadows through opaque
//! surfaces, attenuated by media, by dielectric surfaces' Fresnel transmission and
//! absorption); mirrors and dielectrics continue it (a dielectric reflects with the
//! Fresnel probability, else refracts). A path that leaves the scene sees the environment.
//! Point and directional lights are reached only by shadow rays and the environment only
//! by shadow rays from diffuse surfaces and single scattering, or by escaping paths
//! elsewhere, so no light is counted twice.

use glam::DVec3;
use hytrace_csg::Ray;
use hytrace_volume::Rng;

use super::optics::{
    cosine_direction, fresnel, henyey_greenstein, reflect, refract, sample_henyey_greenstein,
};
use super::spec::{Light, Material, MediumOptics};
use super::Renderer;
use crate::cpu::Hit;
use hytrace_csg::V3;
use hytrace_foundry::UNSET;

/// Volume rendering compiled in: none.
pub const NO_VOLUMES: u8 = 0;
/// Emission-absorption.
pub const EMISSION_ABSORPTION: u8 = 1;
/// Single scattering.
pub const SINGLE_SCATTERING: u8 = 2;
/// Multiple scattering.
pub const MULTIPLE_SCATTERING: u8 = 3;

/// Most surfaces a shadow ray passes (transparent and dielectric ones).
const MAX_SHADOW_CROSSINGS: u32 = 64;

/// How far a new ray starts off the surface it leaves: a few f32 ulps of the coordinates,
/// so the f32 tracer does not find that surface again.
fn surface_offset(p: DVec3) -> f64 {
    64.0 * f32::EPSILON as f64 * (1.0 + p.abs().max_element())
}

/// `p` moved off the surface with normal `n` to the side `w` leaves toward.
pub(super) fn spawn(p: DVec3, n: DVec3, w: DVec3) -> DVec3 {
    let side = if w.dot(n) >= 0.0 { 1.0 } else { -1.0 };
    p + side * surface_offset(p) * n
}

/// The ray as the GPU renderer holds it: origin and direction in f32 (so the tracer's
/// two-part origin has no rest).
fn f32_ray(origin: DVec3, dir: DVec3) -> Ray<f64> {
    let f32_exactly = |v: DVec3| <[f64; 3]>::from(v).map(|c| f64::from(c as f32));
    Ray::from_f64(f32_exactly(origin), f32_exactly(dir))
}

/// A see-through surface a ray has just passed (see [`Renderer::trace_after`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct Crossed {
    /// Where the ray crossed it.
    pub point: DVec3,
    /// Its outward normal there.
    pub normal: DVec3,
}

fn uniforms2(rng: &mut Rng) -> [f64; 2] {
    [rng.next_f64(), rng.next_f64()]
}

impl Renderer<'_> {
    /// The first surface crossing along the ray (f32, as the GPU traces).
    pub(super) fn trace(&self, origin: DVec3, dir: DVec3, tmax: f64) -> Option<Hit<f32>> {
        self.scene.trace(&f32_ray(origin, dir), 0.0, tmax as f32)
    }

    /// The first surface along a ray from `origin` that has just passed the see-through
    /// surface `crossed` (if any), and the origin it is measured from. A ray that finds
    /// itself inside an instance drawn solid (located as the navigator locates the f32
    /// origin) entered it where its face coincides with the surface passed: that instance
    /// is hit there, at distance 0 from the crossing point (returned as the origin), with
    /// the crossed surface's normal. Otherwise [`Self::trace`] from `origin`.
    pub(super) fn trace_after(
        &self,
        origin: DVec3,
        dir: DVec3,
        crossed: Option<Crossed>,
    ) -> (DVec3, Option<Hit<f32>>) {
        if let Some(c) = crossed {
            let located = self
                .scene
                .locate_point(<[f64; 3]>::from(origin).map(|x| f64::from(x as f32)));
            if let Some(&cover) = located.and_then(|l| self.covering.get(l as usize)) {
                if cover != UNSET {
                    let hit = Hit {
                        t: 0.0,
                        normal: V3::from_f64(c.normal.to_array()),
                        instance: cover,
                        prim: UNSET,
                    };
                    return (c.point, Some(hit));
                }
            }
        }
        (origin, self.trace(origin, dir, f64::INFINITY))
    }

    /// The fraction of light arriving at `origin` along `-dir` from distance `dist`
    /// (infinite for the environment and directional lights): 0 behind an opaque surface,
    /// else the product of the media's transmittance and each crossed dielectric's
    /// Fresnel transmission and absorption (refraction's bending is ignored: shadow rays
    /// are straight).
    fn shadow<const VM: u8>(
        &self,
        origin: DVec3,
        dir: DVec3,
        dist: f64,
        rng: &mut Rng,
    ) -> anyhow::Result<f64> {
        let media_t = |o: DVec3, t1: f64, rng: &mut Rng| -> anyhow::Result<f64> {
            match &self.media {
                Some(m) if VM != NO_VOLUMES => m.transmittance(o, dir, 0.0, t1, rng),
                _ => Ok(1.0),
            }
        };
        if !self.see_through {
            if self.scene.occluded(&f32_ray(origin, dir), 0.0, dist as f32) {
                return Ok(0.0);
            }
            return media_t(origin, dist, rng);
        }
        let (mut o, mut left, mut weight) = (origin, dist, 1.0);
        let mut inside: Option<f64> = None;
        for _ in 0..MAX_SHADOW_CROSSINGS {
            let hit = self.trace(o, dir, left);
            let t = hit.map_or(left, |h| h.t as f64);
            // An opaque surface blocks the light: no media are drawn for this piece (the GPU
            // draws none either, so both keep the same random streams).
            let see_through =
                |m: Material| m.is_see_through() || matches!(m, Material::Dielectric { .. });
            if hit.is_some_and(|h| !see_through(self.material(&h))) {
                return Ok(0.0);
            }
            weight *= media_t(o, t, rng)?;
            if let Some(length) = inside {
                weight *= (-t / length).exp();
            }
            let Some(hit) = hit else {
                return Ok(weight);
            };
            let p = o + t * dir;
            let n = DVec3::from(hit.normal.to_f64());
            match self.material(&hit) {
                Material::Transparent | Material::Shell { .. } => {}
                Material::Dielectric {
                    ior,
                    absorption_length,
                } => {
                    let entering = dir.dot(n) < 0.0;
                    let eta = if entering { ior } else { 1.0 / ior };
                    weight *= 1.0 - fresnel(dir.dot(n).abs(), eta);
                    inside = if entering { absorption_length } else { None };
                }
                _ => return Ok(0.0),
            }
            if weight == 0.0 {
                return Ok(0.0);
            }
            o = spawn(p, n, dir);
            left -= t;
            if left <= 0.0 {
                return Ok(weight);
            }
        }
        Ok(0.0)
    }

    /// Light reaching a point from the lights, weighted by `response(direction)`: the
    /// surface's `cos / pi` or the medium's phase function. `environment` samples one
    /// direction toward the environment from `env_direction` (weight 1: the sample is
    /// drawn from the response).
    fn direct<const VM: u8>(
        &self,
        p: DVec3,
        response: impl Fn(DVec3) -> f64,
        env_direction: Option<DVec3>,
        spawn_from: impl Fn(DVec3) -> DVec3,
        rng: &mut Rng,
    ) -> anyhow::Result<DVec3> {
        let mut sum = DVec3::ZERO;
        for light in &self.lights {
            let (w, dist, power) = match *light {
                Light::Point {
                    position,
                    intensity,
                } => {
                    let to = DVec3::from(position) - p;
                    let d2 = to.length_squared();
                    if d2 == 0.0 {
                        continue;
                    }
                    let d = d2.sqrt();
                    (to / d, d, DVec3::from(intensity) / d2)
                }
                Light::Directional {
                    direction,
                    irradiance,
                } => (
                    -DVec3::from(direction).normalize(),
                    f64::INFINITY,
                    DVec3::from(irradiance),
                ),
                Light::Environment { .. } => continue,
            };
            let f = response(w);
            if f <= 0.0 || power == DVec3::ZERO {
                continue;
            }
            let o = spawn_from(w);
            let reach = if dist.is_finite() {
                (dist - (o - p).length()).max(0.0)
            } else {
                dist
            };
            sum += power * f * self.shadow::<VM>(o, w, reach, rng)?;
        }
        if let (Some(w), true) = (env_direction, self.environment != DVec3::ZERO) {
            let o = spawn_from(w);
            sum += self.environment * self.shadow::<VM>(o, w, f64::INFINITY, rng)?;
        }
        Ok(sum)
    }

    /// Radiance arriving at `origin` along `-dir`: one path sample (see the module
    /// documentation). `SHADING`: diffuse surfaces are lit (else they show their colour
    /// under a unit white light); `SPECULAR`: mirrors and dielectrics; `VM`: the volume
    /// rendering compiled in.
    pub(super) fn radiance<const SHADING: bool, const SPECULAR: bool, const VM: u8>(
        &self,
        mut origin: DVec3,
        mut dir: DVec3,
        rng: &mut Rng,
    ) -> anyhow::Result<DVec3> {
        let (mut radiance, mut beta) = (DVec3::ZERO, DVec3::ONE);
        // Absorption length of the dielectric the path is inside, if any.
        let mut inside: Option<f64> = None;
        let mut events = 0;
        let mut crossed = None;
        while events <= self.settings.max_bounces {
            let (from, hit) = self.trace_after(origin, dir, crossed.take());
            origin = from;
            let t_end = hit.map_or(f64::INFINITY, |h| h.t as f64);
            if VM != NO_VOLUMES {
                if let Some(media) = &self.media {
                    if VM == EMISSION_ABSORPTION {
                        let (light, transmittance) =
                            media.emission_absorption(origin, dir, 0.0, t_end)?;
                        radiance += beta * light;
                        beta *= transmittance;
                    } else if let Some(event) = media.collision(origin, dir, 0.0, t_end, rng)? {
                        if let Some(length) = inside {
                            beta *= (-event.t / length).exp();
                        }
                        let p = origin + event.t * dir;
                        let MediumOptics {
                            albedo,
                            g,
                            emission,
                        } = event.optics;
                        // The collision estimator of the emission j / sigma = value * colour.
                        radiance += beta * event.value * DVec3::from(emission);
                        beta *= albedo;
                        if beta == DVec3::ZERO {
                            break;
                        }
                        let env = (VM == SINGLE_SCATTERING)
                            .then(|| sample_henyey_greenstein(dir, g, uniforms2(rng)));
                        let phase = |w: DVec3| henyey_greenstein(dir.dot(w), g);
                        radiance += beta * self.direct::<VM>(p, phase, env, |_| p, rng)?;
                        if VM == SINGLE_SCATTERING {
                            break;
                        }
                        dir = sample_henyey_greenstein(dir, g, uniforms2(rng));
                        origin = p;
                        events += 1;
                        continue;
                    }
                }
            }
            if let Some(length) = inside {
                beta *= (-t_end / length).exp();
            }
            let Some(hit) = hit else {
                radiance += beta * self.environment;
                break;
            };
            let p = origin + t_end * dir;
            let n = DVec3::from(hit.normal.to_f64());
            // The normal on the side the path arrives from.
            let facing = if dir.dot(n) < 0.0 { n } else { -n };
            match self.material(&hit) {
                Material::Emitter { radiance: e } => {
                    radiance += beta * DVec3::from(e);
                    break;
                }
                Material::Transparent => {
                    origin = spawn(p, n, dir);
                    crossed = Some(Crossed {
                        point: p,
                        normal: n,
                    });
                    events += 1;
                    continue;
                }
                Material::Shell { colour, opacity } => {
                    // Unlit: the colour by the cosine to the view, then the light behind.
                    radiance += beta * opacity * dir.dot(n).abs() * DVec3::from(colour);
                    beta *= 1.0 - opacity;
                    origin = spawn(p, n, dir);
                    crossed = Some(Crossed {
                        point: p,
                        normal: n,
                    });
                    events += 1;
                    continue;
                }
                Material::Mirror { colour } if SPECULAR => {
                    beta *= DVec3::from(colour);
                    dir = reflect(dir, facing);
                    origin = spawn(p, n, dir);
                }
                Material::Dielectric {
                    ior,
                    absorption_length,
                } if SPECULAR => {
                    let entering = dir.dot(n) < 0.0;
                    let eta = if entering { ior } else { 1.0 / ior };
                    let reflectance = fresnel(-dir.dot(facing), eta);
                    let through = match refract(dir, facing, eta) {
                        Some(w) if rng.next_f64() >= reflectance => Some(w),
                        _ => None,
                    };
                    dir = match through {
                        Some(w) => {
                            inside = if entering { absorption_length } else { None };
                            w
                        }
                        None => reflect(dir, facing),
                    };
                    origin = spawn(p, n, dir);
                }
                m => {
                    let colour = match m {
                        Material::Diffuse { colour } | Material::Mirror { colour } => {
                            DVec3::from(colour)
                        }
                        _ => DVec3::splat(1.0),
                    };
                    if SHADING {
                        let env = cosine_direction(facing, uniforms2(rng));
                        let cosine = |w: DVec3| facing.dot(w) / std::f64::consts::PI;
                        let light =
                            self.direct::<VM>(p, cosine, Some(env), |w| spawn(p, n, w), rng)?;
                        radiance += beta * colour * light;
                    } else {
                        radiance += beta * colour;
                    }
                    break;
                }
            }
            events += 1;
        }
        Ok(radiance)
    }
}
