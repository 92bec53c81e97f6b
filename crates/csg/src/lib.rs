//! Constructive solid geometry for hytrace.
//!
//! - [`Shape`] is a CSG expression built from primitives ([`sphere`], [`box3`], [`tube`],
//!   [`cone`], [`torus`], [`polyhedron`], cuts...) with `+` (union), `*` (intersection), `-`
//!   (difference), `!` (complement) and placement methods. [`to_tree`] serializes it into the
//!   Foundry's complete binary tree of nodes.
//! - [`PrimTree`] prepares a Foundry CSG prim for intersection in f32 or f64 ([`Real`]) and
//!   finds the first surface crossing of a ray without recursion, as the GPU does.
//! - [`geant4`] maps Geant4 solids onto these primitives.

mod bounds;
pub mod bvh_build;
pub mod expr;
pub mod geant4;
pub mod gpu_layout;
pub mod kernel;
pub mod mesh;
mod prepared;
mod prim_tree;
mod real;
mod serialize;
mod shape;
pub mod simd;
mod solid_store;
pub mod tessellate;
pub mod wide_bvh;

/// Random numbers and meshes shared by the unit tests and the integration tests.
#[cfg(test)]
#[path = "../tests/common/mod.rs"]
mod test_common;

pub use bounds::{polyhedron_vertices, transform_bounds, Aabb, EMPTY_AABB, UNBOUNDED};
pub use bvh_build::bvh2_depth;
pub use expr::{parse_shape, ExprError};
pub use mesh::{CrossingScratch, MeshPrim, MeshQuery};
pub use prepared::PreparedPrim;
pub use prim_tree::{
    ray_bounds_entry, ray_bounds_span, ray_meets_bounds, Bounds, PrimTree, SlabRay,
};
pub use real::{Ray, Real, V3};
pub use serialize::{to_tree, to_tree_with, TreeOptions, LIST_MIN_MEMBERS};
pub use shape::{
    box3, cone, cylinder, halfspace, hyperboloid, paraboloid, phi_cut, polyhedron, saddle, slab,
    sphere, theta_cut, torus, tube, twisted_halfspace, zsphere, CsgError, Primitive, Shape,
    MAX_POLYHEDRON_PLANES,
};
pub use solid_store::add_geometry;
