//! The mesh BVH traversal on rays it could get wrong: direction components exactly zero
//! (the exact slab test, not the reciprocal one) running in the planes of the node boxes'
//! faces and through vertices, grazing rays, and random rays checked against a brute force
//! over every triangle, in f32 and f64.

use hytrace_csg::mesh::INTERLEAVED;
use hytrace_csg::simd::SimdPath;
use hytrace_csg::{CrossingScratch, MeshPrim, MeshQuery, Ray, Real, V3};

mod common;
use common::{grid, Random, Rng};
use hytrace_testkit::vec3::normalized as unit;

type Tri = [[f64; 3]; 3];

fn first_hit<T: Real>(mesh: &MeshPrim<T>, o: [f64; 3], d: [f64; 3]) -> f64 {
    let ray = Ray::from_f64(o, d);
    mesh.first_crossing(&ray, T::ZERO).t.to_f64()
}

/// Checks `got` against the expected distance (`inf`: a miss) within `rel` relative.
fn check(what: &str, got: f64, want: f64, rel: f64, failures: &mut Vec<String>) {
    let ok = if want.is_finite() {
        (got - want).abs() <= rel * want.abs().max(1.0)
    } else {
        !got.is_finite()
    };
    if !ok {
        failures.push(format!("{what}: got {got}, want {want}"));
    }
}

