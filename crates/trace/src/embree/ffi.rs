//! Hand-written bindings to the part of Embree 3's C API (`embree3/rtcore.h`, 3.13) that
//! the backend uses: devices, scenes, triangle, user and instance geometries,
//! `rtcIntersect1` and `rtcOccluded1`.
//!
//! Layouts and constants are copied from the 3.13.5 headers (configured with
//! `RTC_MAX_INSTANCE_LEVEL_COUNT 1` and `RTC_MIN_WIDTH 0`, as Debian builds them);
//! `tests/embree_backend.rs` checks every struct's size, alignment and field offsets
//! against numbers read from those headers. C enums are passed as `u32` (they are
//! `int`-sized and every value used fits).

use std::ffi::{c_char, c_void};

/// `RTC_INVALID_GEOMETRY_ID`: no geometry (or instance) hit.
pub const RTC_INVALID_GEOMETRY_ID: u32 = u32::MAX;
/// `RTC_MAX_INSTANCE_LEVEL_COUNT` of Debian's build: one level of instancing.
pub const RTC_MAX_INSTANCE_LEVEL_COUNT: usize = 1;

/// `RTC_GEOMETRY_TYPE_TRIANGLE`.
pub const RTC_GEOMETRY_TYPE_TRIANGLE: u32 = 0;
/// `RTC_GEOMETRY_TYPE_USER`.
pub const RTC_GEOMETRY_TYPE_USER: u32 = 120;
/// `RTC_GEOMETRY_TYPE_INSTANCE`.
pub const RTC_GEOMETRY_TYPE_INSTANCE: u32 = 121;

/// `RTC_BUFFER_TYPE_INDEX`.
pub const RTC_BUFFER_TYPE_INDEX: u32 = 0;
/// `RTC_BUFFER_TYPE_VERTEX`.
pub const RTC_BUFFER_TYPE_VERTEX: u32 = 1;

/// `RTC_FORMAT_UINT3`: triangle indices.
pub const RTC_FORMAT_UINT3: u32 = 0x5003;
/// `RTC_FORMAT_FLOAT3`: vertices.
pub const RTC_FORMAT_FLOAT3: u32 = 0x9003;
/// `RTC_FORMAT_FLOAT3X4_ROW_MAJOR`: an affine transform as its three rows of four.
pub const RTC_FORMAT_FLOAT3X4_ROW_MAJOR: u32 = 0x9134;

/// `RTC_SCENE_FLAG_ROBUST`: avoid optimizations that reduce arithmetic accuracy.
pub const RTC_SCENE_FLAG_ROBUST: u32 = 1 << 2;
/// `RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT` (the default of `rtcInitIntersectContext`).
pub const RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT: u32 = 0;

/// `RTC_ERROR_*` codes by value (`RTC_ERROR_NONE` is 0).
pub const RTC_ERROR_NAMES: [&str; 7] = [
    "RTC_ERROR_NONE",
    "RTC_ERROR_UNKNOWN",
    "RTC_ERROR_INVALID_ARGUMENT",
    "RTC_ERROR_INVALID_OPERATION",
    "RTC_ERROR_OUT_OF_MEMORY",
    "RTC_ERROR_UNSUPPORTED_CPU",
    "RTC_ERROR_CANCELLED",
];

/// Opaque `struct RTCDeviceTy`.
pub enum RTCDeviceTy {}
/// Opaque `struct RTCSceneTy`.
pub enum RTCSceneTy {}
/// Opaque `struct RTCGeometryTy`.
pub enum RTCGeometryTy {}
/// Opaque `struct RTCRayHitN` (a structure of arrays, see [`RTCIntersectFunctionNArguments`]).
pub enum RTCRayHitN {}

/// `RTCDevice`.
pub type RTCDevice = *mut RTCDeviceTy;
/// `RTCScene`.
pub type RTCScene = *mut RTCSceneTy;
/// `RTCGeometry`.
pub type RTCGeometry = *mut RTCGeometryTy;

