//! The Foundry: every array of a scene, and the builder that appends solids to it.

use crate::error::{FoundryError, Result};
use crate::optics::Optics;
use crate::records::{
    pack_label, Affine64, Brick, Instance, Mother, Node, NodeParam64, Plane, Plane64, Prim, Solid,
    Transform, Transform64, Triangle, COMPLEMENT_BIT,
};
use crate::typecode::{PrimKind, TypeCode};

/// Boundary and identity value meaning "unset".
pub const UNSET: u32 = u32::MAX;

/// A whole scene in flat arrays of POD records.
///
/// Indices between arrays are plain integers, so the arrays can be uploaded to a GPU or
/// written to `.npy` files as they are. The GPU receives eight of them: `solid`, `prim`,
/// `node`, `plan`, `itra`, `inst`, `tri` and `brick`. `tran`, `inst_tran`, `node64` and
/// `plan64` keep the double precision originals for the CPU's f64 path.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Foundry {
    /// Solids: ranges of prims.
    pub solid: Vec<Solid>,
    /// Prims: CSG trees, triangle ranges or brick ranges.
    pub prim: Vec<Prim>,
    /// CSG nodes, each prim's tree stored as a complete binary tree.
    pub node: Vec<Node>,
    /// Double-precision originals of the nodes' parameters (CPU only), one per node.
    pub node64: Vec<NodeParam64>,
    /// Planes of convex polyhedra.
    pub plan: Vec<Plane>,
    /// Double-precision originals of the planes (CPU only), one per plane.
    pub plan64: Vec<Plane64>,
    /// Node and prim transforms (local to parent), double precision originals.
    pub tran: Vec<Transform64>,
    /// Inverses of `tran` in single precision, for the GPU.
    pub itra: Vec<Transform>,
    /// Placements of solids in the world.
    pub inst: Vec<Instance>,
    /// Local-to-world transforms of `inst`, double precision originals.
    pub inst_tran: Vec<Affine64>,
    /// Mother instance of each instance (CPU only; hierarchical scenes such as GDML).
    pub inst_mother: Vec<Mother>,
    /// Triangles of mesh prims.
    pub tri: Vec<Triangle>,
    /// Bricks of volume prims.
    pub brick: Vec<Brick>,
    /// Full name of every solid.
    pub solid_names: Vec<String>,
    /// Materials, optical surfaces, boundaries and volume names.
    pub optics: Optics,
}

/// One CSG tree ready to be appended as a prim.
///
/// `nodes` is a complete binary tree in level order; `members` holds the primitives of its
/// list nodes, stored right after the tree (a list node's `param[0]` is the 0-based index of
/// its first member in `members`, `param[1]` the count). Node transform indices are 1-based
/// into `transforms` (0: none, bit 31: complement) and convex-polyhedron plane indices are
/// 0-based into `planes`. All are relocated when the prim is added.
#[derive(Clone, Debug, Default)]
pub struct CsgTree {
    /// Nodes of the complete binary tree, root first.
    pub nodes: Vec<Node>,
    /// Members of the tree's list nodes.
    pub members: Vec<Node>,
    /// Double-precision parameters of `nodes` then `members` (empty: the f32 values
    /// widened).
    pub node64: Vec<NodeParam64>,
    /// Transforms referenced by the nodes.
    pub transforms: Vec<Transform64>,
    /// Planes referenced by convex-polyhedron nodes.
    pub planes: Vec<Plane>,
    /// Double-precision planes (empty: the f32 planes widened).
    pub planes64: Vec<Plane64>,
}

/// Appends the prims of one solid to a [`Foundry`]; see [`Foundry::begin_solid`].
pub struct SolidBuilder<'a> {
    foundry: &'a mut Foundry,
    name: String,
    first_prim: usize,
}

impl Foundry {
    /// An empty Foundry.
    pub fn new() -> Self {
        Self::default()
    }

