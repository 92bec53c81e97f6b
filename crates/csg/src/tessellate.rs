//! Closed triangle meshes for solids with no analytic form here: stacks of cross-sections
//! (extrusions, twisted and generic trapezoids), refined until the mesh is within a stated
//! distance of the true surface.

use crate::shape::CsgError;

/// A triangle, vertices counter-clockwise seen from outside.
pub type Tri = [[f64; 3]; 3];

fn err(problem: String) -> CsgError {
    CsgError {
        primitive: "tessellation",
        problem,
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn lerp(a: [f64; 3], b: [f64; 3], s: f64) -> [f64; 3] {
    [
        a[0] + s * (b[0] - a[0]),
        a[1] + s * (b[1] - a[1]),
        a[2] + s * (b[2] - a[2]),
    ]
}

/// Twice the signed area of a polygon in xy (positive when counter-clockwise).
pub fn signed_area2(poly: &[[f64; 2]]) -> f64 {
    (0..poly.len())
        .map(|i| {
            let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
            a[0] * b[1] - a[1] * b[0]
        })
        .sum()
}

/// Triangles (index triples, counter-clockwise) of a simple polygon given counter-clockwise,
/// by ear clipping.
pub fn triangulate(poly: &[[f64; 2]]) -> Result<Vec<[usize; 3]>, CsgError> {
    let n = poly.len();
    if n < 3 {
        return Err(err(format!("a polygon needs 3 vertices, got {n}")));
    }
    let area = signed_area2(poly);
    if area.is_nan() || area <= 0.0 {
        return Err(err(format!(
            "the polygon must be counter-clockwise with non-zero area (twice the area {area})"
        )));
    }
    let eps = 1e-12 * area.abs();
    let orient = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| {
        (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    };
    let mut idx: Vec<usize> = (0..n).collect();
    let mut out = Vec::with_capacity(n - 2);
    while idx.len() > 3 {
        let m = idx.len();
        let ear = (0..m).find(|&k| {
            let (a, b, c) = (idx[(k + m - 1) % m], idx[k], idx[(k + 1) % m]);
            if orient(poly[a], poly[b], poly[c]) <= eps {
                return false;
            }
            // No other vertex inside (or on) the candidate ear.
            idx.iter().all(|&p| {
                p == a
                    || p == b
                    || p == c
                    || orient(poly[a], poly[b], poly[p]) < -eps
                    || orient(poly[b], poly[c], poly[p]) < -eps
                    || orient(poly[c], poly[a], poly[p]) < -eps
            })
        });
        let Some(k) = ear else {
            return Err(err("the polygon is not simple (no ear to clip)".into()));
        };
        out.push([idx[(k + m - 1) % m], idx[k], idx[(k + 1) % m]]);
        idx.remove(k);
    }
    out.push([idx[0], idx[1], idx[2]]);
    Ok(out)
}

/// The closed mesh of a stack of cross-sections: `levels[i]` are the polygon's vertices at
/// the i-th level (same count everywhere, ascending z, counter-clockwise seen from +z);
/// consecutive levels are joined by quads split into two triangles, and the first and last
/// levels are capped with the triangulation of `cap` (a subset of the level's vertices:
/// the indices of the polygon's corners, so that collinear edge points do not upset ear
/// clipping).
pub fn section_stack(levels: &[Vec<[f64; 3]>], corners: &[usize]) -> Result<Vec<Tri>, CsgError> {
    let n = levels.first().map_or(0, Vec::len);
    if levels.len() < 2 || n < 3 || levels.iter().any(|l| l.len() != n) {
        return Err(err(
            "a section stack needs 2 levels of the same polygon".into()
        ));
    }
    let mut out = Vec::new();
    for pair in levels.windows(2) {
        let (lo, hi) = (&pair[0], &pair[1]);
        for k in 0..n {
            let j = (k + 1) % n;
            // Counter-clockwise polygon: outward is to the right of the edge k -> j seen
            // from +z, so (lo k, lo j, hi j) runs counter-clockwise seen from outside.
            out.push([lo[k], lo[j], hi[j]]);
            out.push([lo[k], hi[j], hi[k]]);
        }
    }
    for (level, up) in [(&levels[0], false), (&levels[levels.len() - 1], true)] {
        let poly: Vec<[f64; 2]> = corners
            .iter()
            .map(|&c| [level[c][0], level[c][1]])
            .collect();
        for [a, b, c] in triangulate(&poly)? {
            let (a, b, c) = (level[corners[a]], level[corners[b]], level[corners[c]]);
            // Counter-clockwise from +z faces up: right for the top cap, flipped at the bottom.
            out.push(if up { [a, b, c] } else { [a, c, b] });
        }
    }
    Ok(out)
}

/// Distance from `p` to the plane of triangle `t`.
fn plane_distance(p: [f64; 3], t: &Tri) -> f64 {
    let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
    let l = dot(n, n).sqrt();
    if l == 0.0 {
        return 0.0;
    }
    (dot(sub(p, t[0]), n) / l).abs()
}

/// The closed mesh of a solid whose cross-section at height `z` is the polygon
/// `section(z)` (corners counter-clockwise seen from +z) from `z1` to `z2`, with side faces
/// ruled by the straight segments between consecutive corners at every height. Levels and
/// edge subdivisions are doubled until every patch centre and every corner path lies within
/// `tolerance` of the mesh. Fails when that needs more than about 2^20 triangles.
pub fn ruled_solid(
    section: &dyn Fn(f64) -> Vec<[f64; 3]>,
    z1: f64,
    z2: f64,
    tolerance: f64,
) -> Result<Vec<Tri>, CsgError> {
    if tolerance.is_nan()
        || tolerance <= 0.0
        || z1.partial_cmp(&z2) != Some(std::cmp::Ordering::Less)
    {
        return Err(err(format!(
            "needs tolerance > 0 and z1 < z2, got {tolerance}, {z1}..{z2}"
        )));
    }
    let corners = section(z1).len();
    let (mut nz, mut nu) = (2usize, 1usize);
    loop {
        let z_at = |i: usize| z1 + (z2 - z1) * i as f64 / nz as f64;
        let point = |z: f64, edge: usize, s: f64| {
            let p = section(z);
            lerp(p[edge], p[(edge + 1) % corners], s)
        };
        let levels: Vec<Vec<[f64; 3]>> = (0..=nz)
            .map(|i| {
                let z = z_at(i);
                (0..corners)
                    .flat_map(|e| (0..nu).map(move |k| (e, k as f64 / nu as f64)))
                    .map(|(e, s)| point(z, e, s))
                    .collect()
            })
            .collect();
        // Deviation along the corner paths (levels) and across patches (subdivisions).
        let (mut dev_z, mut dev_u) = (0.0f64, 0.0f64);
        for i in 0..nz {
            let zm = 0.5 * (z_at(i) + z_at(i + 1));
            for e in 0..corners {
                let c = point(zm, e, 0.0);
                let chord = lerp(point(z_at(i), e, 0.0), point(z_at(i + 1), e, 0.0), 0.5);
                dev_z = dev_z.max(dot(sub(c, chord), sub(c, chord)).sqrt());
                for k in 0..nu {
                    let (s0, s1) = (k as f64 / nu as f64, (k + 1) as f64 / nu as f64);
                    let centre = point(zm, e, 0.5 * (s0 + s1));
                    let (a, b) = (point(z_at(i), e, s0), point(z_at(i), e, s1));
                    let (c2, d2) = (point(z_at(i + 1), e, s1), point(z_at(i + 1), e, s0));
                    let t1 = [a, b, c2];
                    let t2 = [a, c2, d2];
                    dev_u = dev_u.max(plane_distance(centre, &t1).min(plane_distance(centre, &t2)));
                }
            }
        }
        if dev_z <= tolerance && dev_u <= tolerance {
            let corner_index: Vec<usize> = (0..corners).map(|e| e * nu).collect();
            return section_stack(&levels, &corner_index);
        }
        if dev_z > tolerance {
            nz *= 2;
        }
        if dev_u > tolerance {
            nu *= 2;
            nz = nz.max(2);
        }
        if nz * nu * corners > 1 << 19 {
            return Err(err(format!(
                "more than 2^20 triangles needed for tolerance {tolerance} mm"
            )));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Signed volume of a closed mesh (divergence theorem): positive when outward-facing.
    fn volume(mesh: &[Tri]) -> f64 {
        mesh.iter()
            .map(|t| dot(t[0], cross(t[1], t[2])) / 6.0)
            .sum()
    }

    #[test]
    fn ear_clipping_handles_non_convex_polygons() {
        // An L shape of area 3.
        let l = [
            [0.0, 0.0],
            [2.0, 0.0],
            [2.0, 1.0],
            [1.0, 1.0],
            [1.0, 2.0],
            [0.0, 2.0],
        ];
        let tris = triangulate(&l).unwrap();
        assert_eq!(tris.len(), 4);
        let area: f64 = tris
            .iter()
            .map(|t| 0.5 * signed_area2(&[l[t[0]], l[t[1]], l[t[2]]]))
            .sum();
        assert!((area - 3.0).abs() < 1e-12);
        assert!(tris
            .iter()
            .all(|t| signed_area2(&[l[t[0]], l[t[1]], l[t[2]]]) > 0.0));
        let mut cw = l;
        cw.reverse();
        assert!(triangulate(&cw).is_err());
        assert!(triangulate(&[[0.0, 0.0], [1.0, 0.0]]).is_err());
    }

    #[test]
    fn a_prism_stack_is_closed_with_the_right_volume() {
        let sq = |z: f64| vec![[0.0, 0.0, z], [2.0, 0.0, z], [2.0, 3.0, z], [0.0, 3.0, z]];
        let mesh = section_stack(&[sq(0.0), sq(5.0)], &[0, 1, 2, 3]).unwrap();
        assert!((volume(&mesh) - 30.0).abs() < 1e-9, "{}", volume(&mesh));
    }

    #[test]
    fn twisted_prisms_converge_to_the_analytic_volume() {
        // A square rotated linearly with z keeps its area at every height: volume = area * h.
        let twist = 1.2f64;
        let section = |z: f64| {
            let a = twist * z / 10.0;
            let (s, c) = a.sin_cos();
            [[-3.0, -2.0], [3.0, -2.0], [3.0, 2.0], [-3.0, 2.0]]
                .map(|p| [c * p[0] - s * p[1], s * p[0] + c * p[1], z])
                .to_vec()
        };
        for tol in [1e-1, 1e-2, 1e-3] {
            let mesh = ruled_solid(&section, -5.0, 5.0, tol).unwrap();
            let v = volume(&mesh);
            // The mesh is within tol of the surface everywhere: the volume error is at most
            // tol times the side area (and the mesh chords cut inside the twisted faces).
            let side_area = 2.0 * (6.0 + 4.0) * 10.0 * 1.2;
            assert!(
                (v - 240.0).abs() <= tol * side_area,
                "tol {tol}: volume {v}"
            );
        }
        assert!(ruled_solid(&section, -5.0, 5.0, 0.0).is_err());
    }
}
