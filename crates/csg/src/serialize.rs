//! Serialization of a [`Shape`] into the Foundry's complete binary tree.
//!
//! The expression is first brought to positive form: placements are accumulated into each
//! leaf's transform and complements pushed down to the leaves with De Morgan's laws
//! (`!(A+B) = !A * !B`, `!(A*B) = !A + !B`, `!(A-B) = !A + B`), so operators are never
//! complemented. Then chains of one operator are regrouped, which keeps trees shallow and
//! complete binary trees small:
//! - a union or intersection of many operands becomes an n-ary list node holding its plain
//!   primitive operands ([`LIST_MIN_MEMBERS`] or more), joined with the remaining operands
//!   in a balanced tree;
//! - `((A - B) - C) - D` becomes `A - (B + C + D)`, the subtracted part balanced the same way.
//!
//! These rewrites are exact (associativity and commutativity of union and intersection). A
//! tree still deeper than [`MAX_TREE_HEIGHT`] is rejected.

use hytrace_foundry::{
    aabb_to_f32_outward, CsgTree, Node, NodeParam64, Plane, Plane64, Transform64, TypeCode,
    COMPLEMENT_BIT, MAX_TREE_HEIGHT, UNSET,
};

use crate::bounds::{primitive_bounds, transform_bounds, Aabb};
use crate::shape::{CsgError, Primitive, Shape};

/// Fewest plain primitive operands of a union or intersection that become a list node.
pub const LIST_MIN_MEMBERS: usize = 6;

/// How [`to_tree_with`] regroups chains of one operator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TreeOptions {
    /// Whether many plain operands of a union or intersection become one list node (the
    /// default); without lists they are joined in a balanced binary tree, which has the
    /// same surfaces but a taller tree and more nodes.
    pub lists: bool,
}

impl Default for TreeOptions {
    fn default() -> Self {
        TreeOptions { lists: true }
    }
}

/// An expression in positive form.
#[derive(Clone, Debug)]
enum Positive {
    Leaf {
        primitive: Primitive,
        frame: Transform64,
        complement: bool,
    },
    Op(TypeCode, Box<Positive>, Box<Positive>),
    List(TypeCode, Vec<Positive>),
}

impl Positive {
    fn height(&self) -> u32 {
        match self {
            Positive::Leaf { .. } | Positive::List(..) => 0,
            Positive::Op(_, a, b) => 1 + a.height().max(b.height()),
        }
    }

    fn is_plain_leaf(&self) -> bool {
        matches!(self, Positive::Leaf { primitive, complement: false, .. } if primitive.is_bounded())
    }
}

/// Places and positivizes a shape.
fn positive(shape: &Shape, frame: &Transform64, complement: bool) -> Positive {
    match shape {
        Shape::Placed(t, s) => positive(s, &frame.compose(t), complement),
        Shape::Complement(s) => positive(s, frame, !complement),
        Shape::Leaf(p) => Positive::Leaf {
            primitive: p.clone(),
            frame: *frame,
            complement,
        },
        Shape::Op(code, a, b) => {
            // De Morgan: a complemented operator becomes its dual over complemented operands.
            let (code, ca, cb) = match (code, complement) {
                (c, false) => (*c, false, false),
                (TypeCode::Union, true) => (TypeCode::Intersection, true, true),
                (TypeCode::Intersection, true) => (TypeCode::Union, true, true),
                (_, true) => (TypeCode::Union, true, false),
            };
            Positive::Op(
                code,
                Box::new(positive(a, frame, ca)),
                Box::new(positive(b, frame, cb)),
            )
        }
    }
}

/// Collects the operands of a chain of `code` operators.
fn operands(node: Positive, code: TypeCode, out: &mut Vec<Positive>) {
    match node {
        Positive::Op(c, a, b) if c == code => {
            operands(*a, code, out);
            operands(*b, code, out);
        }
        other => out.push(other),
    }
}

