//! Twin test of the WGSL CSG tree evaluators (shaders/csg/tree.wgsl) against
//! `hytrace_csg::PrimTree::<f32>`: first crossings of rays (random through the bounds,
//! axis-aligned with zero direction components, grazing faces, from inside, from 1e5 mm
//! away, and walked crossing by crossing) and signed distances and inside tests of points
//! (random, on faces that union members share, on the surface), over nested booleans,
//! complements, far transformed leaves, list nodes, coincident faces, thin shells and
//! polyhedra. With HYTRACE_REQUIRE_GPU=1 a missing adapter fails the test.
//!
//! Tolerances: the same hit or miss and inside state; `t` within 1e-6 (scale + |t|) (about
//! 8 f32 ulps of the larger term); unit normals within 1e-5 per component; signed
//! distances within 1e-6 (scale + |x|); the same inside answer. At least 99.9% of the
//! queries of every shape must agree.

use std::f64::consts::PI;

use bytemuck::{Pod, Zeroable};
mod common;
use common::{PcgDraws as Rng, Random};

use hytrace_csg::gpu_layout::tree::CsgArrays;
use hytrace_csg::{
    box3, cone, cylinder, halfspace, phi_cut, polyhedron, sphere, to_tree, torus, tube, zsphere,
    PrimTree, Ray, Shape, LIST_MIN_MEMBERS, V3,
};
use hytrace_foundry::TypeCode;
use hytrace_trace::gpu::oneshot::{run, Buffer};
use hytrace_trace::gpu::GpuContext;

/// The draws of this test beyond the shared ones.
trait BoxDraws: Random {
    /// A uniform point of the box `centre +- half`.
    fn in_box(&mut self, centre: [f64; 3], half: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|k| centre[k] + self.range(-half[k], half[k]))
    }
}

impl BoxDraws for Rng {}

/// One query of `kernels/tree_probe`: `o.w` holds the tree index's bits, `d.w` the ray's
/// tmin (mirrors `TreeQuery`).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Query {
    o: [f32; 4],
    d: [f32; 4],
}

/// A test shape, with planes `(axis, value)` of faces worth grazing and sampling (outer
/// faces and faces members share).
struct Case {
    name: &'static str,
    shape: Shape,
    faces: Vec<(usize, f64)>,
}

