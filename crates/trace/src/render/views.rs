//! Geometry views: what detector people render first. Each pixel shows its camera ray's
//! first surface (transparent solids skipped): the distance, the normal, or a colour per
//! solid, prim, instance or boundary; black where the ray misses.

use glam::DVec3;
use hytrace_foundry::UNSET;
use hytrace_volume::pcg4d;

use super::integrator::spawn;
use super::spec::{Material, View};
use super::Renderer;

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
    /// The colour of the geometry view for the ray `origin + t dir`.
    pub(super) fn geometry_view(&self, mut origin: DVec3, dir: DVec3) -> DVec3 {
        let mut travelled = 0.0;
        for _ in 0..MAX_TRANSPARENT {
            let Some(hit) = self.trace(origin, dir, f64::INFINITY) else {
                return DVec3::ZERO;
            };
            let t = hit.t as f64;
            if self.material(&hit) == Material::Transparent {
                let n = DVec3::from(hit.normal.to_f64());
                let next = spawn(origin + t * dir, n, dir);
                travelled += (next - origin).length();
                origin = next;
                continue;
            }
            let (solid, boundary) = self.identity(hit.instance);
            return match self.effects.view {
                View::Depth => {
                    let [near, far] = self.depth_range;
                    let v = ((far - (travelled + t)) / (far - near).max(1e-12)).clamp(0.0, 1.0);
                    DVec3::splat(v)
                }
                View::Normal => 0.5 * (DVec3::from(hit.normal.to_f64()) + 1.0),
                View::Solid => id_colour(solid),
                View::Prim => id_colour(hit.prim),
                View::Instance => id_colour(hit.instance),
                View::Boundary => id_colour(boundary),
                View::Shaded => unreachable!("the shaded view is not a geometry view"),
            };
        }
        DVec3::ZERO
    }
}
