//! NanoVDB 32.x byte layout: magic numbers, the grid header, node sizes and field offsets, and
//! the enumerations a file stores (value type, class, codec, version).
//!
//! Every offset is relative to the start of its structure; all values are little-endian.
//! The layout of the grid header, tree header, root, internal and leaf nodes of the value
//! types read here is the same from NanoVDB 32.3 to 32.9 (checked against the sources);
//! 32.6 added the grid/file magic numbers and raw grid-buffer files.

use std::fmt;

/// Magic of segment headers and grids up to 32.6: "NanoVDB0".
pub(crate) const MAGIC_NUMB: u64 = 0x3042_4456_6f6e_614e;
/// Magic of grids from 32.7 on (also in the last header word of 32.6 grids): "NanoVDB1".
pub(crate) const MAGIC_GRID: u64 = 0x3142_4456_6f6e_614e;
/// Magic of segment headers from 32.7 on: "NanoVDB2".
pub(crate) const MAGIC_FILE: u64 = 0x3242_4456_6f6e_614e;
/// The low four bytes of an OpenVDB file's magic (" BDV").
pub(crate) const OPENVDB_MAGIC_LOW: u32 = 0x5644_4220;

/// The only major version (ABI and file format) this reader knows.
pub(crate) const MAJOR: u32 = 32;
/// The first minor version whose layout was checked to match.
pub(crate) const MIN_MINOR: u32 = 3;

/// Grid header (GridData): 672 bytes.
pub(crate) mod grid {
    pub const SIZE: usize = 672;
    pub const MAGIC: usize = 0;
    pub const VERSION: usize = 16;
    pub const GRID_SIZE: usize = 32;
    pub const NAME: usize = 40;
    pub const NAME_SIZE: usize = 256;
    /// Map: 9 f32 matrix, 9 f32 inverse, 3 f32 vector, f32 taper, then the same in f64.
    pub const MAP_MATRIX_F64: usize = 296 + 88;
    pub const MAP_VECTOR_F64: usize = 296 + 232;
    pub const WORLD_BBOX: usize = 560;
    pub const VOXEL_SIZE: usize = 608;
    pub const CLASS: usize = 632;
    pub const TYPE: usize = 636;
    /// The last word; 32.6 grids keep "NanoVDB1" here.
    pub const DATA2: usize = 664;
}

/// Tree header (TreeData), right after the grid header: 64 bytes.
pub(crate) mod tree {
    pub const SIZE: usize = 64;
    /// Byte offset (from the tree header) of the root node.
    pub const ROOT_OFFSET: usize = 24;
    /// Node counts: leaf, lower, upper (u32 each).
    pub const NODE_COUNT: usize = 32;
    /// Active tile counts: lower, upper, root (u32 each).
    pub const TILE_COUNT: usize = 44;
    pub const VOXEL_COUNT: usize = 56;
}

/// Root node: bbox (2 x 3 i32), table size, background and statistics, then the tiles.
pub(crate) mod root {
    pub const BBOX: usize = 0;
    pub const TABLE_SIZE: usize = 24;
    /// One root tile: u64 key, i64 child offset (from the root), u32 state, value.
    pub const TILE_SIZE: usize = 32;
    pub const TILE_KEY: usize = 0;
    pub const TILE_CHILD: usize = 8;
    pub const TILE_STATE: usize = 16;
    /// Bits of each coordinate a key keeps (coordinate >> 12 as u32), in 21-bit fields.
    pub const KEY_FIELD_MASK: u64 = (1 << 20) - 1;
}

/// Internal nodes: bbox, flags, value mask, child mask, statistics, then one 8-byte table
/// entry per child slot (a tile value, or a child offset relative to the node).
pub(crate) struct Internal {
    /// log2 of the children per side.
    pub log2: u32,
    /// log2 of the voxels per side of one child.
    pub child_log2: u32,
    pub value_mask: usize,
    pub child_mask: usize,
    pub table: usize,
    pub size: usize,
}

/// The upper internal node: 32^3 children of 128^3 voxels.
pub(crate) const UPPER: Internal = Internal {
    log2: 5,
    child_log2: 7,
    value_mask: 32,
    child_mask: 32 + 4096,
    table: 8256,
    size: 8256 + 32768 * 8,
};

/// The lower internal node: 16^3 children of 8^3 voxels.
pub(crate) const LOWER: Internal = Internal {
    log2: 4,
    child_log2: 3,
    value_mask: 32,
    child_mask: 32 + 512,
    table: 1088,
    size: 1088 + 4096 * 8,
};

