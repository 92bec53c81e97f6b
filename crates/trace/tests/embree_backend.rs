//! The Embree backend (`--features embree`): the FFI's struct layouts match Embree 3.13's
//! headers, Embree and the CPU tracer agree ray by ray on CSG, mesh and hierarchical
//! (GDML) scenes, and `hytrace scan --backend embree` writes what the CPU backend writes.

/// Without the feature, asking for Embree is a clear error.
#[cfg(not(feature = "embree"))]
#[test]
fn embree_backend_needs_the_feature() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("hits.npy");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_hytrace"))
        .args([
            "scan", "default", "--sweep", "axis", "--count", "4", "--out",
        ])
        .arg(&out)
        .args(["--backend", "embree"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("built without Embree") && err.contains("--features embree"),
        "{err}"
    );
    assert!(!out.exists());
}

#[cfg(feature = "embree")]
mod with_embree {
    use std::mem::{align_of, offset_of, size_of};
    use std::path::{Path, PathBuf};
    use std::process::{Command, Output};

    use hytrace_csg::{Ray, V3};
    use hytrace_foundry::gdml::GdmlOptions;
    use hytrace_foundry::npy::read_array;
    use hytrace_foundry::Foundry;
    use hytrace_trace::cpu::{CpuScene, Hit};
    use hytrace_trace::embree::{ffi, EmbreeScene};
    use hytrace_trace::scan::RayRow;
    use hytrace_trace::scene::{default_scene, load_scene, obj_to_foundry};
    use hytrace_trace::sweep::{generate, scene_bounds, Sweep};

