//! The records the GPU kernels read for prepared CSG trees and meshes, in f32: exactly the
//! values the CPU's f32 kernels use, so the WGSL twins can be compared ray by ray. Their
//! WGSL declarations are generated from these definitions (`shaders/generated/trace_records.wgsl`,
//! see `hytrace_trace::gpu::records`).

use hytrace_foundry::layout::{Field, Record};
use hytrace_foundry::record;

use crate::kernel::Frame;

pub mod mesh;
pub mod tree;

record! {
    /// An affine frame as the kernels apply it: row `k` is `(inverse[k].xyz, origin[k])`,
    /// a parent point `p` maps to `dot(inverse[k], p - origin)` (see [`Frame`]).
    pub struct FrameRecord {
        /// The inverse linear part's rows, each with one origin coordinate in `w`.
        pub rows: [[f32; 4]; 3],
    }
}

impl FrameRecord {
    /// The record of an f32 frame.
    pub fn new(frame: &Frame<f32>) -> Self {
        FrameRecord { rows: frame.rows() }
    }
}

/// A record's WGSL name, size and fields, for generators and layout checks.
pub type RecordEntry = (&'static str, usize, &'static [Field]);

/// The table entry of record `R`.
pub fn entry<R: Record>() -> RecordEntry {
    (R::NAME, size_of::<R>(), R::fields())
}

/// Every record of this module and its submodules, in declaration order.
pub fn records() -> Vec<RecordEntry> {
    let mut all = vec![entry::<FrameRecord>()];
    all.extend(tree::records());
    all.extend(mesh::records());
    all
}

/// Appends the WGSL declaration of every record (and shared constant table) of this
/// module and its submodules.
pub fn push_wgsl(out: &mut String) {
    hytrace_foundry::wgsl::push_struct::<FrameRecord>(out);
    tree::push_wgsl(out);
    mesh::push_wgsl(out);
}
