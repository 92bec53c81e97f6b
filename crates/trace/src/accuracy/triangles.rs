//! Accuracy rows of the triangle kernels: the watertight ray/triangle test against the
//! fast Möller-Trumbore test most renderers use, and the BVH build presets.
//!
//! The tests are judged on rays through the vertices and edge midpoints of a closed convex
//! mesh, built so that both precisions represent them exactly and they cross the surface at
//! `t = 1`: the reference is exact without computing anything, and a test that is not
//! watertight shows as a ray that passes through.

use hytrace_csg::{tessellate, MeshPrim, Ray, Real, V3};
use hytrace_volume::Rng;
use obvhs::BvhBuildParams;

use super::{Row, Settings, Timer};

/// Error counted for a ray that finds no triangle of a closed mesh it crosses (mm).
const PASSED_THROUGH: f64 = 200.0;

/// A closed icosphere of `radius` around `centre`, subdivided `levels` times (20 * 4^levels
/// triangles, outward winding), vertices rounded to f32.
fn icosphere(levels: usize, radius: f64, centre: [f64; 3]) -> Vec<[[f64; 3]; 3]> {
    let (verts, faces) = tessellate::icosphere(levels);
    // Shared vertices round identically: same f64 in, same f32 out.
    let placed: Vec<[f64; 3]> = verts
        .iter()
        .map(|p| std::array::from_fn(|k| (centre[k] + radius * p[k]) as f32 as f64))
        .collect();
    faces.iter().map(|f| f.map(|i| placed[i])).collect()
}

/// The classic Möller-Trumbore test (edges from `v0`, determinant by a triple product),
/// either side; `None` on a miss.
fn moller_trumbore<T: Real>(tri: &[V3<T>; 3], ray: &Ray<T>) -> Option<T> {
    let [v0, v1, v2] = *tri;
    let (e1, e2) = (v1 - v0, v2 - v0);
    let p = ray.direction.cross(e2);
    let det = e1.dot(p);
    if det == T::ZERO {
        return None;
    }
    let inv = T::ONE / det;
    let s = ray.origin - v0;
    let u = s.dot(p) * inv;
    if u < T::ZERO || u > T::ONE {
        return None;
    }
    let q = s.cross(e1);
    let v = ray.direction.dot(q) * inv;
    if v < T::ZERO || u + v > T::ONE {
        return None;
    }
    Some(e2.dot(q) * inv)
}

/// Grid the edge-test mesh's vertices are snapped to (mm): coordinates are multiples of
/// 2^-10 below 2^10, so vertices, edge midpoints, ray origins and the directions between
/// them are all exact in f32.
const SNAP: f64 = 1.0 / 1024.0;

fn snapped(p: [f64; 3]) -> [f64; 3] {
    p.map(|c| (c / SNAP).round() * SNAP)
}

/// Rays from outside a closed mesh through its vertices and the midpoints of its edges,
/// exactly: the origin and the non-unit direction `target - origin` are exact in f32, so
/// every ray passes through the vertex or edge in both precisions.
fn edge_rays(tris: &[[[f64; 3]; 3]], centre: [f64; 3], count: usize) -> Vec<Ray<f64>> {
    let mut rng = Rng::new(3, 0, 0);
    (0..count)
        .map(|i| {
            let tri = tris[rng.next_u32() as usize % tris.len()];
            let k = rng.next_u32() as usize % 3;
            let target: [f64; 3] = if i % 2 == 0 {
                tri[k]
            } else {
                std::array::from_fn(|c| 0.5 * (tri[k][c] + tri[(k + 1) % 3][c]))
            };
            // From outside, about one radius beyond the surface, in a random direction of
            // the outer half space.
            let out: [f64; 3] = std::array::from_fn(|c| target[c] - centre[c]);
            let wobble: [f64; 3] = std::array::from_fn(|_| rng.next_f64() - 0.5);
            let from = snapped(std::array::from_fn(|c| {
                target[c] + out[c] + 40.0 * wobble[c]
            }));
            let d: [f64; 3] = std::array::from_fn(|c| target[c] - from[c]);
            Ray::from_f64(from, d)
        })
        .collect()
}