    /// Whether instances are placed inside others (a GDML placement tree): the tracers
    /// then navigate, answering the boundaries of the volume a point is located in.
    pub fn is_hierarchical(&self) -> bool {
        self.inst_mother.iter().any(|m| m.index != UNSET)
    }

    /// Starts a solid; its prims are added through the returned builder.
    pub fn begin_solid(&mut self, name: &str) -> SolidBuilder<'_> {
        let first_prim = self.prim.len();
        SolidBuilder {
            foundry: self,
            name: name.to_string(),
            first_prim,
        }
    }

    /// Appends a transform and its inverse; returns its 1-based index.
    pub fn add_transform(&mut self, transform: Transform64) -> Result<u32> {
        let inverse = invert(&transform)?;
        self.tran.push(transform);
        self.itra.push(inverse.to_f32());
        index_u32(self.tran.len(), "transforms")
    }

    /// Places `solid` in the world with the local-to-world `transform`; returns the
    /// instance index.
    pub fn add_instance(
        &mut self,
        solid: u32,
        transform: Transform64,
        identity: u32,
        copy_number: i32,
    ) -> Result<usize> {
        if solid as usize >= self.solid.len() {
            return Err(FoundryError::Build(format!(
                "instance of solid {solid}, but only {} solids exist",
                self.solid.len()
            )));
        }
        let inverse = invert(&transform)?.to_f32();
        self.inst.push(Instance {
            itra: [inverse.rows[0], inverse.rows[1], inverse.rows[2]],
            solid,
            identity,
            copy_number,
            boundary: UNSET,
        });
        self.inst_tran.push(Affine64::from_transform(&transform));
        self.inst_mother.push(Mother { index: UNSET });
        Ok(self.inst.len() - 1)
    }
}

