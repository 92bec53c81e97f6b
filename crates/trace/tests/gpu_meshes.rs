//! The WGSL mesh prims (shaders/mesh/mesh.wgsl) agree with `MeshPrim::<f32>` ray by ray and
//! point by point: first crossings (t, normal, side) of random rays and of named hard cases
//! (rays through shared edges and vertices, axis-aligned rays along node-box faces, rays in
//! face planes, grazing rays, origins inside, a mesh 1e5 mm away, parity rays past the
//! crossing buffer) and inside tests of random points. With HYTRACE_REQUIRE_GPU=1 a missing
//! adapter fails the test.

mod common;
use common::{PcgDraws as Rng, Random};

use hytrace_csg::gpu_layout::mesh::MeshArrays;
use hytrace_csg::kernel::Step;
use hytrace_csg::{MeshPrim, Ray, V3};
use hytrace_trace::gpu::oneshot::{run, Buffer};
use hytrace_trace::gpu::GpuContext;

/// WGSL's stand-in for infinity (csg/spans.wgsl).
const GPU_INF: f32 = 1.0e38;

type Tri = [[f64; 3]; 3];

/// The 12 triangles of a box, counter-clockwise seen from outside.
fn box_triangles(lo: [f64; 3], hi: [f64; 3]) -> Vec<Tri> {
    let mut out = Vec::new();
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        for side in [lo[axis], hi[axis]] {
            let corner = |a: f64, b: f64| {
                let mut p = [0.0; 3];
                p[axis] = side;
                p[u] = a;
                p[v] = b;
                p
            };
            let q = [
                corner(lo[u], lo[v]),
                corner(hi[u], lo[v]),
                corner(hi[u], hi[v]),
                corner(lo[u], hi[v]),
            ];
            // (u, v, axis) is right-handed: this order faces +axis.
            let outward = side == hi[axis];
            for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
                out.push(if outward { t } else { [t[0], t[2], t[1]] });
            }
        }
    }
    out
}

fn icosphere(levels: usize, centre: [f64; 3], radius: f64) -> Vec<Tri> {
    let (verts, tris) = hytrace_csg::tessellate::icosphere(levels);
    tris.iter()
        .map(|t| t.map(|i| [0, 1, 2].map(|k| centre[k] + radius * verts[i][k])))
        .collect()
}

/// An open heightfield over `n` x `n` cells of 0.5 mm.
fn heightfield(n: usize) -> Vec<Tri> {
    let z = |i: usize, j: usize| {
        let (x, y) = (i as f64 * 0.5, j as f64 * 0.5);
        (0.3 * x).sin() * (0.2 * y).cos() * 2.0 + 0.01 * x
    };
    let p = |i: usize, j: usize| [i as f64 * 0.5 - 10.0, j as f64 * 0.5 - 10.0, z(i, j)];
    let mut out = Vec::new();
    for i in 0..n {
        for j in 0..n {
            out.push([p(i, j), p(i + 1, j), p(i + 1, j + 1)]);
            out.push([p(i, j), p(i + 1, j + 1), p(i, j + 1)]);
        }
    }
    out
}

/// A test mesh: its triangles (f64), the CPU prim, and its index on the GPU.
struct TestMesh {
    name: &'static str,
    triangles: Vec<Tri>,
    prim: MeshPrim<f32>,
    index: u32,
}

fn v3(p: [f64; 3]) -> V3<f32> {
    V3::from_f64(p)
}

/// A ray case: mesh, origin, direction, tmin, and what it is.
struct Case {
    mesh: usize,
    o: [f32; 3],
    d: [f32; 3],
    tmin: f32,
    what: &'static str,
}

fn ulps(a: f32, b: f32) -> u32 {
    let key = |x: f32| {
        let i = x.to_bits() as i32;
        if i < 0 {
            i32::MIN - i
        } else {
            i
        }
    };
    (key(a) as i64 - key(b) as i64)
        .unsigned_abs()
        .min(u32::MAX as u64) as u32
}