impl Internal {
    /// Child slots of the node.
    pub const fn slots(&self) -> usize {
        1 << (3 * self.log2)
    }

    /// Slot of voxel `ijk`: x slowest, z fastest.
    pub fn slot(&self, ijk: [i32; 3]) -> usize {
        let side = (1u32 << self.log2) - 1;
        let part = |c: i32| ((c as u32 >> self.child_log2) & side) as usize;
        (part(ijk[0]) << (2 * self.log2)) | (part(ijk[1]) << self.log2) | part(ijk[2])
    }

    /// Offset from the node origin of the child in `slot`.
    pub fn child_offset(&self, slot: usize) -> [i32; 3] {
        let side = (1usize << self.log2) - 1;
        let c = |shift: u32| (((slot >> shift) & side) as i32) << self.child_log2;
        [c(2 * self.log2), c(self.log2), c(0)]
    }
}

/// Leaf nodes: origin (3 x i32), bbox extent (3 bytes), flags, value mask (64 bytes), then
/// statistics and values that depend on the value type.
pub(crate) mod leaf {
    pub const FLAGS: usize = 15;
    pub const VALUE_MASK: usize = 16;
    /// Quantized leaves: f32 minimum, f32 quantum, four u16 statistics, then the codes.
    pub const FP_MINIMUM: usize = 80;
    pub const FP_QUANTUM: usize = 84;
    pub const FP_CODES: usize = 96;
}

/// Slot of voxel `ijk` in its leaf: x slowest, z fastest.
pub(crate) fn leaf_slot(ijk: [i32; 3]) -> usize {
    let part = |c: i32| (c & 7) as usize;
    (part(ijk[0]) << 6) | (part(ijk[1]) << 3) | part(ijk[2])
}

/// A major.minor.patch version, packed by NanoVDB as 11 + 11 + 10 bits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct NanoVersion {
    /// ABI and file-format version (32 for every file this reader reads).
    pub major: u32,
    /// API version.
    pub minor: u32,
    /// Bug-fix version.
    pub patch: u32,
}

impl NanoVersion {
    /// Unpacks NanoVDB's 32-bit version word.
    pub fn from_packed(word: u32) -> NanoVersion {
        NanoVersion {
            major: word >> 21,
            minor: (word >> 10) & 0x7ff,
            patch: word & 0x3ff,
        }
    }

    /// Whether this reader knows the layout of files of this version.
    pub fn is_supported(&self) -> bool {
        self.major == MAJOR && self.minor >= MIN_MINOR
    }
}

impl fmt::Display for NanoVersion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{}.{}", self.major, self.minor, self.patch)
    }
}

/// How a grid's bytes are compressed in the file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum NanoCodec {
    /// Stored as is (also every raw grid buffer).
    None,
    /// zlib stream (NanoVDB's "ZIP").
    Zip,
    /// Blosc 1 frames of at most 1 GiB each.
    Blosc,
}

impl NanoCodec {
    pub(crate) fn from_code(code: u16) -> Option<NanoCodec> {
        match code {
            0 => Some(NanoCodec::None),
            1 => Some(NanoCodec::Zip),
            2 => Some(NanoCodec::Blosc),
            _ => None,
        }
    }
}

impl fmt::Display for NanoCodec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            NanoCodec::None => "NONE",
            NanoCodec::Zip => "ZIP",
            NanoCodec::Blosc => "BLOSC",
        })
    }
}

