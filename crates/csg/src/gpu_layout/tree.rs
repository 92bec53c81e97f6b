//! GPU records of prepared CSG trees (crates/csg/src/prim_tree.rs): the slots of each
//! tree's complete binary tree, the members of its list slots, their planes and frames,
//! exactly the f32 values [`PrimTree<f32>`] evaluates, and the seam-probe directions of
//! [`PrimTree::contains`]. The WGSL twin is `shaders/csg/tree.wgsl`.

use hytrace_foundry::record;
use hytrace_foundry::{TypeCode, COMPLEMENT_BIT, UNSET};

use super::{entry, FrameRecord, RecordEntry};
use crate::kernel::Leaf;
use crate::prim_tree::{probe_direction, Bounds, PrimTree, Slot, SEAM_PROBES};

record! {
    /// One slot of a tree (position `p` of the tree is `CsgTree::node_offset + p - 1`) or
    /// one member of a list slot.
    pub struct CsgNode {
        /// Primitive parameters `param` (see [`TypeCode`]).
        pub param: [f32; 4],
        /// List slots and list members: their bounds `[min, max]` in the tree's frame.
        pub bounds: [f32; 6],
        /// Primitive parameters `param_ext`.
        pub param_ext: [f32; 2],
        /// The typecode (0: empty slot), with `COMPLEMENT_BIT` set on complemented leaves.
        pub code: u32,
        /// Leaves: index of the leaf's frame in the frames array (`UNSET`: none).
        pub frame: u32,
        /// Polyhedra: first plane in the planes array; list slots: first member node.
        pub first: u32,
        /// Polyhedra: number of planes; list slots: number of members.
        pub count: u32,
    }
}

record! {
    /// One prepared tree (see [`PrimTree`]).
    pub struct CsgTree {
        /// The tree's bounds, widened by the surface tolerance ([`PrimTree::bounds`]).
        pub bounds: [f32; 6],
        /// Index of the tree's root slot (position 1) in the nodes array.
        pub node_offset: u32,
        /// Height of the complete binary tree (0: a single slot).
        pub height: u32,
        /// The size the surface tolerance scales with.
        pub scale: f32,
        /// The surface tolerance at the farthest point of the bounds.
        pub near_max: f32,
    }
}

/// Every record of this module.
pub fn records() -> Vec<RecordEntry> {
    vec![entry::<CsgNode>(), entry::<CsgTree>()]
}

/// Appends the WGSL declarations of this module's records and the table of seam-probe
/// directions (`CSG_SEAM_PROBES`, rounded from the CPU's f64 directions to f32 as the CPU's
/// f32 trees round them).
pub fn push_wgsl(out: &mut String) {
    hytrace_foundry::wgsl::push_struct::<CsgNode>(out);
    hytrace_foundry::wgsl::push_struct::<CsgTree>(out);
    out.push_str(&format!(
        "// Directions of the rays that decide inside tests on faces union members share.\n\
         const CSG_SEAM_PROBE_COUNT: u32 = {SEAM_PROBES}u;\n\
         const CSG_SEAM_PROBES: array<vec3<f32>, {SEAM_PROBES}> = array<vec3<f32>, {SEAM_PROBES}>(\n"
    ));
    for k in 0..SEAM_PROBES {
        let [x, y, z] = probe_direction(k).map(|v| v as f32);
        out.push_str(&format!("    vec3<f32>({x:?}f, {y:?}f, {z:?}f),\n"));
    }
    out.push_str(");\n\n");
}

/// Prepared trees packed into the arrays the GPU binds (see `shaders/csg/tree_bindings.wgsl`):
/// every offset is absolute into these arrays.
#[derive(Clone, Debug, Default)]
pub struct CsgArrays {
    /// Slots of every tree, each tree's list members after its slots.
    pub nodes: Vec<CsgNode>,
    /// Convex polyhedron planes `(nx, ny, nz, d)`.
    pub planes: Vec<[f32; 4]>,
    /// Leaf frames.
    pub frames: Vec<FrameRecord>,
    /// One record per tree.
    pub trees: Vec<CsgTree>,
}

fn flat_bounds(b: &Bounds<f32>) -> [f32; 6] {
    [b[0].x, b[0].y, b[0].z, b[1].x, b[1].y, b[1].z]
}

impl CsgArrays {
    /// Appends `tree`; returns its index in `trees`.
    pub fn push(&mut self, tree: &PrimTree<f32>) -> u32 {
        let plane_base = self.planes.len() as u32;
        self.planes.extend_from_slice(&tree.planes);
        let node_offset = self.nodes.len() as u32;
        let member_base = node_offset + tree.slots.len() as u32;
        for slot in &tree.slots {
            let node = match slot {
                Slot::Empty => CsgNode::default(),
                Slot::Operator(code) => CsgNode {
                    code: *code as u32,
                    ..CsgNode::default()
                },
                Slot::List {
                    code,
                    members,
                    bounds,
                } => CsgNode {
                    code: *code as u32,
                    bounds: flat_bounds(bounds),
                    first: member_base + members.start as u32,
                    count: members.len() as u32,
                    frame: UNSET,
                    ..CsgNode::default()
                },
                Slot::Leaf(leaf) => self.leaf_node(leaf, plane_base, [0.0; 6]),
            };
            self.nodes.push(node);
        }
        for (leaf, bounds) in &tree.members {
            let node = self.leaf_node(leaf, plane_base, flat_bounds(bounds));
            self.nodes.push(node);
        }
        self.trees.push(CsgTree {
            bounds: flat_bounds(&tree.bounds),
            node_offset,
            height: tree.height,
            scale: tree.scale,
            near_max: tree.near_max,
        });
        self.trees.len() as u32 - 1
    }

    /// The node of a leaf (its frame appended to `frames`).
    fn leaf_node(&mut self, leaf: &Leaf<f32>, plane_base: u32, bounds: [f32; 6]) -> CsgNode {
        let frame = match &leaf.frame {
            Some(f) => {
                self.frames.push(FrameRecord::new(f));
                self.frames.len() as u32 - 1
            }
            None => UNSET,
        };
        let p = leaf.params;
        let (first, count) = if leaf.code == TypeCode::ConvexPolyhedron {
            (
                plane_base + leaf.planes.start as u32,
                leaf.planes.len() as u32,
            )
        } else {
            (0, 0)
        };
        CsgNode {
            param: [p[0], p[1], p[2], p[3]],
            bounds,
            param_ext: [p[4], p[5]],
            code: leaf.code as u32 | if leaf.complement { COMPLEMENT_BIT } else { 0 },
            frame,
            first,
            count,
        }
    }
}