/// Agreement tolerance: same hit or miss and side; t within 4 ulps or 1e-6 relative;
/// normals within 1e-5 after normalization.
fn agrees(cpu: &Step<f32>, gpu_t: f32, gpu_n: [f32; 3], gpu_inside: bool) -> bool {
    let cpu_hit = cpu.t.is_finite();
    let gpu_hit = gpu_t < GPU_INF;
    if cpu_hit != gpu_hit || cpu.inside_before != gpu_inside {
        return false;
    }
    if !cpu_hit {
        return true;
    }
    let t_ok =
        ulps(cpu.t, gpu_t) <= 4 || (cpu.t - gpu_t).abs() <= 1e-6 * cpu.t.abs().max(gpu_t.abs());
    let unit = |n: [f32; 3]| {
        let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        n.map(|c| c / l)
    };
    let (a, b) = (
        unit([cpu.normal.x, cpu.normal.y, cpu.normal.z]),
        unit(gpu_n),
    );
    t_ok && (0..3).all(|k| (a[k] - b[k]).abs() <= 1e-5)
}

fn identical(cpu: &Step<f32>, gpu_t: f32, gpu_n: [f32; 3], gpu_inside: bool) -> bool {
    if !cpu.t.is_finite() {
        return gpu_t >= GPU_INF && gpu_inside == cpu.inside_before;
    }
    cpu.t.to_bits() == gpu_t.to_bits()
        && [cpu.normal.x, cpu.normal.y, cpu.normal.z]
            .iter()
            .zip(gpu_n)
            .all(|(a, b)| a.to_bits() == b.to_bits())
        && cpu.inside_before == gpu_inside
}

fn build_meshes() -> (Vec<TestMesh>, MeshArrays) {
    let mut touching = Vec::new();
    for i in 0..5 {
        for j in 0..5 {
            for k in 0..2 {
                let lo = [i as f64, j as f64, k as f64];
                touching.extend(box_triangles(lo, lo.map(|c| c + 1.0)));
            }
        }
    }
    // 17 plates: 34 crossings for a parity ray through them all, past the CPU's buffer of
    // 32, so `contains` falls back to nearest-crossing queries. No more: llvmpipe stops a
    // SIMD group's loops after 65535 iterations in all (LP_MAX_TGSI_LOOP_ITERATIONS, shared
    // by every loop of an invocation and by the 8 lanes run together), and the fallback walks
    // the BVH once per crossing.
    let mut plates = Vec::new();
    for i in 0..17 {
        let z = i as f64;
        plates.extend(box_triangles([-30.0, -30.0, z], [30.0, 30.0, z + 0.5]));
    }
    let far = [1.0e5, 3.0e4, -2.0e4];
    let sets: Vec<(&'static str, Vec<Tri>)> = vec![
        ("icosphere", icosphere(3, [1.0, 2.0, 3.0], 10.0)),
        ("cube", box_triangles([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0])),
        (
            "far cube",
            box_triangles(far, [far[0] + 10.0, far[1] + 10.0, far[2] + 10.0]),
        ),
        ("heightfield", heightfield(40)),
        ("touching boxes", touching),
        ("plates", plates),
        ("small sphere", icosphere(1, [0.0, 0.0, 0.0], 1.0)),
    ];
    let mut arrays = MeshArrays::default();
    let meshes = sets
        .into_iter()
        .map(|(name, triangles)| {
            let prim = MeshPrim::<f32>::new(&triangles).unwrap();
            let index = arrays.push(&prim).unwrap();
            TestMesh {
                name,
                triangles,
                prim,
                index,
            }
        })
        .collect();
    (meshes, arrays)
}

fn centre_radius(m: &TestMesh) -> ([f64; 3], f64) {
    let b = m.prim.bounds();
    let (lo, hi) = (b[0].to_f64(), b[1].to_f64());
    let c = [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k]));
    let r = 0.5 * (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
    (c, r)
}

fn f32s(p: [f64; 3]) -> [f32; 3] {
    p.map(|c| c as f32)
}