/// Watertight and Möller-Trumbore, f32 and f64: fraction of edge and vertex rays that
/// find no triangle, and time per ray/triangle test.
fn test_rows(settings: Settings) -> Vec<Row> {
    let centre = [300.0, 200.0, 100.0];
    let tris: Vec<[[f64; 3]; 3]> = icosphere(settings.size(3, 2), 100.0, centre)
        .iter()
        .map(|t| t.map(snapped))
        .collect();
    let rays = edge_rays(&tris, centre, settings.size(2000, 200));
    let timer = Timer::new(settings);
    let tests = rays.len() * tris.len();
    // The nearest crossing ahead of each ray; every ray crosses at t = 1 (see edge_rays):
    // the error is the distance from there, or the penalty when the ray passes through.
    let row = |variant: &str, crossing: &dyn Fn(&Ray<f64>) -> Option<f64>| {
        let error = rays
            .iter()
            .map(|r| crossing(r).map_or(PASSED_THROUGH, |t| (t - 1.0).abs() * r.direction.length()))
            .fold(0.0, f64::max);
        Row {
            component: "triangle test",
            variant: variant.to_string(),
            metric: "max |t - t_ref| (mm) at edges and vertices of a closed mesh; a ray that \
                     passes through counts 200",
            reference: "exact: each ray is built through a vertex or edge midpoint",
            error,
            ns_per_op: timer.ns_per_op(tests, || rays.iter().filter_map(crossing).sum::<f64>()),
            memory_bytes: None,
        }
    };
    let t32: Vec<[V3<f32>; 3]> = tris.iter().map(|t| t.map(V3::from_f64)).collect();
    let t64: Vec<[V3<f64>; 3]> = tris.iter().map(|t| t.map(V3::from_f64)).collect();
    let r32 = |r: &Ray<f64>| Ray {
        origin: V3::<f32>::from_f64(r.origin.to_f64()),
        direction: V3::<f32>::from_f64(r.direction.to_f64()),
    };
    let nearest = |ts: &mut dyn Iterator<Item = f64>| ts.filter(|t| *t > 0.0).reduce(f64::min);
    vec![
        row("watertight, f32", &|r| {
            let r = r32(r);
            nearest(
                &mut t32
                    .iter()
                    .filter_map(|t| MeshPrim::triangle_crossing(t, &r))
                    .map(f64::from),
            )
        }),
        row("watertight, f64", &|r| {
            nearest(&mut t64.iter().filter_map(|t| MeshPrim::triangle_crossing(t, r)))
        }),
        row("Moller-Trumbore, f32", &|r| {
            let r = r32(r);
            nearest(
                &mut t32
                    .iter()
                    .filter_map(|t| moller_trumbore(t, &r))
                    .map(f64::from),
            )
        }),
        row("Moller-Trumbore, f64", &|r| {
            nearest(&mut t64.iter().filter_map(|t| moller_trumbore(t, r)))
        }),
    ]
}