/// A balanced tree of `code` over `items` (at least one).
fn balanced(code: TypeCode, mut items: Vec<Positive>) -> Positive {
    // Shallow operands first, so that pairing keeps the tree as low as possible.
    items.sort_by_key(Positive::height);
    while items.len() > 1 {
        let mut next = Vec::with_capacity(items.len().div_ceil(2));
        let mut it = items.into_iter();
        while let Some(a) = it.next() {
            match it.next() {
                Some(b) => next.push(Positive::Op(code, Box::new(a), Box::new(b))),
                None => next.push(a),
            }
        }
        next.sort_by_key(Positive::height);
        items = next;
    }
    items.pop().expect("at least one operand")
}

/// Regroups chains of one operator into lists and balanced trees (see the module docs).
fn regroup(node: Positive, options: TreeOptions) -> Positive {
    match node {
        Positive::Op(code @ (TypeCode::Union | TypeCode::Intersection), ..) => {
            let mut items = Vec::new();
            operands(node, code, &mut items);
            let items: Vec<Positive> = items.into_iter().map(|i| regroup(i, options)).collect();
            let (plain, other): (Vec<_>, Vec<_>) =
                items.into_iter().partition(Positive::is_plain_leaf);
            let mut joined = other;
            if options.lists && plain.len() >= LIST_MIN_MEMBERS {
                let list = if code == TypeCode::Union {
                    TypeCode::ListContiguous
                } else {
                    TypeCode::ListOverlap
                };
                joined.push(Positive::List(list, plain));
            } else {
                joined.extend(plain);
            }
            balanced(code, joined)
        }
        Positive::Op(TypeCode::Difference, ..) => {
            // ((A - B) - C) - D: collect the subtracted operands down the left spine.
            let mut subtracted = Vec::new();
            let mut left = node;
            while let Positive::Op(TypeCode::Difference, a, b) = left {
                subtracted.push(*b);
                left = *a;
            }
            let minuend = regroup(left, options);
            let subtrahend = if subtracted.len() == 1 {
                regroup(subtracted.pop().expect("one operand"), options)
            } else {
                regroup(balanced(TypeCode::Union, subtracted), options)
            };
            Positive::Op(
                TypeCode::Difference,
                Box::new(minuend),
                Box::new(subtrahend),
            )
        }
        other => other,
    }
}

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

fn is_empty(b: &Aabb) -> bool {
    (0..3).any(|k| b[k] > b[k + 3])
}

fn empty_error() -> CsgError {
    CsgError {
        primitive: "intersection",
        problem: "the operands' bounds do not overlap: the solid is empty".to_string(),
    }
}

struct Writer {
    nodes: Vec<Node>,
    /// Double-precision parameters of `nodes` (index-carrying nodes are filled in by the
    /// Foundry when it relocates them).
    nodes64: Vec<NodeParam64>,
    members: Vec<Node>,
    members64: Vec<NodeParam64>,
    transforms: Vec<Transform64>,
    planes: Vec<Plane>,
    planes64: Vec<Plane64>,
}

impl Writer {
    /// The node of one primitive leaf, its transform and planes appended.
    fn leaf_node(
        &mut self,
        primitive: &Primitive,
        frame: &Transform64,
        complement: bool,
    ) -> (Node, NodeParam64, Extent) {
        let (code, mut param, param_ext) = primitive.node_params();
        let (_, param64) = primitive.node_params64();
        if let Primitive::Polyhedron { planes } = primitive {
            param[0] = f32::from_bits(self.planes.len() as u32);
            self.planes.extend(planes.iter().map(|p| Plane {
                plane: p.map(|v| v as f32),
            }));
            self.planes64
                .extend(planes.iter().map(|p| Plane64 { plane: *p }));
        }
        let bounds = transform_bounds(&primitive_bounds(primitive), frame);
        let mut transform = 0;
        if *frame != Transform64::IDENTITY {
            self.transforms.push(*frame);
            transform = self.transforms.len() as u32;
        }
        if complement {
            transform |= COMPLEMENT_BIT;
        }
        let node = Node {
            param,
            param_ext,
            boundary: UNSET,
            index: UNSET,
            aabb: aabb_to_f32_outward(&bounds),
            typecode: code as u32,
            transform,
        };
        let extent = Extent {
            surfaces: bounds,
            bounded: primitive.is_bounded() && !complement,
        };
        let wide = if code == TypeCode::ConvexPolyhedron {
            NodeParam64::widened(&node)
        } else {
            NodeParam64 { param: param64 }
        };
        (node, wide, extent)
    }

