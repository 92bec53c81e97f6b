//! Constructive solid geometry for hytrace.
//!
//! [`Shape`] is a CSG expression built from primitives ([`sphere`], [`box3`], [`cylinder`],
//! [`cone`], [`torus`]) with `+` (union), `*` (intersection), `-` (difference), `!`
//! (complement) and placement methods. [`Shape::to_tree`] serializes it into the Foundry's
//! complete binary tree of nodes, with each leaf's transform and every node's bounds.

mod bounds;
mod shape;
mod tree;

pub use shape::{box3, cone, cylinder, sphere, torus, CsgError, Primitive, Shape};
pub use tree::to_tree;
