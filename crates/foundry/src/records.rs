//! The POD records of the Foundry store.
//!
//! Node, Prim, Solid, Instance and Brick are 64 bytes (four quads of 4x32 bits), in the spirit
//! of Opticks' CSGFoundry. Planes are one quad, triangles three, transforms four. The GPU
//! declarations in `shaders/generated/foundry.wgsl` are generated from these definitions.

use crate::record;

/// Bit of [`Node::transform`] that marks a complemented (inside-out) leaf.
pub const COMPLEMENT_BIT: u32 = 0x8000_0000;

record! {
    /// A node of a CSG tree stored as a complete binary tree (level order, root first).
    ///
    /// `param` and `param_ext` hold the primitive parameters (see [`crate::TypeCode`] for each
    /// primitive's convention); operator and empty nodes leave them zero.
    pub struct Node {
        /// Primitive parameters 0-3.
        pub param: [f32; 4],
        /// Primitive parameters 4-5.
        pub param_ext: [f32; 2],
        /// Boundary index: which (inner material, outer material, surface) this node's surface
        /// separates. `u32::MAX` when unset.
        pub boundary: u32,
        /// User index of the node (e.g. the source solid's index in an importer).
        pub index: u32,
        /// Axis-aligned bounds in the prim's frame: min xyz then max xyz.
        pub aabb: [f32; 6],
        /// The [`crate::TypeCode`] of the node.
        pub typecode: u32,
        /// 1-based index into `tran`/`itra` (0: no transform); bit 31 is the complement flag.
        pub transform: u32,
    }
}

record! {
    /// A prim: one CSG tree, one range of triangles or one range of volume bricks.
    pub struct Prim {
        /// Number of nodes of the complete binary tree (2^(h+1) - 1); 0 for non-CSG prims.
        pub num_node: u32,
        /// Index of the tree's root in `node`.
        pub node_offset: u32,
        /// First transform used by the prim's nodes (0-based, into `tran`/`itra`).
        pub tran_offset: u32,
        /// First plane used by the prim's nodes (0-based, into `plan`).
        pub plan_offset: u32,
        /// The [`crate::PrimKind`] of the prim.
        pub kind: u32,
        /// First triangle (mesh prims) or brick (volume prims).
        pub item_offset: u32,
        /// Number of triangles or bricks.
        pub item_count: u32,
        /// User identity of the prim (e.g. a logical volume index).
        pub identity: u32,
        /// Bounds in the solid's frame: min xyz then max xyz.
        pub aabb: [f32; 6],
        /// Mesh and volume prims: 1-based transform from the prim's data space (mesh
        /// coordinates, volume index space) into the solid's frame; 0 is the identity.
        pub transform: u32,
        /// Default boundary index of the prim's surfaces (`u32::MAX` when unset).
        pub boundary: u32,
    }
}

record! {
    /// A solid: a contiguous range of prims traced together (one BLAS).
    pub struct Solid {
        /// Up to 16 bytes of the solid's name, NUL-padded (full names are in `meta.json`).
        pub label: [u32; 4],
        /// Number of prims.
        pub num_prim: u32,
        /// Index of the first prim in `prim`.
        pub prim_offset: u32,
        /// Bit set of the [`crate::PrimKind`]s present (bit `1 << kind`).
        pub content: u32,
        /// Largest CSG tree height among the solid's prims (sizes the GPU stacks).
        pub max_height: u32,
        /// Bounds in the solid's frame: min xyz then max xyz.
        pub aabb: [f32; 6],
        /// Half of the largest side of `aabb`, as Opticks' center_extent.
        pub extent: f32,
        /// User identity of the solid (e.g. a logical volume index).
        pub identity: u32,
    }
}