/// Rays with zero direction components along the planes `x = i` and `y = j` (the box
/// faces), through vertices, edge midpoints and quad centres, onto a sloped grid
/// `z = 0.5 y` whose coordinates are exact in f32: every target on the grid (on the
/// edges and vertices shared by its triangles too) is hit at the analytic distance, every
/// target outside is missed.
#[test]
fn zero_direction_components_along_box_faces() {
    let n = 24;
    let tris = grid(n, |_, y| 0.5 * y);
    let (m32, m64) = (
        MeshPrim::<f32>::new(&tris).unwrap(),
        MeshPrim::<f64>::new(&tris).unwrap(),
    );
    // Dyadic directions (not unit: `t` counts them) and origins, so every ray passes
    // exactly through its target, in f32 as in f64.
    let dirs = [
        [0.0, 0.0, -1.0],
        [0.0, 0.5, -1.0],
        [0.0, -0.5, -1.0],
        [0.5, 0.0, -1.0],
        [-0.5, 0.0, -1.0],
    ];
    let mut failures = Vec::new();
    let mut rays = 0;
    for i2 in -2..=(2 * n as i32 + 2) {
        for j2 in -2..=(2 * n as i32 + 2) {
            // Vertices (both even), edge midpoints and quad centres, and a ring outside.
            let (x, y) = (f64::from(i2) / 2.0, f64::from(j2) / 2.0);
            let inside = (0.0..=n as f64).contains(&x) && (0.0..=n as f64).contains(&y);
            // The mesh's own outer edge is the one place where hit or miss is within
            // rounding: the ray is moved along itself (recentred) before the test.
            if inside && (x == 0.0 || y == 0.0 || x == n as f64 || y == n as f64) {
                continue;
            }
            let target = [x, y, 0.5 * y];
            for d in dirs {
                let o = [0, 1, 2].map(|k| target[k] - 8.0 * d[k]);
                let want = if inside { 8.0 } else { f64::INFINITY };
                let what = format!("target {target:?} direction {d:?}");
                check(
                    &format!("f64 {what}"),
                    first_hit(&m64, o, d),
                    want,
                    1e-12,
                    &mut failures,
                );
                check(
                    &format!("f32 {what}"),
                    first_hit(&m32, o, d),
                    want,
                    1e-5,
                    &mut failures,
                );
                rays += 1;
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {rays} rays wrong:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

/// Rays along a box face plane that run exactly through a row of vertices of a flat grid
/// at a shallow angle, and grazing rays (a thousandth of a radian) onto a sloped grid, with
/// and without zero components.
#[test]
fn grazing_rays() {
    let n = 24;
    let flat = grid(n, |_, _| 0.0);
    let sloped = grid(n, |_, y| 0.5 * y);
    let mut failures = Vec::new();
    // Flat grid, ray in the plane x = 7 (a column of vertices), descending 1 in 1000.
    let (f32_flat, f64_flat) = (
        MeshPrim::<f32>::new(&flat).unwrap(),
        MeshPrim::<f64>::new(&flat).unwrap(),
    );
    for x in [0.0, 7.0, 7.5, n as f64] {
        let d = unit([0.0, 1.0, -1e-3]);
        let o = [x, -1.0, 0.012];
        // Reaches z = 0 at y = 11.
        let want = 12.0 / d[1];
        check(
            &format!("f64 flat x={x}"),
            first_hit(&f64_flat, o, d),
            want,
            1e-12,
            &mut failures,
        );
        check(
            &format!("f32 flat x={x}"),
            first_hit(&f32_flat, o, d),
            want,
            1e-3,
            &mut failures,
        );
    }
    let (f32_sloped, f64_sloped) = (
        MeshPrim::<f32>::new(&sloped).unwrap(),
        MeshPrim::<f64>::new(&sloped).unwrap(),
    );
    for dx in [0.0, 1e-3, -2e-3] {
        // 0.01 above the plane at y = 0, climbing 1e-3 less steeply: meets it at y = 10.
        let d = unit([dx, 1.0, 0.5 - 1e-3]);
        let o = [5.25, 0.0, 0.01];
        let want = 10.0 / d[1];
        check(
            &format!("f64 sloped dx={dx}"),
            first_hit(&f64_sloped, o, d),
            want,
            1e-9,
            &mut failures,
        );
        check(
            &format!("f32 sloped dx={dx}"),
            first_hit(&f32_sloped, o, d),
            want,
            1e-3,
            &mut failures,
        );
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The nearest crossing of any triangle by brute force in f64 (Moller-Trumbore), and
/// whether the ray passes within `margin` (in barycentric terms) of an edge of a triangle
/// it might cross there, where f32 and the watertight test may legitimately differ.
fn brute_force(tris: &[Tri], o: [f64; 3], d: [f64; 3], margin: f64) -> (f64, bool) {
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let (mut best, mut near_edge) = (f64::INFINITY, false);
    for [v0, v1, v2] in tris {
        let (e1, e2) = (sub(*v1, *v0), sub(*v2, *v0));
        let p = cross(d, e2);
        let det = dot(p, e1);
        if det == 0.0 {
            continue;
        }
        let s = sub(o, *v0);
        let u = dot(s, p) / det;
        let q = cross(s, e1);
        let v = dot(d, q) / det;
        let t = dot(q, e2) / det;
        let w = 1.0 - u - v;
        if t <= 0.0 || u.min(v).min(w) < -margin {
            continue;
        }
        if u.min(v).min(w) < margin {
            near_edge = true;
        }
        best = best.min(t);
    }
    (best, near_edge)
}

/// Random rays, a third of them with a zero direction component, onto a bumpy grid: the
/// BVH traversal finds what a loop over every triangle finds.
#[test]
fn random_rays_match_brute_force() {
    let n = 16;
    let mut rng = Rng(6);
    let heights: Vec<f64> = (0..(n + 1) * (n + 1))
        .map(|_| rng.range(0.0, 3.0))
        .collect();
    let tris = grid(n, |x, y| heights[x as usize * (n + 1) + y as usize]);
    let (m32, m64) = (
        MeshPrim::<f32>::new(&tris).unwrap(),
        MeshPrim::<f64>::new(&tris).unwrap(),
    );
    let mut failures = Vec::new();
    let mut skipped = 0;
    for k in 0..4000 {
        let target = [
            rng.range(-1.0, 17.0),
            rng.range(-1.0, 17.0),
            rng.range(0.0, 3.0),
        ];
        let mut d = rng.direction();
        match k % 3 {
            0 => d[k % 2] = 0.0,
            1 => {
                d[0] = 0.0;
                d[1] = 0.0;
            }
            _ => {}
        }
        let d = unit(d);
        let o = [0, 1, 2].map(|c| target[c] - 30.0 * d[c]);
        let (want, near_edge) = brute_force(&tris, o, d, 1e-6);
        if near_edge {
            skipped += 1;
            continue;
        }
        let what = format!("ray {k} origin {o:?} direction {d:?}");
        check(
            &format!("f64 {what}"),
            first_hit(&m64, o, d),
            want,
            1e-9,
            &mut failures,
        );
        check(
            &format!("f32 {what}"),
            first_hit(&m32, o, d),
            want,
            1e-4,
            &mut failures,
        );
    }
    assert!(skipped < 400, "{skipped} rays too close to edges");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The 12 outward-wound triangles of the cube of half side `h` about `c`.
fn cube(c: [f64; 3], h: f64) -> Vec<Tri> {
    let p = |i: usize| [0, 1, 2].map(|k| c[k] + if i >> k & 1 == 1 { h } else { -h });
    // Each face as a quad counter-clockwise from outside (corner bits: x = 1, y = 2, z = 4).
    let faces = [
        [0, 4, 6, 2],
        [1, 3, 7, 5],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 2, 3, 1],
        [4, 5, 7, 6],
    ];
    faces
        .iter()
        .flat_map(|&[a, b, c, d]| [[p(a), p(b), p(c)], [p(a), p(c), p(d)]])
        .collect()
}

/// `contains` on points whose parity ray crosses many surfaces (a row of 40 cubes along
/// it: 80 crossings, more than one walk collects) and few, in f32 and f64.
#[test]
fn contains_with_many_crossings() {
    let dir = unit([0.577_215_664_9, 0.618_033_988_7, 0.533_751_168_8]);
    // Along `dir` each cube spans 1.62 either side of its centre: spaced 4 apart, they
    // leave gaps.
    let centre = |k: usize| dir.map(|c| 4.0 * k as f64 * c);
    let tris: Vec<Tri> = (0..=40).flat_map(|k| cube(centre(k), 1.0)).collect();
    let (m32, m64) = (
        MeshPrim::<f32>::new(&tris).unwrap(),
        MeshPrim::<f64>::new(&tris).unwrap(),
    );
    for k in [0, 1, 20, 39, 40] {
        let inside = centre(k);
        // Halfway between cube k and cube k + 1, outside both.
        let between = [0, 1, 2].map(|c| inside[c] + 2.0 * dir[c]);
        for (x, want) in [(inside, true), (between, false)] {
            assert_eq!(m64.contains(V3::from_f64(x)), want, "f64 cube {k} {x:?}");
            assert_eq!(m32.contains(V3::from_f64(x)), want, "f32 cube {k} {x:?}");
        }
    }
}

/// Queries over several meshes, for [`interleaved_searches_answer_as_one_at_a_time`]:
/// random rays (some with zero direction components), rays from the surfaces' own points
/// with `tmin` there, and rays that miss every box.
fn mixed_queries<'a, T: Real>(
    meshes: &'a [(MeshPrim<T>, [f64; 3])],
    rng: &mut Rng,
) -> Vec<MeshQuery<'a, T>> {
    (0..500)
        .map(|k| {
            let (mesh, centre) = &meshes[k % meshes.len()];
            // Aimed at a point near the mesh's centre, some with a zero component.
            let o = [0, 1, 2].map(|c| centre[c] + rng.range(-12.0, 12.0));
            let target = [0, 1, 2].map(|c| centre[c] + rng.range(-4.0, 4.0));
            let mut d = [0, 1, 2].map(|c| target[c] - o[c]);
            if k % 5 == 0 {
                d[k % 3] = 0.0;
            }
            let d = unit(d);
            let (o, tmin) = match k % 7 {
                // Away from every mesh.
                0 => ([0, 1, 2].map(|c| centre[c] + 1.0e3), 0.0),
                // From a point the ray reaches, tmin there (a surface it may start on).
                1 => (o, rng.range(0.0, 20.0)),
                _ => (o, 0.0),
            };
            let (o, d) = if k % 7 == 0 {
                (o, [1.0, 0.0, 0.0])
            } else {
                (o, d)
            };
            MeshQuery {
                mesh,
                ray: Ray::from_f64(o, d),
                tmin: T::from_f64(tmin),
            }
        })
        .collect()
}

/// Checks that [`MeshPrim::first_crossings`] of `queries`, in windows of each length of
/// `windows`, on every SIMD path this CPU runs, answers every query bit for bit as
/// [`MeshPrim::first_crossing`] does; returns how many crossings it found (on one path).
fn answers_as_one_at_a_time<T: Real>(queries: &[MeshQuery<'_, T>], windows: &[usize]) -> usize {
    let mut scratch = CrossingScratch::default();
    let mut out = Vec::new();
    let mut hits = 0;
    let paths = SimdPath::available();
    for (&len, &path) in windows
        .iter()
        .flat_map(|w| paths.iter().map(move |p| (w, p)))
    {
        for batch in queries.chunks(len) {
            MeshPrim::first_crossings_on(path, batch, &mut scratch, &mut out);
            assert_eq!(out.len(), batch.len());
            for (q, got) in batch.iter().zip(&out) {
                let want = q.mesh.first_crossing(&q.ray, q.tmin);
                let bits = |s: &hytrace_csg::kernel::Step<T>| {
                    (
                        s.t.to_f64().to_bits(),
                        s.normal.to_f64().map(f64::to_bits),
                        s.inside_before,
                    )
                };
                assert_eq!(
                    bits(got),
                    bits(&want),
                    "{} query {q:?} in windows of {len} ({path})",
                    T::NAME
                );
                hits += (path == SimdPath::Portable && got.t.is_finite()) as usize;
            }
        }
    }
    hits
}

fn interleaved_case<T: Real>() {
    let mut rng = Rng(17);
    let heights: Vec<f64> = (0..17 * 17).map(|_| rng.range(0.0, 3.0)).collect();
    let hills = grid(16, |x, y| heights[x as usize * 17 + y as usize]);
    let shifted = |tris: &[Tri], by: [f64; 3]| -> Vec<Tri> {
        tris.iter()
            .map(|t| t.map(|v| [0, 1, 2].map(|c| v[c] + by[c])))
            .collect()
    };
    let far = [1.0e5, -2.0e5, 3.0e4];
    let meshes: Vec<(MeshPrim<T>, [f64; 3])> = [
        (shifted(&hills, [-8.0, -8.0, 0.0]), [0.0, 0.0, 1.5]),
        (
            shifted(&hills, far),
            [far[0] + 8.0, far[1] + 8.0, far[2] + 1.5],
        ),
        (cube([1.0, 2.0, 3.0], 4.0), [1.0, 2.0, 3.0]),
    ]
    .into_iter()
    .map(|(tris, centre)| (MeshPrim::<T>::new(&tris).unwrap(), centre))
    .collect();
    let queries = mixed_queries(&meshes, &mut rng);
    // Windows of every size up to past the interleaving width, then all at once.
    let windows: Vec<usize> = (1..=INTERLEAVED + 3).chain([queries.len()]).collect();
    let hits = answers_as_one_at_a_time(&queries, &windows);
    assert!(
        hits > 2000,
        "only {hits} crossings among the {} {} queries",
        12 * queries.len(),
        T::NAME
    );
}

/// [`MeshPrim::first_crossings`], searches interleaved, answers every query bit for bit as
/// [`MeshPrim::first_crossing`] does, whatever the windows, meshes (one far from the
/// origin) and starting points.
#[test]
fn interleaved_searches_answer_as_one_at_a_time() {
    interleaved_case::<f32>();
    interleaved_case::<f64>();
}

/// Queries in runs of one mesh whose rays run close together, as a camera's rows and a
/// sweep give them: the searches take them as packets (8 at a time), and still answer as
/// [`MeshPrim::first_crossing`] does, bit for bit, in f32 and f64.
fn packet_case<T: Real>() {
    let mut rng = Rng(23);
    let heights: Vec<f64> = (0..33 * 33).map(|_| rng.range(0.0, 3.0)).collect();
    let hills = grid(32, |x, y| heights[x as usize * 33 + y as usize]);
    let far = [3.0e4, -2.0e4, 1.0e4];
    let meshes: Vec<(MeshPrim<T>, [f64; 3])> = [[0.0; 3], far]
        .into_iter()
        .map(|by| {
            let tris: Vec<Tri> = hills
                .iter()
                .map(|t| t.map(|v| [0, 1, 2].map(|c| v[c] + by[c])))
                .collect();
            (MeshPrim::<T>::new(&tris).unwrap(), by)
        })
        .collect();
    let mut queries = Vec::new();
    for (mesh, by) in &meshes {
        // A camera's rows, from far above one corner; some rows from the surface's height
        // on (`tmin`).
        let eye = [by[0] - 40.0, by[1] - 40.0, by[2] + 60.0];
        for row in 0..64 {
            for col in 0..64 {
                let d = [
                    0.6 + f64::from(col) / 512.0,
                    0.6 + f64::from(row) / 96.0,
                    -1.0,
                ];
                let tmin = if row % 4 == 3 { 70.0 } else { 0.0 };
                queries.push(MeshQuery {
                    mesh,
                    ray: Ray::from_f64(eye, unit(d)),
                    tmin: T::from_f64(tmin),
                });
            }
        }
        // A sweep straight down onto vertices and edges (two zero components), and one
        // starting past the field (every ray a miss).
        for z in [10.0, -10.0] {
            for k in 0..32 * 64 {
                let (x, y) = (f64::from(k % 64) / 64.0 + 8.0, f64::from(k / 64));
                queries.push(MeshQuery {
                    mesh,
                    ray: Ray::from_f64([by[0] + x, by[1] + y, by[2] + z], [0.0, 0.0, -1.0]),
                    tmin: T::ZERO,
                });
            }
        }
    }
    let hits = answers_as_one_at_a_time(&queries, &[5, 8, 13, 256]);
    assert!(hits > 20_000, "only {hits} {} crossings", T::NAME);
}

#[test]
fn packet_searches_answer_as_one_at_a_time() {
    packet_case::<f32>();
    packet_case::<f64>();
}
