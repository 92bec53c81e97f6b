//! Geometry views: what detector people render first. Each pixel shows its camera ray's
//! first surface drawn solid (transparent solids and shells passed; a shell shows where
//! nothing solid lies behind it): the distance, the normal, or a colour per solid, prim,
//! instance or boundary; black where the ray misses.

use glam::DVec3;
use hytrace_foundry::UNSET;
use hytrace_volume::pcg4d;

use super::integrator::{spawn, Crossed};
use super::spec::{Material, View};
use super::Renderer;
use crate::cpu::Hit;

/// Most transparent surfaces a geometry view passes.
const MAX_TRANSPARENT: u32 = 256;

/// The colour of identity `id` (`UNSET`: grey): a hash spread over [0.15, 1] per channel,
/// the same on the GPU.
pub fn id_colour(id: u32) -> DVec3 {
    if id == UNSET {
        return DVec3::splat(0.5);
    }
    let h = pcg4d([id, 0x6879_7472, 0, 0]);
    let channel = |x: u32| 0.15 + 0.85 * ((x >> 24) as f64 / 255.0);
    DVec3::new(channel(h[0]), channel(h[1]), channel(h[2]))
}

impl Renderer<'_> {
    /// The colour of the geometry view for the ray `origin + t dir`: its first surface
    /// drawn solid, else the first shell it passes (an envelope with nothing drawn behind
    /// it), else black.
    pub(super) fn geometry_view(&self, mut origin: DVec3, dir: DVec3) -> DVec3 {
        let mut travelled = 0.0;
        let mut crossed = None;
        let mut first_shell: Option<(Hit<f32>, f64)> = None;
        for _ in 0..MAX_TRANSPARENT {
            let (from, hit) = self.trace_after(origin, dir, crossed);
            origin = from;
            let Some(hit) = hit else {
                break;
            };
            let t = hit.t as f64;
            let material = self.material(&hit);
            if material.is_see_through() {
                if first_shell.is_none() && matches!(material, Material::Shell { .. }) {
                    first_shell = Some((hit, travelled + t));
                }
                let p = origin + t * dir;
                let n = DVec3::from(hit.normal.to_f64());
                let next = spawn(p, n, dir);
                travelled += (next - origin).length();
                crossed = Some(Crossed {
                    point: p,
                    normal: n,
                });
                origin = next;
                continue;
            }
            return self.view_colour(&hit, travelled + t);
        }
        first_shell.map_or(DVec3::ZERO, |(hit, distance)| {
            self.view_colour(&hit, distance)
        })
    }

    /// The geometry view's colour of `hit`, `distance` from the camera.
    fn view_colour(&self, hit: &Hit<f32>, distance: f64) -> DVec3 {
        let (solid, boundary) = self.identity(hit.instance);
        match self.effects.view {
            View::Depth => {
                let [near, far] = self.depth_range;
                DVec3::splat(((far - distance) / (far - near).max(1e-12)).clamp(0.0, 1.0))
            }
            View::Normal => 0.5 * (DVec3::from(hit.normal.to_f64()) + 1.0),
            View::Solid => id_colour(solid),
            View::Prim => id_colour(hit.prim),
            View::Instance => id_colour(hit.instance),
            View::Boundary => id_colour(boundary),
            View::Shaded => unreachable!("the shaded view is not a geometry view"),
        }
    }
}
