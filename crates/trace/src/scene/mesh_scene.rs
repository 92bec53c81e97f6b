//! Triangle-mesh files as scenes: Wavefront OBJ (via `tobj`) and glTF 2.0, `.gltf` or
//! binary `.glb` (via `gltf`).
//!
//! OBJ: every object or group (`o`/`g`) with faces becomes one solid, placed once; faces
//! are fan-triangulated and positions read in f64 (normals, texture coordinates and
//! materials are ignored).
//!
//! glTF: every mesh of the scene (the default scene, else the first) becomes one solid of
//! the triangles of all its `TRIANGLES` primitives (other modes are skipped), and every node
//! of the hierarchy that has a mesh becomes one instance of it, placed by the product of
//! the node transforms from the root. A mesh used by several nodes is one solid placed
//! several times. Buffers are the GLB's binary chunk, base64 `data:` URIs or files beside
//! the `.gltf`.
//!
//! Each solid's vertices are stored relative to (about) the centre of its bounds, the
//! centre going into the instance's (f64) transform, so meshes far from the origin keep
//! their f32 precision. The centre is chosen so that vertices given in f32 (every glTF
//! file's, and OBJ text written from f32) are stored exactly ([`storage_centre`]). Meshes
//! need not be closed: an open mesh gives first hits only (see [`hytrace_csg::MeshPrim`]).

use std::collections::hash_map::{Entry, HashMap};
use std::path::Path;

use crate::error::{bail, ensure, Context};
use hytrace_foundry::{Foundry, Transform64, Triangle, UNSET};

/// Most nodes a glTF hierarchy walk may visit (shared subtrees are walked once per use).
const MAX_GLTF_NODES: usize = 10_000_000;

/// Reads an `.obj`, `.gltf` or `.glb` file into a Foundry; errors name the file.
pub fn load_mesh_scene(path: &Path) -> crate::Result<Foundry> {
    let source = path.display().to_string();
    let bytes = std::fs::read(path).with_context(|| format!("reading {source}"))?;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let dir = path.parent();
    match ext.as_str() {
        "obj" => obj_to_foundry(&bytes),
        "gltf" | "glb" => gltf_to_foundry(&bytes, dir),
        _ => bail!("not a mesh file (expected .obj, .gltf or .glb)"),
    }
    .with_context(|| format!("{source}: reading the mesh"))
}

/// Vertex positions and the triangles indexing them.
type IndexedTriangles = (Vec<[f64; 3]>, Vec<[usize; 3]>);

/// A Foundry solid and the centre its vertices are stored relative to.
type CentredSolid = (u32, [f64; 3]);

/// The point, near the centre of the bounds `lo..hi` of `positions`, that a mesh's vertices
/// are stored relative to (in f32): on each axis the centre rounded to a multiple of the
/// f32 spacing at the coordinate nearest zero, where every f32 coordinate minus it is an
/// f32 (the mesh lies far from the origin for its size); else zero (an f32 coordinate is
/// its own f32). So a vertex given in f32 is stored exactly, the mesh Embree or any f32
/// tracer sees: subtracting the plain centre rounded such vertices by up to half an ulp,
/// which moved grazing crossings by that over the sine of the angle (1e-5 on a sphere of
/// radius 10 at 1 degree).
fn storage_centre(lo: [f64; 3], hi: [f64; 3], positions: &[[f64; 3]]) -> [f64; 3] {
    std::array::from_fn(|k| {
        let nearest = if lo[k] > 0.0 {
            lo[k]
        } else if hi[k] < 0.0 {
            -hi[k]
        } else {
            return 0.0;
        };
        // The spacing of f32 values at `nearest`, and below it at most half that.
        let spacing = f64::from(f32::from_bits((nearest as f32).to_bits() & 0x7f80_0000))
            * f64::from(f32::EPSILON);
        let centre = (0.5 * (lo[k] + hi[k]) / spacing).round() * spacing;
        let exact = positions.iter().all(|p| {
            let v = p[k];
            v != f64::from(v as f32) || f64::from((v - centre) as f32) == v - centre
        });
        if exact {
            centre
        } else {
            0.0
        }
    })
}