/// The obvhs build presets of a mesh's BVH: build time, trace time and the answers, which
/// must not depend on the preset.
fn bvh_rows(settings: Settings) -> crate::Result<Vec<Row>> {
    let centre = [0.0; 3];
    let tris = icosphere(settings.size(6, 4), 100.0, centre);
    let mut rng = Rng::new(5, 0, 0);
    let rays: Vec<Ray<f32>> = (0..settings.size(4000, 200))
        .map(|_| {
            let from: [f64; 3] = std::array::from_fn(|_| 400.0 * (rng.next_f64() - 0.5));
            let to: [f64; 3] = std::array::from_fn(|_| 120.0 * (rng.next_f64() - 0.5));
            let d: [f64; 3] = std::array::from_fn(|k| to[k] - from[k]);
            let n = d.iter().map(|c| c * c).sum::<f64>().sqrt();
            Ray::from_f64(from, d.map(|c| c / n))
        })
        .collect();
    // The reference: every triangle tested, in f64, no BVH.
    let t64: Vec<[V3<f64>; 3]> = tris.iter().map(|t| t.map(V3::from_f64)).collect();
    let want: Vec<Option<f64>> = rays
        .iter()
        .map(|r| {
            let r = Ray {
                origin: V3::<f64>::from_f64(r.origin.to_f64()),
                direction: V3::<f64>::from_f64(r.direction.to_f64()),
            };
            t64.iter()
                .filter_map(|t| MeshPrim::triangle_crossing(t, &r))
                .filter(|t| *t > 0.0)
                .reduce(f64::min)
        })
        .collect();
    let timer = Timer::new(settings);
    let presets = [
        ("fastest_build", BvhBuildParams::fastest_build()),
        ("fast_build", BvhBuildParams::fast_build()),
        ("medium_build", BvhBuildParams::medium_build()),
        ("slow_build", BvhBuildParams::slow_build()),
    ];
    let mut rows = Vec::new();
    for (name, params) in presets {
        let mesh = MeshPrim::<f32>::with_bvh_build(&tris, params)?;
        let build_ms = timer.ns_per_op(1, || MeshPrim::<f32>::with_bvh_build(&tris, params)) * 1e-6;
        let answer = |r: &Ray<f32>| {
            let s = mesh.first_crossing(r, 0.0);
            s.is_hit().then_some(s.t)
        };
        let error = rays
            .iter()
            .zip(&want)
            .map(|(r, w)| match (answer(r), w) {
                (Some(g), Some(w)) => (g as f64 - w).abs(),
                (None, None) => 0.0,
                _ => f64::INFINITY,
            })
            .fold(0.0, f64::max);
        let ns = timer.ns_per_op(rays.len(), || rays.iter().filter_map(answer).sum::<f32>());
        rows.push(Row {
            component: "triangle BVH preset",
            variant: format!(
                "{name}, {} triangles, built in {build_ms:.1} ms",
                tris.len()
            ),
            metric: "max |t - t_ref| (mm)",
            reference: "every triangle tested in f64, no BVH",
            error,
            ns_per_op: ns,
            memory_bytes: Some(mesh.bvh_bytes() as u64),
        });
    }
    Ok(rows)
}

/// Every triangle row.
pub(super) fn rows(settings: Settings) -> crate::Result<Vec<Row>> {
    let mut rows = test_rows(settings);
    rows.extend(bvh_rows(settings)?);
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn icosphere_is_closed_and_outward() {
        let tris = icosphere(2, 10.0, [1.0, 2.0, 3.0]);
        assert_eq!(tris.len(), 320);
        // Closed: every edge is used once in each direction.
        let key = |p: [f64; 3]| p.map(f64::to_bits);
        let mut edges = std::collections::HashMap::new();
        for t in &tris {
            for k in 0..3 {
                *edges.entry((key(t[k]), key(t[(k + 1) % 3]))).or_insert(0) += 1;
            }
        }
        for (&(a, b), &n) in &edges {
            assert_eq!(n, 1);
            assert_eq!(edges.get(&(b, a)), Some(&1));
        }
        // Outward: the normal points away from the centre.
        for t in &tris {
            let e1: [f64; 3] = std::array::from_fn(|k| t[1][k] - t[0][k]);
            let e2: [f64; 3] = std::array::from_fn(|k| t[2][k] - t[0][k]);
            let n = [
                e1[1] * e2[2] - e1[2] * e2[1],
                e1[2] * e2[0] - e1[0] * e2[2],
                e1[0] * e2[1] - e1[1] * e2[0],
            ];
            let c = [t[0][0] - 1.0, t[0][1] - 2.0, t[0][2] - 3.0];
            assert!(n[0] * c[0] + n[1] * c[1] + n[2] * c[2] > 0.0);
        }
    }
}