record! {
    /// One placement of a solid in the world.
    pub struct Instance {
        /// World-to-local affine transform, the top three rows of the 4x4 matrix (f32, for
        /// the GPU; the f64 local-to-world original is kept in `inst_tran`).
        pub itra: [[f32; 4]; 3],
        /// Index of the placed solid.
        pub solid: u32,
        /// User identity of the placement (e.g. a physical volume index).
        pub identity: u32,
        /// Copy number of the placement (Geant4's copyNo; sensor identity).
        pub copy_number: i32,
        /// Boundary index of the placement's outer surface (`u32::MAX` when unset).
        pub boundary: u32,
    }
}

record! {
    /// An affine transform in double precision without the constant last row (CPU only):
    /// the local-to-world placement of an instance, 96 bytes instead of 128.
    pub struct Affine64 {
        /// The top three rows of the 4x4 matrix.
        pub rows: [[f64; 4]; 3],
    }
}

record! {
    /// Where an instance sits in a placement hierarchy (CPU only): the instance whose solid
    /// contains it, as a Geant4 daughter sits in its mother volume.
    pub struct Mother {
        /// Index of the mother instance (always lower than the daughter's); `u32::MAX` for
        /// an instance of a flat scene or the world.
        pub index: u32,
    }
}

record! {
    /// A row-major 4x4 affine transform acting on column vectors (f32, the GPU's copy).
    pub struct Transform {
        /// Matrix rows; the last row is (0, 0, 0, 1).
        pub rows: [[f32; 4]; 4],
    }
}

record! {
    /// A row-major 4x4 affine transform in double precision (CPU only): the original
    /// from which the f32 inverse given to the GPU is derived.
    pub struct Transform64 {
        /// Matrix rows; the last row is (0, 0, 0, 1).
        pub rows: [[f64; 4]; 4],
    }
}

record! {
    /// The primitive parameters of a [`Node`] in double precision (CPU only): the originals
    /// from which `param` and `param_ext` are rounded. Nodes whose parameters are indices
    /// (lists, convex polyhedra) or that have none hold their f32 values widened.
    pub struct NodeParam64 {
        /// `param` then `param_ext`.
        pub param: [f64; 6],
    }
}

record! {
    /// A [`Plane`] in double precision (CPU only): the original of the f32 plane.
    pub struct Plane64 {
        /// Unit outward normal xyz and the signed distance from the origin.
        pub plane: [f64; 4],
    }
}

record! {
    /// A plane `dot(normal, p) = distance` bounding a convex polyhedron (outward normal).
    pub struct Plane {
        /// Unit outward normal xyz and the signed distance from the origin.
        pub plane: [f32; 4],
    }
}

record! {
    /// One triangle of a mesh prim, vertices in the prim's data space (w = 0).
    pub struct Triangle {
        /// The three vertices, counter-clockwise seen from outside.
        pub v: [[f32; 4]; 3],
    }
}

record! {
    /// One 8^3 brick of a sparse volume.
    pub struct Brick {
        /// Index-space coordinate of the brick's first voxel.
        pub origin: [i32; 3],
        /// Resolution level (0: full resolution).
        pub level: u32,
        /// Slot of the brick's texels in the atlas (`u32::MAX` for constant bricks).
        pub atlas_slot: u32,
        /// Index of the volume prim the brick belongs to.
        pub prim: u32,
        /// Smallest value any lookup inside the brick can return (halo included).
        pub value_min: f32,
        /// Largest value any lookup inside the brick can return (halo included): the majorant.
        pub value_max: f32,
        /// Bounds in the prim's data (index) space: min xyz then max xyz.
        pub aabb: [f32; 6],
        /// Number of active voxels in the brick.
        pub active_voxels: u32,
        /// Number of voxels per side (8 for the bricked grid).
        pub size: u32,
    }
}

impl Transform64 {
    /// The identity transform.
    pub const IDENTITY: Transform64 = Transform64 {
        rows: [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ],
    };

    /// A pure translation.
    pub fn translation(t: [f64; 3]) -> Transform64 {
        let mut m = Self::IDENTITY;
        for (row, ti) in m.rows.iter_mut().zip(t) {
            row[3] = ti;
        }
        m
    }

