//! The flat Foundry store of hytrace.
//!
//! A scene is a handful of arrays of 64-byte POD records (solids, prims, CSG nodes,
//! instances, volume bricks) plus planes, transforms and triangles, in the style of Opticks'
//! CSGFoundry. The arrays go to the GPU as they are (eight storage buffers, see
//! [`gpu_arrays`]) and to NumPy as `.npy` files (see [`Foundry::save`]). Every reference
//! between arrays is validated before anything reads through it ([`Foundry::validate`]).

pub mod error;
pub mod g4solid;
pub mod gdml;
pub mod layout;
mod merge;
pub mod npy;
pub mod optics;
mod persist;
pub mod records;
mod store;
pub mod typecode;
mod validate;
pub mod wgsl;

pub use error::{FoundryError, Result};
pub use merge::Appended;
pub use persist::{file_names, gpu_arrays, FORMAT_NAME, FORMAT_VERSION};
pub use records::{
    pack_label, Affine64, Brick, Instance, Mother, Node, NodeParam64, Plane, Plane64, Prim, Solid,
    Transform, Transform64, Triangle, COMPLEMENT_BIT,
};
pub use store::{aabb_to_f32_outward, aabb_union, CsgTree, Foundry, SolidBuilder, UNSET};
pub use typecode::{PrimKind, TypeCode};
pub use validate::{tree_height, MAX_TREE_HEIGHT};
