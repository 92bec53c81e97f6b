//! Validation of a whole Foundry: every offset, count, typecode and index is checked before
//! anything (CPU or GPU) reads through it.

use crate::error::{FoundryError, Result};
use crate::records::{Prim, Transform, Transform64, COMPLEMENT_BIT};
use crate::store::{aabb_union, Foundry, UNSET};
use crate::typecode::{PrimKind, TypeCode};

/// Deepest CSG tree the store accepts: the evaluators keep one stack frame per level, so
/// their fixed-size stacks (CPU and GPU) are sized by it. Deeper expressions are rebuilt
/// (n-ary lists, rebalanced unions and intersections) or rejected when the tree is built.
pub const MAX_TREE_HEIGHT: u32 = 10;

/// Largest relative difference allowed between an f32 inverse and the inverse of its f64
/// original (a few ulps of f32, relative to the matrix's scale).
const INVERSE_TOLERANCE: f64 = 1e-5;

/// Aggregates of a solid's prims, as stored in [`crate::Solid`].
pub(crate) struct PrimSummary {
    pub content: u32,
    pub max_height: u32,
    pub aabb: [f32; 6],
    pub extent: f32,
}

pub(crate) fn summarize_prims(prims: &[Prim]) -> PrimSummary {
    let mut content = 0;
    let mut max_height = 0;
    let mut aabb = [
        f32::INFINITY,
        f32::INFINITY,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NEG_INFINITY,
        f32::NEG_INFINITY,
    ];
    for p in prims {
        content |= 1u32.checked_shl(p.kind).unwrap_or(0);
        if p.kind == PrimKind::Csg as u32 {
            max_height = max_height.max(tree_height(p.num_node).unwrap_or(0));
        }
        aabb = aabb_union(aabb, p.aabb);
    }
    let extent = (0..3)
        .map(|k| 0.5 * (aabb[k + 3] - aabb[k]))
        .fold(0.0f32, f32::max);
    PrimSummary {
        content,
        max_height,
        aabb,
        extent,
    }
}

/// Height of a complete binary tree of `num_node` nodes, if `num_node` is 2^(h+1) - 1.
pub fn tree_height(num_node: u32) -> Option<u32> {
    let n = num_node.checked_add(1)?;
    (num_node > 0 && n.is_power_of_two()).then(|| n.trailing_zeros() - 1)
}

fn record_error(
    array: &'static str,
    record: usize,
    field: &'static str,
    problem: impl Into<String>,
) -> FoundryError {
    FoundryError::Record {
        array,
        record,
        field,
        problem: problem.into(),
    }
}

/// Checks that `offset..offset+count` lies inside an array of `len` records.
fn check_range(
    array: &'static str,
    record: usize,
    field: &'static str,
    offset: u32,
    count: u32,
    len: usize,
    target: &str,
) -> Result<()> {
    if offset as u64 + count as u64 > len as u64 {
        return Err(record_error(
            array,
            record,
            field,
            format!(
                "range {offset}..{} exceeds the {len} records of `{target}`",
                offset as u64 + count as u64
            ),
        ));
    }
    Ok(())
}

fn check_aabb(array: &'static str, record: usize, aabb: &[f32; 6]) -> Result<()> {
    if aabb.iter().any(|v| !v.is_finite()) {
        return Err(record_error(
            array,
            record,
            "aabb",
            format!("not finite: {aabb:?}"),
        ));
    }
    if (0..3).any(|k| aabb[k] > aabb[k + 3]) {
        return Err(record_error(
            array,
            record,
            "aabb",
            format!("min exceeds max: {aabb:?}"),
        ));
    }
    Ok(())
}

/// Largest element-wise difference between `f32` and the f32 rounding of `inverse(f64)`,
/// relative to the matrix's largest element; `None` if `f64` is not invertible.
fn inverse_mismatch(original: &Transform64, stored: &[[f32; 4]]) -> Option<f64> {
    let expected: Transform = original.inverse()?.to_f32();
    let scale = expected
        .rows
        .iter()
        .flatten()
        .fold(1.0f64, |a, v| a.max(v.abs() as f64));
    let worst = expected
        .rows
        .iter()
        .zip(stored)
        .flat_map(|(e, s)| e.iter().zip(s).map(|(a, b)| (*a as f64 - *b as f64).abs()))
        .fold(
            0.0f64,
            |a, d| if d.is_nan() { f64::INFINITY } else { a.max(d) },
        );
    Some(worst / scale)
}