/// Appends one solid of the triangles `indices` over `positions`, vertices stored relative
/// to (about) the centre of their bounds ([`storage_centre`]); returns the solid and that
/// centre.
fn add_mesh_solid(
    f: &mut Foundry,
    name: &str,
    positions: &[[f64; 3]],
    indices: &[[usize; 3]],
) -> crate::Result<CentredSolid> {
    ensure!(!indices.is_empty(), "mesh `{name}` has no triangles");
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for (t, tri) in indices.iter().enumerate() {
        for &i in tri {
            let p = positions.get(i).with_context(|| {
                format!(
                    "mesh `{name}`: triangle {t} uses vertex {i} of {}",
                    positions.len()
                )
            })?;
            ensure!(
                p.iter().all(|c| c.is_finite()),
                "mesh `{name}`: vertex {i} is not finite: {p:?}"
            );
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
    }
    let centre = storage_centre(lo, hi, positions);
    let relative = |i: usize| {
        let p = positions[i];
        [
            (p[0] - centre[0]) as f32,
            (p[1] - centre[1]) as f32,
            (p[2] - centre[2]) as f32,
            0.0,
        ]
    };
    let triangles: Vec<Triangle> = indices
        .iter()
        .map(|t| Triangle { v: t.map(relative) })
        .collect();
    let identity = f.solid.len() as u32;
    let mut s = f.begin_solid(name);
    s.add_mesh(&triangles, None, identity, UNSET)?;
    Ok((s.finish(identity)?, centre))
}

/// Appends one solid holding every triangle of the mesh file `path` (all its meshes in
/// their placements, in the file's frame), its vertices stored relative to the centre of
/// their bounds; returns the solid and that centre, which placements of the solid must
/// apply first.
pub fn add_mesh_file_solid(
    f: &mut Foundry,
    name: &str,
    path: &Path,
) -> crate::Result<(u32, [f64; 3])> {
    let g = load_mesh_scene(path)?;
    let mut positions = Vec::new();
    for (inst, placement) in g.inst.iter().zip(&g.inst_tran) {
        let placement = placement.to_transform();
        let solid = &g.solid[inst.solid as usize];
        for p in &g.prim[solid.prim_offset as usize..(solid.prim_offset + solid.num_prim) as usize]
        {
            let to_file = match p.transform {
                0 => placement,
                k => placement.compose(&g.tran[k as usize - 1]),
            };
            let tris = &g.tri[p.item_offset as usize..(p.item_offset + p.item_count) as usize];
            positions.extend(tris.iter().flat_map(|t| {
                t.v.map(|v| to_file.apply_point([v[0], v[1], v[2]].map(f64::from)))
            }));
        }
    }
    let indices: Vec<[usize; 3]> = (0..positions.len() / 3)
        .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
        .collect();
    add_mesh_solid(f, name, &positions, &indices).with_context(|| path.display().to_string())
}

/// The line (from 1, and its text, abridged) that `error` of the OBJ reader is about, found
/// again by reading the lines as it does; `None` for errors not tied to one line.
fn obj_error_line(bytes: &[u8], error: &tobj::LoadError) -> Option<(usize, String)> {
    use tobj::LoadError as E;
    let text = String::from_utf8_lossy(bytes);
    let floats = |fields: &[&str], counts: &[usize]| {
        counts.contains(&fields.len()) && fields.iter().all(|f| f.parse::<f32>().is_ok())
    };
    let (mut positions, mut texcoords, mut normals) = (0i64, 0i64, 0i64);
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        let Some(key) = words.next() else { continue };
        let fields: Vec<&str> = words.collect();
        let bad = match key {
            "v" => {
                positions += 1;
                matches!(error, E::PositionParseError) && !floats(&fields, &[3, 4, 6, 7])
            }
            "vt" => {
                texcoords += 1;
                matches!(error, E::TexcoordParseError) && !floats(&fields, &[1, 2, 3])
            }
            "vn" => {
                normals += 1;
                matches!(error, E::NormalParseError) && !floats(&fields, &[3])
            }
            "f" => fields.iter().any(|corner| {
                let parts: Vec<&str> = corner.split('/').collect();
                // An index counts from 1, or back from the last one read when negative.
                let resolves = |k: usize, count: i64| match parts.get(k) {
                    None | Some(&"") => true,
                    Some(p) => p
                        .parse::<i64>()
                        .is_ok_and(|i| (1..=count).contains(&i) || (1..=count).contains(&-i)),
                };
                let parses = parts
                    .iter()
                    .all(|p| p.is_empty() || p.parse::<i64>().is_ok());
                match error {
                    E::FaceParseError => !parses || parts[0].is_empty(),
                    E::FaceVertexOutOfBounds => !resolves(0, positions),
                    E::FaceTexCoordOutOfBounds => !resolves(1, texcoords),
                    E::FaceNormalOutOfBounds => !resolves(2, normals),
                    _ => false,
                }
            }),
            _ => false,
        };
        if bad {
            let shown: String = line.chars().take(60).collect();
            return Some((n + 1, shown));
        }
    }
    None
}

