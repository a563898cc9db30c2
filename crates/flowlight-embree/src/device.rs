//! The Embree library, opened at run time once per process, and its one device: the entry
//! points this crate calls, resolved by name and checked against the 4.x signatures (the
//! structures in [`crate::abi`]).

use crate::BUILD_LIBRARY;
use embree4_sys::{
    RTCBufferType, RTCBuildQuality, RTCDevice, RTCFormat, RTCGeometry, RTCGeometryType, RTCRay,
    RTCScene, RTCSceneFlags,
};
use std::ffi::{c_char, c_uint, c_void};
use std::sync::OnceLock;

use crate::abi;

pub(crate) type Fn<A> = A;

/// The Embree entry points this crate uses, resolved from the library at run time. Enum
/// results are read as `c_uint`/`isize` so that a value unknown to the 4.2 headers is not UB.
pub(crate) struct Api {
    pub(crate) new_device: Fn<unsafe extern "C" fn(*const c_char) -> RTCDevice>,
    pub(crate) get_device_error: Fn<unsafe extern "C" fn(RTCDevice) -> c_uint>,
    pub(crate) get_device_property: Fn<unsafe extern "C" fn(RTCDevice, c_uint) -> isize>,
    pub(crate) new_scene: Fn<unsafe extern "C" fn(RTCDevice) -> RTCScene>,
    pub(crate) release_scene: Fn<unsafe extern "C" fn(RTCScene)>,
    pub(crate) set_scene_flags: Fn<unsafe extern "C" fn(RTCScene, RTCSceneFlags)>,
    pub(crate) set_scene_build_quality: Fn<unsafe extern "C" fn(RTCScene, RTCBuildQuality)>,
    pub(crate) new_geometry: Fn<unsafe extern "C" fn(RTCDevice, RTCGeometryType) -> RTCGeometry>,
    pub(crate) set_new_geometry_buffer: Fn<
        unsafe extern "C" fn(
            RTCGeometry,
            RTCBufferType,
            c_uint,
            RTCFormat,
            usize,
            usize,
        ) -> *mut c_void,
    >,
    pub(crate) set_geometry_build_quality: Fn<unsafe extern "C" fn(RTCGeometry, RTCBuildQuality)>,
    pub(crate) commit_geometry: Fn<unsafe extern "C" fn(RTCGeometry)>,
    pub(crate) attach_geometry: Fn<unsafe extern "C" fn(RTCScene, RTCGeometry) -> c_uint>,
    pub(crate) release_geometry: Fn<unsafe extern "C" fn(RTCGeometry)>,
    pub(crate) commit_scene: Fn<unsafe extern "C" fn(RTCScene)>,
    pub(crate) set_geometry_instanced_scene: Fn<unsafe extern "C" fn(RTCGeometry, RTCScene)>,
    pub(crate) set_geometry_transform:
        Fn<unsafe extern "C" fn(RTCGeometry, c_uint, RTCFormat, *const c_void)>,
    /// The third argument is `RTCIntersectArguments*` (NULL for the defaults).
    pub(crate) intersect1: Fn<unsafe extern "C" fn(RTCScene, *mut abi::RTCRayHit, *mut c_void)>,
    pub(crate) occluded1: Fn<unsafe extern "C" fn(RTCScene, *mut RTCRay, *mut c_void)>,
    /// `rtcIntersect16(valid, scene, rayhit, args)`: coherent camera rays.
    pub(crate) intersect16: IntersectN<16>,
    /// `rtcIntersect8` / `rtcOccluded8(valid, scene, ray, args)`: incoherent rays.
    pub(crate) intersect8: IntersectN<8>,
    pub(crate) occluded8: OccludedN<8>,
}

/// `rtcIntersect{N}(valid, scene, rayhit, args)`.
pub(crate) type IntersectN<const N: usize> =
    unsafe extern "C" fn(*const abi::ValidN<N>, RTCScene, *mut abi::RTCRayHitN<N>, *mut c_void);
/// `rtcOccluded{N}(valid, scene, ray, args)`.
pub(crate) type OccludedN<const N: usize> =
    unsafe extern "C" fn(*const abi::ValidN<N>, RTCScene, *mut abi::RTCRayN<N>, *mut c_void);

/// The process's one Embree device and the library it came from.
pub struct Device {
    pub(crate) api: Api,
    pub(crate) handle: RTCDevice,
    /// The file that was opened.
    pub library: String,
    /// `RTC_DEVICE_PROPERTY_VERSION`, e.g. 40400.
    pub version: u32,
    _lib: libloading::Library,
}

// SAFETY: an Embree device may be used from any thread; the handle is never released.
unsafe impl Send for Device {}
unsafe impl Sync for Device {}