macro_rules! code_enum {
    ($(#[$doc:meta])* $name:ident { $($(#[$vdoc:meta])* $variant:ident = $code:literal => $text:literal,)* }) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum $name {
            $($(#[$vdoc])* $variant,)*
            /// A code this reader does not know.
            Other(u32),
        }

        impl $name {
            /// The enumeration value of NanoVDB's code.
            pub fn from_code(code: u32) -> $name {
                match code {
                    $($code => $name::$variant,)*
                    other => $name::Other(other),
                }
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                match self {
                    $($name::$variant => f.write_str($text),)*
                    $name::Other(code) => write!(f, "unknown({code})"),
                }
            }
        }
    };
}

code_enum! {
    /// The value type of a grid (NanoVDB's GridType).
    NanoGridType {
        /// No type given.
        Unknown = 0 => "unknown",
        /// 32-bit float values.
        Float = 1 => "float",
        /// 64-bit float values.
        Double = 2 => "double",
        /// 16-bit integers.
        Int16 = 3 => "int16",
        /// 32-bit integers.
        Int32 = 4 => "int32",
        /// 64-bit integers.
        Int64 = 5 => "int64",
        /// 3 x f32 vectors.
        Vec3f = 6 => "Vec3f",
        /// 3 x f64 vectors.
        Vec3d = 7 => "Vec3d",
        /// Active states only.
        Mask = 8 => "Mask",
        /// IEEE half floats (a placeholder in NanoVDB 32.x: no leaf layout is defined).
        Half = 9 => "Half",
        /// 32-bit unsigned integers.
        UInt32 = 10 => "uint32",
        /// Booleans.
        Boolean = 11 => "bool",
        /// Packed RGBA colours.
        Rgba8 = 12 => "RGBA8",
        /// Floats quantized to 4 bits per leaf.
        Fp4 = 13 => "Fp4",
        /// Floats quantized to 8 bits per leaf.
        Fp8 = 14 => "Fp8",
        /// Floats quantized to 16 bits per leaf.
        Fp16 = 15 => "Fp16",
        /// Floats quantized to 1, 2, 4, 8 or 16 bits chosen per leaf.
        FpN = 16 => "FpN",
        /// 4 x f32 vectors.
        Vec4f = 17 => "Vec4f",
        /// 4 x f64 vectors.
        Vec4d = 18 => "Vec4d",
        /// Indices into external arrays of all values.
        Index = 19 => "Index",
        /// Indices into external arrays of active values.
        OnIndex = 20 => "OnIndex",
        /// Indices of points.
        PointIndex = 23 => "PointIndex",
        /// Quantized 3 x u8 vectors.
        Vec3u8 = 24 => "Vec3u8",
        /// Quantized 3 x u16 vectors.
        Vec3u16 = 25 => "Vec3u16",
        /// 8-bit unsigned integers.
        UInt8 = 26 => "uint8",
    }
}

code_enum! {
    /// What a grid represents (NanoVDB's GridClass).
    NanoGridClass {
        /// No class given.
        Unknown = 0 => "unknown",
        /// Narrow-band level set.
        LevelSet = 1 => "level set",
        /// Fog volume (density).
        FogVolume = 2 => "fog volume",
        /// Staggered (MAC) grid.
        Staggered = 3 => "staggered",
        /// Point index grid.
        PointIndex = 4 => "point index",
        /// Point data grid.
        PointData = 5 => "point data",
        /// Topology only.
        Topology = 6 => "topology",
        /// Voxel volume (coloured cubes).
        VoxelVolume = 7 => "voxel volume",
        /// Index grid.
        IndexGrid = 8 => "index grid",
        /// Tensor grid.
        TensorGrid = 9 => "tensor grid",
        /// Voxel BVH.
        VoxelBvh = 10 => "voxel BVH",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn magic_numbers_spell_their_names() {
        assert_eq!(&MAGIC_NUMB.to_le_bytes(), b"NanoVDB0");
        assert_eq!(&MAGIC_GRID.to_le_bytes(), b"NanoVDB1");
        assert_eq!(&MAGIC_FILE.to_le_bytes(), b"NanoVDB2");
        assert_eq!(&OPENVDB_MAGIC_LOW.to_le_bytes(), b" BDV");
    }

    #[test]
    fn versions_unpack_and_slots_round_trip() {
        let v = NanoVersion::from_packed(32 << 21 | 4 << 10 | 2);
        assert_eq!(v.to_string(), "32.4.2");
        assert!(v.is_supported());
        assert!(!NanoVersion::from_packed(31 << 21).is_supported());
        assert!(!NanoVersion::from_packed(32 << 21 | 2 << 10).is_supported());
        for node in [&UPPER, &LOWER] {
            for slot in [0, 1, 77, node.slots() - 1] {
                let o = node.child_offset(slot);
                assert_eq!(node.slot(o), slot);
                assert_eq!(
                    node.slot(o.map(|c| c - (1 << (node.log2 + node.child_log2)))),
                    slot
                );
            }
        }
        assert_eq!(leaf_slot([-1, -1, -1]), 511);
        assert_eq!(leaf_slot([1, 2, 3]), 64 + 16 + 3);
        assert_eq!(NanoGridType::from_code(15).to_string(), "Fp16");
        assert_eq!(NanoGridType::from_code(99), NanoGridType::Other(99));
        assert_eq!(NanoGridClass::from_code(2).to_string(), "fog volume");
    }
}