impl SolidBuilder<'_> {
    /// Appends a CSG tree as a prim; returns the prim index.
    pub fn add_csg(&mut self, tree: CsgTree, identity: u32, boundary: u32) -> Result<usize> {
        let f = &mut *self.foundry;
        let n = tree.nodes.len();
        if n == 0 || !(n + 1).is_power_of_two() {
            return Err(FoundryError::Build(format!(
                "solid `{}`: a CSG tree needs 2^k - 1 nodes, got {n}",
                self.name
            )));
        }
        let tran_offset = index_u32(f.tran.len(), "transforms")?;
        let plan_offset = index_u32(f.plan.len(), "planes")?;
        let node_offset = index_u32(f.node.len(), "nodes")?;
        let members_offset = node_offset + n as u32;
        let mut nodes = tree.nodes;
        nodes.extend(tree.members.iter().copied());
        for (i, node) in nodes.iter_mut().enumerate() {
            let local = node.transform & !COMPLEMENT_BIT;
            if local as usize > tree.transforms.len() {
                return Err(FoundryError::Build(format!(
                    "solid `{}`: node {i} uses transform {local} of {}",
                    self.name,
                    tree.transforms.len()
                )));
            }
            if local > 0 {
                node.transform += tran_offset;
            }
            // Convex polyhedra index the tree's planes, lists its members (lists only in
            // the tree itself): check the range, then make it absolute.
            let code = TypeCode::from_u32(node.typecode);
            let range = match code {
                Some(TypeCode::ConvexPolyhedron) => {
                    Some(("planes", tree.planes.len(), plan_offset))
                }
                Some(c) if c.is_list() && i < n => {
                    Some(("members", tree.members.len(), members_offset))
                }
                Some(c) if c.is_list() => {
                    return Err(FoundryError::Build(format!(
                        "solid `{}`: list member {i} is itself a list",
                        self.name
                    )));
                }
                _ => None,
            };
            if let Some((what, available, offset)) = range {
                let first = node.param[0].to_bits();
                let end = first as usize + node.param[1].to_bits() as usize;
                if end > available {
                    return Err(FoundryError::Build(format!(
                        "solid `{}`: node {i} uses {what} {first}..{end} of {available}",
                        self.name
                    )));
                }
                node.param[0] = f32::from_bits(first + offset);
            }
        }
        let mut node64 = double_copies(
            tree.node64,
            &nodes,
            NodeParam64::widened,
            &self.name,
            "node",
        )?;
        // Index-carrying nodes were relocated: their f64 copies follow the f32 values.
        for (p, n) in node64.iter_mut().zip(&nodes) {
            let code = TypeCode::from_u32(n.typecode);
            if !code.is_some_and(TypeCode::is_primitive) || code == Some(TypeCode::ConvexPolyhedron)
            {
                *p = NodeParam64::widened(n);
            }
        }
        let widen_plane = |p: &Plane| Plane64 {
            plane: p.plane.map(f64::from),
        };
        let planes64 = double_copies(
            tree.planes64,
            &tree.planes,
            widen_plane,
            &self.name,
            "plane",
        )?;
        for t in tree.transforms {
            f.add_transform(t)?;
        }
        f.plan.extend(tree.planes);
        f.plan64.extend(planes64);
        f.node64.extend(node64);
        let aabb = nodes[0].aabb;
        f.node.extend(nodes);
        f.prim.push(Prim {
            num_node: n as u32,
            node_offset,
            tran_offset,
            plan_offset,
            kind: PrimKind::Csg as u32,
            aabb,
            identity,
            boundary,
            ..Prim::default()
        });
        Ok(f.prim.len() - 1)
    }

    /// Appends a triangle mesh as a prim, its vertices mapped into the solid's frame by
    /// `transform` (identity when `None`); returns the prim index.
    pub fn add_mesh(
        &mut self,
        triangles: &[Triangle],
        transform: Option<Transform64>,
        identity: u32,
        boundary: u32,
    ) -> Result<usize> {
        if triangles.is_empty() {
            return Err(FoundryError::Build(format!(
                "solid `{}`: a mesh prim needs at least one triangle",
                self.name
            )));
        }
        let points = triangles
            .iter()
            .flat_map(|t| t.v.iter().map(|v| [v[0] as f64, v[1] as f64, v[2] as f64]));
        let aabb = transformed_bounds(points, transform.as_ref());
        let f = &mut *self.foundry;
        let item_offset = index_u32(f.tri.len(), "triangles")?;
        f.tri.extend_from_slice(triangles);
        self.push_data_prim(
            PrimKind::Mesh,
            item_offset,
            triangles.len(),
            aabb,
            transform,
            identity,
            boundary,
        )
    }

    /// Appends volume bricks (index space) as a prim, mapped into the solid's frame by
    /// `transform`; returns the prim index. Each brick's `prim` field is set here.
    pub fn add_volume(
        &mut self,
        bricks: &[Brick],
        transform: Option<Transform64>,
        identity: u32,
    ) -> Result<usize> {
        if bricks.is_empty() {
            return Err(FoundryError::Build(format!(
                "solid `{}`: a volume prim needs at least one brick",
                self.name
            )));
        }
        let corners = bricks.iter().flat_map(|b| {
            [
                [b.aabb[0], b.aabb[1], b.aabb[2]],
                [b.aabb[3], b.aabb[4], b.aabb[5]],
            ]
            .map(|c| c.map(f64::from))
        });
        let aabb = transformed_bounds(corners, transform.as_ref());
        let f = &mut *self.foundry;
        let prim = index_u32(f.prim.len(), "prims")?;
        let item_offset = index_u32(f.brick.len(), "bricks")?;
        f.brick.extend(bricks.iter().map(|b| Brick { prim, ..*b }));
        self.push_data_prim(
            PrimKind::Volume,
            item_offset,
            bricks.len(),
            aabb,
            transform,
            identity,
            UNSET,
        )
    }

    #[allow(clippy::too_many_arguments)]
    fn push_data_prim(
        &mut self,
        kind: PrimKind,
        item_offset: u32,
        item_count: usize,
        aabb: [f32; 6],
        transform: Option<Transform64>,
        identity: u32,
        boundary: u32,
    ) -> Result<usize> {
        let f = &mut *self.foundry;
        let transform = match transform {
            Some(t) => f.add_transform(t)?,
            None => 0,
        };
        f.prim.push(Prim {
            kind: kind as u32,
            item_offset,
            item_count: index_u32(item_count, "items")?,
            tran_offset: index_u32(f.tran.len(), "transforms")?,
            plan_offset: index_u32(f.plan.len(), "planes")?,
            aabb,
            transform,
            identity,
            boundary,
            ..Prim::default()
        });
        Ok(f.prim.len() - 1)
    }

    /// Closes the solid; returns its index.
    pub fn finish(self, identity: u32) -> Result<u32> {
        let f = self.foundry;
        let prims = &f.prim[self.first_prim..];
        if prims.is_empty() {
            return Err(FoundryError::Build(format!(
                "solid `{}` has no prims",
                self.name
            )));
        }
        let summary = crate::validate::summarize_prims(prims);
        if !summary.aabb.iter().all(|v| v.is_finite()) {
            return Err(FoundryError::Build(format!(
                "solid `{}`: its bounds {:?} are not finite (a size beyond f32's range?)",
                self.name, summary.aabb
            )));
        }
        f.solid.push(Solid {
            label: pack_label(&self.name),
            num_prim: prims.len() as u32,
            prim_offset: self.first_prim as u32,
            content: summary.content,
            max_height: summary.max_height,
            aabb: summary.aabb,
            extent: summary.extent,
            identity,
        });
        f.solid_names.push(self.name);
        index_u32(f.solid.len() - 1, "solids")
    }
}