/// Builds a Foundry from the bytes of an OBJ file: one solid per object or group with
/// faces, each placed once. Material libraries are not read.
pub fn obj_to_foundry(bytes: &[u8]) -> crate::Result<Foundry> {
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, _) = tobj::load_obj_buf(&mut &bytes[..], &options, |_| {
        Ok((Vec::new(), Default::default()))
    })
    .map_err(|e| match obj_error_line(bytes, &e) {
        Some((n, line)) => {
            crate::Error::Invalid(format!("not a valid OBJ file: line {n}: {e}: `{line}`"))
        }
        None => crate::Error::Invalid(format!("not a valid OBJ file: {e}")),
    })?;
    let mut f = Foundry::new();
    for (k, model) in models.iter().enumerate() {
        let m = &model.mesh;
        if m.indices.is_empty() {
            continue;
        }
        ensure!(
            m.indices.len().is_multiple_of(3),
            "object `{}`: {} face indices, not whole triangles",
            model.name,
            m.indices.len()
        );
        let positions: Vec<[f64; 3]> = m
            .positions
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        let indices: Vec<[usize; 3]> = m
            .indices
            .chunks_exact(3)
            .map(|c| [c[0] as usize, c[1] as usize, c[2] as usize])
            .collect();
        let name = if model.name.is_empty() {
            format!("object{k}")
        } else {
            model.name.clone()
        };
        let (solid, centre) = add_mesh_solid(&mut f, &name, &positions, &indices)?;
        f.add_instance(solid, Transform64::translation(centre), UNSET, k as i32)?;
    }
    ensure!(!f.inst.is_empty(), "no triangles (no object has faces)");
    f.validate().context("built an invalid Foundry")?;
    Ok(f)
}

/// The bytes of every buffer: the GLB's binary chunk, a base64 `data:` URI, or a file
/// beside the `.gltf` (`dir`).
fn gltf_buffers(doc: &gltf::Gltf, dir: Option<&Path>) -> crate::Result<Vec<Vec<u8>>> {
    doc.buffers()
        .map(|b| {
            let data = match b.source() {
                gltf::buffer::Source::Bin => doc
                    .blob
                    .clone()
                    .with_context(|| format!("buffer {}: no binary chunk", b.index()))?,
                gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                    let (_, payload) = uri
                        .split_once(";base64,")
                        .with_context(|| format!("buffer {}: data URI is not base64", b.index()))?;
                    base64_decode(payload)
                        .with_context(|| format!("buffer {}: bad base64", b.index()))?
                }
                gltf::buffer::Source::Uri(uri) => {
                    let dir = dir.with_context(|| format!("buffer {}: no directory", b.index()))?;
                    let p = dir.join(uri);
                    std::fs::read(&p)
                        .with_context(|| format!("buffer {}: reading {}", b.index(), p.display()))?
                }
            };
            ensure!(
                data.len() >= b.length(),
                "buffer {}: {} bytes, shorter than its byteLength {}",
                b.index(),
                data.len(),
                b.length()
            );
            Ok(data)
        })
        .collect()
}

/// Decodes standard base64 (padding optional, no whitespace).
fn base64_decode(text: &str) -> Option<Vec<u8>> {
    let value = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        } as u32)
    };
    let text = text.trim_end_matches('=').as_bytes();
    let mut out = Vec::with_capacity(text.len() * 3 / 4);
    for chunk in text.chunks(4) {
        if chunk.len() == 1 {
            return None;
        }
        let mut bits = 0u32;
        for (k, &c) in chunk.iter().enumerate() {
            bits |= value(c)? << (18 - 6 * k);
        }
        out.extend_from_slice(&bits.to_be_bytes()[1..chunk.len()]);
    }
    Some(out)
}