    fn write(&mut self, shape: &Positive, position: usize) -> Result<Extent, CsgError> {
        let (node, extent) = match shape {
            Positive::Leaf {
                primitive,
                frame,
                complement,
            } => {
                let (node, wide, extent) = self.leaf_node(primitive, frame, *complement);
                self.nodes64[position - 1] = wide;
                (node, extent)
            }
            Positive::List(code, items) => {
                let first = self.members.len();
                let mut surfaces: Option<Aabb> = None;
                for item in items {
                    let Positive::Leaf {
                        primitive, frame, ..
                    } = item
                    else {
                        unreachable!("lists hold plain leaves");
                    };
                    let (node, wide, e) = self.leaf_node(primitive, frame, false);
                    self.members.push(node);
                    self.members64.push(wide);
                    surfaces = Some(match (surfaces, *code) {
                        (None, _) => e.surfaces,
                        (Some(s), TypeCode::ListOverlap) => intersection(&s, &e.surfaces),
                        (Some(s), _) => union(&s, &e.surfaces),
                    });
                }
                let surfaces = surfaces.expect("lists have members");
                if is_empty(&surfaces) {
                    return Err(empty_error());
                }
                let node = Node {
                    param: [
                        f32::from_bits(first as u32),
                        f32::from_bits(items.len() as u32),
                        0.0,
                        0.0,
                    ],
                    boundary: UNSET,
                    index: UNSET,
                    aabb: aabb_to_f32_outward(&surfaces),
                    typecode: *code as u32,
                    ..Node::default()
                };
                let extent = Extent {
                    surfaces,
                    bounded: true,
                };
                (node, extent)
            }
            Positive::Op(code, a, b) => {
                let ea = self.write(a, 2 * position)?;
                let eb = self.write(b, 2 * position + 1)?;
                let surfaces = union(&ea.surfaces, &eb.surfaces);
                let unbounded = Extent {
                    surfaces,
                    bounded: false,
                };
                let extent = match (code, ea.bounded, eb.bounded) {
                    (TypeCode::Union, true, true) => Extent {
                        surfaces,
                        bounded: true,
                    },
                    (TypeCode::Intersection, true, true) => Extent {
                        surfaces: intersection(&ea.surfaces, &eb.surfaces),
                        bounded: true,
                    },
                    (TypeCode::Intersection, true, false) => ea,
                    (TypeCode::Intersection, false, true) => eb,
                    (TypeCode::Difference, true, _) => ea,
                    _ => unbounded,
                };
                if extent.bounded && is_empty(&extent.surfaces) {
                    return Err(empty_error());
                }
                let node = Node {
                    boundary: UNSET,
                    index: UNSET,
                    aabb: aabb_to_f32_outward(&extent.surfaces),
                    typecode: *code as u32,
                    ..Node::default()
                };
                (node, extent)
            }
        };
        self.nodes[position - 1] = node;
        Ok(extent)
    }
}

impl Shape {
    /// Height of the operator tree as written (a single primitive has height 0).
    pub fn height(&self) -> u32 {
        match self {
            Shape::Leaf(_) => 0,
            Shape::Op(_, a, b) => 1 + a.height().max(b.height()),
            Shape::Placed(_, s) | Shape::Complement(s) => s.height(),
        }
    }
}

