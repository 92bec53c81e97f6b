//! A Foundry prim of either surface kind (CSG tree or triangle mesh) prepared for tracing.

use hytrace_foundry::{Foundry, PrimKind};

use crate::kernel::Step;
use crate::mesh::MeshPrim;
use crate::prim_tree::{Bounds, PrimTree};
use crate::real::{Ray, Real, V3};
use crate::shape::CsgError;

/// A prim with surfaces: a CSG tree or a triangle mesh.
#[derive(Clone, Debug, PartialEq)]
pub enum PreparedPrim<T> {
    /// A CSG tree.
    Csg(PrimTree<T>),
    /// A triangle mesh, closed or open (see [`MeshPrim`]).
    Mesh(MeshPrim<T>),
}

impl<T: Real> PreparedPrim<T> {
    /// Prepares prim `prim` of a validated Foundry; `None` for volume prims (media, not
    /// surfaces).
    pub fn from_foundry(foundry: &Foundry, prim: usize) -> Result<Option<Self>, CsgError> {
        let kind = foundry.prim.get(prim).map(|p| p.kind);
        Ok(match kind {
            Some(k) if k == PrimKind::Csg as u32 => {
                Some(PreparedPrim::Csg(PrimTree::from_foundry(foundry, prim)?))
            }
            Some(k) if k == PrimKind::Mesh as u32 => {
                Some(PreparedPrim::Mesh(MeshPrim::from_foundry(foundry, prim)?))
            }
            _ => None,
        })
    }

    /// Bounds in the solid's frame.
    pub fn bounds(&self) -> &Bounds<T> {
        match self {
            PreparedPrim::Csg(t) => t.bounds(),
            PreparedPrim::Mesh(m) => m.bounds(),
        }
    }

    /// The first surface crossing after `tmin` (see [`PrimTree::first_crossing`]).
    pub fn first_crossing(&self, ray: &Ray<T>, tmin: T) -> Step<T> {
        match self {
            PreparedPrim::Csg(t) => t.first_crossing(ray, tmin),
            PreparedPrim::Mesh(m) => m.first_crossing(ray, tmin),
        }
    }

    /// Whether a point of the solid's frame is inside.
    pub fn contains(&self, x: V3<T>) -> bool {
        match self {
            PreparedPrim::Csg(t) => t.contains(x),
            PreparedPrim::Mesh(m) => m.contains(x),
        }
    }
}
