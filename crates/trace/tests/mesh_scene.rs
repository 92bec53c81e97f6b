//! Mesh-file scenes: OBJ objects and glTF node hierarchies become solids and instances,
//! traced first hits land where the geometry says, scans of a large mesh (interleaved
//! searches) answer as single traces, bad files are errors naming the file, and truncated
//! or mutated OBJ and GLB bytes never panic the loader.

use std::path::Path;

use hytrace_foundry::gdml::GdmlOptions;
use hytrace_testkit::{Random, XorShift64Star};
use hytrace_trace::cpu::{TraceScratch, BATCH};
use hytrace_trace::scan::{rays_from_rows, scan, Precision, RayRow};
use hytrace_trace::scene::{gltf_to_foundry, load_scene, obj_to_foundry};

/// A unit cube `[0, 1]^3` as OBJ text (quads, counter-clockwise from outside), twice: the
/// second object shifted by `(3, 0, 0)`.
const TWO_CUBES_OBJ: &str = "\
o first
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
f 1 4 3 2
f 5 6 7 8
f 1 2 6 5
f 2 3 7 6
f 3 4 8 7
f 4 1 5 8
o second
v 3 0 0
v 4 0 0
v 4 1 0
v 3 1 0
v 3 0 1
v 4 0 1
v 4 1 1
v 3 1 1
f -8 -5 -6 -7
f -4 -3 -2 -1
f -8 -7 -3 -4
f -7 -6 -2 -3
f -6 -5 -1 -2
f -5 -8 -4 -1
";

/// The first-hit distance of a ray with origin `o` and direction `d` (f64 kernels).
fn first_hit(f: &hytrace_foundry::Foundry, o: [f64; 3], d: [f64; 3]) -> f64 {
    let row = [o[0], o[1], o[2], 0.0, d[0], d[1], d[2], f64::INFINITY];
    let rays = rays_from_rows(&[row], "test").unwrap();
    scan(f, &rays, Precision::F64).unwrap().0.hits[0][3]
}

#[test]
fn obj_objects_become_one_solid_each() {
    let f = obj_to_foundry(TWO_CUBES_OBJ.as_bytes()).unwrap();
    assert_eq!(f.solid.len(), 2);
    assert_eq!(f.inst.len(), 2);
    assert_eq!(f.solid_names, ["first", "second"]);
    assert_eq!(first_hit(&f, [-1.0, 0.5, 0.5], [1.0, 0.0, 0.0]), 1.0);
    assert_eq!(first_hit(&f, [2.0, 0.5, 0.5], [1.0, 0.0, 0.0]), 1.0);
    assert_eq!(first_hit(&f, [3.5, 0.5, 5.0], [0.0, 0.0, -1.0]), 4.0);
    assert!(first_hit(&f, [2.0, 5.0, 0.5], [1.0, 0.0, 0.0]).is_infinite());
}

/// glTF JSON and binary buffer: one tetrahedron mesh (u16 indices) placed by a root node
/// at the origin and by a child node (translation (0, 0, 5), scale 2) of a root translated
/// by (10, 0, 0). The buffer is the GLB's binary chunk, or the file `uri`.
fn tetra_gltf(uri: Option<&str>) -> (String, Vec<u8>) {
    let positions: [[f32; 3]; 4] = [[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.]];
    let indices: [u16; 12] = [0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3];
    let mut bin: Vec<u8> = positions
        .iter()
        .flatten()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    bin.extend(indices.iter().flat_map(|i| i.to_le_bytes()));
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0,1]}}],
"nodes":[{{"mesh":0}},{{"translation":[10,0,0],"children":[2]}},
{{"mesh":0,"translation":[0,0,5],"scale":[2,2,2]}}],
"meshes":[{{"name":"tetra","primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3",
"min":[0,0,0],"max":[1,1,1]}},{{"bufferView":1,"componentType":5123,"count":12,"type":"SCALAR"}}],
"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":48}},
{{"buffer":0,"byteOffset":48,"byteLength":24}}],
"buffers":[{{"byteLength":{}{}}}]}}"#,
        bin.len(),
        uri.map_or(String::new(), |u| format!(r#","uri":"{u}""#))
    );
    (json, bin)
}

