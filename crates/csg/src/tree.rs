//! Serialization of a [`Shape`] into the Foundry's complete binary tree.
//!
//! Complements are pushed down to the leaves with De Morgan's laws while the tree is written
//! (`!(A+B) = !A * !B`, `!(A*B) = !A + !B`, `!(A-B) = !A + B`), so operators are never
//! complemented. Placements are accumulated into each leaf's transform.

use hytrace_foundry::{
    aabb_to_f32_outward, CsgTree, Node, Transform64, TypeCode, COMPLEMENT_BIT, MAX_TREE_HEIGHT,
    UNSET,
};

use crate::bounds::{primitive_bounds, transform_bounds, Aabb};
use crate::shape::{CsgError, Shape};

/// Bounds of a subtree: its region when bounded, otherwise only its surfaces.
#[derive(Clone, Copy)]
struct Extent {
    surfaces: Aabb,
    bounded: bool,
}

fn union(a: &Aabb, b: &Aabb) -> Aabb {
    std::array::from_fn(|k| {
        if k < 3 {
            a[k].min(b[k])
        } else {
            a[k].max(b[k])
        }
    })
}

fn intersection(a: &Aabb, b: &Aabb) -> Aabb {
    std::array::from_fn(|k| {
        if k < 3 {
            a[k].max(b[k])
        } else {
            a[k].min(b[k])
        }
    })
}

impl Shape {
    /// Height of the operator tree (a single primitive has height 0).
    pub fn height(&self) -> u32 {
        match self {
            Shape::Leaf(_) => 0,
            Shape::Op(_, a, b) => 1 + a.height().max(b.height()),
            Shape::Placed(_, s) | Shape::Complement(s) => s.height(),
        }
    }
}

struct Writer {
    nodes: Vec<Node>,
    transforms: Vec<Transform64>,
}

impl Writer {
    fn write(
        &mut self,
        shape: &Shape,
        position: usize,
        frame: &Transform64,
        complement: bool,
    ) -> Result<Extent, CsgError> {
        match shape {
            Shape::Placed(t, s) => self.write(s, position, &frame.compose(t), complement),
            Shape::Complement(s) => self.write(s, position, frame, !complement),
            Shape::Leaf(p) => {
                let (code, param, param_ext) = p.node_params();
                let bounds = transform_bounds(&primitive_bounds(p), frame);
                let mut transform = 0;
                if *frame != Transform64::IDENTITY {
                    self.transforms.push(*frame);
                    transform = self.transforms.len() as u32;
                }
                if complement {
                    transform |= COMPLEMENT_BIT;
                }
                self.nodes[position - 1] = Node {
                    param,
                    param_ext,
                    boundary: UNSET,
                    index: UNSET,
                    aabb: aabb_to_f32_outward(&bounds),
                    typecode: code as u32,
                    transform,
                };
                Ok(Extent {
                    surfaces: bounds,
                    bounded: !complement,
                })
            }
            Shape::Op(code, a, b) => {
                // De Morgan: a complemented operator becomes its dual over complemented operands.
                let (code, ca, cb) = match (code, complement) {
                    (c, false) => (*c, false, false),
                    (TypeCode::Union, true) => (TypeCode::Intersection, true, true),
                    (TypeCode::Intersection, true) => (TypeCode::Union, true, true),
                    (_, true) => (TypeCode::Union, true, false),
                };
                let ea = self.write(a, 2 * position, frame, ca)?;
                let eb = self.write(b, 2 * position + 1, frame, cb)?;
                let surfaces = union(&ea.surfaces, &eb.surfaces);
                let extent = match (code, ea.bounded, eb.bounded) {
                    (TypeCode::Union, true, true) => Extent {
                        surfaces,
                        bounded: true,
                    },
                    (TypeCode::Union, ..) => Extent {
                        surfaces,
                        bounded: false,
                    },
                    (TypeCode::Intersection, true, true) => Extent {
                        surfaces: intersection(&ea.surfaces, &eb.surfaces),
                        bounded: true,
                    },
                    (TypeCode::Intersection, true, false) => ea,
                    (TypeCode::Intersection, false, true) => eb,
                    (TypeCode::Difference, true, _) => ea,
                    _ => Extent {
                        surfaces,
                        bounded: false,
                    },
                };
                if extent.bounded && (0..3).any(|k| extent.surfaces[k] > extent.surfaces[k + 3]) {
                    return Err(CsgError {
                        primitive: "intersection",
                        problem: "the operands' bounds do not overlap: the solid is empty"
                            .to_string(),
                    });
                }
                self.nodes[position - 1] = Node {
                    boundary: UNSET,
                    index: UNSET,
                    aabb: aabb_to_f32_outward(&extent.surfaces),
                    typecode: code as u32,
                    ..Node::default()
                };
                Ok(extent)
            }
        }
    }
}

