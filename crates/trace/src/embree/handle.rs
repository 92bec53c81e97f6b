//! Owned Embree handles (device, scene, geometry), released on drop, and device errors as
//! the library's errors.

use std::ptr;

use crate::error::bail;

use super::ffi;

/// An Embree device.
pub(crate) struct Device(ffi::RTCDevice);

impl Device {
    /// A device with Embree's default configuration.
    pub(crate) fn new() -> crate::Result<Self> {
        // SAFETY: a null configuration string selects the defaults.
        let raw = unsafe { ffi::rtcNewDevice(ptr::null()) };
        if raw.is_null() {
            // SAFETY: a null device asks for the error of the failed device creation.
            let code = unsafe { ffi::rtcGetDeviceError(ptr::null_mut()) };
            bail!("Embree: creating the device failed ({})", error_name(code));
        }
        Ok(Device(raw))
    }

    /// The raw handle, valid while `self` lives.
    pub(crate) fn raw(&self) -> ffi::RTCDevice {
        self.0
    }

    /// Fails, naming `what`, if Embree reported an error since the last check.
    pub(crate) fn check(&self, what: impl FnOnce() -> String) -> crate::Result<()> {
        // SAFETY: the device is alive; the call only reads and clears its error slot.
        let code = unsafe { ffi::rtcGetDeviceError(self.0) };
        if code != 0 {
            bail!("Embree: {} failed ({})", what(), error_name(code));
        }
        Ok(())
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // SAFETY: we own one reference; scenes and geometries hold their own.
        unsafe { ffi::rtcReleaseDevice(self.0) }
    }
}

/// An Embree scene, with the number of geometries attached.
pub(crate) struct Scene(ffi::RTCScene, u32);

impl Scene {
    /// An empty robust scene (see `RTC_SCENE_FLAG_ROBUST`).
    pub(crate) fn new(device: &Device) -> crate::Result<Self> {
        // SAFETY: the device is alive.
        let raw = unsafe { ffi::rtcNewScene(device.raw()) };
        if raw.is_null() {
            device.check(|| "creating a scene".into())?;
            bail!("Embree: creating a scene failed");
        }
        // SAFETY: `raw` is a new scene; the flag is one of the header's.
        unsafe { ffi::rtcSetSceneFlags(raw, ffi::RTC_SCENE_FLAG_ROBUST) };
        Ok(Scene(raw, 0))
    }

    /// The raw handle, valid while `self` lives.
    pub(crate) fn raw(&self) -> ffi::RTCScene {
        self.0
    }

    /// Commits `geometry` and attaches it. Geometry ids are attachment indices: Embree
    /// numbers a scene's geometries from 0 up when none is detached (checked).
    pub(crate) fn attach(&mut self, geometry: Geometry) -> crate::Result<()> {
        // SAFETY: both handles are alive; the scene takes its own reference to the
        // geometry, ours is released when `geometry` drops.
        let id = unsafe {
            ffi::rtcCommitGeometry(geometry.0);
            ffi::rtcAttachGeometry(self.0, geometry.0)
        };
        if id != self.1 {
            bail!("Embree: attached geometry got id {id}, expected {}", self.1);
        }
        self.1 += 1;
        Ok(())
    }

    /// Builds the acceleration structure.
    pub(crate) fn commit(&self) {
        // SAFETY: the scene is alive and every attached geometry committed.
        unsafe { ffi::rtcCommitScene(self.0) }
    }
}

impl Drop for Scene {
    fn drop(&mut self) {
        // SAFETY: we own one reference.
        unsafe { ffi::rtcReleaseScene(self.0) }
    }
}

/// A geometry not yet attached (attaching consumes it).
pub(crate) struct Geometry(ffi::RTCGeometry);

impl Geometry {
    /// A new geometry of type `kind` (`RTC_GEOMETRY_TYPE_*`).
    pub(crate) fn new(device: &Device, kind: u32) -> crate::Result<Self> {
        // SAFETY: the device is alive.
        let raw = unsafe { ffi::rtcNewGeometry(device.raw(), kind) };
        if raw.is_null() {
            device.check(|| format!("creating a geometry of type {kind}"))?;
            bail!("Embree: creating a geometry of type {kind} failed");
        }
        Ok(Geometry(raw))
    }

    /// The raw handle, valid while `self` lives.
    pub(crate) fn raw(&self) -> ffi::RTCGeometry {
        self.0
    }
}

impl Drop for Geometry {
    fn drop(&mut self) {
        // SAFETY: we own one reference.
        unsafe { ffi::rtcReleaseGeometry(self.0) }
    }
}

/// The name of an `RTCError` code.
fn error_name(code: u32) -> String {
    ffi::RTC_ERROR_NAMES
        .get(code as usize)
        .map_or_else(|| format!("error code {code}"), |n| n.to_string())
}