    /// A scaling by `s` along the axes.
    pub fn scaling(s: [f64; 3]) -> Transform64 {
        let mut m = Self::IDENTITY;
        for (k, sk) in s.into_iter().enumerate() {
            m.rows[k][k] = sk;
        }
        m
    }

    /// A right-handed rotation by `angle` radians about `axis` (any non-zero length;
    /// Rodrigues' formula).
    pub fn rotation(axis: [f64; 3], angle: f64) -> Transform64 {
        let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
        let [x, y, z] = axis.map(|a| a / n);
        let (s, c) = angle.sin_cos();
        let t = 1.0 - c;
        Transform64 {
            rows: [
                [t * x * x + c, t * x * y - s * z, t * x * z + s * y, 0.0],
                [t * x * y + s * z, t * y * y + c, t * y * z - s * x, 0.0],
                [t * x * z - s * y, t * y * z + s * x, t * z * z + c, 0.0],
                [0.0, 0.0, 0.0, 1.0],
            ],
        }
    }

    /// Applies the transform to a point.
    pub fn apply_point(&self, p: [f64; 3]) -> [f64; 3] {
        let r = &self.rows;
        std::array::from_fn(|i| r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2] + r[i][3])
    }

    /// Applies the linear part of the transform to a direction.
    pub fn apply_vector(&self, v: [f64; 3]) -> [f64; 3] {
        let r = &self.rows;
        std::array::from_fn(|i| r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2])
    }

    /// Matrix product `self * other` (apply `other` first).
    pub fn compose(&self, other: &Transform64) -> Transform64 {
        let (a, b) = (&self.rows, &other.rows);
        Transform64 {
            rows: std::array::from_fn(|i| {
                std::array::from_fn(|j| (0..4).map(|k| a[i][k] * b[k][j]).sum())
            }),
        }
    }

    /// Determinant of the linear 3x3 part (negative for a reflection).
    pub fn linear_determinant(&self) -> f64 {
        let m = &self.rows;
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    }

    /// Whether the last row is (0, 0, 0, 1) and every element finite.
    pub fn is_affine(&self) -> bool {
        self.rows.iter().flatten().all(|v| v.is_finite()) && self.rows[3] == [0.0, 0.0, 0.0, 1.0]
    }

    /// The inverse of an affine transform, or `None` when the linear part is singular.
    pub fn inverse(&self) -> Option<Transform64> {
        let m = &self.rows;
        // Inverse of the 3x3 linear part by cofactors; the translation follows as -A^-1 t.
        let c = |r0: usize, r1: usize, c0: usize, c1: usize| {
            m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]
        };
        let cof = [
            [c(1, 2, 1, 2), -c(1, 2, 0, 2), c(1, 2, 0, 1)],
            [-c(0, 2, 1, 2), c(0, 2, 0, 2), -c(0, 2, 0, 1)],
            [c(0, 1, 1, 2), -c(0, 1, 0, 2), c(0, 1, 0, 1)],
        ];
        let det = m[0][0] * cof[0][0] + m[0][1] * cof[0][1] + m[0][2] * cof[0][2];
        let scale = m[..3]
            .iter()
            .flat_map(|r| &r[..3])
            .fold(0.0f64, |a, v| a.max(v.abs()));
        if !det.is_finite() || det.abs() <= 1e-12 * scale.powi(3) || scale == 0.0 {
            return None;
        }
        let mut inv = Self::IDENTITY;
        for (i, row) in inv.rows[..3].iter_mut().enumerate() {
            for (j, v) in row[..3].iter_mut().enumerate() {
                *v = cof[j][i] / det;
            }
            row[3] = -(0..3).map(|k| row[k] * m[k][3]).sum::<f64>();
        }
        Some(inv)
    }

    /// Rounds to single precision.
    pub fn to_f32(&self) -> Transform {
        Transform {
            rows: self.rows.map(|r| r.map(|v| v as f32)),
        }
    }
}