fn cases() -> Vec<Case> {
    let s = |r| sphere(r).unwrap();
    let b = |x, y, z| box3(x, y, z).unwrap();
    let tetra = [
        [1.0, 1.0, 1.0, 1.0],
        [-1.0, -1.0, 1.0, 1.0],
        [-1.0, 1.0, -1.0, 1.0],
        [1.0, -1.0, -1.0, 1.0],
    ];
    let octa: Vec<[f64; 4]> = (0..8)
        .map(|k| {
            let sx = if k & 1 == 0 { 1.0 } else { -1.0 };
            let sy = if k & 2 == 0 { 1.0 } else { -1.0 };
            let sz = if k & 4 == 0 { 1.0 } else { -1.0 };
            [sx, sy, sz, 1.2]
        })
        .collect();
    let union_all = |parts: Vec<Shape>| parts.into_iter().reduce(|a, b| a + b).unwrap();
    vec![
        Case {
            name: "nested booleans",
            shape: ((b(4.0, 4.0, 4.0) - s(2.3)) + cylinder(0.8, -3.0, 3.0).unwrap()) * s(3.2)
                - b(1.0, 1.0, 8.0).translate(1.5, 1.5, 0.0),
            faces: vec![(0, 2.0), (1, -2.0), (0, 1.0), (1, 1.0), (2, 2.0)],
        },
        Case {
            name: "complements",
            shape: b(6.0, 6.0, 6.0)
                * !(s(2.0)
                    + cylinder(1.0, -4.0, 4.0)
                        .unwrap()
                        .rotate([1.0, 0.0, 0.0], PI / 2.0))
                + (!b(1.0, 1.0, 1.0) * s(0.9)).translate(4.0, 0.0, 0.0),
            faces: vec![(0, 3.0), (2, -3.0), (0, 3.5)],
        },
        Case {
            name: "far rotated leaves",
            shape: (b(2.0, 3.0, 4.0).rotate([0.6, 0.8, 0.0], 0.7)
                + s(1.5).translate(1.0, 1.0, 1.0)
                - cylinder(0.5, -5.0, 5.0)
                    .unwrap()
                    .rotate([0.0, 1.0, 0.0], 0.3))
            .translate(1.0e5, -1.0e5, 5.0e4),
            faces: vec![(0, 1.0e5), (1, -1.0e5 + 1.0), (2, 5.0e4 + 2.5)],
        },
        Case {
            name: "list of touching spheres",
            shape: union_all(
                (0..8)
                    .map(|k| s(1.0).translate(2.0 * k as f64, 0.0, 0.0))
                    .collect(),
            ),
            faces: vec![(0, 1.0), (0, 3.0), (1, 0.0), (2, 0.0)],
        },
        Case {
            name: "list of disjoint spheres",
            shape: union_all(
                (0..6)
                    .map(|k| s(1.0).translate(3.0 * k as f64, (k % 2) as f64, 0.0))
                    .collect(),
            ),
            faces: vec![(1, 0.0), (2, 0.0)],
        },
        Case {
            name: "list of boxes sharing faces",
            shape: union_all(
                (0..8)
                    .map(|k| {
                        let c = |bit: usize| if k & bit == 0 { -0.5 } else { 0.5 };
                        b(1.0, 1.0, 1.0).translate(c(1), c(2), c(4))
                    })
                    .collect(),
            ),
            faces: vec![(0, 0.0), (1, 0.0), (2, 0.0), (0, 1.0), (1, -1.0), (2, 1.0)],
        },
        Case {
            name: "two boxes sharing a face",
            shape: b(2.0, 2.0, 2.0) + b(2.0, 2.0, 2.0).translate(2.0, 0.0, 0.0),
            faces: vec![(0, 1.0), (1, 1.0), (2, -1.0), (0, 3.0)],
        },
        Case {
            name: "list intersection",
            shape: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
                .into_iter()
                .flat_map(|a| [a, a.map(|v: f64| -v)])
                .map(|a| s(3.0).translate(a[0], a[1], a[2]))
                .reduce(|a, b| a * b)
                .unwrap(),
            faces: vec![(0, 0.0), (1, 2.0)],
        },
        Case {
            name: "thin shell",
            shape: (s(10.0) - s(9.99)) * b(30.0, 30.0, 10.0) + tube(4.99, 5.0, -5.0, 5.0).unwrap(),
            faces: vec![(2, 5.0), (2, 0.0), (0, 0.0)],
        },
        Case {
            name: "polyhedra",
            shape: (polyhedron(&tetra).unwrap()
                + polyhedron(&octa).unwrap().translate(1.5, 0.0, 0.0))
                - b(0.5, 0.5, 4.0).translate(0.2, 0.0, 0.0),
            faces: vec![(0, 0.0), (0, 1.5), (2, 0.0)],
        },
        Case {
            name: "list of mixed transformed members",
            shape: union_all(vec![
                b(1.0, 2.0, 1.0).rotate([0.0, 0.0, 1.0], 0.4),
                cylinder(0.7, -1.0, 1.0).unwrap().translate(3.0, 0.0, 0.0),
                cone(1.0, -1.0, 0.2, 1.0).unwrap().translate(0.0, 3.0, 0.0),
                zsphere(1.0, -0.5, 0.7).unwrap().translate(3.0, 3.0, 0.0),
                polyhedron(&tetra).unwrap().translate(-3.0, 0.0, 0.0),
                b(1.0, 1.0, 1.0).translate(0.0, 0.0, 1.0),
                s(0.8).scale(1.0, 1.5, 0.7).translate(0.0, -3.0, 0.0),
            ]),
            faces: vec![(2, 1.0), (2, 0.5), (0, 3.0)],
        },
        Case {
            name: "cuts",
            shape: s(3.0) * phi_cut(0.3, 4.0).unwrap()
                - halfspace([0.0, 0.0, 1.0], 1.0)
                    .unwrap()
                    .translate(0.0, 0.0, 1.0),
            faces: vec![(2, 2.0), (1, 0.0)],
        },
        Case {
            name: "torus",
            shape: torus(0.5, 1.0, 3.0).unwrap() - b(8.0, 8.0, 0.5),
            faces: vec![(2, 0.25), (2, 0.0)],
        },
    ]
}

fn v3(a: [f64; 3]) -> V3<f32> {
    V3::from_f64(a)
}

fn f3(v: V3<f32>) -> [f32; 3] {
    [v.x, v.y, v.z]
}