/// The bytes of element `i` of an accessor for each `i`, bounds checked against its view
/// and buffer (no sparse accessors).
fn accessor_elements<'a>(
    acc: &gltf::Accessor,
    buffers: &'a [Vec<u8>],
) -> crate::Result<Vec<&'a [u8]>> {
    ensure!(
        acc.sparse().is_none(),
        "accessor {}: sparse accessors are not supported",
        acc.index()
    );
    let view = acc
        .view()
        .with_context(|| format!("accessor {}: no buffer view", acc.index()))?;
    let size = acc.size();
    let stride = view.stride().unwrap_or(size);
    let buffer = &buffers[view.buffer().index()];
    let out_of_range = || format!("accessor {}: reaches past its buffer", acc.index());
    let view_end = view
        .offset()
        .checked_add(view.length())
        .filter(|&e| e <= buffer.len())
        .with_context(out_of_range)?;
    let data = &buffer[view.offset()..view_end];
    (0..acc.count())
        .map(|i| {
            let start = i
                .checked_mul(stride)
                .and_then(|s| s.checked_add(acc.offset()))
                .with_context(out_of_range)?;
            data.get(start..start.saturating_add(size))
                .with_context(out_of_range)
        })
        .collect()
}

/// Positions and triangles of the `TRIANGLES` primitives of a glTF mesh.
fn gltf_mesh_triangles(mesh: &gltf::Mesh, buffers: &[Vec<u8>]) -> crate::Result<IndexedTriangles> {
    use gltf::accessor::{DataType, Dimensions};
    let (mut positions, mut triangles) = (Vec::new(), Vec::new());
    for prim in mesh.primitives() {
        if prim.mode() != gltf::mesh::Mode::Triangles {
            continue;
        }
        let what = || format!("mesh {} primitive {}", mesh.index(), prim.index());
        let acc = prim
            .get(&gltf::Semantic::Positions)
            .with_context(|| format!("{}: no POSITION attribute", what()))?;
        ensure!(
            acc.data_type() == DataType::F32 && acc.dimensions() == Dimensions::Vec3,
            "{}: POSITION must be float VEC3",
            what()
        );
        let first = positions.len();
        for e in accessor_elements(&acc, buffers).with_context(what)? {
            let c = |k: usize| f32::from_le_bytes(e[4 * k..4 * k + 4].try_into().unwrap());
            positions.push([c(0), c(1), c(2)].map(f64::from));
        }
        let corners: Vec<usize> = match prim.indices() {
            None => (0..positions.len() - first).collect(),
            Some(acc) => {
                ensure!(
                    acc.dimensions() == Dimensions::Scalar,
                    "{}: indices must be SCALAR",
                    what()
                );
                let elements = accessor_elements(&acc, buffers).with_context(what)?;
                match acc.data_type() {
                    DataType::U8 => elements.iter().map(|e| e[0] as usize).collect(),
                    DataType::U16 => elements
                        .iter()
                        .map(|e| u16::from_le_bytes([e[0], e[1]]) as usize)
                        .collect(),
                    DataType::U32 => elements
                        .iter()
                        .map(|e| u32::from_le_bytes([e[0], e[1], e[2], e[3]]) as usize)
                        .collect(),
                    other => bail!("{}: indices of type {other:?}", what()),
                }
            }
        };
        ensure!(
            corners.len().is_multiple_of(3),
            "{}: {} indices, not whole triangles",
            what(),
            corners.len()
        );
        let count = positions.len() - first;
        for c in corners.chunks_exact(3) {
            ensure!(
                c.iter().all(|&i| i < count),
                "{}: index out of range in {c:?} ({count} vertices)",
                what()
            );
            triangles.push([first + c[0], first + c[1], first + c[2]]);
        }
    }
    Ok((positions, triangles))
}