/// Serializes `shape` into a complete binary tree of Foundry nodes with its transforms.
///
/// Fails when the tree is deeper than [`MAX_TREE_HEIGHT`], when the solid is unbounded (its
/// complement reaches the root) or empty (disjoint intersection).
pub fn to_tree(shape: &Shape) -> Result<CsgTree, CsgError> {
    let height = shape.height();
    if height > MAX_TREE_HEIGHT {
        return Err(CsgError {
            primitive: "tree",
            problem: format!("height {height} exceeds the evaluator's limit of {MAX_TREE_HEIGHT}"),
        });
    }
    let mut w = Writer {
        nodes: vec![Node::default(); (1usize << (height + 1)) - 1],
        transforms: Vec::new(),
    };
    let root = w.write(shape, 1, &Transform64::IDENTITY, false)?;
    if !root.bounded {
        return Err(CsgError {
            primitive: "tree",
            problem: "the solid is unbounded (a complement reaches the root)".to_string(),
        });
    }
    Ok(CsgTree {
        nodes: w.nodes,
        transforms: w.transforms,
        planes: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{box3, sphere};

    #[test]
    fn difference_keeps_left_bounds_and_pads_the_tree() {
        let s = (sphere(10.0).unwrap() - box3(4.0, 4.0, 4.0).unwrap().translate(0.0, 0.0, 10.0))
            + sphere(1.0).unwrap().translate(100.0, 0.0, 0.0);
        let t = to_tree(&s).unwrap();
        assert_eq!(t.nodes.len(), 7);
        assert_eq!(t.nodes[0].typecode, TypeCode::Union as u32);
        assert_eq!(t.nodes[1].typecode, TypeCode::Difference as u32);
        assert_eq!(t.nodes[1].aabb, [-10.0, -10.0, -10.0, 10.0, 10.0, 10.0]);
        assert_eq!(t.nodes[0].aabb, [-10.0, -10.0, -10.0, 101.0, 10.0, 10.0]);
        assert_eq!(t.nodes[2].typecode, TypeCode::Sphere as u32);
        assert_eq!(t.nodes[5].typecode, TypeCode::Zero as u32);
        assert_eq!(t.transforms.len(), 2);
    }

    #[test]
    fn de_morgan_pushes_complements_to_leaves() {
        let s = sphere(10.0).unwrap() * !(sphere(5.0).unwrap() - sphere(2.0).unwrap());
        let t = to_tree(&s).unwrap();
        // !(A - B) = !A + B
        assert_eq!(t.nodes[2].typecode, TypeCode::Union as u32);
        assert_eq!(t.nodes[5].transform & COMPLEMENT_BIT, COMPLEMENT_BIT);
        assert_eq!(t.nodes[6].transform & COMPLEMENT_BIT, 0);
        assert_eq!(t.nodes[0].aabb, [-10.0, -10.0, -10.0, 10.0, 10.0, 10.0]);
    }

    #[test]
    fn unbounded_and_empty_solids_are_rejected() {
        assert!(to_tree(&!sphere(1.0).unwrap()).is_err());
        let disjoint = sphere(1.0).unwrap() * sphere(1.0).unwrap().translate(5.0, 0.0, 0.0);
        assert!(to_tree(&disjoint).unwrap_err().problem.contains("empty"));
    }
}
