//! Appending a whole Foundry to another: [`Foundry::append`].

use std::ops::Range;

use crate::error::{FoundryError, Result};
use crate::optics::{Boundary, Medium};
use crate::records::{Affine64, Instance, Mother, Prim, Transform64, COMPLEMENT_BIT};
use crate::store::{index_u32, invert, Foundry, UNSET};
use crate::typecode::{PrimKind, TypeCode};

/// Where [`Foundry::append`] put the appended Foundry's records.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Appended {
    /// Its solids, in its order (shared by every copy).
    pub solids: Range<u32>,
    /// Its instances, one range per placement in placement order: its instance `i` is
    /// instance `instances[k].start + i` of copy `k`.
    pub instances: Vec<Range<u32>>,
    /// Its boundaries (shared by every copy).
    pub boundaries: Range<u32>,
}

/// How far each array of the appended Foundry moves: the receiving Foundry's lengths.
#[derive(Clone, Copy)]
struct Offsets {
    solid: u32,
    prim: u32,
    node: u32,
    plan: u32,
    tran: u32,
    tri: u32,
    brick: u32,
    boundary: u32,
    material: u32,
    surface: u32,
    volume: u32,
}

fn overflow(
    array: &'static str,
    record: usize,
    field: &'static str,
    v: u32,
    by: u32,
) -> FoundryError {
    FoundryError::Record {
        array,
        record,
        field,
        problem: format!("index {v} moved by {by} does not fit the store"),
    }
}

/// The length `n` of a receiving array (where appended records start), once it is
/// checked that `n + extra` records are still indexable by `u32`.
fn offset(n: usize, extra: usize, what: &str) -> Result<u32> {
    index_u32(n.saturating_add(extra), what)?;
    Ok(n as u32)
}

/// `v + by` for index `field` of record `record` of `array` (never [`UNSET`]).
fn shift(
    v: u32,
    by: u32,
    (array, record, field): (&'static str, usize, &'static str),
) -> Result<u32> {
    v.checked_add(by)
        .filter(|&r| r != UNSET)
        .ok_or_else(|| overflow(array, record, field, v, by))
}

/// As [`shift`], keeping [`UNSET`] unset.
fn shift_set(v: u32, by: u32, at: (&'static str, usize, &'static str)) -> Result<u32> {
    if v == UNSET {
        Ok(UNSET)
    } else {
        shift(v, by, at)
    }
}

