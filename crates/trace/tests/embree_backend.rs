//! The Embree backend (`--features embree`): the FFI's struct layouts match Embree 3.13's
//! headers, Embree and the CPU tracer agree ray by ray on CSG, mesh and hierarchical
//! (GDML) scenes, `hytrace scan --backend embree` writes what the CPU backend writes, and
//! its scans trace the rays they flag again in f64.

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
mod common;

#[cfg(feature = "embree")]
mod with_embree {
    use super::common::{
        block_with_pit, check, f32_ray, mesh_obj, mesh_scene_rays, rays_across_the_pit_edge,
        rays_for, Random, Rng,
    };
    use std::mem::{align_of, offset_of, size_of};
    use std::path::{Path, PathBuf};
    use std::process::{Command, Output};

    use hytrace_csg::Ray;
    use hytrace_foundry::gdml::GdmlOptions;
    use hytrace_foundry::npy::read_array;
    use hytrace_foundry::Foundry;
    use hytrace_trace::cpu::media::SceneMedia;
    use hytrace_trace::cpu::{CpuScene, Hit};
    use hytrace_trace::embree::{ffi, EmbreeScene};
    use hytrace_trace::scan::{scan_with, Backend, Precision, RayRow};
    use hytrace_trace::scene::{default_scene, load_scene, obj_to_foundry};
    use hytrace_volume::{Estimator, TransmittanceParams};

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

    /// Embree's answer for every ray.
    fn embree_answers(f: &Foundry, rays: &[RayRow]) -> Vec<Option<Hit<f32>>> {
        let cpu = CpuScene::<f32>::new(f).unwrap();
        let embree = EmbreeScene::new(f, &cpu).unwrap();
        rays.iter()
            .map(|r| {
                let (ray, tmin, tmax) = f32_ray(r);
                embree.trace(&ray, tmin, tmax).unwrap()
            })
            .collect()
    }

    fn repo(path: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../..")
            .join(path)
    }

    #[test]
    fn backends_agree_on_the_default_scene() {
        let f = default_scene().unwrap();
        let rays = rays_for(&f, 100, 20_000);
        check("default", &f, &rays, &embree_answers(&f, &rays));
    }

    #[test]
    fn backends_agree_on_the_csg_showcase() {
        let path = repo("scenes/csg-showcase.toml");
        let f = load_scene(Some(&path), &GdmlOptions::default()).unwrap();
        let rays = rays_for(&f, 100, 20_000);
        check("csg-showcase", &f, &rays, &embree_answers(&f, &rays));
    }

    /// CSG solids, a mesh read from a file and a medium (which both backends go through).
    #[test]
    fn backends_agree_on_the_mixed_scene() {
        let path = repo("scenes/mixed.toml");
        let f = load_scene(Some(&path), &GdmlOptions::default()).unwrap();
        let rays = rays_for(&f, 100, 20_000);
        check("mixed", &f, &rays, &embree_answers(&f, &rays));
    }

    #[test]
    fn backends_agree_on_a_mesh_scene() {
        let f = obj_to_foundry(mesh_obj().as_bytes()).unwrap();
        assert_eq!(f.inst.len(), 3);
        // Rays around the near pair, and rays at the far cube.
        let rays = mesh_scene_rays(&f);
        check("mesh", &f, &rays, &embree_answers(&f, &rays));
    }

    /// The project's GDML file (24 placements, several levels, reflections, replicas,
    /// tessellated solids as meshes, twisted solids as CSG).
    #[test]
    fn backends_agree_on_a_hierarchical_gdml_scene() {
        let path = repo("tests/data/gdml/coverage.gdml");
        let f = load_scene(Some(&path), &GdmlOptions::default()).unwrap();
        assert!(f
            .inst_mother
            .iter()
            .any(|m| m.index != hytrace_foundry::UNSET));
        let rays = rays_for(&f, 100, 20_000);
        check("coverage.gdml", &f, &rays, &embree_answers(&f, &rays));
    }

    /// Smaller shared public GDML files with hierarchies (when `../shared/gdml` is there, as on
    /// CI): nested envelopes and a tessellated solid.
    #[test]
    fn backends_agree_on_shared_gdml_files() {
        let dir = hytrace_testkit::files::shared_gdml_dir();
        for name in ["celeritas/multi-level.gdml", "geant4/tess.gdml"] {
            let f = load_scene(Some(&dir.join(name)), &GdmlOptions::default()).unwrap();
            let rays = rays_for(&f, 60, 10_000);
            check(name, &f, &rays, &embree_answers(&f, &rays));
        }
    }