impl Affine64 {
    /// The top three rows of an affine transform.
    pub fn from_transform(t: &Transform64) -> Self {
        Affine64 {
            rows: [t.rows[0], t.rows[1], t.rows[2]],
        }
    }

    /// The full 4x4 transform.
    pub fn to_transform(&self) -> Transform64 {
        Transform64 {
            rows: [
                self.rows[0],
                self.rows[1],
                self.rows[2],
                [0.0, 0.0, 0.0, 1.0],
            ],
        }
    }

    /// Applies the transform to a point.
    pub fn apply_point(&self, p: [f64; 3]) -> [f64; 3] {
        self.to_transform().apply_point(p)
    }
}

impl NodeParam64 {
    /// The f32 parameters of a node widened to f64 (exact).
    pub fn widened(node: &Node) -> Self {
        let p = [
            node.param[0],
            node.param[1],
            node.param[2],
            node.param[3],
            node.param_ext[0],
            node.param_ext[1],
        ];
        NodeParam64 {
            param: p.map(f64::from),
        }
    }
}

/// Packs a solid name into a [`Solid::label`]: its first 16 bytes, NUL-padded.
pub fn pack_label(name: &str) -> [u32; 4] {
    let mut bytes = [0u8; 16];
    for (dst, src) in bytes.iter_mut().zip(name.bytes()) {
        *dst = src;
    }
    bytemuck::cast(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::layout::Record;

    #[test]
    fn quad_records_are_64_bytes() {
        for (name, size) in [
            (Node::NAME, size_of::<Node>()),
            (Prim::NAME, size_of::<Prim>()),
            (Solid::NAME, size_of::<Solid>()),
            (Instance::NAME, size_of::<Instance>()),
            (Transform::NAME, size_of::<Transform>()),
            (Brick::NAME, size_of::<Brick>()),
        ] {
            assert_eq!(size, 64, "{name}");
        }
    }

    #[test]
    fn field_tables_cover_every_byte() {
        fn check<R: Record>() {
            let mut end = 0;
            for f in R::fields() {
                assert_eq!(f.offset, end, "{}.{} leaves a gap", R::NAME, f.name);
                end += f.size();
            }
            assert_eq!(end, size_of::<R>(), "{} has trailing padding", R::NAME);
        }
        check::<Node>();
        check::<Prim>();
        check::<Solid>();
        check::<Instance>();
        check::<Transform>();
        check::<Transform64>();
        check::<Plane>();
        check::<Triangle>();
        check::<Brick>();
    }

    #[test]
    fn inverse_of_a_rotation_scale_translation_is_exact_to_rounding() {
        let (s, c) = (0.3f64.sin(), 0.3f64.cos());
        let m = Transform64 {
            rows: [
                [2.0 * c, -s, 0.0, 10.0],
                [2.0 * s, c, 0.0, -4.0],
                [0.0, 0.0, 0.5, 2e4],
                [0.0, 0.0, 0.0, 1.0],
            ],
        };
        let id = m.compose(&m.inverse().unwrap());
        for i in 0..4 {
            for j in 0..4 {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!(
                    (id.rows[i][j] - want).abs() < 1e-12,
                    "{i}{j}: {}",
                    id.rows[i][j]
                );
            }
        }
        let singular = Transform64 {
            rows: [
                [1.0, 0.0, 0.0, 0.0],
                [2.0, 0.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 0.0],
                [0.0; 4],
            ],
        };
        assert!(singular.inverse().is_none());
    }

    #[test]
    fn labels_keep_sixteen_bytes() {
        let l = pack_label("a_rather_long_solid_name");
        let bytes: [u8; 16] = bytemuck::cast(l);
        assert_eq!(&bytes, b"a_rather_long_so");
        let bytes: [u8; 16] = bytemuck::cast(pack_label("pmt"));
        assert_eq!(&bytes[..4], b"pmt\0");
    }
}