/// The queries of one shape: rays (with the CPU's crossings as further tmins) and points.
fn queries(
    tree: &PrimTree<f32>,
    faces: &[(usize, f64)],
    index: u32,
    rng: &mut Rng,
) -> (Vec<Query>, Vec<Query>) {
    let [lo, hi] = *tree.bounds();
    let centre: [f64; 3] = std::array::from_fn(|k| 0.5 * (lo.get(k) as f64 + hi.get(k) as f64));
    let half: [f64; 3] = std::array::from_fn(|k| 0.5 * (hi.get(k) as f64 - lo.get(k) as f64));
    let scaled = |f: f64| half.map(|h| h * f);
    let tag = f32::from_bits(index);
    let mut rays: Vec<(V3<f32>, V3<f32>)> = Vec::new();
    // Random rays through the bounds, some starting inside.
    for _ in 0..150 {
        let o = rng.in_box(centre, scaled(2.0));
        let target = rng.in_box(centre, half);
        let d = std::array::from_fn(|k| target[k] - o[k]);
        rays.push((v3(o), v3(d).normalized()));
    }
    // Axis-aligned rays (two zero direction components).
    for k in 0..60 {
        let o = rng.in_box(centre, scaled(1.5));
        let mut d = [0.0; 3];
        d[k % 3] = if k % 2 == 0 { 1.0 } else { -1.0 };
        rays.push((v3(o), v3(d)));
    }
    // Rays in face planes (grazing), along axes and oblique within the plane.
    for &(axis, value) in faces {
        for j in 0..24 {
            let mut o = rng.in_box(centre, scaled(1.5));
            o[axis] = value;
            let mut d = rng.direction();
            d[axis] = 0.0;
            if j % 3 == 0 {
                d = [0.0; 3];
                d[(axis + 1 + j % 2) % 3] = 1.0;
            }
            rays.push((v3(o), v3(d).normalized()));
        }
    }
    // From inside (origins near the centre) and from far away.
    for _ in 0..40 {
        let o = rng.in_box(centre, scaled(0.3));
        rays.push((v3(o), v3(rng.direction())));
    }
    for _ in 0..20 {
        let u = rng.direction();
        let o = std::array::from_fn(|k| centre[k] + 1.0e5 * u[k]);
        let target = rng.in_box(centre, half);
        let d: [f64; 3] = std::array::from_fn(|k| target[k] - o[k]);
        rays.push((v3(o), v3(d).normalized()));
    }
    let mut ray_queries = Vec::new();
    let mut surface = Vec::new();
    for (o, d) in rays {
        let ray = Ray {
            origin: o,
            direction: d,
        };
        let mut tmin = 0.0f32;
        for k in 0..6 {
            ray_queries.push(Query {
                o: [o.x, o.y, o.z, tag],
                d: [d.x, d.y, d.z, tmin],
            });
            let step = tree.first_crossing(&ray, tmin);
            if !step.is_hit() {
                break;
            }
            if k == 0 {
                surface.push(o.at(d, step.t));
            }
            tmin = step.t;
        }
    }
    let mut points: Vec<V3<f32>> = (0..150)
        .map(|_| v3(rng.in_box(centre, scaled(1.2))))
        .collect();
    for &(axis, value) in faces {
        for _ in 0..30 {
            let mut p = rng.in_box(centre, half);
            p[axis] = value;
            points.push(v3(p));
        }
    }
    points.extend(surface.into_iter().take(100));
    let point_queries = points
        .into_iter()
        .map(|p| Query {
            o: [p.x, p.y, p.z, tag],
            d: [0.0; 4],
        })
        .collect();
    (ray_queries, point_queries)
}

fn vec4s(bytes: &[u8]) -> Vec<[f32; 4]> {
    bytemuck::pod_collect_to_vec(bytes)
}

fn unit_or_zero(n: [f32; 3]) -> [f64; 3] {
    let n = n.map(f64::from);
    let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if l > 0.0 {
        n.map(|c| c / l)
    } else {
        n
    }
}