    /// Sizes, alignments and field offsets as `gcc` reports them for Embree 3.13.5's headers
    /// (`sizeof`, `_Alignof`, `offsetof` on x86-64 Linux).
    #[test]
    fn ffi_layouts_match_the_headers() {
        assert_eq!(
            (size_of::<ffi::RTCRay>(), align_of::<ffi::RTCRay>()),
            (48, 16)
        );
        assert_eq!(offset_of!(ffi::RTCRay, tnear), 12);
        assert_eq!(offset_of!(ffi::RTCRay, dir_x), 16);
        assert_eq!(offset_of!(ffi::RTCRay, time), 28);
        assert_eq!(offset_of!(ffi::RTCRay, tfar), 32);
        assert_eq!(offset_of!(ffi::RTCRay, mask), 36);
        assert_eq!(offset_of!(ffi::RTCRay, id), 40);
        assert_eq!(offset_of!(ffi::RTCRay, flags), 44);

        assert_eq!(
            (size_of::<ffi::RTCHit>(), align_of::<ffi::RTCHit>()),
            (32, 16)
        );
        assert_eq!(offset_of!(ffi::RTCHit, u), 12);
        assert_eq!(offset_of!(ffi::RTCHit, v), 16);
        assert_eq!(offset_of!(ffi::RTCHit, prim_id), 20);
        assert_eq!(offset_of!(ffi::RTCHit, geom_id), 24);
        assert_eq!(offset_of!(ffi::RTCHit, inst_id), 28);

        assert_eq!(
            (size_of::<ffi::RTCRayHit>(), align_of::<ffi::RTCRayHit>()),
            (80, 16)
        );
        assert_eq!(offset_of!(ffi::RTCRayHit, hit), 48);
        // With N = 1 the callbacks' structure of arrays is RTCRayHit word for word: ray
        // fields at words 0..12 (tnear 3, tfar 8), hit fields from word 12.
        assert_eq!(offset_of!(ffi::RTCRayHit, hit) / 4, 12);

        assert_eq!(
            (
                size_of::<ffi::RTCIntersectContext>(),
                align_of::<ffi::RTCIntersectContext>()
            ),
            (24, 8)
        );
        assert_eq!(offset_of!(ffi::RTCIntersectContext, filter), 8);
        assert_eq!(offset_of!(ffi::RTCIntersectContext, inst_id), 16);

        assert_eq!(
            (size_of::<ffi::RTCBounds>(), align_of::<ffi::RTCBounds>()),
            (32, 16)
        );
        assert_eq!(offset_of!(ffi::RTCBounds, upper_x), 16);

        assert_eq!(
            (
                size_of::<ffi::RTCBoundsFunctionArguments>(),
                align_of::<ffi::RTCBoundsFunctionArguments>()
            ),
            (24, 8)
        );
        assert_eq!(offset_of!(ffi::RTCBoundsFunctionArguments, prim_id), 8);
        assert_eq!(offset_of!(ffi::RTCBoundsFunctionArguments, time_step), 12);
        assert_eq!(offset_of!(ffi::RTCBoundsFunctionArguments, bounds_o), 16);

        assert_eq!(
            (
                size_of::<ffi::RTCIntersectFunctionNArguments>(),
                align_of::<ffi::RTCIntersectFunctionNArguments>()
            ),
            (48, 8)
        );
        assert_eq!(
            offset_of!(ffi::RTCIntersectFunctionNArguments, geometry_user_ptr),
            8
        );
        assert_eq!(offset_of!(ffi::RTCIntersectFunctionNArguments, prim_id), 16);
        assert_eq!(offset_of!(ffi::RTCIntersectFunctionNArguments, context), 24);
        assert_eq!(offset_of!(ffi::RTCIntersectFunctionNArguments, rayhit), 32);
        assert_eq!(offset_of!(ffi::RTCIntersectFunctionNArguments, n), 40);
        assert_eq!(offset_of!(ffi::RTCIntersectFunctionNArguments, geom_id), 44);

        // Enum values read from rtcore_common.h, rtcore_geometry.h, rtcore_buffer.h and
        // rtcore_scene.h.
        assert_eq!(ffi::RTC_FORMAT_UINT3, 0x5003);
        assert_eq!(ffi::RTC_FORMAT_FLOAT3, 0x9003);
        assert_eq!(ffi::RTC_FORMAT_FLOAT3X4_ROW_MAJOR, 0x9134);
        assert_eq!(ffi::RTC_GEOMETRY_TYPE_TRIANGLE, 0);
        assert_eq!(ffi::RTC_GEOMETRY_TYPE_USER, 120);
        assert_eq!(ffi::RTC_GEOMETRY_TYPE_INSTANCE, 121);
        assert_eq!(ffi::RTC_BUFFER_TYPE_INDEX, 0);
        assert_eq!(ffi::RTC_BUFFER_TYPE_VERTEX, 1);
        assert_eq!(ffi::RTC_SCENE_FLAG_ROBUST, 4);
        assert_eq!(ffi::RTC_INVALID_GEOMETRY_ID, 0xffff_ffff);
    }