/// A node's local transform (glTF matrices are column-major).
fn node_transform(node: &gltf::Node) -> crate::Result<Transform64> {
    let m = node.transform().matrix();
    let rows: [[f64; 4]; 4] = std::array::from_fn(|r| std::array::from_fn(|c| m[c][r] as f64));
    ensure!(
        rows.iter().flatten().all(|v| v.is_finite()),
        "node {}: transform is not finite",
        node.index()
    );
    Ok(Transform64 { rows })
}

/// Parses and validates a `.gltf` or `.glb` file. gltf-json's validation indexes a
/// primitive's POSITION accessor before checking that it exists, so that is checked first.
fn parse_gltf(bytes: &[u8]) -> crate::Result<gltf::Gltf> {
    use gltf::json::mesh::Semantic;
    use gltf::json::validation::Checked;
    let invalid = |e: gltf::Error| crate::Error::Invalid(format!("not valid glTF: {e}"));
    let unchecked = gltf::Gltf::from_slice_without_validation(bytes).map_err(invalid)?;
    let root = unchecked.document.as_json();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for p in &mesh.primitives {
            if let Some(i) = p.attributes.get(&Checked::Valid(Semantic::Positions)) {
                ensure!(
                    i.value() < root.accessors.len(),
                    "not valid glTF: mesh {m}: POSITION accessor {} of {}",
                    i.value(),
                    root.accessors.len()
                );
            }
        }
    }
    let document = gltf::Document::from_json(unchecked.document.into_json()).map_err(invalid)?;
    Ok(gltf::Gltf {
        document,
        blob: unchecked.blob,
    })
}

/// Builds a Foundry from the bytes of a `.gltf` or `.glb` file; `dir` holds its external
/// buffers.
pub fn gltf_to_foundry(bytes: &[u8], dir: Option<&Path>) -> crate::Result<Foundry> {
    let doc = parse_gltf(bytes)?;
    let buffers = gltf_buffers(&doc, dir)?;
    let scene = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .context("no scene")?;
    let mut f = Foundry::new();
    // Foundry solid of each glTF mesh built so far (None: the mesh has no triangles).
    let mut solids: HashMap<usize, Option<CentredSolid>> = HashMap::new();
    let mut stack: Vec<(gltf::Node, Transform64, usize)> = scene
        .nodes()
        .map(|n| (n, Transform64::IDENTITY, 0))
        .collect();
    let mut visited = 0usize;
    while let Some((node, parent, depth)) = stack.pop() {
        visited += 1;
        ensure!(
            visited <= MAX_GLTF_NODES && depth <= doc.nodes().len(),
            "the node hierarchy has a cycle or expands into more than {MAX_GLTF_NODES} nodes"
        );
        let to_world = parent.compose(&node_transform(&node)?);
        if let Some(mesh) = node.mesh() {
            let built = match solids.entry(mesh.index()) {
                Entry::Occupied(e) => *e.get(),
                Entry::Vacant(e) => {
                    let (positions, triangles) = gltf_mesh_triangles(&mesh, &buffers)?;
                    let name = mesh
                        .name()
                        .map_or_else(|| format!("mesh{}", mesh.index()), str::to_string);
                    let built = if triangles.is_empty() {
                        None
                    } else {
                        Some(add_mesh_solid(&mut f, &name, &positions, &triangles)?)
                    };
                    *e.insert(built)
                }
            };
            if let Some((solid, centre)) = built {
                let placement = to_world.compose(&Transform64::translation(centre));
                let copy = f.inst.len() as i32;
                f.add_instance(solid, placement, UNSET, copy)
                    .with_context(|| format!("placing node {}", node.index()))?;
            }
        }
        stack.extend(node.children().map(|c| (c, to_world, depth + 1)));
    }
    ensure!(
        !f.inst.is_empty(),
        "no triangles (no node has a triangle mesh)"
    );
    f.validate().context("built an invalid Foundry")?;
    Ok(f)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_round_trips_known_strings() {
        assert_eq!(base64_decode("aGVsbG8=").unwrap(), b"hello");
        assert_eq!(base64_decode("aGVsbG8h").unwrap(), b"hello!");
        assert_eq!(base64_decode("aGk").unwrap(), b"hi");
        assert!(base64_decode("a").is_none());
        assert!(base64_decode("a*==").is_none());
    }
}