/// Random rays at each mesh (some with zero direction components, some from inside) and
/// the named hard cases.
fn ray_cases(meshes: &[TestMesh], arrays: &MeshArrays, rng: &mut Rng) -> Vec<Case> {
    let mut cases = Vec::new();
    for (mi, m) in meshes.iter().enumerate() {
        let (c, r) = centre_radius(m);
        let b = m.prim.bounds();
        let (lo, hi) = (b[0].to_f64(), b[1].to_f64());
        let inside_box = |rng: &mut Rng| [0, 1, 2].map(|k| rng.range(lo[k], hi[k]));
        for _ in 0..600 {
            let target = inside_box(rng);
            let inside = rng.uniform() < 0.25;
            let o = if inside {
                inside_box(rng)
            } else {
                [0, 1, 2].map(|k| c[k] + rng.range(-2.0, 2.0) * r)
            };
            let mut d = [0, 1, 2].map(|k| target[k] - o[k]);
            if rng.uniform() < 0.15 {
                d[rng.below(3)] = 0.0;
            }
            if d.iter().all(|&x| x == 0.0) {
                d = [0.0, 0.0, 1.0];
            }
            let tmin = if rng.uniform() < 0.7 {
                0.0
            } else {
                rng.range(-r, r) as f32
            };
            cases.push(Case {
                mesh: mi,
                o: f32s(o),
                d: f32s(d),
                tmin,
                what: if inside {
                    "random, inside box"
                } else {
                    "random"
                },
            });
        }
        // Axis-aligned rays along node-box faces and edges (zero direction components at
        // exactly the boxes' coordinates).
        let rec = arrays.meshes[m.index as usize];
        let nodes = &arrays.nodes[rec.node_offset as usize..][..rec.node_count as usize];
        for _ in 0..150 {
            let n = nodes[rng.below(nodes.len())];
            let axis = rng.below(3);
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let mut o = [0.0f32; 3];
            o[u] = if rng.uniform() < 0.5 {
                n.lo[u]
            } else {
                n.hi[u]
            };
            o[v] = if rng.uniform() < 0.5 {
                n.lo[v]
            } else {
                rng.range(n.lo[v] as f64, n.hi[v] as f64) as f32
            };
            let forward = rng.uniform() < 0.5;
            o[axis] = if forward { lo[axis] - r } else { hi[axis] + r } as f32;
            let mut d = [0.0f32; 3];
            d[axis] = if forward { 1.0 } else { -2.5 };
            cases.push(Case {
                mesh: mi,
                o,
                d,
                tmin: 0.0,
                what: "axis-aligned along a node box face",
            });
        }
        // Through vertices and edge midpoints: from afar, axis-aligned and not.
        for _ in 0..150 {
            let t = m.triangles[rng.below(m.triangles.len())];
            let k = rng.below(3);
            let p = if rng.uniform() < 0.5 {
                t[k]
            } else {
                [0, 1, 2].map(|a| 0.5 * (t[k][a] + t[(k + 1) % 3][a]))
            };
            let (o, d, what) = if rng.uniform() < 0.5 {
                let axis = rng.below(3);
                let mut o = p;
                o[axis] -= 2.0 * r;
                let mut d = [0.0; 3];
                d[axis] = 1.0;
                (o, d, "axis-aligned through a vertex or edge midpoint")
            } else {
                let o = [0, 1, 2].map(|a| c[a] + rng.range(-2.0, 2.0) * r);
                (
                    o,
                    [0, 1, 2].map(|a| p[a] - o[a]),
                    "through a vertex or edge midpoint",
                )
            };
            cases.push(Case {
                mesh: mi,
                o: f32s(o),
                d: f32s(d),
                tmin: 0.0,
                what,
            });
        }
        // Grazing: rays in the planes of the bounds' faces and just off them.
        for _ in 0..60 {
            let axis = rng.below(3);
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let mut o = inside_box(rng);
            let plane = if rng.uniform() < 0.5 {
                lo[axis]
            } else {
                hi[axis]
            };
            o[axis] = plane + [0.0, 1e-6, -1e-6][rng.below(3)] * r;
            o[u] = lo[u] - r;
            let mut d = [0.0; 3];
            d[u] = 1.0;
            d[v] = rng.range(-0.5, 0.5);
            cases.push(Case {
                mesh: mi,
                o: f32s(o),
                d: f32s(d),
                tmin: 0.0,
                what: "grazing a bounds face",
            });
        }
    }
    // Tangent rays of the sphere (facets lie inside the sphere: near misses and grazes).
    let (c, _) = centre_radius(&meshes[0]);
    for i in 0..100 {
        let s = 10.0 * (1.0 + (i as f64 - 50.0) * 2e-4);
        let a = i as f64 * 0.37;
        let side = [a.cos(), a.sin(), 0.0];
        let o = [
            c[0] + s * side[0] - 30.0 * side[1],
            c[1] + s * side[1] + 30.0 * side[0],
            c[2],
        ];
        cases.push(Case {
            mesh: 0,
            o: f32s(o),
            d: f32s([side[1], -side[0], 0.0]),
            tmin: 0.0,
            what: "tangent to the sphere",
        });
    }
    // The cube's edges, vertices and face diagonals exactly.
    let cube = 1;
    for (o, d, what) in [
        ([-3.0, 1.0, 1.0], [1.0, 0.0, 0.0], "along a cube edge"),
        ([-3.0, 1.0, 0.0], [1.0, 0.0, 0.0], "in a cube face plane"),
        ([-3.0, -3.0, -3.0], [1.0, 1.0, 1.0], "through cube vertices"),
        (
            [-3.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            "through face centres (diagonals)",
        ),
        ([-3.0, 0.5, 0.5], [1.0, 0.0, 0.0], "through a face diagonal"),
        (
            [-3.0, 0.5, -0.5],
            [1.0, 0.0, 0.0],
            "through a face diagonal",
        ),
        ([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], "from the centre"),
        ([1.0, 0.0, 0.0], [1.0, 0.0, 0.0], "from a face, outward"),
        ([1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], "from a face, inward"),
        ([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0], "from a vertex, inward"),
        ([0.0, 0.0, 5.0], [0.0, 0.0, -1.0], "down the z axis"),
        ([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], "zero direction"),
    ] {
        cases.push(Case {
            mesh: cube,
            o,
            d,
            tmin: 0.0,
            what,
        });
    }
    // The far cube from near the origin and from right beside it.
    for _ in 0..200 {
        let m = &meshes[2];
        let b = m.prim.bounds();
        let target = [0, 1, 2].map(|k| rng.range(b[0].get(k) as f64, b[1].get(k) as f64));
        let o = if rng.uniform() < 0.5 {
            [
                rng.range(-10.0, 10.0),
                rng.range(-10.0, 10.0),
                rng.range(-10.0, 10.0),
            ]
        } else {
            [0, 1, 2].map(|k| target[k] + rng.range(-20.0, 20.0))
        };
        cases.push(Case {
            mesh: 2,
            o: f32s(o),
            d: f32s([0, 1, 2].map(|k| target[k] - o[k])),
            tmin: 0.0,
            what: "far cube",
        });
    }
    // Vertical rays through the heightfield's grid points and cell diagonals.
    for _ in 0..200 {
        let (i, j) = (rng.below(41), rng.below(41));
        let half = if rng.uniform() < 0.5 { 0.0 } else { 0.25 };
        let o = [
            i as f64 * 0.5 - 10.0 + half,
            j as f64 * 0.5 - 10.0 + half,
            if rng.uniform() < 0.5 { 10.0 } else { -10.0 },
        ];
        cases.push(Case {
            mesh: 3,
            o: f32s(o),
            d: [0.0, 0.0, if o[2] > 0.0 { -1.0 } else { 1.0 }],
            tmin: 0.0,
            what: "vertical through heightfield grid",
        });
    }
    cases
}

/// Points to test: random in and around each mesh's bounds, vertices, face points, and
/// points under the plate stack (past the parity buffer).
fn point_cases(meshes: &[TestMesh], rng: &mut Rng) -> Vec<(usize, [f32; 3])> {
    let mut out = Vec::new();
    for (mi, m) in meshes.iter().enumerate() {
        let b = m.prim.bounds();
        let (lo, hi) = (b[0].to_f64(), b[1].to_f64());
        for _ in 0..800 {
            let p = [0, 1, 2].map(|k| {
                let w = hi[k] - lo[k];
                rng.range(lo[k] - 0.1 * w, hi[k] + 0.1 * w)
            });
            out.push((mi, f32s(p)));
        }
        for _ in 0..100 {
            let t = m.triangles[rng.below(m.triangles.len())];
            let (a, bb) = (rng.uniform(), rng.uniform());
            let p = if rng.uniform() < 0.3 {
                t[rng.below(3)]
            } else {
                let (a, bb) = if a + bb > 1.0 {
                    (1.0 - a, 1.0 - bb)
                } else {
                    (a, bb)
                };
                [0, 1, 2].map(|k| t[0][k] + a * (t[1][k] - t[0][k]) + bb * (t[2][k] - t[0][k]))
            };
            out.push((mi, f32s(p)));
        }
    }
    for _ in 0..100 {
        out.push((
            5,
            f32s([
                rng.range(-25.0, -15.0),
                rng.range(-25.0, -15.0),
                rng.range(-2.0, 1.0),
            ]),
        ));
    }
    out
}

#[test]
fn gpu_meshes_match_cpu() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let (meshes, arrays) = build_meshes();
    let mut rng = Rng::new(7);
    let cases = ray_cases(&meshes, &arrays, &mut rng);
    let points = point_cases(&meshes, &mut rng);

    let rays: Vec<[f32; 8]> = cases
        .iter()
        .map(|c| {
            let m = f32::from_bits(meshes[c.mesh].index);
            [c.o[0], c.o[1], c.o[2], c.tmin, c.d[0], c.d[1], c.d[2], m]
        })
        .collect();
    let pts: Vec<[f32; 4]> = points
        .iter()
        .map(|(m, p)| [p[0], p[1], p[2], f32::from_bits(meshes[*m].index)])
        .collect();
    let dummy = [0u8; 16];
    let mesh_group = || {
        vec![
            Buffer::Input(&dummy),
            Buffer::Input(&dummy),
            Buffer::Input(&dummy),
            Buffer::Input(&dummy),
            Buffer::Input(bytemuck::cast_slice(&arrays.nodes)),
            Buffer::Input(bytemuck::cast_slice(&arrays.triangles)),
            Buffer::Input(bytemuck::cast_slice(&arrays.meshes)),
        ]
    };
    let no_points = [[0.0f32; 4]];
    let steps = run(
        &ctx,
        "kernels/mesh_probe",
        "first_crossing",
        rays.len() as u32,
        &[
            vec![
                Buffer::Input(bytemuck::cast_slice(&rays)),
                Buffer::Output((rays.len() * 32) as u64),
                Buffer::Input(bytemuck::cast_slice(&no_points)),
                Buffer::Output(16),
            ],
            mesh_group(),
        ],
    )
    .unwrap();
    let steps: &[[f32; 4]] = bytemuck::cast_slice(&steps[0]);

    let mut disagree = 0;
    let mut exact = 0;
    let mut hits = 0;
    for (i, c) in cases.iter().enumerate() {
        let ray = Ray {
            origin: V3::new(c.o[0], c.o[1], c.o[2]),
            direction: V3::new(c.d[0], c.d[1], c.d[2]),
        };
        let cpu = meshes[c.mesh].prim.first_crossing(&ray, c.tmin);
        let (s, flags) = (steps[2 * i], steps[2 * i + 1]);
        let gpu_n = [s[1], s[2], s[3]];
        let gpu_inside = flags[0] == 1.0;
        hits += cpu.t.is_finite() as usize;
        if identical(&cpu, s[0], gpu_n, gpu_inside) {
            exact += 1;
        }
        if !agrees(&cpu, s[0], gpu_n, gpu_inside) {
            disagree += 1;
            if disagree <= 20 {
                println!(
                    "{} ({}): o {:?} d {:?} tmin {}: cpu t {} n {:?} inside {} | gpu t {} n {:?} inside {}",
                    meshes[c.mesh].name,
                    c.what,
                    c.o,
                    c.d,
                    c.tmin,
                    cpu.t,
                    cpu.normal,
                    cpu.inside_before,
                    s[0],
                    gpu_n,
                    gpu_inside
                );
            }
        }
    }
    println!(
        "first_crossing: {} rays ({hits} hits), {exact} bit-identical, {disagree} outside tolerance",
        cases.len()
    );

    let no_rays = [[0.0f32; 8]];
    let inside = run(
        &ctx,
        "kernels/mesh_probe",
        "contains",
        pts.len() as u32,
        &[
            vec![
                Buffer::Input(bytemuck::cast_slice(&no_rays)),
                Buffer::Output(32),
                Buffer::Input(bytemuck::cast_slice(&pts)),
                Buffer::Output((pts.len() * 4) as u64),
            ],
            mesh_group(),
        ],
    )
    .unwrap();
    let inside: &[u32] = bytemuck::cast_slice(&inside[1]);
    let alone = |p: [f32; 4]| -> u32 {
        let out = run(
            &ctx,
            "kernels/mesh_probe",
            "contains",
            1,
            &[
                vec![
                    Buffer::Input(bytemuck::cast_slice(&no_rays)),
                    Buffer::Output(32),
                    Buffer::Input(bytemuck::cast_slice(&[p])),
                    Buffer::Output(4),
                ],
                mesh_group(),
            ],
        )
        .unwrap();
        bytemuck::cast_slice::<u8, u32>(&out[1])[0]
    };
    let mut wrong = 0;
    let mut wrong_by_mesh = vec![0; meshes.len()];
    let mut inside_count = 0;
    for (i, (m, p)) in points.iter().enumerate() {
        let cpu = meshes[*m].prim.contains(v3(p.map(f64::from)));
        inside_count += cpu as usize;
        if cpu != (inside[i] == 1) {
            wrong += 1;
            wrong_by_mesh[*m] += 1;
            if wrong <= 20 {
                println!(
                    "contains {}: {:?}: cpu {cpu} gpu {} (alone: {})",
                    meshes[*m].name,
                    p,
                    inside[i],
                    alone(pts[i])
                );
            }
        }
    }
    println!(
        "contains: {} points ({inside_count} inside), {wrong} disagree",
        points.len()
    );
    for (m, w) in meshes.iter().zip(&wrong_by_mesh) {
        if *w > 0 {
            println!("contains: {} disagree on {}", w, m.name);
        }
    }

    // The parity fallback ran: points whose parity ray crosses more than 32 triangles.
    let parity = V3::from_f64([0.577_215_664_9, 0.618_033_988_7, 0.533_751_168_8]);
    let past_buffer = points
        .iter()
        .filter(|(m, p)| {
            let mut n = 0;
            let mut t = 0.0;
            let ray = Ray {
                origin: v3(p.map(f64::from)),
                direction: parity,
            };
            loop {
                let s = meshes[*m].prim.first_crossing(&ray, t);
                if !s.t.is_finite() {
                    break n > 32;
                }
                n += 1;
                t = s.t;
            }
        })
        .count();
    println!("contains: {past_buffer} points past the parity buffer");
    assert!(past_buffer >= 50);

    let ray_rate = 1.0 - disagree as f64 / cases.len() as f64;
    let point_rate = 1.0 - wrong as f64 / points.len() as f64;
    assert!(ray_rate >= 0.999, "first_crossing agreement {ray_rate}");
    assert!(point_rate >= 0.999, "contains agreement {point_rate}");
}