    /// A deterministic generator (SplitMix64).
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^ (z >> 31)
        }

        /// Uniform in `[0, 1)`.
        fn unit(&mut self) -> f64 {
            (self.next() >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// Sweeps (`axis`, `rect`, `circle`) around the scene plus `random` rays from points in
    /// its (enlarged) bounds, a quarter of them with one or two direction components zero
    /// and a fifth on a finite segment `(tmin, tmax)`.
    fn rays_for(f: &Foundry, count: usize, random: usize) -> Vec<RayRow> {
        let b = scene_bounds(f).expect("scene has solids");
        let mut rays: Vec<RayRow> = [Sweep::Axis, Sweep::Rect, Sweep::Circle]
            .into_iter()
            .flat_map(|s| generate(s, &b, count))
            .collect();
        let mut rng = Rng(0x5eed_0000 + f.inst.len() as u64);
        for i in 0..random {
            let origin: [f64; 3] = std::array::from_fn(|k| {
                let (lo, hi) = (b[k], b[k + 3]);
                lo + (hi - lo) * (1.2 * rng.unit() - 0.1)
            });
            let mut d: [f64; 3] = std::array::from_fn(|_| 2.0 * rng.unit() - 1.0);
            match i % 8 {
                0 => d[(i / 8) % 3] = 0.0,
                1 => {
                    d[(i / 8) % 3] = 0.0;
                    d[(i / 8 + 1) % 3] = 0.0;
                }
                _ => {}
            }
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            if len < 1e-3 {
                continue;
            }
            // A fifth of them on a finite segment.
            let (tmin, tmax) = if i % 5 == 2 {
                let size = (0..3).fold(0.0f64, |a, k| a.max(b[k + 3] - b[k]));
                let tmin = 0.3 * size * rng.unit();
                (tmin, tmin + size * rng.unit())
            } else {
                (0.0, f64::INFINITY)
            };
            rays.push(RayRow {
                origin,
                direction: d.map(|v| v / len),
                tmin,
                tmax,
            });
        }
        rays
    }

    /// How the two backends compare on a set of rays.
    #[derive(Debug, Default)]
    struct Agreement {
        rays: usize,
        hits: usize,
        agree: usize,
        /// Same `t` (within tolerance) on different instances: ties broken differently.
        ties: usize,
        /// Agreeing hits on the same instance whose normals differ.
        normals: usize,
    }

    impl Agreement {
        fn percent(&self) -> f64 {
            100.0 * self.agree as f64 / self.rays.max(1) as f64
        }
    }

    /// Traces `rays` with both backends in f32 and counts agreement: the same hit or miss, and
    /// `t` within `max(1e-4, 4e-7 * scale)` where `scale` is the size of the coordinates
    /// involved (scene extent, origin and distance). Prints the disagreements.
    fn compare(name: &str, f: &Foundry, rays: &[RayRow]) -> Agreement {
        let cpu = CpuScene::<f32>::new(f).unwrap();
        let embree = EmbreeScene::new(f, &cpu).unwrap();
        let b = scene_bounds(f).unwrap();
        let extent = b.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let mut a = Agreement {
            rays: rays.len(),
            ..Default::default()
        };
        let mut shown = 0;
        for (i, r) in rays.iter().enumerate() {
            let ray = Ray {
                origin: V3::from_f64(r.origin),
                direction: V3::from_f64(r.direction),
            };
            let tmax = if r.tmax.is_finite() {
                r.tmax as f32
            } else {
                f32::INFINITY
            };
            let want = cpu.trace(&ray, r.tmin as f32, tmax);
            let got = embree.trace(&ray, r.tmin as f32, tmax).unwrap();
            a.hits += usize::from(want.is_some());
            let ok = match (want, got) {
                (None, None) => true,
                (Some(w), Some(g)) => {
                    let o = r.origin.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                    let scale = extent.max(o + f64::from(w.t.abs()));
                    let close = f64::from((w.t - g.t).abs()) <= (4e-7 * scale).max(1e-4);
                    if close && w.instance != g.instance {
                        a.ties += 1;
                    } else if close && w.normal.dot(g.normal) < 0.999 {
                        a.normals += 1;
                    }
                    close
                }
                _ => false,
            };
            if ok {
                a.agree += 1;
            } else if shown < 10 {
                shown += 1;
                eprintln!("{name}: ray {i} {r:?}: cpu {want:?}, embree {got:?}");
            }
        }
        eprintln!(
            "{name}: {} rays, {} hits, {:.3}% agree ({} ties on different instances, {} normals differ)",
            a.rays,
            a.hits,
            a.percent(),
            a.ties,
            a.normals
        );
        a
    }

    /// Requires at least 99.9% agreement, normals agreeing on 99.9% of the hits, and some hits.
    fn check(name: &str, f: &Foundry, rays: &[RayRow]) {
        let a = compare(name, f, rays);
        assert!(a.hits > a.rays / 10, "{name}: too few hits: {a:?}");
        assert!(a.percent() >= 99.9, "{name}: {a:?}");
        assert!(a.normals * 1000 <= a.hits, "{name}: {a:?}");
    }

    fn repo(path: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../..")
            .join(path)
    }

    #[test]
    fn backends_agree_on_the_default_scene() {
        let f = default_scene().unwrap();
        check("default", &f, &rays_for(&f, 100, 20_000));
    }

    #[test]
    fn backends_agree_on_the_csg_showcase() {
        let path = repo("scenes/csg-showcase.toml");
        let f = load_scene(Some(&path), &GdmlOptions::default()).unwrap();
        check("csg-showcase", &f, &rays_for(&f, 100, 20_000));
    }

    /// CSG solids, a mesh read from a file and a medium (which both backends go through).
    #[test]
    fn backends_agree_on_the_mixed_scene() {
        let path = repo("scenes/mixed.toml");
        let f = load_scene(Some(&path), &GdmlOptions::default()).unwrap();
        check("mixed", &f, &rays_for(&f, 100, 20_000));
    }

    /// OBJ text: an icosphere of radius 50 (three subdivisions), a 40 x 40 heightfield beside
    /// it, and a cube 10^5 mm out (far from the origin). Rays along a shared edge may take
    /// either triangle's normal: the sphere is turned and the grid jittered off the sweeps.
    fn mesh_obj() -> String {
        let mut out = String::new();
        let mut base = 1;
        let mut object =
            |name: &str, verts: &[[f64; 3]], faces: &[[usize; 3]], out: &mut String| {
                out.push_str(&format!("o {name}\n"));
                for v in verts {
                    out.push_str(&format!("v {} {} {}\n", v[0], v[1], v[2]));
                }
                for t in faces {
                    out.push_str(&format!(
                        "f {} {} {}\n",
                        t[0] + base,
                        t[1] + base,
                        t[2] + base
                    ));
                }
                base += verts.len();
            };
        let (verts, faces) = hytrace_csg::tessellate::icosphere(3);
        // Turned off the axes, so the axis-aligned sweeps do not run along its edges
        // (where either triangle's normal is right).
        let (c, s) = (0.3f64.cos(), 0.3f64.sin());
        let sphere: Vec<[f64; 3]> = verts
            .iter()
            .map(|v| {
                [
                    c * v[0] - s * v[1],
                    s * c * v[0] + c * c * v[1] - s * v[2],
                    s * s * v[0] + s * c * v[1] + c * v[2],
                ]
                .map(|x| 50.0 * x)
            })
            .collect();
        object("sphere", &sphere, &faces, &mut out);
        let n = 40;
        let mut grid = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                // Jittered, so no sweep runs along a row of edges.
                let (i, j) = (i as f64, j as f64);
                let (x, y) = (
                    5.0 * i + (1.7 * i).sin() + 80.0,
                    5.0 * j + (2.3 * j).sin() - 100.0,
                );
                grid.push([x, y, 10.0 * (x * 0.05).sin() * (y * 0.07).cos()]);
            }
        }
        let mut quads = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let v = j * (n + 1) + i;
                quads.push([v, v + 1, v + n + 2]);
                quads.push([v, v + n + 2, v + n + 1]);
            }
        }
        object("heightfield", &grid, &quads, &mut out);
        let c = |x: f64, y: f64, z: f64| [1e5 + 30.0 * x, 30.0 * y, 30.0 * z];
        let cube = [
            c(0., 0., 0.),
            c(1., 0., 0.),
            c(1., 1., 0.),
            c(0., 1., 0.),
            c(0., 0., 1.),
            c(1., 0., 1.),
            c(1., 1., 1.),
            c(0., 1., 1.),
        ];
        let cube_faces = [
            [0, 3, 2],
            [0, 2, 1],
            [4, 5, 6],
            [4, 6, 7],
            [0, 1, 5],
            [0, 5, 4],
            [1, 2, 6],
            [1, 6, 5],
            [2, 3, 7],
            [2, 7, 6],
            [3, 0, 4],
            [3, 4, 7],
        ];
        object("far_cube", &cube, &cube_faces, &mut out);
        out
    }

    #[test]
    fn backends_agree_on_a_mesh_scene() {
        let f = obj_to_foundry(mesh_obj().as_bytes()).unwrap();
        assert_eq!(f.inst.len(), 3);
        // Rays around the near pair, and rays at the far cube.
        let near = {
            let mut g = f.clone();
            g.inst.truncate(2);
            g.inst_tran.truncate(2);
            scene_bounds(&g).unwrap()
        };
        let mut rays: Vec<RayRow> = [Sweep::Axis, Sweep::Rect, Sweep::Circle]
            .into_iter()
            .flat_map(|s| generate(s, &near, 100))
            .collect();
        let far = [1e5, 0.0, 0.0, 1e5 + 30.0, 30.0, 30.0];
        rays.extend(generate(Sweep::Rect, &far, 60));
        rays.extend(generate(Sweep::Circle, &far, 2000));
        let mut rng = Rng(7);
        for _ in 0..20_000 {
            let origin: [f64; 3] =
                std::array::from_fn(|k| near[k] + (near[k + 3] - near[k]) * rng.unit());
            let d: [f64; 3] = std::array::from_fn(|_| 2.0 * rng.unit() - 1.0);
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            rays.push(RayRow {
                origin,
                direction: d.map(|v| v / len),
                tmin: 0.0,
                tmax: f64::INFINITY,
            });
        }
        check("mesh", &f, &rays);
    }

    /// The project's GDML file (24 placements, several levels, reflections, replicas,
    /// tessellated and twisted solids as meshes).
    #[test]
    fn backends_agree_on_a_hierarchical_gdml_scene() {
        let path = repo("tests/data/gdml/coverage.gdml");
        let f = load_scene(Some(&path), &GdmlOptions::default()).unwrap();
        assert!(f
            .inst_mother
            .iter()
            .any(|m| m.index != hytrace_foundry::UNSET));
        check("coverage.gdml", &f, &rays_for(&f, 100, 20_000));
    }

    /// Smaller shared public GDML files with hierarchies (when `../shared/gdml` is there, as on
    /// CI): nested envelopes and a tessellated solid.
    #[test]
    fn backends_agree_on_shared_gdml_files() {
        let dir = std::env::var_os("HYTRACE_GDML_DIR")
            .map(PathBuf::from)
            .unwrap_or_else(|| repo("../shared/gdml"));
        assert!(dir.is_dir(), "{}: shared GDML files missing", dir.display());
        for name in ["celeritas/multi-level.gdml", "geant4/tess.gdml"] {
            let f = load_scene(Some(&dir.join(name)), &GdmlOptions::default()).unwrap();
            check(name, &f, &rays_for(&f, 60, 10_000));
        }
    }

    fn hytrace(args: &[&str]) -> Output {
        Command::new(env!("CARGO_BIN_EXE_hytrace"))
            .args(args)
            .output()
            .unwrap()
    }

    /// Shape and values of an `.npy` file, as f64.
    fn read_f64(path: &Path) -> (Vec<u64>, Vec<f64>) {
        let a = read_array(path).unwrap();
        let v = match a.scalar {
            hytrace_foundry::layout::Scalar::F32 => {
                bytemuck::pod_collect_to_vec::<u8, f32>(&a.bytes)
                    .into_iter()
                    .map(f64::from)
                    .collect()
            }
            s => panic!("unexpected {s:?}"),
        };
        (a.shape, v)
    }

    #[test]
    fn scan_cli_with_embree_matches_cpu() {
        let dir = tempfile::tempdir().unwrap();
        let p = |n: &str| dir.path().join(n).display().to_string();
        let mut outputs = Vec::new();
        for backend in ["cpu", "embree"] {
            let (hits, ids) = (
                p(&format!("{backend}.npy")),
                p(&format!("{backend}-ids.npy")),
            );
            let o = hytrace(&[
                "scan",
                "default",
                "--sweep",
                "rect",
                "--count",
                "60",
                "--out",
                &hits,
                "--ids",
                &ids,
                "--backend",
                backend,
                "--stats",
            ]);
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            let stats: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
            assert_eq!(stats["backend"], backend);
            assert!(stats["build_s"].as_f64().unwrap() > 0.0);
            assert!(stats["trace_s"].as_f64().unwrap() > 0.0);
            outputs.push((
                read_f64(Path::new(&hits)),
                read_array(Path::new(&ids)).unwrap(),
            ));
        }
        let ((cpu_shape, cpu_hits), cpu_ids) = &outputs[0];
        let ((em_shape, em_hits), em_ids) = &outputs[1];
        assert_eq!(cpu_shape, &[3600, 4]);
        assert_eq!(em_shape, cpu_shape);
        assert_eq!(em_ids.shape, cpu_ids.shape);
        let t = |h: &[f64]| h.chunks(4).map(|r| r[3]).collect::<Vec<_>>();
        let (tc, te) = (t(cpu_hits), t(em_hits));
        let agree = tc
            .iter()
            .zip(&te)
            .filter(|(a, b)| (a.is_infinite() && b.is_infinite()) || (*a - *b).abs() <= 1e-3)
            .count();
        assert!(agree * 1000 >= 999 * tc.len(), "{agree} of {}", tc.len());
    }

    #[test]
    fn scan_cli_with_embree_rejects_f64_and_bad_rays() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("hits.npy");
        let o = hytrace(&[
            "scan",
            "default",
            "--sweep",
            "axis",
            "--count",
            "4",
            "--out",
            out.to_str().unwrap(),
            "--backend",
            "embree",
            "--precision",
            "f64",
        ]);
        assert!(!o.status.success());
        assert!(String::from_utf8_lossy(&o.stderr).contains("Embree backend traces in f32"));
        assert!(!out.exists());

        let rays = dir.path().join("rays.npy");
        let rows: [f32; 16] = [
            0.,
            0.,
            0.,
            0.,
            1.,
            0.,
            0.,
            f32::INFINITY,
            0.,
            0.,
            0.,
            0.,
            f32::NAN,
            0.,
            1.,
            f32::INFINITY,
        ];
        hytrace_foundry::npy::write_array(
            &rays,
            hytrace_foundry::layout::Scalar::F32,
            &[2, 8],
            bytemuck::cast_slice(&rows),
        )
        .unwrap();
        for backend in ["cpu", "embree"] {
            let o = hytrace(&[
                "scan",
                "default",
                "--rays",
                rays.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
                "--backend",
                backend,
            ]);
            let err = String::from_utf8_lossy(&o.stderr);
            assert!(!o.status.success(), "{backend}");
            assert!(
                err.contains("ray 1") && err.contains("not finite"),
                "{backend}: {err}"
            );
            assert!(!err.contains("panicked"), "{backend}: {err}");
            assert!(!out.exists());
        }
    }

    /// Traced results carry the crossing's identity like the CPU's (instance and prim).
    #[test]
    fn embree_hits_name_the_instance_and_prim() {
        let f = default_scene().unwrap();
        let cpu = CpuScene::<f32>::new(&f).unwrap();
        let embree = EmbreeScene::new(&f, &cpu).unwrap();
        let (mut same, mut total) = (0, 0);
        for r in rays_for(&f, 40, 2000) {
            let ray = Ray {
                origin: V3::from_f64(r.origin),
                direction: V3::from_f64(r.direction),
            };
            let want: Option<Hit<f32>> = cpu.trace(&ray, 0.0, f32::INFINITY);
            let got = embree.trace(&ray, 0.0, f32::INFINITY).unwrap();
            if let (Some(w), Some(g)) = (want, got) {
                total += 1;
                same += usize::from(w.instance == g.instance && w.prim == g.prim);
            }
        }
        assert!(total > 0 && same * 1000 >= 999 * total, "{same} of {total}");
    }
}
