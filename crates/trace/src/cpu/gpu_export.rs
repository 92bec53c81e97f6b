//! The f32 scene as the GPU tracer reads it: every array the scan kernel binds, built from
//! the prepared [`CpuScene<f32>`] itself (its frames, bounds, trees, meshes and BVHs), so
//! the kernel and its CPU twin work on the same numbers.

use hytrace_csg::gpu_layout::mesh::MeshArrays;
use hytrace_csg::gpu_layout::tree::CsgArrays;
use hytrace_csg::{Bounds, PreparedPrim};
use hytrace_foundry::PrimKind;

use super::bvh::BoxBvh;
use super::{CpuScene, Group, Layout};
use crate::gpu::records::{BoxNode, Placement, SearchList, SurfacePrim};

/// The arrays of a scene on the GPU.
#[derive(Default)]
pub struct SceneArrays {
    /// Prepared CSG trees.
    pub csg: CsgArrays,
    /// Prepared meshes.
    pub meshes: MeshArrays,
    /// Every solid's surface prims, solid after solid.
    pub surface_prims: Vec<SurfacePrim>,
    /// Per solid, its surface prims.
    pub solids: Vec<SearchList>,
    /// The placements, by instance index.
    pub placements: Vec<Placement>,
    /// Instance groups: a flat scene's one group, or a hierarchy's roots then the daughters
    /// of each instance (group `i + 1` for instance `i`).
    pub groups: Vec<SearchList>,
    /// Instance ids of the groups.
    pub group_members: Vec<u32>,
    /// Nodes of every box BVH.
    pub box_nodes: Vec<BoxNode>,
    /// Item ids of every box BVH.
    pub box_items: Vec<u32>,
    /// Whether the scene is hierarchical (the navigator's answer).
    pub hierarchical: bool,
}

fn corners(b: &Bounds<f32>) -> ([f32; 3], [f32; 3]) {
    ([b[0].x, b[0].y, b[0].z], [b[1].x, b[1].y, b[1].z])
}

impl SceneArrays {
    /// A search list over `count` members from `first`, with `bvh` exported when present.
    fn search_list(&mut self, first: u32, count: u32, bvh: Option<&BoxBvh<f32>>) -> SearchList {
        let mut list = SearchList {
            first,
            count,
            root: u32::MAX,
            ..Default::default()
        };
        if let Some(bvh) = bvh {
            let (root, unbounded) = bvh.export(&mut self.box_nodes, &mut self.box_items);
            list.has_bvh = 1;
            list.root = root;
            list.unbounded_first = unbounded.start;
            list.unbounded_count = unbounded.len() as u32;
        }
        list
    }

    fn push_group(&mut self, group: &Group<f32>) {
        let first = self.group_members.len() as u32;
        self.group_members.extend_from_slice(&group.members);
        let list = self.search_list(first, group.members.len() as u32, group.bvh.as_deref());
        self.groups.push(SearchList {
            largest: group.largest,
            ..list
        });
    }
}

impl CpuScene<f32> {
    /// Every array the GPU tracer binds.
    pub fn gpu_arrays(&self) -> crate::Result<SceneArrays> {
        let mut out = SceneArrays::default();
        for solid in &self.solids {
            let first = out.surface_prims.len() as u32;
            for (prim, &foundry_prim) in solid.prims.iter().zip(&solid.prim_ids) {
                let (kind, index) = match prim {
                    PreparedPrim::Csg(tree) => (PrimKind::Csg, out.csg.push(tree)),
                    PreparedPrim::Mesh(mesh) => (PrimKind::Mesh, out.meshes.push(mesh)?),
                };
                let (lo, hi) = corners(prim.bounds());
                out.surface_prims.push(SurfacePrim {
                    lo,
                    kind: kind as u32,
                    hi,
                    index,
                    foundry_prim,
                    pad: [0; 3],
                });
            }
            let list = out.search_list(first, solid.prims.len() as u32, solid.bvh.as_ref());
            out.solids.push(list);
        }
        out.placements = self
            .placements
            .iter()
            .map(|p| {
                let (lo, hi) = corners(&p.bounds);
                Placement {
                    rows: p.frame.rows(),
                    lo,
                    solid: p.solid as u32,
                    hi,
                    sdf_decides: (self.solids[p.solid].sdf_decides && p.rigid) as u32,
                    origin_lo: p.origin_lo.to_f64().map(|c| c as f32),
                    pad_lo: 0,
                    centre: p.centre.to_f64().map(|c| c as f32),
                    reach: p.reach,
                }
            })
            .collect();
        match &self.layout {
            Layout::Flat(all) => out.push_group(all),
            Layout::Tree(h) => {
                out.hierarchical = true;
                out.push_group(&h.roots);
                for d in &h.daughters {
                    out.push_group(d);
                }
            }
        }
        Ok(out)
    }
}