impl Foundry {
    /// Appends `other` whole, its instance set placed once per transform of `placements`.
    ///
    /// Every array of `other` except the instances (solids, prims, nodes, planes,
    /// transforms, triangles, bricks, solid names and optics: materials, surfaces,
    /// boundaries, volume names, media) is appended once and shared by all copies. Copy `k`
    /// repeats every instance of `other` with the local-to-world transform
    /// `placements[k] ∘ instance transform`, its mother (if any) within the same copy. Every
    /// index is relocated: absolute indices move by the length of the array they point
    /// into (node transforms, list members and convex-polyhedron planes, prims' offsets,
    /// data transforms and boundaries, bricks' prims, instances' solids, boundaries,
    /// identities (volume names) and mothers, boundaries' materials and surfaces, media's
    /// prims); [`UNSET`] stays unset, and user indices (`Node::index`, prim and solid
    /// identities, copy numbers) are kept. An empty `placements` appends the shared records
    /// only.
    ///
    /// With `self` and `other` valid (see [`Foundry::validate`]), the result is valid and
    /// traces as if both had been built into one Foundry. On error (a singular or
    /// non-affine placement, an index that no longer fits in 32 bits) `self` is unchanged.
    pub fn append(&mut self, other: &Foundry, placements: &[Transform64]) -> Result<Appended> {
        if other.inst_tran.len() != other.inst.len() || other.inst_mother.len() != other.inst.len()
        {
            return Err(FoundryError::Array {
                array: "inst",
                problem: format!(
                    "{} instances, {} transforms and {} mothers in the appended Foundry",
                    other.inst.len(),
                    other.inst_tran.len(),
                    other.inst_mother.len()
                ),
            });
        }
        let copies = other.inst.len().saturating_mul(placements.len());
        offset(self.inst.len(), copies, "instances")?;
        let (mine, theirs) = (&self.optics, &other.optics);
        let off = Offsets {
            solid: offset(self.solid.len(), other.solid.len(), "solids")?,
            prim: offset(self.prim.len(), other.prim.len(), "prims")?,
            node: offset(self.node.len(), other.node.len(), "nodes")?,
            plan: offset(self.plan.len(), other.plan.len(), "planes")?,
            tran: offset(self.tran.len(), other.tran.len(), "transforms")?,
            tri: offset(self.tri.len(), other.tri.len(), "triangles")?,
            brick: offset(self.brick.len(), other.brick.len(), "bricks")?,
            boundary: offset(mine.boundaries.len(), theirs.boundaries.len(), "boundaries")?,
            material: offset(mine.materials.len(), theirs.materials.len(), "materials")?,
            surface: offset(mine.surfaces.len(), theirs.surfaces.len(), "surfaces")?,
            volume: offset(mine.volumes.len(), theirs.volumes.len(), "volumes")?,
        };

        // Everything is relocated into new arrays first, so an error leaves `self` as it was.
        let solid = other
            .solid
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let mut s = *s;
                s.prim_offset = shift(s.prim_offset, off.prim, ("solid", i, "prim_offset"))?;
                Ok(s)
            })
            .collect::<Result<Vec<_>>>()?;
        let prim = other
            .prim
            .iter()
            .enumerate()
            .map(|(i, p)| relocate_prim(p, i, &off))
            .collect::<Result<Vec<_>>>()?;
        let mut node = other.node.clone();
        let mut node64 = other.node64.clone();
        for (i, n) in node.iter_mut().enumerate() {
            let code = TypeCode::from_u32(n.typecode);
            // Empty slots of the complete tree hold nothing (builders leave them zeroed).
            if code == Some(TypeCode::Zero) {
                continue;
            }
            let local = n.transform & !COMPLEMENT_BIT;
            if local > 0 {
                let moved = shift(local, off.tran, ("node", i, "transform"))?;
                if moved & COMPLEMENT_BIT != 0 {
                    return Err(overflow("node", i, "transform", local, off.tran));
                }
                n.transform = moved | (n.transform & COMPLEMENT_BIT);
            }
            n.boundary = shift_set(n.boundary, off.boundary, ("node", i, "boundary"))?;
            // Convex polyhedra hold their first plane, lists their first member, as the
            // bits of param[0]; the f64 copy holds the f32 value widened.
            let by = match code {
                Some(TypeCode::ConvexPolyhedron) => off.plan,
                Some(c) if c.is_list() => off.node,
                _ => continue,
            };
            let first = shift(n.param[0].to_bits(), by, ("node", i, "param"))?;
            n.param[0] = f32::from_bits(first);
            if let Some(p) = node64.get_mut(i) {
                p.param[0] = f64::from(n.param[0]);
            }
        }
        let brick = other
            .brick
            .iter()
            .enumerate()
            .map(|(i, b)| {
                let mut b = *b;
                b.prim = shift(b.prim, off.prim, ("brick", i, "prim"))?;
                Ok(b)
            })
            .collect::<Result<Vec<_>>>()?;
        let boundaries = other
            .optics
            .boundaries
            .iter()
            .enumerate()
            .map(|(i, b)| {
                let at = |field| ("boundary", i, field);
                Ok(Boundary {
                    outer_material: shift_set(
                        b.outer_material,
                        off.material,
                        at("outer_material"),
                    )?,
                    outer_surface: shift_set(b.outer_surface, off.surface, at("outer_surface"))?,
                    inner_surface: shift_set(b.inner_surface, off.surface, at("inner_surface"))?,
                    inner_material: shift_set(
                        b.inner_material,
                        off.material,
                        at("inner_material"),
                    )?,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let media = other
            .optics
            .media
            .iter()
            .enumerate()
            .map(|(i, m)| {
                Ok(Medium {
                    prim: shift(m.prim, off.prim, ("medium", i, "prim"))?,
                    ..m.clone()
                })
            })
            .collect::<Result<Vec<_>>>()?;

        let mut inst = Vec::with_capacity(copies);
        let mut inst_tran = Vec::with_capacity(copies);
        let mut inst_mother = Vec::with_capacity(copies);
        let mut instances = Vec::with_capacity(placements.len());
        for (k, placement) in placements.iter().enumerate() {
            invert(placement).map_err(|e| FoundryError::Build(format!("placement {k}: {e}")))?;
            let base = (self.inst.len() + inst.len()) as u32;
            instances.push(base..base + other.inst.len() as u32);
            let records = other
                .inst
                .iter()
                .zip(&other.inst_tran)
                .zip(&other.inst_mother);
            for (i, ((x, t), m)) in records.enumerate() {
                let world = placement.compose(&t.to_transform());
                let inverse = invert(&world)
                    .map_err(|e| FoundryError::Build(format!("placement {k}, instance {i}: {e}")))?
                    .to_f32();
                inst.push(Instance {
                    itra: [inverse.rows[0], inverse.rows[1], inverse.rows[2]],
                    solid: shift(x.solid, off.solid, ("inst", i, "solid"))?,
                    identity: shift_set(x.identity, off.volume, ("inst", i, "identity"))?,
                    copy_number: x.copy_number,
                    boundary: shift_set(x.boundary, off.boundary, ("inst", i, "boundary"))?,
                });
                inst_tran.push(Affine64::from_transform(&world));
                inst_mother.push(Mother {
                    index: shift_set(m.index, base, ("inst_mother", i, "index"))?,
                });
            }
        }

        let appended = Appended {
            solids: off.solid..off.solid + solid.len() as u32,
            instances,
            boundaries: off.boundary..off.boundary + boundaries.len() as u32,
        };
        self.solid.extend(solid);
        self.prim.extend(prim);
        self.node.extend(node);
        self.node64.extend(node64);
        self.plan.extend_from_slice(&other.plan);
        self.plan64.extend_from_slice(&other.plan64);
        self.tran.extend_from_slice(&other.tran);
        self.itra.extend_from_slice(&other.itra);
        self.inst.extend(inst);
        self.inst_tran.extend(inst_tran);
        self.inst_mother.extend(inst_mother);
        self.tri.extend_from_slice(&other.tri);
        self.brick.extend(brick);
        self.solid_names.extend_from_slice(&other.solid_names);
        let optics = &mut self.optics;
        optics.materials.extend_from_slice(&other.optics.materials);
        optics.surfaces.extend_from_slice(&other.optics.surfaces);
        optics.boundaries.extend(boundaries);
        optics.volumes.extend_from_slice(&other.optics.volumes);
        optics.media.extend(media);
        Ok(appended)
    }
}

/// A prim of the appended Foundry with its indices moved by `off`: nodes for CSG prims,
/// triangles or bricks for data prims (whose `node_offset` stays 0, as built).
fn relocate_prim(p: &Prim, i: usize, off: &Offsets) -> Result<Prim> {
    let at = |field| ("prim", i, field);
    let mut p = *p;
    match PrimKind::from_u32(p.kind) {
        Some(PrimKind::Csg) => p.node_offset = shift(p.node_offset, off.node, at("node_offset"))?,
        Some(PrimKind::Mesh) => p.item_offset = shift(p.item_offset, off.tri, at("item_offset"))?,
        Some(PrimKind::Volume) => {
            p.item_offset = shift(p.item_offset, off.brick, at("item_offset"))?
        }
        None => {
            return Err(FoundryError::Record {
                array: "prim",
                record: i,
                field: "kind",
                problem: format!("unknown prim kind {}", p.kind),
            })
        }
    }
    p.tran_offset = shift(p.tran_offset, off.tran, at("tran_offset"))?;
    p.plan_offset = shift(p.plan_offset, off.plan, at("plan_offset"))?;
    if p.transform != 0 {
        p.transform = shift(p.transform, off.tran, at("transform"))?;
    }
    p.boundary = shift_set(p.boundary, off.boundary, at("boundary"))?;
    Ok(p)
}