/// `struct RTCRay`: one ray.
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, Default)]
pub struct RTCRay {
    /// Origin x.
    pub org_x: f32,
    /// Origin y.
    pub org_y: f32,
    /// Origin z.
    pub org_z: f32,
    /// Start of the ray segment.
    pub tnear: f32,
    /// Direction x.
    pub dir_x: f32,
    /// Direction y.
    pub dir_y: f32,
    /// Direction z.
    pub dir_z: f32,
    /// Time (motion blur; unused).
    pub time: f32,
    /// End of the ray segment, set to the hit distance.
    pub tfar: f32,
    /// Ray mask.
    pub mask: u32,
    /// Ray id.
    pub id: u32,
    /// Ray flags.
    pub flags: u32,
}

/// `struct RTCHit`: what a ray hit.
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, Default)]
pub struct RTCHit {
    /// Geometric normal x (`Ng_x`), in the hit geometry's own frame.
    pub ng_x: f32,
    /// Geometric normal y.
    pub ng_y: f32,
    /// Geometric normal z.
    pub ng_z: f32,
    /// Barycentric u.
    pub u: f32,
    /// Barycentric v.
    pub v: f32,
    /// Primitive id within the geometry.
    pub prim_id: u32,
    /// Geometry id within its scene.
    pub geom_id: u32,
    /// Instance ids (geometry ids of the instances traversed).
    pub inst_id: [u32; RTC_MAX_INSTANCE_LEVEL_COUNT],
}

/// `struct RTCRayHit`: a ray and its hit.
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, Default)]
pub struct RTCRayHit {
    /// The ray.
    pub ray: RTCRay,
    /// The hit.
    pub hit: RTCHit,
}

/// `struct RTCIntersectContext` (without `instStackSize` and `minWidthDistanceFactor`,
/// absent at one instance level and `RTC_MIN_WIDTH 0`). Applications may embed it at the
/// start of a larger struct: callbacks get the same pointer back.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct RTCIntersectContext {
    /// `enum RTCIntersectContextFlags`.
    pub flags: u32,
    /// `RTCFilterFunctionN`, or none.
    pub filter: Option<unsafe extern "C" fn(args: *const c_void)>,
    /// The stack of instance ids, set by Embree while it traverses instances.
    pub inst_id: [u32; RTC_MAX_INSTANCE_LEVEL_COUNT],
}

impl Default for RTCIntersectContext {
    /// What the header's inline `rtcInitIntersectContext` sets.
    fn default() -> Self {
        RTCIntersectContext {
            flags: RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT,
            filter: None,
            inst_id: [RTC_INVALID_GEOMETRY_ID; RTC_MAX_INSTANCE_LEVEL_COUNT],
        }
    }
}

/// `struct RTCBounds`.
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, Default)]
pub struct RTCBounds {
    /// Lower x.
    pub lower_x: f32,
    /// Lower y.
    pub lower_y: f32,
    /// Lower z.
    pub lower_z: f32,
    /// Padding.
    pub align0: f32,
    /// Upper x.
    pub upper_x: f32,
    /// Upper y.
    pub upper_y: f32,
    /// Upper z.
    pub upper_z: f32,
    /// Padding.
    pub align1: f32,
}

/// `struct RTCBoundsFunctionArguments`.
#[repr(C)]
#[derive(Debug)]
pub struct RTCBoundsFunctionArguments {
    /// The geometry's user data.
    pub geometry_user_ptr: *mut c_void,
    /// The primitive whose bounds are asked.
    pub prim_id: u32,
    /// Time step (motion blur; unused).
    pub time_step: u32,
    /// Where to write the bounds.
    pub bounds_o: *mut RTCBounds,
}

/// `struct RTCIntersectFunctionNArguments`. `rayhit` holds `N` rays and hits as a
/// structure of arrays: 32-bit field `k` of lane `i` is word `k * N + i`, the ray's twelve
/// fields (in [`RTCRay`]'s order) first, then the hit's (in [`RTCHit`]'s order).
#[repr(C)]
#[derive(Debug)]
pub struct RTCIntersectFunctionNArguments {
    /// Per lane: -1 valid, 0 not.
    pub valid: *mut i32,
    /// The geometry's user data.
    pub geometry_user_ptr: *mut c_void,
    /// The primitive to intersect.
    pub prim_id: u32,
    /// The context given to `rtcIntersect1` (with the instance stack filled in).
    pub context: *mut RTCIntersectContext,
    /// Rays and hits, structure of arrays.
    pub rayhit: *mut RTCRayHitN,
    /// Lanes.
    pub n: u32,
    /// The geometry's id in its scene.
    pub geom_id: u32,
}