/// Serializes `shape` into a complete binary tree of Foundry nodes with its transforms,
/// planes and list members (see the module docs for the regrouping).
///
/// Fails when the regrouped tree is deeper than [`MAX_TREE_HEIGHT`], when the solid is
/// unbounded (a complement or cut reaches the root) or empty (disjoint intersection).
pub fn to_tree(shape: &Shape) -> Result<CsgTree, CsgError> {
    to_tree_with(shape, TreeOptions::default())
}

/// [`to_tree`] with a choice of regrouping.
pub fn to_tree_with(shape: &Shape, options: TreeOptions) -> Result<CsgTree, CsgError> {
    let shape = regroup(positive(shape, &Transform64::IDENTITY, false), options);
    let height = shape.height();
    if height > MAX_TREE_HEIGHT {
        return Err(CsgError {
            primitive: "tree",
            problem: format!(
                "height {height} after regrouping exceeds the evaluator's limit of \
                 {MAX_TREE_HEIGHT} levels"
            ),
        });
    }
    let size = (1usize << (height + 1)) - 1;
    let mut w = Writer {
        nodes: vec![Node::default(); size],
        nodes64: vec![NodeParam64::default(); size],
        members: Vec::new(),
        members64: Vec::new(),
        transforms: Vec::new(),
        planes: Vec::new(),
        planes64: Vec::new(),
    };
    let root = w.write(&shape, 1)?;
    if !root.bounded {
        return Err(CsgError {
            primitive: "tree",
            problem: "the solid is unbounded (a complement or cut reaches the root)".to_string(),
        });
    }
    let mut node64 = w.nodes64;
    node64.extend(w.members64);
    Ok(CsgTree {
        nodes: w.nodes,
        members: w.members,
        node64,
        transforms: w.transforms,
        planes: w.planes,
        planes64: w.planes64,
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
        // Shallow operands come first after regrouping.
        assert_eq!(t.nodes[1].typecode, TypeCode::Sphere as u32);
        assert_eq!(t.nodes[2].typecode, TypeCode::Difference as u32);
        assert_eq!(t.nodes[2].aabb, [-10.0, -10.0, -10.0, 10.0, 10.0, 10.0]);
        assert_eq!(t.nodes[0].aabb, [-10.0, -10.0, -10.0, 101.0, 10.0, 10.0]);
        assert_eq!(t.nodes[3].typecode, TypeCode::Zero as u32);
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

    #[test]
    fn a_union_of_a_hundred_parts_is_one_list_node() {
        let mut s = sphere(1.0).unwrap();
        for i in 1..100 {
            s = s + sphere(1.0).unwrap().translate(3.0 * i as f64, 0.0, 0.0);
        }
        assert_eq!(s.height(), 99);
        let t = to_tree(&s).unwrap();
        assert_eq!(t.nodes.len(), 1);
        assert_eq!(t.nodes[0].typecode, TypeCode::ListContiguous as u32);
        assert_eq!(t.members.len(), 100);
        assert_eq!(t.nodes[0].aabb, [-1.0, -1.0, -1.0, 298.0, 1.0, 1.0]);
    }

    #[test]
    fn long_difference_chains_are_rebalanced() {
        let mut s = box3(100.0, 100.0, 100.0).unwrap();
        for i in 0..40 {
            s = s
                - (sphere(1.0).unwrap() - box3(0.5, 0.5, 0.5).unwrap())
                    .translate(i as f64, 0.0, 0.0);
        }
        assert_eq!(s.height(), 41);
        let t = to_tree(&s).unwrap();
        let height = (t.nodes.len() + 1).trailing_zeros() - 1;
        assert!(height <= 8, "height {height}");
    }

    #[test]
    fn trees_too_deep_after_regrouping_are_rejected() {
        // Alternating operators cannot be regrouped.
        let mut s = sphere(100.0).unwrap();
        for i in 0..(MAX_TREE_HEIGHT + 1) {
            let part = sphere(50.0).unwrap().translate(i as f64, 0.0, 0.0);
            s = if i % 2 == 0 { s * part } else { s + part };
        }
        let e = to_tree(&s).unwrap_err();
        assert!(e.problem.contains("exceeds"), "{e}");
    }
}