/// The double-precision copies of `narrow` records: `given` when it has one per record,
/// the f32 values widened when it is empty.
fn double_copies<W, N>(
    given: Vec<W>,
    narrow: &[N],
    widen: impl Fn(&N) -> W,
    solid: &str,
    what: &str,
) -> Result<Vec<W>> {
    if given.is_empty() {
        Ok(narrow.iter().map(widen).collect())
    } else if given.len() == narrow.len() {
        Ok(given)
    } else {
        Err(FoundryError::Build(format!(
            "solid `{solid}`: {} double-precision {what} rows for {} {what}s",
            given.len(),
            narrow.len()
        )))
    }
}

/// Union of AABBs given as min xyz, max xyz.
pub fn aabb_union(a: [f32; 6], b: [f32; 6]) -> [f32; 6] {
    [
        a[0].min(b[0]),
        a[1].min(b[1]),
        a[2].min(b[2]),
        a[3].max(b[3]),
        a[4].max(b[4]),
        a[5].max(b[5]),
    ]
}

/// Bounds of points after an optional transform, rounded outward to f32.
fn transformed_bounds(
    points: impl Iterator<Item = [f64; 3]>,
    transform: Option<&Transform64>,
) -> [f32; 6] {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        let q = transform.map_or(p, |t| t.apply_point(p));
        for k in 0..3 {
            lo[k] = lo[k].min(q[k]);
            hi[k] = hi[k].max(q[k]);
        }
    }
    aabb_to_f32_outward(&[lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]])
}

/// Rounds double-precision bounds (min xyz, max xyz) outward to single precision, so the
/// f32 box still contains the f64 one.
pub fn aabb_to_f32_outward(b: &[f64; 6]) -> [f32; 6] {
    std::array::from_fn(|k| {
        let f = b[k] as f32;
        if k < 3 && f as f64 > b[k] {
            f.next_down()
        } else if k >= 3 && (f as f64) < b[k] {
            f.next_up()
        } else {
            f
        }
    })
}

pub(crate) fn invert(t: &Transform64) -> Result<Transform64> {
    if !t.is_affine() {
        return Err(FoundryError::Build(format!(
            "transform is not a finite affine matrix: {:?}",
            t.rows
        )));
    }
    t.inverse()
        .ok_or_else(|| FoundryError::Build(format!("transform is singular: {:?}", t.rows)))
}

pub(crate) fn index_u32(n: usize, what: &str) -> Result<u32> {
    u32::try_from(n).map_err(|_| FoundryError::Build(format!("too many {what}: {n}")))
}
