//! Node typecodes and prim kinds: numeric codes shared by the CPU, the GPU and `.npy` files.

/// Declares a `#[repr(u32)]` enum with its WGSL constant names and a checked conversion.
macro_rules! code_enum {
    (
        $(#[$meta:meta])*
        pub enum $name:ident : $prefix:literal {
            $( $(#[$vmeta:meta])* $variant:ident = $value:literal => $wgsl:literal, )+
        }
    ) => {
        $(#[$meta])*
        #[repr(u32)]
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum $name {
            $( $(#[$vmeta])* $variant = $value, )+
        }

        impl $name {
            /// Every code, in declaration order.
            pub const ALL: &'static [$name] = &[$($name::$variant),+];

            /// The code for a raw value, if it names one.
            pub fn from_u32(value: u32) -> Option<Self> {
                match value {
                    $( $value => Some($name::$variant), )+
                    _ => None,
                }
            }

            /// The name of the WGSL constant that holds this code.
            pub fn wgsl_name(self) -> &'static str {
                match self {
                    $( $name::$variant => concat!($prefix, $wgsl), )+
                }
            }
        }
    };
}

code_enum! {
    /// What a [`crate::Node`] is. Operators and lists are below 100, primitives from 100.
    ///
    /// Primitive parameter conventions (`param[0..4]`, then `param_ext[0..2]`), in the node's
    /// own frame after its transform:
    /// - `Sphere`: centre x, y, z, radius.
    /// - `ZSphere`: centre x, y, z, radius; `param_ext`: z1, z2 cut planes relative to the centre
    ///   (z1 < z2).
    /// - `Cylinder`: centre x, y, -, radius; `param_ext`: z1, z2 (z1 < z2).
    /// - `Disc`: centre x, y, inner radius, outer radius; `param_ext`: z1, z2 (a tube: the
    ///   annular cylinder of G4Tubs).
    /// - `Cone`: r1, z1, r2, z2 (z1 < z2).
    /// - `Hyperboloid`: r0 (waist radius at z = 0), tan(stereo) (`r^2 = r0^2 + (tan z)^2`), z1, z2.
    /// - `Torus`: rmin, rmax (tube radii), rtor (swept radius).
    /// - `Box3`: full side lengths x, y, z; centred on the origin.
    /// - `ConvexPolyhedron`: first plane index (bits of `param[0]` as u32), plane count (bits of `param[1]`).
    /// - `Paraboloid`: r at z = -dz, r at z = +dz, dz.
    /// - `HalfSpace`: outward normal x, y, z, distance (inside where dot(n, p) < d).
    /// - `Slab`: normal x, y, z; `param_ext`: a, b (inside where a < dot(n, p) < b).
    /// - `PhiCut`: cos phi0, sin phi0, cos phi1, sin phi1 (inside the wedge from phi0 to phi1).
    /// - `ThetaCut`: theta0, theta1 in radians (inside the cone shell between them).
    /// - `Saddle`: kappa (inside where y <= kappa x z, below a hyperbolic paraboloid).
    /// - `TwistedHalfSpace`: unit normal x, y, z, distance; `param_ext`: twist rate w, half
    ///   height h (inside where |z| <= h and dot(n, (R(-w z) (x, y), z)) <= distance).
    pub enum TypeCode : "CSG_" {
        /// An empty slot of the complete binary tree.
        Zero = 0 => "ZERO",
        /// Boolean union of the two children.
        Union = 1 => "UNION",
        /// Boolean intersection of the two children.
        Intersection = 2 => "INTERSECTION",
        /// Left child minus right child.
        Difference = 3 => "DIFFERENCE",
        /// N-ary union of members that touch, stored as a node range.
        ListContiguous = 11 => "LIST_CONTIGUOUS",
        /// N-ary union of disjoint members, stored as a node range.
        ListDiscontiguous = 12 => "LIST_DISCONTIGUOUS",
        /// N-ary intersection of members, stored as a node range.
        ListOverlap = 13 => "LIST_OVERLAP",
        /// Sphere.
        Sphere = 101 => "SPHERE",
        /// Sphere cut by two z planes.
        ZSphere = 102 => "ZSPHERE",
        /// Capped cylinder along z.
        Cylinder = 103 => "CYLINDER",
        /// Tube: annular cylinder along z.
        Disc = 104 => "DISC",
        /// Capped cone frustum along z.
        Cone = 105 => "CONE",
        /// Capped one-sheet hyperboloid along z.
        Hyperboloid = 106 => "HYPERBOLOID",
        /// Torus around z.
        Torus = 107 => "TORUS",
        /// Axis-aligned box centred on the origin.
        Box3 = 108 => "BOX3",
        /// Intersection of half-spaces from the plane buffer.
        ConvexPolyhedron = 109 => "CONVEX_POLYHEDRON",
        /// Capped paraboloid of revolution along z.
        Paraboloid = 110 => "PARABOLOID",
        /// Half-space.
        HalfSpace = 111 => "HALFSPACE",
        /// Region between two parallel planes.
        Slab = 112 => "SLAB",
        /// Wedge of azimuthal angle around z.
        PhiCut = 113 => "PHICUT",
        /// Region between two polar-angle cones around z.
        ThetaCut = 114 => "THETACUT",
        /// Half-space below the hyperbolic paraboloid `y = kappa x z` (a G4TwistedTubs side).
        Saddle = 115 => "SADDLE",
        /// Half-space twisted about z, capped by two z planes (a G4TwistedBox/Trd/Trap side).
        TwistedHalfSpace = 116 => "TWISTED_HALFSPACE",
    }
}

impl TypeCode {
    /// Whether the code is a boolean operator of a binary tree.
    pub fn is_operator(self) -> bool {
        matches!(
            self,
            TypeCode::Union | TypeCode::Intersection | TypeCode::Difference
        )
    }

    /// Whether the code is an n-ary list node.
    pub fn is_list(self) -> bool {
        matches!(
            self,
            TypeCode::ListContiguous | TypeCode::ListDiscontiguous | TypeCode::ListOverlap
        )
    }

    /// Whether the code is a primitive (a leaf with geometry).
    pub fn is_primitive(self) -> bool {
        self as u32 >= 100
    }
}

code_enum! {
    /// What a [`crate::Prim`] holds.
    pub enum PrimKind : "PRIM_" {
        /// A CSG tree of nodes.
        Csg = 0 => "CSG",
        /// A range of triangles.
        Mesh = 1 => "MESH",
        /// A range of volume bricks.
        Volume = 2 => "VOLUME",
    }
}

impl PrimKind {
    /// The bit of this kind in [`crate::Solid::content`].
    pub fn bit(self) -> u32 {
        1 << self as u32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_and_are_unique() {
        let mut seen = std::collections::HashSet::new();
        for &c in TypeCode::ALL {
            assert_eq!(TypeCode::from_u32(c as u32), Some(c));
            assert!(seen.insert(c as u32));
            assert_eq!(
                c.is_primitive() as u8 + c.is_operator() as u8 + c.is_list() as u8,
                (c != TypeCode::Zero) as u8
            );
        }
        assert_eq!(TypeCode::from_u32(4), None);
        assert_eq!(PrimKind::from_u32(3), None);
        assert_eq!(TypeCode::Sphere.wgsl_name(), "CSG_SPHERE");
    }
}
