//! GPU records of prepared triangle meshes ([`MeshPrim<f32>`], crates/csg/src/mesh.rs): its
//! BVH nodes, reordered triangles, bounds and scale exactly as the CPU's f32 kernel reads
//! them, for the WGSL twin `shaders/mesh/mesh.wgsl`.
//!
//! Meshes are concatenated into three arrays ([`MeshArrays`]). A node's `first` stays
//! relative to its own mesh, as in [`MeshPrim`]: a child pair is at
//! `node_offset + first`, a leaf's triangles at `triangle_offset + first ..`, with the
//! offsets of the mesh's [`MeshRecord`].

use std::fmt::Write;

use super::RecordEntry;
use crate::mesh::{MeshPrim, MAX_BVH_DEPTH, PARITY_BUFFER, PARITY_DIRECTION};
use crate::shape::CsgError;

hytrace_foundry::record! {
    /// A BVH node of a mesh: padded bounds, then either children `first, first + 1`
    /// (`count == 0`) or triangles `first..first + count`, both relative to the mesh's
    /// offsets.
    pub struct MeshNode {
        /// Lower corner.
        pub lo: [f32; 3],
        /// First child or first triangle.
        pub first: u32,
        /// Upper corner.
        pub hi: [f32; 3],
        /// Triangles of a leaf; 0 for an inner node.
        pub count: u32,
    }
}

hytrace_foundry::record! {
    /// A triangle of a mesh, counter-clockwise seen from outside (`w` unused, 0).
    pub struct MeshTriangle {
        /// Vertices `v0, v1, v2`.
        pub v: [[f32; 4]; 3],
    }
}

hytrace_foundry::record! {
    /// One mesh: its bounds, surface-tolerance scale, and where its nodes and triangles
    /// start in the concatenated arrays.
    pub struct MeshRecord {
        /// Lower corner of the mesh's padded bounds.
        pub lo: [f32; 3],
        /// Index of the mesh's root node in the node array.
        pub node_offset: u32,
        /// Upper corner of the mesh's padded bounds.
        pub hi: [f32; 3],
        /// Index of the mesh's first triangle in the triangle array.
        pub triangle_offset: u32,
        /// The scale of the mesh's surface tolerance (half its size).
        pub scale: f32,
        /// Nodes of the mesh.
        pub node_count: u32,
        /// Triangles of the mesh.
        pub triangle_count: u32,
        /// Padding to 16 bytes.
        pub pad: u32,
    }
}

/// Prepared meshes in the form the GPU binds (`shaders/mesh/bindings.wgsl`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshArrays {
    /// Nodes of every mesh, mesh after mesh.
    pub nodes: Vec<MeshNode>,
    /// Triangles of every mesh, mesh after mesh.
    pub triangles: Vec<MeshTriangle>,
    /// Per mesh, its record.
    pub meshes: Vec<MeshRecord>,
}

/// Levels below the root of a laid-out mesh BVH (the traversal's stack needs one slot per
/// level).
fn depth(mesh: &MeshPrim<f32>) -> usize {
    crate::bvh_build::binary_tree_depth(|i| {
        let n = mesh.nodes.get(i)?;
        Some((n.count == 0).then_some(n.first as usize))
    })
}

impl MeshArrays {
    /// Appends a mesh and returns its index. Fails when its BVH is deeper than the GPU
    /// traversal's stack ([`MeshPrim::new`] already refuses those) or the arrays outgrow
    /// u32 indices.
    pub fn push(&mut self, mesh: &MeshPrim<f32>) -> Result<u32, CsgError> {
        let err = |problem: String| CsgError {
            primitive: "mesh",
            problem,
        };
        let levels = depth(mesh);
        if levels > MAX_BVH_DEPTH {
            return Err(err(format!(
                "BVH is {levels} levels deep, more than the GPU stack's {MAX_BVH_DEPTH}"
            )));
        }
        let index = |n: usize| u32::try_from(n).map_err(|_| err("too many meshes".into()));
        let record = MeshRecord {
            lo: [mesh.bounds[0].x, mesh.bounds[0].y, mesh.bounds[0].z],
            node_offset: index(self.nodes.len())?,
            hi: [mesh.bounds[1].x, mesh.bounds[1].y, mesh.bounds[1].z],
            triangle_offset: index(self.triangles.len())?,
            scale: mesh.scale,
            node_count: index(mesh.nodes.len())?,
            triangle_count: index(mesh.triangles.len())?,
            pad: 0,
        };
        index(self.nodes.len() + mesh.nodes.len())?;
        index(self.triangles.len() + mesh.triangles.len())?;
        let mesh_index = index(self.meshes.len())?;
        self.nodes.extend(mesh.nodes.iter().map(|n| MeshNode {
            lo: [n.bounds[0].x, n.bounds[0].y, n.bounds[0].z],
            first: n.first,
            hi: [n.bounds[1].x, n.bounds[1].y, n.bounds[1].z],
            count: n.count,
        }));
        self.triangles
            .extend(mesh.triangles.iter().map(|t| MeshTriangle {
                v: t.map(|p| [p.x, p.y, p.z, 0.0]),
            }));
        self.meshes.push(record);
        Ok(mesh_index)
    }
}

/// Every record of this module.
pub fn records() -> Vec<RecordEntry> {
    vec![
        super::entry::<MeshNode>(),
        super::entry::<MeshTriangle>(),
        super::entry::<MeshRecord>(),
    ]
}

/// Appends the WGSL declarations of this module's records and the constants of the mesh
/// kernel (its stack depth, parity buffer and parity direction rounded to f32, written as
/// the exact decimal values of those f32s).
pub fn push_wgsl(out: &mut String) {
    hytrace_foundry::wgsl::push_struct::<MeshNode>(out);
    hytrace_foundry::wgsl::push_struct::<MeshTriangle>(out);
    hytrace_foundry::wgsl::push_struct::<MeshRecord>(out);
    let [x, y, z] = PARITY_DIRECTION.map(|c| c as f32 as f64);
    writeln!(out, "const MESH_MAX_BVH_DEPTH: u32 = {MAX_BVH_DEPTH}u;").unwrap();
    writeln!(out, "const MESH_PARITY_BUFFER: u32 = {PARITY_BUFFER}u;").unwrap();
    writeln!(
        out,
        "const MESH_PARITY_DIRECTION: vec3<f32> = vec3<f32>({x:?}, {y:?}, {z:?});\n"
    )
    .unwrap();
}