/// Checks record `i` of an f64 transform array (`original`: array and field) and the f32
/// inverse stored for it (`inverse`: array and field): affine, invertible, and consistent.
fn check_inverse_pair(
    original: (&'static str, &'static str),
    inverse: (&'static str, &'static str),
    i: usize,
    transform: &Transform64,
    stored: &[[f32; 4]],
) -> Result<()> {
    if !transform.is_affine() {
        return Err(record_error(
            original.0,
            i,
            original.1,
            "not a finite affine matrix (last row must be 0 0 0 1)",
        ));
    }
    match inverse_mismatch(transform, stored) {
        None => Err(record_error(original.0, i, original.1, "singular matrix")),
        Some(d) if d > INVERSE_TOLERANCE => Err(record_error(
            inverse.0,
            i,
            inverse.1,
            format!(
                "not the inverse of {}[{i}] (relative difference {d:.3e})",
                original.0
            ),
        )),
        Some(_) => Ok(()),
    }
}

impl Foundry {
    /// Checks every cross-array reference and every field that a reader would trust.
    pub fn validate(&self) -> Result<()> {
        self.validate_transforms()?;
        self.validate_planes()?;
        self.validate_double_precision()?;
        self.validate_nodes()?;
        self.validate_prims()?;
        self.validate_solids()?;
        self.validate_instances()?;
        self.validate_items()
    }

    fn validate_transforms(&self) -> Result<()> {
        if self.tran.len() != self.itra.len() {
            return Err(FoundryError::Array {
                array: "itra",
                problem: format!(
                    "{} records, but `tran` has {}",
                    self.itra.len(),
                    self.tran.len()
                ),
            });
        }
        for (i, (t, it)) in self.tran.iter().zip(&self.itra).enumerate() {
            check_inverse_pair(("tran", "rows"), ("itra", "rows"), i, t, &it.rows)?;
        }
        Ok(())
    }

    fn validate_planes(&self) -> Result<()> {
        for (i, p) in self.plan.iter().enumerate() {
            let [x, y, z, d] = p.plane;
            let norm = (x * x + y * y + z * z).sqrt();
            if !d.is_finite() || !norm.is_finite() || (norm - 1.0).abs() > 1e-4 {
                return Err(record_error(
                    "plan",
                    i,
                    "plane",
                    format!("needs a finite unit normal and distance, got {:?}", p.plane),
                ));
            }
        }
        Ok(())
    }

    /// `node64` and `plan64` have one row per node and plane, and round to exactly the f32
    /// values the GPU gets.
    fn validate_double_precision(&self) -> Result<()> {
        let pairs = [
            ("node64", "node", self.node64.len(), self.node.len()),
            ("plan64", "plan", self.plan64.len(), self.plan.len()),
        ];
        for (wide, narrow, a, b) in pairs {
            if a != b {
                return Err(record_error(
                    wide,
                    a.min(b),
                    if wide == "node64" { "param" } else { "plane" },
                    format!("{a} records for the {b} records of `{narrow}`"),
                ));
            }
        }
        let rounds_to = |wide: &[f64], narrow: &[f32]| {
            wide.iter()
                .zip(narrow)
                .all(|(w, n)| (*w as f32).to_bits() == n.to_bits() || (w.is_nan() && n.is_nan()))
        };
        for (i, (w, n)) in self.node64.iter().zip(&self.node).enumerate() {
            let narrow = [
                n.param[0],
                n.param[1],
                n.param[2],
                n.param[3],
                n.param_ext[0],
                n.param_ext[1],
            ];
            if !rounds_to(&w.param, &narrow) {
                return Err(record_error(
                    "node64",
                    i,
                    "param",
                    format!("{:?} does not round to node {i}'s {narrow:?}", w.param),
                ));
            }
        }
        for (i, (w, n)) in self.plan64.iter().zip(&self.plan).enumerate() {
            if !rounds_to(&w.plane, &n.plane) {
                return Err(record_error(
                    "plan64",
                    i,
                    "plane",
                    format!("{:?} does not round to plane {i}'s {:?}", w.plane, n.plane),
                ));
            }
        }
        Ok(())
    }