    /// Any-hit queries: Embree's `rtcOccluded1` (triangles native, CSG through the occluded
    /// callback, instances) against [`CpuScene::occluded`] on every ray, and on each ray that
    /// hits again with its segment ending halfway to the CPU's hit (nothing is crossed
    /// before it) and just past it (the hit is crossed): flat CSG, mixed, mesh-file and
    /// hierarchical GDML scenes.
    #[test]
    fn occlusion_agrees_with_the_cpu() {
        let mesh = obj_to_foundry(mesh_obj().as_bytes()).unwrap();
        let mesh_rays = mesh_scene_rays(&mesh);
        let mut scenes = vec![("mesh", mesh, mesh_rays)];
        for (name, f) in [
            ("default", default_scene().unwrap()),
            (
                "mixed",
                load_scene(Some(&repo("scenes/mixed.toml")), &GdmlOptions::default()).unwrap(),
            ),
            (
                "coverage.gdml",
                load_scene(
                    Some(&repo("tests/data/gdml/coverage.gdml")),
                    &GdmlOptions::default(),
                )
                .unwrap(),
            ),
        ] {
            let rays = rays_for(&f, 60, 10_000);
            scenes.push((name, f, rays));
        }
        for (name, f, rays) in scenes {
            let cpu = CpuScene::<f32>::new(&f).unwrap();
            let embree = EmbreeScene::new(&f, &cpu).unwrap();
            let (mut queries, mut blocked, mut differ) = (0usize, 0usize, Vec::new());
            for (i, r) in rays.iter().enumerate() {
                let (ray, tmin, tmax) = f32_ray(r);
                // The CPU tracer takes rays in f64: the same ray, exactly.
                let exact = Ray::from_f64(ray.origin.to_f64(), ray.direction.to_f64());
                let mut segments = vec![(tmin, tmax)];
                if let Some(h) = cpu.trace(&exact, tmin, tmax) {
                    let to_hit = h.t - tmin;
                    segments.push((tmin, tmin + 0.5 * to_hit));
                    segments.push((tmin, (h.t + 0.01 * to_hit).min(tmax)));
                }
                for (a, b) in segments {
                    let want = cpu.occluded(&exact, a, b);
                    let got = embree.occluded(&ray, a, b).unwrap();
                    queries += 1;
                    blocked += want as usize;
                    if got != want {
                        differ.push(format!("ray {i} over ({a}, {b}): cpu {want}, embree {got}"));
                    }
                }
            }
            eprintln!(
                "{name}: {queries} any-hit queries, {blocked} occluded, {} differ",
                differ.len()
            );
            assert!(
                blocked > queries / 10 && blocked < queries * 9 / 10,
                "{name}: {blocked} of {queries} occluded"
            );
            assert!(
                differ.len() * 1000 <= queries,
                "{name}: {} of {queries} differ: {:?}",
                differ.len(),
                &differ[..differ.len().min(10)]
            );
        }
    }

    /// Transmittance with Embree finding the surface and the brick clusters (a user
    /// geometry of clusters, instanced) against the CPU's, ray by ray, on the same random
    /// streams: the mixed scene's fog box, placed twice more (once turned), by exact
    /// integration and by ratio tracking.
    #[test]
    fn transmittance_agrees_with_the_cpu_ray_by_ray() {
        let mut text = std::fs::read_to_string(repo("scenes/mixed.toml")).unwrap();
        text.push_str(
            "[[place]]\nsolid = \"fog\"\ntranslate = [300, 200, 400]\n\n\
             [[place]]\nsolid = \"fog\"\ntranslate = [-200, 0, -300]\nrotate = [0, 0, 1, 30]\n",
        );
        let f =
            hytrace_trace::scene::scene_from_toml(&text, "mixed.toml", &repo("scenes")).unwrap();
        assert!(!f.optics.media.is_empty() && !f.brick.is_empty());
        let rays = rays_for(&f, 60, 4000);
        let cpu = CpuScene::<f32>::new(&f).unwrap();
        let embree = EmbreeScene::new(&f, &cpu).unwrap();
        for estimator in [Estimator::Exact, Estimator::Ratio] {
            let media = SceneMedia::new(&cpu, &f, &TransmittanceParams::new(estimator)).unwrap();
            let (mut attenuated, mut differ) = (0, Vec::new());
            for (i, r) in rays.iter().enumerate() {
                let i = i as u32;
                let want = media
                    .trace_transmittance(r.origin, r.direction, r.tmin, r.tmax, i)
                    .unwrap();
                let got = embree
                    .trace_transmittance(&media, r.origin, r.direction, r.tmin, r.tmax, i)
                    .unwrap();
                attenuated += (want.transmittance < 1.0) as usize;
                let same_hit = want.hit.map(|h| h.t) == got.hit.map(|h| h.t);
                if same_hit && got.transmittance != want.transmittance {
                    differ.push(format!(
                        "ray {i}: cpu {} embree {}",
                        want.transmittance, got.transmittance
                    ));
                }
            }
            eprintln!(
                "{estimator:?}: {} rays, {attenuated} attenuated, {} differ",
                rays.len(),
                differ.len()
            );
            assert!(attenuated > rays.len() / 10, "{attenuated} attenuated");
            // Visits naming a placement the scene lacks are an error, not a panic.
            let r = &rays[0];
            let err = media
                .transmittance_with(r.origin, r.direction, r.tmin, 1.0, [(0, 7, 0.0, 1.0)], 0)
                .unwrap_err();
            assert!(
                format!("{err:#}").contains("does not hold medium 7"),
                "{err:#}"
            );
            assert!(
                differ.is_empty(),
                "{estimator:?}: {:?}",
                &differ[..differ.len().min(10)]
            );
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
            let ray = Ray::from_f64(r.origin, r.direction);
            let want: Option<Hit<f32>> = cpu.trace(&ray, 0.0, f32::INFINITY);
            let got = embree.trace(&Ray::from_f64(r.origin, r.direction), 0.0, f32::INFINITY);
            let got = got.unwrap();
            if let (Some(w), Some(g)) = (want, got) {
                total += 1;
                same += usize::from(w.instance == g.instance && w.prim == g.prim);
            }
        }
        assert!(total > 0 && same * 1000 >= 999 * total, "{same} of {total}");
    }