/// [`tetra_gltf`] as a GLB.
fn tetra_glb() -> Vec<u8> {
    let (json, bin) = tetra_gltf(None);
    let pad = |mut v: Vec<u8>, with: u8| {
        while !v.len().is_multiple_of(4) {
            v.push(with);
        }
        v
    };
    let (json, bin) = (pad(json.into_bytes(), b' '), pad(bin, 0));
    let mut glb = Vec::new();
    glb.extend(b"glTF");
    glb.extend(2u32.to_le_bytes());
    glb.extend(((12 + 8 + json.len() + 8 + bin.len()) as u32).to_le_bytes());
    glb.extend((json.len() as u32).to_le_bytes());
    glb.extend(b"JSON");
    glb.extend(&json);
    glb.extend((bin.len() as u32).to_le_bytes());
    glb.extend(b"BIN\0");
    glb.extend(&bin);
    glb
}

#[test]
fn gltf_nodes_place_one_shared_solid() {
    let f = gltf_to_foundry(&tetra_glb(), None).unwrap();
    assert_eq!(f.solid.len(), 1, "the mesh is one solid");
    assert_eq!(f.inst.len(), 2, "placed by two nodes");
    // The node at the origin: the face x = 0 from -x.
    let t = first_hit(&f, [-2.0, 0.2, 0.2], [1.0, 0.0, 0.0]);
    assert!((t - 2.0).abs() < 1e-12, "{t}");
    // The child node: scaled by 2, then moved by (0, 0, 5) and its parent's (10, 0, 0):
    // its base face is at z = 5, its slanted face x + y + z = 2 in its frame.
    let t = first_hit(&f, [10.5, 0.5, 0.0], [0.0, 0.0, 1.0]);
    assert!((t - 5.0).abs() < 1e-12, "{t}");
    let t = first_hit(&f, [10.5, 0.5, 10.0], [0.0, 0.0, -1.0]);
    assert!((t - 4.0).abs() < 1e-12, "{t}");
}

#[test]
fn scene_files_load_by_extension() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("cubes.OBJ");
    std::fs::write(&obj, TWO_CUBES_OBJ).unwrap();
    let glb = dir.path().join("tetra.glb");
    std::fs::write(&glb, tetra_glb()).unwrap();
    let options = GdmlOptions::default();
    assert_eq!(load_scene(Some(&obj), &options).unwrap().inst.len(), 2);
    assert_eq!(load_scene(Some(&glb), &options).unwrap().inst.len(), 2);
    let (json, bin) = tetra_gltf(Some("tetra.bin"));
    let gltf = dir.path().join("tetra.gltf");
    std::fs::write(&gltf, json).unwrap();
    std::fs::write(dir.path().join("tetra.bin"), bin).unwrap();
    assert_eq!(load_scene(Some(&gltf), &options).unwrap().inst.len(), 2);
}

/// The error of loading `bytes` written as `name`, which must name the file and say
/// `what`.
fn load_error(name: &str, bytes: &[u8], what: &str) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    let e = format!(
        "{:#}",
        load_scene(Some(&path), &GdmlOptions::default()).unwrap_err()
    );
    assert!(e.contains(name), "{e}");
    assert!(e.contains(what), "`{what}` not in: {e}");
}