    fn validate_nodes(&self) -> Result<()> {
        for (i, n) in self.node.iter().enumerate() {
            let Some(code) = TypeCode::from_u32(n.typecode) else {
                return Err(record_error(
                    "node",
                    i,
                    "typecode",
                    format!("unknown typecode {}", n.typecode),
                ));
            };
            let local = n.transform & !COMPLEMENT_BIT;
            if local as usize > self.tran.len() {
                return Err(record_error(
                    "node",
                    i,
                    "transform",
                    format!("transform {local} of {} (1-based)", self.tran.len()),
                ));
            }
            if n.transform & COMPLEMENT_BIT != 0 && !code.is_primitive() {
                return Err(record_error(
                    "node",
                    i,
                    "transform",
                    format!("complement flag on a {code:?} node"),
                ));
            }
            if code == TypeCode::Zero {
                continue;
            }
            check_aabb("node", i, &n.aabb)?;
            match code {
                TypeCode::ConvexPolyhedron => {
                    let (first, count) = (n.param[0].to_bits(), n.param[1].to_bits());
                    if count < 4 {
                        return Err(record_error(
                            "node",
                            i,
                            "param",
                            format!("a convex polyhedron needs at least 4 planes, got {count}"),
                        ));
                    }
                    check_range("node", i, "param", first, count, self.plan.len(), "plan")?;
                }
                c if c.is_list() => {
                    let (first, count) = (n.param[0].to_bits(), n.param[1].to_bits());
                    if count == 0 {
                        return Err(record_error(
                            "node",
                            i,
                            "param",
                            "a list node needs members",
                        ));
                    }
                    check_range("node", i, "param", first, count, self.node.len(), "node")?;
                    let members = &self.node[first as usize..(first + count) as usize];
                    if let Some(m) = members.iter().position(|m| {
                        !TypeCode::from_u32(m.typecode).is_some_and(TypeCode::is_primitive)
                    }) {
                        return Err(record_error(
                            "node",
                            i,
                            "param",
                            format!("list member {} is not a primitive", first as usize + m),
                        ));
                    }
                }
                c if c.is_primitive()
                    && n.param.iter().chain(&n.param_ext).any(|v| !v.is_finite()) =>
                {
                    return Err(record_error(
                        "node",
                        i,
                        "param",
                        format!("not finite: {:?} {:?}", n.param, n.param_ext),
                    ));
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// Checks that the nodes of one CSG prim form a proper complete binary tree: operators
    /// have two non-empty children inside the tree, leaves have only empty slots below.
    fn validate_tree(&self, prim_index: usize, p: &Prim) -> Result<()> {
        let nodes = &self.node[p.node_offset as usize..][..p.num_node as usize];
        for (i, n) in nodes.iter().enumerate() {
            let level_index = i + 1; // 1-based level-order index
            let children = [2 * level_index - 1, 2 * level_index];
            let code = TypeCode::from_u32(n.typecode).unwrap_or(TypeCode::Zero);
            let child_codes = children.map(|c| nodes.get(c).map(|n| n.typecode));
            let problem = if code.is_operator() {
                match child_codes {
                    [Some(a), Some(b)] if a != 0 && b != 0 => None,
                    _ => Some(format!(
                        "{code:?} node at tree position {level_index} lacks a child"
                    )),
                }
            } else if child_codes.iter().any(|c| matches!(c, Some(v) if *v != 0)) {
                Some(format!(
                    "{code:?} node at tree position {level_index} has non-empty children"
                ))
            } else if i == 0 && code == TypeCode::Zero {
                Some("the root node is empty".to_string())
            } else {
                None
            };
            if let Some(problem) = problem {
                return Err(record_error(
                    "prim",
                    prim_index,
                    "node_offset",
                    format!("tree of node {}: {problem}", p.node_offset as usize + i),
                ));
            }
        }
        Ok(())
    }

    fn validate_prims(&self) -> Result<()> {
        for (i, p) in self.prim.iter().enumerate() {
            let Some(kind) = PrimKind::from_u32(p.kind) else {
                return Err(record_error(
                    "prim",
                    i,
                    "kind",
                    format!("unknown prim kind {}", p.kind),
                ));
            };
            check_aabb("prim", i, &p.aabb)?;
            if p.tran_offset as usize > self.tran.len() {
                return Err(record_error(
                    "prim",
                    i,
                    "tran_offset",
                    format!(
                        "{} exceeds the {} transforms",
                        p.tran_offset,
                        self.tran.len()
                    ),
                ));
            }
            if p.plan_offset as usize > self.plan.len() {
                return Err(record_error(
                    "prim",
                    i,
                    "plan_offset",
                    format!("{} exceeds the {} planes", p.plan_offset, self.plan.len()),
                ));
            }
            if p.transform as usize > self.tran.len() {
                return Err(record_error(
                    "prim",
                    i,
                    "transform",
                    format!("transform {} of {} (1-based)", p.transform, self.tran.len()),
                ));
            }
            match kind {
                PrimKind::Csg => {
                    let Some(height) = tree_height(p.num_node) else {
                        return Err(record_error(
                            "prim",
                            i,
                            "num_node",
                            format!("{} is not 2^k - 1", p.num_node),
                        ));
                    };
                    if height > MAX_TREE_HEIGHT {
                        return Err(record_error(
                            "prim",
                            i,
                            "num_node",
                            format!("tree height {height} exceeds {MAX_TREE_HEIGHT}"),
                        ));
                    }
                    check_range(
                        "prim",
                        i,
                        "node_offset",
                        p.node_offset,
                        p.num_node,
                        self.node.len(),
                        "node",
                    )?;
                    if p.item_count != 0 || p.transform != 0 {
                        return Err(record_error(
                            "prim",
                            i,
                            "item_count",
                            "a CSG prim has no items and no data transform",
                        ));
                    }
                    self.validate_tree(i, p)?;
                }
                PrimKind::Mesh | PrimKind::Volume => {
                    if p.num_node != 0 {
                        return Err(record_error(
                            "prim",
                            i,
                            "num_node",
                            format!("a {kind:?} prim has no nodes, got {}", p.num_node),
                        ));
                    }
                    if p.item_count == 0 {
                        return Err(record_error("prim", i, "item_count", "empty item range"));
                    }
                    let (len, target) = match kind {
                        PrimKind::Mesh => (self.tri.len(), "tri"),
                        _ => (self.brick.len(), "brick"),
                    };
                    check_range(
                        "prim",
                        i,
                        "item_offset",
                        p.item_offset,
                        p.item_count,
                        len,
                        target,
                    )?;
                }
            }
        }
        Ok(())
    }

    fn validate_solids(&self) -> Result<()> {
        if self.solid_names.len() != self.solid.len() {
            return Err(FoundryError::Array {
                array: "solid",
                problem: format!(
                    "{} solids but {} solid names",
                    self.solid.len(),
                    self.solid_names.len()
                ),
            });
        }
        for (i, s) in self.solid.iter().enumerate() {
            if s.num_prim == 0 {
                return Err(record_error(
                    "solid",
                    i,
                    "num_prim",
                    "a solid needs at least one prim",
                ));
            }
            check_range(
                "solid",
                i,
                "prim_offset",
                s.prim_offset,
                s.num_prim,
                self.prim.len(),
                "prim",
            )?;
            let summary =
                summarize_prims(&self.prim[s.prim_offset as usize..][..s.num_prim as usize]);
            if s.content != summary.content {
                return Err(record_error(
                    "solid",
                    i,
                    "content",
                    format!(
                        "{:#b}, but its prims give {:#b}",
                        s.content, summary.content
                    ),
                ));
            }
            if s.max_height != summary.max_height {
                return Err(record_error(
                    "solid",
                    i,
                    "max_height",
                    format!(
                        "{}, but its prims give {}",
                        s.max_height, summary.max_height
                    ),
                ));
            }
            check_aabb("solid", i, &s.aabb)?;
            if !(s.extent.is_finite() && s.extent >= 0.0) {
                return Err(record_error(
                    "solid",
                    i,
                    "extent",
                    format!("must be finite and >= 0, got {}", s.extent),
                ));
            }
        }
        Ok(())
    }

    fn validate_instances(&self) -> Result<()> {
        if self.inst.len() != self.inst_tran.len() {
            return Err(FoundryError::Array {
                array: "inst_tran",
                problem: format!(
                    "{} records, but `inst` has {}",
                    self.inst_tran.len(),
                    self.inst.len()
                ),
            });
        }
        if self.inst.len() != self.inst_mother.len() {
            return Err(FoundryError::Array {
                array: "inst_mother",
                problem: format!(
                    "{} records, but `inst` has {}",
                    self.inst_mother.len(),
                    self.inst.len()
                ),
            });
        }
        for (i, m) in self.inst_mother.iter().enumerate() {
            if m.index != UNSET && m.index as usize >= i {
                return Err(record_error(
                    "inst_mother",
                    i,
                    "index",
                    format!("mother {} is not an earlier instance", m.index),
                ));
            }
        }
        for (i, (inst, t)) in self.inst.iter().zip(&self.inst_tran).enumerate() {
            if inst.solid as usize >= self.solid.len() {
                return Err(record_error(
                    "inst",
                    i,
                    "solid",
                    format!("solid {} of {}", inst.solid, self.solid.len()),
                ));
            }
            check_inverse_pair(
                ("inst_tran", "rows"),
                ("inst", "itra"),
                i,
                &t.to_transform(),
                &inst.itra,
            )?;
            let boundaries = self.optics.boundaries.len();
            if inst.boundary != UNSET && inst.boundary as usize >= boundaries {
                return Err(record_error(
                    "inst",
                    i,
                    "boundary",
                    format!(
                        "boundary {}, but optics.json has {boundaries} boundaries",
                        inst.boundary
                    ),
                ));
            }
        }
        self.validate_media()?;
        self.optics.validate()
    }

    /// Every volume prim has exactly one medium, and every medium names a volume prim.
    fn validate_media(&self) -> Result<()> {
        let mut owner = vec![None; self.prim.len()];
        for (i, m) in self.optics.media.iter().enumerate() {
            let is_volume = self
                .prim
                .get(m.prim as usize)
                .is_some_and(|p| p.kind == PrimKind::Volume as u32);
            if !is_volume {
                return Err(FoundryError::File {
                    path: "optics.json".into(),
                    problem: format!("medium {i}: prim {} is not a volume prim", m.prim),
                });
            }
            if let Some(j) = owner[m.prim as usize].replace(i) {
                return Err(FoundryError::File {
                    path: "optics.json".into(),
                    problem: format!("media {j} and {i} both describe prim {}", m.prim),
                });
            }
        }
        match self
            .prim
            .iter()
            .enumerate()
            .find(|(i, p)| p.kind == PrimKind::Volume as u32 && owner[*i].is_none())
        {
            Some((i, _)) => Err(FoundryError::File {
                path: "optics.json".into(),
                problem: format!("volume prim {i} has no medium"),
            }),
            None => Ok(()),
        }
    }

    fn validate_items(&self) -> Result<()> {
        for (i, t) in self.tri.iter().enumerate() {
            if t.v.iter().flatten().any(|v| !v.is_finite()) {
                return Err(record_error(
                    "tri",
                    i,
                    "v",
                    format!("not finite: {:?}", t.v),
                ));
            }
        }
        for (i, b) in self.brick.iter().enumerate() {
            let owner = self.prim.get(b.prim as usize);
            if owner.map(|p| p.kind) != Some(PrimKind::Volume as u32) {
                return Err(record_error(
                    "brick",
                    i,
                    "prim",
                    format!("{} is not a volume prim", b.prim),
                ));
            }
            let p = owner.expect("checked above");
            if (i as u64) < p.item_offset as u64
                || i as u64 >= p.item_offset as u64 + p.item_count as u64
            {
                return Err(record_error(
                    "brick",
                    i,
                    "prim",
                    format!("prim {} does not list this brick", b.prim),
                ));
            }
            if !(b.value_min.is_finite() && b.value_max.is_finite() && b.value_min <= b.value_max) {
                return Err(record_error(
                    "brick",
                    i,
                    "value_max",
                    format!(
                        "range {}..{} is not finite and ordered",
                        b.value_min, b.value_max
                    ),
                ));
            }
            if b.size == 0 {
                return Err(record_error("brick", i, "size", "zero"));
            }
            check_aabb("brick", i, &b.aabb)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heights_of_complete_trees() {
        assert_eq!(tree_height(1), Some(0));
        assert_eq!(tree_height(3), Some(1));
        assert_eq!(tree_height(7), Some(2));
        assert_eq!(tree_height(u32::MAX), None);
        for bad in [0, 2, 4, 6, 8] {
            assert_eq!(tree_height(bad), None, "{bad}");
        }
    }
}