    /// The f32 fallback on Embree (issue 30): an Embree scan traces again in f64 the rays
    /// its trace flags, as the default scan does. On [`block_with_pit`]: chords through the
    /// edge of its pit (2e-4 to 4e-3 mm, and under one ulp of `t`: `f32_decisions`' rays),
    /// which the CSG user geometry drops as touches, and rays starting 1e-6 to 1e-3 mm
    /// below its top face going out, or above it coming in (their starts round onto the
    /// face in f32). Exact answers, from the geometry: the pit's wall 200 mm on, the face
    /// at `offset / sine of elevation`. Embree's plain f32 trace is wrong on most of them;
    /// its scan is right on every one, having flagged them (`flagged`, `redone_in_f64` and
    /// `fallback_s` of `--stats`).
    #[test]
    fn embree_scans_trace_flagged_rays_again_in_f64() {
        let f = block_with_pit();
        let mut rows = rays_across_the_pit_edge(23, 400, [-4.0, -2.7]);
        rows.extend(rays_across_the_pit_edge(29, 400, [-7.0, -5.5]));
        let mut want = vec![200.0; rows.len()];
        let mut rng = Rng(31);
        for i in 0..400 {
            // Away from the pit, at 20 to 70 degrees to the face: out from below, in from
            // above.
            let below = i % 2 == 0;
            let offset = 10f64.powf(-6.0 + 3.0 * rng.uniform());
            let elevation = (20.0 + 50.0 * rng.uniform()).to_radians();
            let phi = std::f64::consts::TAU * rng.uniform();
            let up = if below { 1.0 } else { -1.0 };
            let d = [
                elevation.cos() * phi.cos(),
                elevation.cos() * phi.sin(),
                up * elevation.sin(),
            ];
            let z = 500.0 - up * offset;
            rows.push(RayRow {
                origin: [
                    500.0 + 300.0 * rng.uniform(),
                    600.0 * rng.uniform() - 300.0,
                    z,
                ],
                direction: d,
                tmin: 0.0,
                tmax: f64::INFINITY,
            });
            want.push(offset / elevation.sin());
        }
        let tolerance = |r: &RayRow, t: f64| {
            let o = r.origin.iter().map(|c| c * c).sum::<f64>().sqrt();
            (2e-6 * (o + t)).max(1e-9)
        };
        let right = |got: f64, i: usize| (got - want[i]).abs() <= tolerance(&rows[i], want[i]);
        let plain = embree_answers(&f, &rows);
        let plain_wrong = (0..rows.len())
            .filter(|&i| !right(plain[i].map_or(f64::INFINITY, |h| f64::from(h.t)), i))
            .count();
        eprintln!(
            "plain Embree f32 trace: {plain_wrong} of {} rays wrong",
            rows.len()
        );
        assert!(plain_wrong > rows.len() / 2, "{plain_wrong}");
        let (got, times) = scan_with(&f, &rows, Precision::F32, Backend::Embree).unwrap();
        eprintln!(
            "Embree scan: {} flagged, {} traced again in f64, fallback {} s",
            times.flagged, times.redone_in_f64, times.fallback_s
        );
        let wrong: Vec<String> = (0..rows.len())
            .filter(|&i| !right(got.hits[i][3], i))
            .map(|i| {
                format!(
                    "ray {i} {:?}: {}, exact {}",
                    rows[i], got.hits[i][3], want[i]
                )
            })
            .collect();
        assert!(
            wrong.is_empty(),
            "{} wrong: {:?}",
            wrong.len(),
            &wrong[..wrong.len().min(5)]
        );
        assert!(times.flagged >= plain_wrong && times.redone_in_f64 >= plain_wrong);
        assert!(times.fallback_s > 0.0);
    }
}
