//! Field-level descriptions of the POD records shared with the GPU and with NumPy.
//!
//! Every record type carries a static table of its fields (name, scalar type, shape and byte
//! offset taken from the Rust definition). That one table generates the WGSL struct
//! declaration (see [`crate::wgsl`]) and the NumPy dtype of the record's `.npy` file (see
//! [`crate::npy`]), so the CPU, the GPU and Python cannot disagree about a layout.

/// Scalar element type of a record field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scalar {
    /// 32-bit IEEE float.
    F32,
    /// 64-bit IEEE float (CPU-side records only: WGSL has no portable f64).
    F64,
    /// 32-bit unsigned integer.
    U32,
    /// 32-bit signed integer.
    I32,
}

impl Scalar {
    /// Size in bytes.
    pub const fn size(self) -> usize {
        match self {
            Scalar::F64 => 8,
            _ => 4,
        }
    }

    /// The WGSL spelling, or `None` where WGSL has no portable equivalent.
    pub const fn wgsl(self) -> Option<&'static str> {
        match self {
            Scalar::F32 => Some("f32"),
            Scalar::U32 => Some("u32"),
            Scalar::I32 => Some("i32"),
            Scalar::F64 => None,
        }
    }

    /// The little-endian NumPy type string (`<f4`, `<u4`, ...).
    pub const fn numpy(self) -> &'static str {
        match self {
            Scalar::F32 => "<f4",
            Scalar::F64 => "<f8",
            Scalar::U32 => "<u4",
            Scalar::I32 => "<i4",
        }
    }
}

/// One field of a record: `shape` is empty for a scalar, `[n]` for `[T; n]`, `[m, n]` for
/// `[[T; n]; m]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Field {
    /// Field name, identical in Rust, WGSL and the NumPy dtype.
    pub name: &'static str,
    /// Element type.
    pub scalar: Scalar,
    /// Array dimensions, outermost first.
    pub shape: &'static [usize],
    /// Byte offset inside the record, from `core::mem::offset_of!`.
    pub offset: usize,
}

impl Field {
    /// Number of scalars in the field.
    pub fn count(&self) -> usize {
        self.shape.iter().product()
    }

    /// Size of the field in bytes.
    pub fn size(&self) -> usize {
        self.count() * self.scalar.size()
    }

    /// The WGSL type of the field. An innermost dimension of 4 becomes a `vec4`, which gives
    /// 16-byte loads on the GPU; every other dimension becomes an `array`.
    pub fn wgsl_type(&self) -> Option<String> {
        let scalar = self.scalar.wgsl()?;
        let mut ty = scalar.to_string();
        for (i, &n) in self.shape.iter().rev().enumerate() {
            ty = if i == 0 && n == 4 {
                format!("vec4<{scalar}>")
            } else {
                format!("array<{ty}, {n}>")
            };
        }
        Some(ty)
    }
}

/// A `#[repr(C)]` plain-old-data record with a field table.
pub trait Record: bytemuck::Pod {
    /// Name of the record type (also its WGSL struct name).
    const NAME: &'static str;
    /// The fields in declaration order.
    fn fields() -> &'static [Field];
    /// Whether the record is declared in WGSL (false for CPU-only f64 records).
    fn on_gpu() -> bool {
        Self::fields().iter().all(|f| f.scalar.wgsl().is_some())
    }
}

/// Maps a Rust field type to its scalar type and shape.
pub trait FieldType {
    /// Element type.
    const SCALAR: Scalar;
    /// Array dimensions, outermost first.
    const SHAPE: &'static [usize];
}

macro_rules! scalar_field_type {
    ($t:ty, $s:expr) => {
        impl FieldType for $t {
            const SCALAR: Scalar = $s;
            const SHAPE: &'static [usize] = &[];
        }
        impl<const N: usize> FieldType for [$t; N] {
            const SCALAR: Scalar = $s;
            const SHAPE: &'static [usize] = &[N];
        }
        impl<const N: usize, const M: usize> FieldType for [[$t; N]; M] {
            const SCALAR: Scalar = $s;
            const SHAPE: &'static [usize] = &[M, N];
        }
    };
}
scalar_field_type!(f32, Scalar::F32);
scalar_field_type!(f64, Scalar::F64);
scalar_field_type!(u32, Scalar::U32);
scalar_field_type!(i32, Scalar::I32);

/// Declares a `#[repr(C)]` POD record and implements [`Record`] for it from its fields.
#[macro_export]
macro_rules! record {
    (
        $(#[$meta:meta])*
        pub struct $name:ident {
            $( $(#[$fmeta:meta])* pub $field:ident : $ty:ty, )+
        }
    ) => {
        $(#[$meta])*
        #[repr(C)]
        #[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
        pub struct $name {
            $( $(#[$fmeta])* pub $field: $ty, )+
        }

        impl $crate::layout::Record for $name {
            const NAME: &'static str = stringify!($name);
            fn fields() -> &'static [$crate::layout::Field] {
                const FIELDS: &[$crate::layout::Field] = &[
                    $( $crate::layout::Field {
                        name: stringify!($field),
                        scalar: <$ty as $crate::layout::FieldType>::SCALAR,
                        shape: <$ty as $crate::layout::FieldType>::SHAPE,
                        offset: core::mem::offset_of!($name, $field),
                    }, )+
                ];
                FIELDS
            }
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wgsl_types_follow_shapes() {
        let f = |scalar, shape| Field {
            name: "x",
            scalar,
            shape,
            offset: 0,
        };
        assert_eq!(f(Scalar::F32, &[]).wgsl_type().unwrap(), "f32");
        assert_eq!(f(Scalar::U32, &[4]).wgsl_type().unwrap(), "vec4<u32>");
        assert_eq!(f(Scalar::F32, &[6]).wgsl_type().unwrap(), "array<f32, 6>");
        assert_eq!(
            f(Scalar::F32, &[3, 4]).wgsl_type().unwrap(),
            "array<vec4<f32>, 3>"
        );
        assert_eq!(f(Scalar::F64, &[4]).wgsl_type(), None);
    }
}