/// The library candidates, in order: `FLOWLIGHT_EMBREE_LIB` at run time (then the only one), the file the build
/// provisioned, a copy beside the executable, the system loader's search.
fn candidates() -> Vec<String> {
    let mut c = Vec::new();
    if let Ok(p) = std::env::var("FLOWLIGHT_EMBREE_LIB") {
        // The user named the library: no silent fallback to another one.
        c.push(p);
        return c;
    }
    c.push(BUILD_LIBRARY.to_string());
    if let Some(dir) = std::env::current_exe()
        .ok()
        .and_then(|e| e.parent().map(|d| d.to_path_buf()))
    {
        let name = std::path::Path::new(BUILD_LIBRARY)
            .file_name()
            .unwrap_or_default();
        c.push(dir.join(name).display().to_string());
    }
    c.push("libembree4.so.4".to_string());
    c
}

fn open_device() -> Result<Device, String> {
    let mut tried = Vec::new();
    let (lib, path) = candidates()
        .into_iter()
        .find_map(|p| {
            // A file path is checked before it is mapped: a truncated or foreign library
            // would crash the process inside dlopen (SIGBUS). A bare name is the system
            // loader's to resolve.
            if p.contains('/') && std::path::Path::new(&p).exists() {
                if let Err(e) =
                    flowlight_elf::check_library(std::path::Path::new(&p), "rtcNewDevice")
                {
                    tried.push(format!("{p}: refused before loading: {e}"));
                    return None;
                }
            }
            // SAFETY: loading Embree runs its (and TBB's) initialisers, which are sound.
            match unsafe { libloading::Library::new(&p) } {
                Ok(l) => Some((l, p)),
                Err(e) => {
                    tried.push(format!("{p}: {e}"));
                    None
                }
            }
        })
        .ok_or_else(|| format!("could not open Embree 4 ({})", tried.join("; ")))?;
    macro_rules! sym {
        ($name:literal) => {
            // SAFETY: the signature is Embree 4's (see the `abi` module for the structs).
            *unsafe { lib.get(concat!($name, "\0").as_bytes()) }
                .map_err(|e| format!("{path}: no symbol {}: {e}", $name))?
        };
    }
    let api = Api {
        new_device: sym!("rtcNewDevice"),
        get_device_error: sym!("rtcGetDeviceError"),
        get_device_property: sym!("rtcGetDeviceProperty"),
        new_scene: sym!("rtcNewScene"),
        release_scene: sym!("rtcReleaseScene"),
        set_scene_flags: sym!("rtcSetSceneFlags"),
        set_scene_build_quality: sym!("rtcSetSceneBuildQuality"),
        new_geometry: sym!("rtcNewGeometry"),
        set_new_geometry_buffer: sym!("rtcSetNewGeometryBuffer"),
        set_geometry_build_quality: sym!("rtcSetGeometryBuildQuality"),
        commit_geometry: sym!("rtcCommitGeometry"),
        attach_geometry: sym!("rtcAttachGeometry"),
        release_geometry: sym!("rtcReleaseGeometry"),
        commit_scene: sym!("rtcCommitScene"),
        set_geometry_instanced_scene: sym!("rtcSetGeometryInstancedScene"),
        set_geometry_transform: sym!("rtcSetGeometryTransform"),
        intersect1: sym!("rtcIntersect1"),
        occluded1: sym!("rtcOccluded1"),
        intersect16: sym!("rtcIntersect16"),
        intersect8: sym!("rtcIntersect8"),
        occluded8: sym!("rtcOccluded8"),
    };
    // SAFETY: a NUL-terminated config string.
    let handle = unsafe { (api.new_device)(c"verbose=0".as_ptr()) };
    if handle.is_null() {
        let err = unsafe { (api.get_device_error)(std::ptr::null_mut()) };
        return Err(format!("{path}: rtcNewDevice failed (RTCError {err})"));
    }
    let version = unsafe { (api.get_device_property)(handle, 0) } as u32;
    if !(40000..50000).contains(&version) {
        return Err(format!("{path} is Embree {version}, not Embree 4"));
    }
    Ok(Device {
        api,
        handle,
        library: path,
        version,
        _lib: lib,
    })
}

static DEVICE: OnceLock<Result<Device, String>> = OnceLock::new();

/// The process's Embree device, made on first use; an error when no Embree 4 library can
/// be opened (the host's `auto` then uses the BVH).
pub fn device() -> Result<&'static Device, String> {
    DEVICE
        .get_or_init(open_device)
        .as_ref()
        .map_err(Clone::clone)
}
impl Device {
    pub(crate) fn check(&self, what: &str) -> Result<(), String> {
        // SAFETY: a valid device; the error code is per thread.
        let e = unsafe { (self.api.get_device_error)(self.handle) };
        if e == 0 {
            Ok(())
        } else {
            Err(format!("Embree: {what} failed (RTCError {e})"))
        }
    }

    /// "4.4.0", from the version property.
    pub fn version_string(&self) -> String {
        let v = self.version;
        format!("{}.{}.{}", v / 10000, v / 100 % 100, v % 100)
    }
}