/// `mesh_exact_edge` (integer arithmetic) is the CPU's f64 recomputation of an edge function,
/// bit for bit, including near-total cancellation and exact zeros.
#[test]
fn gpu_exact_edge_matches_f64() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let mut rng = Rng::new(11);
    let mut inputs: Vec<[f32; 4]> = Vec::new();
    for i in 0..4000 {
        let scale = [1e-3, 1.0, 1e3, 1e5][i % 4];
        let mut v = [0; 4].map(|_| (rng.range(-1.0, 1.0) * scale) as f32);
        match i % 5 {
            // qy near py * qx / px: the two products cancel to their last bits.
            0 | 1 if v[0] != 0.0 => v[3] = (v[1] as f64 * v[2] as f64 / v[0] as f64) as f32,
            // Exactly equal products.
            2 => {
                v[2] = v[0];
                v[3] = v[1];
            }
            // Mixed magnitudes (exponents far apart).
            3 => v[1] *= 1e-20,
            _ => {}
        }
        if i % 97 == 0 {
            v[rng.below(4)] = 0.0;
        }
        inputs.push(v);
    }
    let no_rays = [[0.0f32; 8]];
    let dummy = [0u8; 16];
    let out = run(
        &ctx,
        "kernels/mesh_probe",
        "exact_edge",
        inputs.len() as u32,
        &[
            vec![
                Buffer::Input(bytemuck::cast_slice(&no_rays)),
                Buffer::Output(32),
                Buffer::Input(bytemuck::cast_slice(&inputs)),
                Buffer::Output((inputs.len() * 4) as u64),
            ],
            vec![
                Buffer::Input(&dummy),
                Buffer::Input(&dummy),
                Buffer::Input(&dummy),
                Buffer::Input(&dummy),
                Buffer::Input(&dummy),
                Buffer::Input(&dummy),
                Buffer::Input(&dummy),
            ],
        ],
    )
    .unwrap();
    let gpu: &[u32] = bytemuck::cast_slice(&out[1]);
    let mut wrong = 0;
    for (v, &g) in inputs.iter().zip(gpu) {
        let cpu = (v[0] as f64 * v[3] as f64 - v[1] as f64 * v[2] as f64) as f32;
        // Zeros compare by value (the sign of an exact zero is not modelled).
        if cpu.to_bits() != g && !(cpu == 0.0 && f32::from_bits(g) == 0.0) {
            wrong += 1;
            if wrong <= 20 {
                println!("edge {v:?}: cpu {cpu:e} gpu {:e}", f32::from_bits(g));
            }
        }
    }
    println!("exact edge: {} inputs, {wrong} differ", inputs.len());
    assert_eq!(wrong, 0);
}