#[test]
fn bad_mesh_files_are_errors_naming_the_file() {
    let missing = Path::new("/nonexistent/mesh.obj");
    let e = format!(
        "{:#}",
        load_scene(Some(missing), &GdmlOptions::default()).unwrap_err()
    );
    assert!(e.contains("mesh.obj"), "{e}");
    load_error("empty.obj", b"# nothing\n", "no triangles");
    load_error("lines.obj", b"v 0 0 0\nv 1 0 0\nl 1 2\n", "no triangles");
    load_error(
        "range.obj",
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n",
        "line 4: face vertex index out of bounds: `f 1 2 7`",
    );
    // Errors name the line, counted as the reader does (comments, blank lines, and
    // negative indices back from the vertices read so far).
    load_error(
        "late.obj",
        b"# a comment\n\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -3\nf 1 2 -4\n",
        "line 7: face vertex index out of bounds",
    );
    load_error(
        "word.obj",
        b"v 0 0 0\nv 1 zero 0\nv 0 1 0\nf 1 2 3\n",
        "line 2: position parse error: `v 1 zero 0`",
    );
    load_error(
        "normal.obj",
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//2\n",
        "line 5: face normal index out of bounds",
    );
    load_error(
        "nan.obj",
        b"v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n",
        "not finite",
    );
    load_error("junk.glb", b"not a glb at all", "glTF");
    let glb = tetra_glb();
    load_error("short.glb", &glb[..glb.len() - 30], "glTF");
    // An index past the four vertices.
    let mut bad_index = glb.clone();
    let at = bad_index.len() - 24;
    bad_index[at..at + 2].copy_from_slice(&9u16.to_le_bytes());
    load_error("index.glb", &bad_index, "out of range");
    // A NaN coordinate.
    let mut nan = glb.clone();
    let at = nan.len() - 24 - 48 + 4;
    nan[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    load_error("nan.glb", &nan, "not finite");
}

/// Every truncation and a few thousand random byte mutations of valid files load or fail,
/// but never panic.
#[test]
fn truncated_and_mutated_files_never_panic() {
    let obj = TWO_CUBES_OBJ.as_bytes().to_vec();
    let glb = tetra_glb();
    for n in 0..obj.len() {
        let _ = obj_to_foundry(&obj[..n]);
    }
    for n in 0..glb.len() {
        let _ = gltf_to_foundry(&glb[..n], None);
    }
    let mut rng = XorShift64Star(0x5eed);
    let obj_bytes = b"0123456789 -+.eE/\nvfo#";
    // 10^5 mutations of each format.
    for _ in 0..100_000 {
        let mut m = obj.clone();
        for _ in 0..1 + rng.below(4) {
            let at = rng.below(m.len());
            m[at] = obj_bytes[rng.below(obj_bytes.len())];
        }
        let _ = obj_to_foundry(&m);
        let mut g = glb.clone();
        for _ in 0..1 + rng.below(4) {
            let at = rng.below(g.len());
            g[at] = rng.below(256) as u8;
        }
        let _ = gltf_to_foundry(&g, None);
    }
}

/// The f32 tracer's batches over a mesh large enough for its searches to be interleaved
/// (what `hytrace scan` hands it) answer every ray bit for bit as tracing it alone does,
/// and agree with the f64 scan (its own kernel, one box at a time) within f32's
/// tolerance: incoherent rays from above, some with a `tmax` short of the surface or a
/// `tmin` past it, then coherent ones (searched as packets): a sweep straight down and a
/// camera's rows.
#[test]
fn scans_of_a_large_mesh_equal_single_traces() {
    // A 128 x 128 heightfield: 32 768 triangles.
    let n = 128;
    let height = |i: usize, j: usize| 3.0 * ((i as f64 * 0.31).sin() + (j as f64 * 0.17).cos());
    let mut obj = String::new();
    for i in 0..=n {
        for j in 0..=n {
            obj.push_str(&format!("v {i} {j} {}\n", height(i, j)));
        }
    }
    let at = |i: usize, j: usize| i * (n + 1) + j + 1;
    for i in 0..n {
        for j in 0..n {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            obj.push_str(&format!("f {a} {b} {c}\nf {a} {c} {d}\n"));
        }
    }
    let f = obj_to_foundry(obj.as_bytes()).unwrap();
    let mesh = hytrace_csg::PreparedPrim::<f32>::from_foundry(&f, 0).unwrap();
    match mesh {
        Some(hytrace_csg::PreparedPrim::Mesh(m)) => assert!(
            m.bvh_bytes() >= hytrace_trace::cpu::INTERLEAVE_MIN_BYTES,
            "the mesh ({} bytes) is too small to be interleaved",
            m.bvh_bytes()
        ),
        _ => panic!("prim 0 is not a mesh"),
    }
    let mut rng = XorShift64Star(0x2545_f491_4f6c_dd1d);
    let mut uniform = || rng.uniform();
    let mut rows: Vec<[f64; 8]> = (0..20_000)
        .map(|k| {
            let o = [uniform() * 140.0 - 6.0, uniform() * 140.0 - 6.0, 10.0];
            let d = [uniform() - 0.5, uniform() - 0.5, -uniform()];
            let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let (tmin, tmax) = match k % 5 {
                0 => (0.0, 4.0),
                1 => (9.0, f64::INFINITY),
                _ => (0.0, f64::INFINITY),
            };
            [o[0], o[1], o[2], tmin, d[0] / l, d[1] / l, d[2] / l, tmax]
        })
        .collect();
    let incoherent = rows.len();
    // A sweep straight down, rows of rays 1/16 apart; a camera's rows, pixels 1/1024 rad
    // apart, from above one corner.
    for k in 0..16 * 1024 {
        let (x, y) = (
            10.0 + (k % 1024) as f64 / 16.0,
            20.0 + (k / 1024) as f64 * 4.0,
        );
        rows.push([x, y, 10.0, 0.0, 0.0, 0.0, -1.0, f64::INFINITY]);
    }
    for k in 0..64 * 256 {
        let (u, v) = ((k % 256) as f64 / 1024.0, (k / 256) as f64 / 128.0);
        let d = [0.5 + u, 0.5 + v, -0.7];
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        rows.push([
            -20.0,
            -20.0,
            40.0,
            0.0,
            d[0] / l,
            d[1] / l,
            d[2] / l,
            f64::INFINITY,
        ]);
    }
    let rays = rays_from_rows(&rows, "test rays").unwrap();
    let (exact, _) = scan(&f, &rays, Precision::F64).unwrap();
    let scene = hytrace_trace::cpu::CpuScene::<f32>::new(&f).unwrap();
    let query = |r: &RayRow| {
        let ray = hytrace_csg::Ray::<f64>::from_f64(r.origin, r.direction);
        let tmax = if r.tmax.is_finite() {
            r.tmax as f32
        } else {
            f32::INFINITY
        };
        (ray, r.tmin as f32, tmax)
    };
    // In batches of the size scans hand over.
    let (mut scratch, mut batched, mut out) = (TraceScratch::default(), Vec::new(), Vec::new());
    for chunk in rays.chunks(BATCH) {
        let queries: Vec<_> = chunk.iter().map(query).collect();
        scene.trace_batch(&queries, &mut scratch, &mut out);
        batched.extend_from_slice(&out);
    }
    let (mut hits, mut coherent_hits, mut far) = (0, 0, 0);
    for (i, r) in rays.iter().enumerate() {
        let (ray, tmin, tmax) = query(r);
        let alone = scene.trace(&ray, tmin, tmax);
        assert_eq!(batched[i], alone, "ray {i} {r:?}");
        let t = alone.map_or(f64::INFINITY, |h| f64::from(h.t));
        let want = exact.hits[i][3];
        if want.is_finite() != t.is_finite() || (t.is_finite() && (t - want).abs() > 1e-3) {
            far += 1;
        }
        if i < incoherent {
            hits += usize::from(t.is_finite());
        } else {
            coherent_hits += usize::from(t.is_finite());
        }
    }
    assert!(hits > 8000 && hits < 19_000, "{hits} of 20000 rays hit");
    assert!(
        coherent_hits > 20_000,
        "{coherent_hits} of {} coherent rays hit",
        rays.len() - incoherent
    );
    assert!(far <= 2, "{far} rays disagree with the f64 scan");
}