/// `RTCBoundsFunction`.
pub type RTCBoundsFunction = unsafe extern "C" fn(args: *const RTCBoundsFunctionArguments);
/// `RTCIntersectFunctionN`.
pub type RTCIntersectFunctionN = unsafe extern "C" fn(args: *const RTCIntersectFunctionNArguments);
/// `RTCOccludedFunctionN`. Its `struct RTCOccludedFunctionNArguments` has the fields of
/// [`RTCIntersectFunctionNArguments`] in the same order, with rays only (an `RTCRayN`,
/// [`RTCRay`]'s fields) where `rayhit` is; an occluded ray gets `tfar = -inf`.
pub type RTCOccludedFunctionN = unsafe extern "C" fn(args: *const RTCIntersectFunctionNArguments);

#[allow(non_snake_case)]
extern "C" {
    /// Creates a device (`config` may be null).
    pub fn rtcNewDevice(config: *const c_char) -> RTCDevice;
    /// Releases a device reference.
    pub fn rtcReleaseDevice(device: RTCDevice);
    /// The first error since the last call (and clears it); `enum RTCError`.
    pub fn rtcGetDeviceError(device: RTCDevice) -> u32;

    /// Creates a scene.
    pub fn rtcNewScene(device: RTCDevice) -> RTCScene;
    /// Releases a scene reference.
    pub fn rtcReleaseScene(scene: RTCScene);
    /// Sets `enum RTCSceneFlags`.
    pub fn rtcSetSceneFlags(scene: RTCScene, flags: u32);
    /// Attaches a geometry (the scene takes a reference); returns its id.
    pub fn rtcAttachGeometry(scene: RTCScene, geometry: RTCGeometry) -> u32;
    /// Builds the scene's acceleration structure.
    pub fn rtcCommitScene(scene: RTCScene);
    /// Closest hit of one ray.
    pub fn rtcIntersect1(
        scene: RTCScene,
        context: *mut RTCIntersectContext,
        rayhit: *mut RTCRayHit,
    );
    /// Sets `ray.tfar` to -inf when some geometry crosses the ray in `[tnear, tfar]`.
    pub fn rtcOccluded1(scene: RTCScene, context: *mut RTCIntersectContext, ray: *mut RTCRay);

    /// Creates a geometry of `enum RTCGeometryType`.
    pub fn rtcNewGeometry(device: RTCDevice, kind: u32) -> RTCGeometry;
    /// Releases a geometry reference.
    pub fn rtcReleaseGeometry(geometry: RTCGeometry);
    /// Commits a geometry's changes.
    pub fn rtcCommitGeometry(geometry: RTCGeometry);
    /// Allocates a buffer owned by the geometry; returns its (16-byte aligned) data.
    pub fn rtcSetNewGeometryBuffer(
        geometry: RTCGeometry,
        kind: u32,
        slot: u32,
        format: u32,
        byte_stride: usize,
        item_count: usize,
    ) -> *mut c_void;
    /// Number of primitives of a user geometry.
    pub fn rtcSetGeometryUserPrimitiveCount(geometry: RTCGeometry, count: u32);
    /// User data handed to the geometry's callbacks.
    pub fn rtcSetGeometryUserData(geometry: RTCGeometry, ptr: *mut c_void);
    /// Bounds callback of a user geometry.
    pub fn rtcSetGeometryBoundsFunction(
        geometry: RTCGeometry,
        bounds: Option<RTCBoundsFunction>,
        user_ptr: *mut c_void,
    );
    /// Intersection callback of a user geometry.
    pub fn rtcSetGeometryIntersectFunction(
        geometry: RTCGeometry,
        intersect: Option<RTCIntersectFunctionN>,
    );
    /// Occlusion callback of a user geometry.
    pub fn rtcSetGeometryOccludedFunction(
        geometry: RTCGeometry,
        occluded: Option<RTCOccludedFunctionN>,
    );
    /// The scene an instance geometry places.
    pub fn rtcSetGeometryInstancedScene(geometry: RTCGeometry, scene: RTCScene);
    /// An instance's local-to-world transform (`format` a `RTC_FORMAT_FLOAT3X4_*`).
    pub fn rtcSetGeometryTransform(
        geometry: RTCGeometry,
        time_step: u32,
        format: u32,
        xfm: *const c_void,
    );
}