#[test]
fn gpu_tree_evaluators_match_cpu_f32() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let cases = cases();
    let mut arrays = CsgArrays::default();
    let mut trees = Vec::new();
    let mut rng = Rng::new(0x7ee5);
    let (mut rays, mut points) = (Vec::new(), Vec::new());
    let mut ranges = Vec::new();
    for case in &cases {
        let tree = PrimTree::<f32>::from_shape(&case.shape).unwrap();
        let index = arrays.push(&tree);
        let (r, p) = queries(&tree, &case.faces, index, &mut rng);
        ranges.push((
            rays.len()..rays.len() + r.len(),
            points.len()..points.len() + p.len(),
        ));
        rays.extend(r);
        points.extend(p);
        trees.push(tree);
    }
    // The cases exercise list slots of each kind.
    let lists: Vec<u32> = cases
        .iter()
        .flat_map(|c| {
            to_tree(&c.shape)
                .unwrap()
                .nodes
                .iter()
                .map(|n| n.typecode)
                .collect::<Vec<_>>()
        })
        .filter(|&c| (TypeCode::ListContiguous as u32..=TypeCode::ListOverlap as u32).contains(&c))
        .collect();
    // (`to_tree` makes unions ListContiguous: ListDiscontiguous evaluates the same way.)
    for code in [TypeCode::ListContiguous, TypeCode::ListOverlap] {
        assert!(
            lists.contains(&(code as u32)),
            "no {code:?} among the cases (>= {LIST_MIN_MEMBERS} members)"
        );
    }

    let group1 = || {
        vec![
            Buffer::Input(bytemuck::cast_slice(&arrays.planes)),
            Buffer::Input(bytemuck::cast_slice(&arrays.nodes)),
            Buffer::Input(bytemuck::cast_slice(&arrays.frames)),
            Buffer::Input(bytemuck::cast_slice(&arrays.trees)),
        ]
    };
    let dispatch = |entry: &str, queries: &[Query]| {
        let out = run(
            &ctx,
            "kernels/tree_probe",
            entry,
            queries.len() as u32,
            &[
                vec![
                    Buffer::Input(bytemuck::cast_slice(queries)),
                    Buffer::Output((queries.len() * 32) as u64),
                ],
                group1(),
            ],
        )
        .unwrap();
        vec4s(&out[0])
    };
    let timed = |entry: &str, queries: &[Query]| {
        let start = std::time::Instant::now();
        let out = dispatch(entry, queries);
        println!(
            "{entry}: {} queries in {:.1?} (pipeline compilation included)",
            queries.len(),
            start.elapsed()
        );
        out
    };
    let gpu_rays = timed("crossings", &rays);
    let gpu_inside = timed("contains", &points);
    let gpu_sdf = timed("sdfs", &points);

    let mut failed = Vec::new();
    for (case, (tree, (ray_range, point_range))) in cases.iter().zip(trees.iter().zip(&ranges)) {
        let [lo, hi] = *tree.bounds();
        let scale = 0.5 * (hi - lo).max_abs() as f64;
        let mut bad = Vec::new();
        for i in ray_range.clone() {
            let q = &rays[i];
            let ray = Ray {
                origin: V3::new(q.o[0], q.o[1], q.o[2]),
                direction: V3::new(q.d[0], q.d[1], q.d[2]),
            };
            let cpu = tree.first_crossing(&ray, q.d[3]);
            let (g, flags) = (gpu_rays[2 * i], gpu_rays[2 * i + 1]);
            let gpu_hit = g[3] < 1.0e38;
            let gpu_inside = flags[0] != 0.0;
            let mut ok = gpu_hit == cpu.is_hit() && gpu_inside == cpu.inside_before;
            if ok && gpu_hit {
                let (tg, tc) = (g[3] as f64, cpu.t as f64);
                let (ng, nc) = (
                    unit_or_zero([g[0], g[1], g[2]]),
                    unit_or_zero(f3(cpu.normal)),
                );
                ok = (tg - tc).abs() <= 1e-6 * (scale + tc.abs())
                    && (0..3).all(|k| (ng[k] - nc[k]).abs() <= 1e-5);
            }
            if !ok {
                bad.push(format!(
                    "ray o {:?} d {:?} tmin {}: gpu t {} n {:?} inside {gpu_inside}; cpu t {} n {:?} inside {}",
                    &q.o[..3], &q.d[..3], q.d[3], g[3], &g[..3], cpu.t, f3(cpu.normal), cpu.inside_before
                ));
            }
        }
        for i in point_range.clone() {
            let q = &points[i];
            let x = V3::new(q.o[0], q.o[1], q.o[2]);
            let (sdf, inside) = (tree.sdf(x), tree.contains(x));
            let (g_sdf, g_inside) = (gpu_sdf[2 * i][0], gpu_inside[2 * i][0] != 0.0);
            let ok = g_inside == inside
                && (g_sdf as f64 - sdf as f64).abs() <= 1e-6 * (scale + x.max_abs() as f64);
            if !ok {
                bad.push(format!(
                    "point {:?}: gpu sdf {g_sdf} inside {g_inside}; cpu sdf {sdf} inside {inside}",
                    &q.o[..3]
                ));
            }
        }
        let total = ray_range.len() + point_range.len();
        let rate = 1.0 - bad.len() as f64 / total as f64;
        println!(
            "{:<36} height {:>2}: {:>5} ray queries, {:>4} points, {:>3} disagreements ({:.3}% agree)",
            case.name,
            tree.height(),
            ray_range.len(),
            point_range.len(),
            bad.len(),
            100.0 * rate
        );
        for b in bad.iter().take(20) {
            println!("    {b}");
        }
        if rate < 0.999 {
            failed.push(case.name);
        }
    }
    assert!(failed.is_empty(), "agreement below 99.9% for {failed:?}");
}
