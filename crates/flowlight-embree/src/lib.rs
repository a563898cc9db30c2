//! Embree 4 ray queries for the Flowlight host.
//!
//! The library the build provisioned (see `build.rs`) is opened at run time, once per
//! process, and one Embree device is made from it ([`device`]). A scene is built and
//! committed once ([`EmbreeScene::build`]) and then answers closest-hit and any-hit queries
//! from any number of threads. Nothing of Embree crosses the plugin boundary: the host wraps
//! [`EmbreeScene`] in its own intersector trait.
//!
//! Types come from `embree4-sys` (bindgen over the Embree **4.2** headers it ships). Where
//! those differ from the 4.4 library, this crate has its own `#[repr(C)]` definitions: see
//! [`abi`] and docs/embree.md.
// The workspace lint `unsafe_op_in_unsafe_fn` is not yet applied to this FFI crate (owned by
// the instancing work): its two `unsafe fn`s are each one unsafe region.
#![allow(unsafe_op_in_unsafe_fn)]

use embree4_sys::{
    RTCBufferType, RTCBuildQuality, RTCDevice, RTCFeatureFlags, RTCFormat, RTCGeometry,
    RTCGeometryType, RTCRay, RTCRayQueryFlags, RTCScene, RTCSceneFlags,
};
use flowlight_core::geometry::{HitFilter, InstanceHit, InstanceHitFilter, Ray, TriangleHit};
use flowlight_core::mesh::CompactHit;
use glam::{Mat4, Vec3};
use std::ffi::{c_char, c_uint, c_void};
use std::sync::OnceLock;

/// Where the build found Embree: `EMBREE_DIR`, `system` or the pinned wheel.
pub const BUILD_SOURCE: &str = env!("FLOWLIGHT_EMBREE_SOURCE");
/// The library file the build found, opened at run time.
pub const BUILD_LIBRARY: &str = env!("FLOWLIGHT_EMBREE_LIB");

use flowlight_core::denormals;

/// Layouts of the structures that cross into Embree, as the 4.4 library uses them.
pub mod abi {
    use embree4_sys::RTCRay;

    /// `RTCHit` of Embree ≥ 4.3 built with instance arrays (the default, and the 4.4 wheel):
    /// `instPrimID[RTC_MAX_INSTANCE_LEVEL_COUNT]` follows `instID`. embree4-sys 0.0.12's
    /// 4.2 `RTCHit` lacks it, so its `RTCRayHit` is 80 bytes where the library writes 96.
    #[repr(C, align(16))]
    #[derive(Clone, Copy, Debug)]
    pub struct RTCHit {
        pub ng_x: f32,
        pub ng_y: f32,
        pub ng_z: f32,
        pub u: f32,
        pub v: f32,
        pub prim_id: u32,
        pub geom_id: u32,
        pub inst_id: [u32; 1],
        pub inst_prim_id: [u32; 1],
    }

    /// `RTCRayHitN` of the 4.4 library for `rtcIntersect{N}` (N = 4, 8 or 16): the N-lane
    /// ray, then the N-lane hit (structure of arrays; the hit with `instPrimID` as in
    /// [`RTCHit`]). 64-byte aligned, which covers every N's alignment (16, 32, 64 bytes);
    /// the ray is 12·4·N bytes, a multiple of 64 for N ≥ 4, so the hit starts where Embree
    /// expects it.
    #[repr(C, align(64))]
    #[derive(Clone, Copy, Debug)]
    pub struct RTCRayHitN<const N: usize> {
        pub ray: RTCRayN<N>,
        pub hit: RTCHitN<N>,
    }

    /// `RTCHitN` of the 4.4 library.
    #[repr(C, align(64))]
    #[derive(Clone, Copy, Debug)]
    pub struct RTCHitN<const N: usize> {
        pub ng_x: [f32; N],
        pub ng_y: [f32; N],
        pub ng_z: [f32; N],
        pub u: [f32; N],
        pub v: [f32; N],
        pub prim_id: [u32; N],
        pub geom_id: [u32; N],
        pub inst_id: [[u32; N]; 1],
        pub inst_prim_id: [[u32; N]; 1],
    }

    /// `RTCRayN`: the ray half of [`RTCRayHitN`], for `rtcOccluded{N}`.
    #[repr(C, align(64))]
    #[derive(Clone, Copy, Debug)]
    pub struct RTCRayN<const N: usize> {
        pub org_x: [f32; N],
        pub org_y: [f32; N],
        pub org_z: [f32; N],
        pub tnear: [f32; N],
        pub dir_x: [f32; N],
        pub dir_y: [f32; N],
        pub dir_z: [f32; N],
        pub time: [f32; N],
        pub tfar: [f32; N],
        pub mask: [u32; N],
        pub id: [u32; N],
        pub flags: [u32; N],
    }

    /// The `valid` mask of a packet call (−1 = active lane), 64-byte aligned (Embree
    /// requires 4·N).
    #[repr(C, align(64))]
    #[derive(Clone, Copy, Debug)]
    pub struct ValidN<const N: usize>(pub [i32; N]);

    /// `RTCRayHit` with the 4.4 hit.
    #[repr(C, align(16))]
    #[derive(Clone, Copy, Debug)]
    pub struct RTCRayHit {
        pub ray: RTCRay,
        pub hit: RTCHit,
    }

    // What embree4-sys declares and what this crate relies on (checked at compile time).
    const _: () = assert!(std::mem::size_of::<RTCRay>() == 48);
    const _: () = assert!(std::mem::align_of::<RTCRay>() == 16);
    const _: () = assert!(std::mem::size_of::<embree4_sys::RTCHit>() == 32);
    const _: () = assert!(std::mem::size_of::<embree4_sys::RTCRayHit>() == 80);
    const _: () = assert!(std::mem::size_of::<RTCHit>() == 48);
    const _: () = assert!(std::mem::size_of::<RTCRayHit>() == 96);
    // RTCRayN (12 arrays of N) then RTCHitN (9 arrays of N, instID and instPrimID one
    // level), for the two widths used.
    const _: () = assert!(std::mem::size_of::<RTCRayHitN<16>>() == 21 * 64);
    const _: () = assert!(std::mem::offset_of!(RTCRayHitN<16>, hit) == 12 * 64);
    const _: () = assert!(std::mem::size_of::<RTCRayN<16>>() == 12 * 64);
    const _: () = assert!(std::mem::size_of::<ValidN<16>>() == 64);
    const _: () = assert!(std::mem::offset_of!(RTCRayHitN<8>, hit) == 12 * 32);
    const _: () = assert!(std::mem::size_of::<RTCRayN<8>>() == 12 * 32);
    const _: () = assert!(std::mem::size_of::<RTCHitN<8>>() == 9 * 32 + 32);
    const _: () = assert!(std::mem::offset_of!(RTCRayHit, hit) == 48);
    const _: () = assert!(std::mem::size_of::<embree4_sys::RTCIntersectArguments>() == 32);
    const _: () = assert!(embree4_sys::RTC_MAX_INSTANCE_LEVEL_COUNT == 1);
}

type Fn<A> = A;

/// The Embree entry points this crate uses, resolved from the library at run time. Enum
/// results are read as `c_uint`/`isize` so that a value unknown to the 4.2 headers is not UB.
struct Api {
    new_device: Fn<unsafe extern "C" fn(*const c_char) -> RTCDevice>,
    get_device_error: Fn<unsafe extern "C" fn(RTCDevice) -> c_uint>,
    get_device_property: Fn<unsafe extern "C" fn(RTCDevice, c_uint) -> isize>,
    new_scene: Fn<unsafe extern "C" fn(RTCDevice) -> RTCScene>,
    release_scene: Fn<unsafe extern "C" fn(RTCScene)>,
    set_scene_flags: Fn<unsafe extern "C" fn(RTCScene, RTCSceneFlags)>,
    set_scene_build_quality: Fn<unsafe extern "C" fn(RTCScene, RTCBuildQuality)>,
    new_geometry: Fn<unsafe extern "C" fn(RTCDevice, RTCGeometryType) -> RTCGeometry>,
    set_new_geometry_buffer: Fn<
        unsafe extern "C" fn(
            RTCGeometry,
            RTCBufferType,
            c_uint,
            RTCFormat,
            usize,
            usize,
        ) -> *mut c_void,
    >,
    set_geometry_build_quality: Fn<unsafe extern "C" fn(RTCGeometry, RTCBuildQuality)>,
    commit_geometry: Fn<unsafe extern "C" fn(RTCGeometry)>,
    attach_geometry: Fn<unsafe extern "C" fn(RTCScene, RTCGeometry) -> c_uint>,
    release_geometry: Fn<unsafe extern "C" fn(RTCGeometry)>,
    commit_scene: Fn<unsafe extern "C" fn(RTCScene)>,
    set_geometry_instanced_scene: Fn<unsafe extern "C" fn(RTCGeometry, RTCScene)>,
    set_geometry_transform: Fn<unsafe extern "C" fn(RTCGeometry, c_uint, RTCFormat, *const c_void)>,
    /// The third argument is `RTCIntersectArguments*` (NULL for the defaults).
    intersect1: Fn<unsafe extern "C" fn(RTCScene, *mut abi::RTCRayHit, *mut c_void)>,
    occluded1: Fn<unsafe extern "C" fn(RTCScene, *mut RTCRay, *mut c_void)>,
    /// `rtcIntersect16(valid, scene, rayhit, args)`: coherent camera rays.
    intersect16: IntersectN<16>,
    /// `rtcIntersect8` / `rtcOccluded8(valid, scene, ray, args)`: incoherent rays.
    intersect8: IntersectN<8>,
    occluded8: OccludedN<8>,
}

/// `rtcIntersect{N}(valid, scene, rayhit, args)`.
type IntersectN<const N: usize> =
    unsafe extern "C" fn(*const abi::ValidN<N>, RTCScene, *mut abi::RTCRayHitN<N>, *mut c_void);
/// `rtcOccluded{N}(valid, scene, ray, args)`.
type OccludedN<const N: usize> =
    unsafe extern "C" fn(*const abi::ValidN<N>, RTCScene, *mut abi::RTCRayN<N>, *mut c_void);

/// The process's one Embree device and the library it came from.
pub struct Device {
    api: Api,
    handle: RTCDevice,
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
    /// `rtcIntersect1` of `ray` against the committed `scene`, with filter `args` when given
    /// (their context must outlive the call): the hit record, or `None` for a miss.
    #[inline]
    fn closest_hit(
        &self,
        scene: RTCScene,
        ray: &Ray,
        args: Option<&mut filter::IntersectArguments>,
    ) -> Option<abi::RTCRayHit> {
        denormals::with_denormals_flushed(|| self.closest_hit_in_mode(scene, ray, args))
    }

    /// [`Device::closest_hit`] in the caller's FP mode (inside `denormals::with_denormals_flushed`).
    #[inline(always)]
    fn closest_hit_in_mode(
        &self,
        scene: RTCScene,
        ray: &Ray,
        args: Option<&mut filter::IntersectArguments>,
    ) -> Option<abi::RTCRayHit> {
        let mut rh = EmbreeScene::rtc_ray_hit(ray);
        let args = args.map_or(std::ptr::null_mut(), |a| a as *mut _ as *mut c_void);
        // SAFETY: a committed scene, a 4.4-layout ray/hit, and NULL (defaults) or arguments
        // the caller keeps alive; the filter callback only reads the context it is given.
        unsafe { (self.api.intersect1)(scene, &mut rh, args) };
        (rh.hit.geom_id != u32::MAX).then_some(rh)
    }

    /// `rtcOccluded1`: whether anything lies at `0 < t < ray.t_max` in `scene` (filter `args`
    /// as in [`Device::closest_hit`]; RTCOccludedArguments has the same layout).
    #[inline]
    fn any_hit(
        &self,
        scene: RTCScene,
        ray: &Ray,
        args: Option<&mut filter::IntersectArguments>,
    ) -> bool {
        denormals::with_denormals_flushed(|| self.any_hit_in_mode(scene, ray, args))
    }

    /// [`Device::any_hit`] in the caller's FP mode (inside `denormals::with_denormals_flushed`).
    #[inline(always)]
    fn any_hit_in_mode(
        &self,
        scene: RTCScene,
        ray: &Ray,
        args: Option<&mut filter::IntersectArguments>,
    ) -> bool {
        let mut r = EmbreeScene::rtc_ray(ray);
        let args = args.map_or(std::ptr::null_mut(), |a| a as *mut _ as *mut c_void);
        // SAFETY: as in `closest_hit`; Embree sets tfar to -inf when the ray is blocked.
        unsafe { (self.api.occluded1)(scene, &mut r, args) };
        r.tfar == f32::NEG_INFINITY
    }

    /// The closest hits of `rays` in `scene`, handed to `emit(i, hit)` in order, in one FP
    /// mode switch: one by one through `rtcIntersect1` ([`BatchMode::SingleRays`]), 8 at a
    /// time through `rtcIntersect8` ([`BatchMode::Packets`]), or 16 at a time through
    /// `rtcIntersect16` with `RTC_RAY_QUERY_FLAG_COHERENT` in the arguments
    /// ([`BatchMode::CoherentPackets`]: a tile's camera rays; 16 lanes as when that mode was
    /// measured, and 8 there made no difference to a Cornell box render). Single rays and
    /// plain packets give the same hits bit for bit; coherent packets the same distances,
    /// but a tie between two triangles at one distance may go the other way (the tests). A
    /// flat scene's hits carry Embree's invalid instance id.
    fn closest_batch(
        &self,
        scene: RTCScene,
        mode: BatchMode,
        rays: &[Ray],
        mut emit: impl FnMut(usize, Option<InstanceHit>),
    ) {
        // The FP mode Embree asks for, set once for the batch instead of around each query.
        denormals::with_denormals_flushed(|| match mode {
            BatchMode::SingleRays => {
                for (i, ray) in rays.iter().enumerate() {
                    emit(
                        i,
                        self.closest_hit_in_mode(scene, ray, None).map(instance_hit),
                    );
                }
            }
            BatchMode::Packets => {
                let defaults = std::ptr::null_mut();
                self.closest_packets::<8>(self.api.intersect8, scene, rays, defaults, emit)
            }
            BatchMode::CoherentPackets => {
                // Embree's coherent packet traversal (one node stack for the packet, for rays
                // that cross the same nodes in the same order) is taken only when the call's
                // arguments say so; on incoherent rays it is about twice as slow as its
                // default.
                let mut coherent = filter::IntersectArguments {
                    flags: RTCRayQueryFlags::COHERENT,
                    feature_mask: RTCFeatureFlags::RTC_FEATURE_FLAG_ALL,
                    context: std::ptr::null_mut(),
                    filter: None,
                    intersect: None,
                    min_width_distance_factor: 0.0,
                    _pad: [0; 4],
                };
                let args = &mut coherent as *mut _ as *mut c_void;
                self.closest_packets::<16>(self.api.intersect16, scene, rays, args, emit)
            }
        })
    }

    /// [`Device::closest_batch`]'s packets of N lanes through `intersect` (`rtcIntersect{N}`).
    #[inline]
    fn closest_packets<const N: usize>(
        &self,
        intersect: IntersectN<N>,
        scene: RTCScene,
        rays: &[Ray],
        args: *mut c_void,
        mut emit: impl FnMut(usize, Option<InstanceHit>),
    ) {
        let mut p = empty_packet::<N>();
        for (c, chunk) in rays.chunks(N).enumerate() {
            let valid = load_lanes(&mut p.ray, chunk);
            p.hit.geom_id = [u32::MAX; N];
            // SAFETY: a committed scene; the 4.4 `RTCRayHitN` layout (checked in `abi`),
            // 64-byte aligned, as is the valid mask; `args` NULL (the defaults, as for the
            // single-ray call) or the coherent arguments, alive on the caller's frame and
            // laid out as `RTCIntersectArguments` (checked in `filter`).
            unsafe { intersect(&valid, scene, &mut p, args) };
            for k in 0..chunk.len() {
                let hit = (p.hit.geom_id[k] != u32::MAX).then_some(InstanceHit {
                    t: p.ray.tfar[k],
                    instance: p.hit.inst_id[0][k],
                    prim: p.hit.prim_id[k],
                    b1: p.hit.u[k],
                    b2: p.hit.v[k],
                });
                emit(N * c + k, hit);
            }
        }
    }

    /// Whether each of `rays` is blocked in `scene` (`blocked[i]` 1 or 0), in one FP mode
    /// switch, by packets (8 lanes, as [`Device::closest_batch`]'s incoherent packets) or
    /// single rays.
    fn occluded_batch(&self, scene: RTCScene, packets: bool, rays: &[Ray], blocked: &mut [u8]) {
        assert_eq!(rays.len(), blocked.len(), "one answer per ray");
        // The FP mode Embree asks for, set once for the batch instead of around each query.
        denormals::with_denormals_flushed(|| {
            if !packets {
                for (ray, b) in rays.iter().zip(blocked.iter_mut()) {
                    *b = u8::from(self.any_hit_in_mode(scene, ray, None));
                }
                return;
            }
            const N: usize = 8;
            let mut ray = empty_packet::<N>().ray;
            for (chunk, blocked) in rays.chunks(N).zip(blocked.chunks_mut(N)) {
                let valid = load_lanes(&mut ray, chunk);
                // SAFETY: as in `closest_packets`; Embree sets a blocked lane's tfar to -inf.
                unsafe { (self.api.occluded8)(&valid, scene, &mut ray, std::ptr::null_mut()) };
                for (k, b) in blocked.iter_mut().enumerate() {
                    *b = u8::from(ray.tfar[k] == f32::NEG_INFINITY);
                }
            }
        })
    }

    fn check(&self, what: &str) -> Result<(), String> {
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

/// Embree's BVH build quality.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BuildQuality {
    Low,
    Medium,
    High,
}

impl BuildQuality {
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "low" => Ok(Self::Low),
            "medium" => Ok(Self::Medium),
            "high" => Ok(Self::High),
            _ => Err(format!(
                "unknown Embree build quality {s:?}; expected \"low\", \"medium\" or \"high\""
            )),
        }
    }
    fn raw(self) -> RTCBuildQuality {
        match self {
            Self::Low => RTCBuildQuality::LOW,
            Self::Medium => RTCBuildQuality::MEDIUM,
            Self::High => RTCBuildQuality::HIGH,
        }
    }
}

/// How a scene is built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SceneOptions {
    /// `RTC_SCENE_FLAG_ROBUST`: rays on shared edges and vertices never slip through.
    pub robust: bool,
    pub quality: BuildQuality,
    /// `RTC_SCENE_FLAG_FILTER_FUNCTION_IN_ARGUMENTS`: needed by
    /// [`EmbreeScene::intersect_filtered`] and [`EmbreeScene::occluded_filtered`] (alpha
    /// testing); without it their filter is never called.
    pub hit_filter: bool,
    /// How [`EmbreeScene::intersect_batch`] and [`EmbreeScene::occluded_batch`] trace.
    pub packets: Packets,
    /// Whether [`EmbreeScene::intersect_coherent_batch`] takes Embree's coherent packet
    /// traversal (unless `packets` is [`Packets::Never`]): several times faster on camera
    /// rays, and the same hits but for ties (a ray meeting two triangles at the same
    /// distance may get the other one). Off, it is the plain batch call.
    pub coherent: bool,
}

impl Default for SceneOptions {
    fn default() -> Self {
        SceneOptions {
            robust: true,
            quality: BuildQuality::Medium,
            hit_filter: false,
            packets: Packets::Auto,
            coherent: true,
        }
    }
}

/// Whether a scene (flat or instanced) answers batches of rays with Embree's 8-lane packet
/// traversal (`rtcIntersect8` / `rtcOccluded8`) or one `rtcIntersect1` / `rtcOccluded1`
/// per ray. Both give the same hits bit for bit (the tests); only the speed differs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Packets {
    /// Packets for scenes of at most [`PACKET_MAX_TRIANGLES`] triangles, single rays above.
    Auto,
    Always,
    Never,
}

/// The largest scene [`Packets::Auto`] traces in packets: the largest size measured. A
/// packet of incoherent rays descends into the union of the nodes its rays need: in a small
/// tree that union is nearly the whole tree anyway, so one call serves all lanes at little
/// extra work, while in a large one the lanes part ways. Embree's 16-lane packets (until `4f135ca`,
/// 2026-12-05) paid only up to about 100k triangles: the `rays` bench had them at
/// 0.93–0.98× single rays at 100k and 0.97–1.03× at 1M, and renders of the dragon (871k)
/// unchanged. Its 8-lane packets are 1.07–1.14× as fast as single rays at 10k triangles,
/// 1.05–1.10× at 100k and 1.02–1.11× at 1M (robust mode, closest and any hit, 1 and 2
/// threads); a Cornell box render takes 9% less CPU with them than with the 16-lane ones,
/// and a dragon render 4% less than with single rays (`4f135ca`; docs/performance.md,
/// "Standing decisions"). Above 1M: untested, single rays as before.
pub const PACKET_MAX_TRIANGLES: usize = 1_000_000;

impl Packets {
    /// Whether a scene of `triangles` triangles uses packets.
    pub fn resolve(self, triangles: usize) -> bool {
        match self {
            Packets::Auto => triangles <= PACKET_MAX_TRIANGLES,
            Packets::Always => true,
            Packets::Never => false,
        }
    }

    /// `FLOWLIGHT_EMBREE_PACKETS` (`auto` | `always` | `never`), [`Packets::Auto`] when unset:
    /// renders and the benchmarks read it.
    pub fn from_env() -> Result<Packets, String> {
        match std::env::var("FLOWLIGHT_EMBREE_PACKETS") {
            Ok(p) => Packets::parse(&p).map_err(|e| format!("FLOWLIGHT_EMBREE_PACKETS: {e}")),
            Err(_) => Ok(Packets::Auto),
        }
    }

    pub fn parse(s: &str) -> Result<Packets, String> {
        match s {
            "auto" => Ok(Packets::Auto),
            "always" => Ok(Packets::Always),
            "never" => Ok(Packets::Never),
            _ => Err(format!("{s:?}: expected auto, always or never")),
        }
    }
}

impl SceneOptions {
    /// How a scene built with these options traces coherent batches, given how it traces
    /// the others (`plain`): Embree's coherent packets when [`SceneOptions::coherent`] is on
    /// and packets are not off altogether, else as the others.
    fn coherent_mode(&self, plain: BatchMode) -> BatchMode {
        if self.coherent && self.packets != Packets::Never {
            BatchMode::CoherentPackets
        } else {
            plain
        }
    }

    /// The defaults (robust, medium quality, packets by size), changed by
    /// `FLOWLIGHT_EMBREE_QUALITY` (`low` | `medium` | `high`), `FLOWLIGHT_EMBREE_ROBUST`
    /// (`0` | `1`) and `FLOWLIGHT_EMBREE_PACKETS` (`auto` | `always` | `never`).
    pub fn from_env() -> Result<Self, String> {
        let mut o = SceneOptions::default();
        if let Ok(q) = std::env::var("FLOWLIGHT_EMBREE_QUALITY") {
            o.quality =
                BuildQuality::parse(&q).map_err(|e| format!("FLOWLIGHT_EMBREE_QUALITY: {e}"))?;
        }
        if let Ok(r) = std::env::var("FLOWLIGHT_EMBREE_ROBUST") {
            o.robust = match r.as_str() {
                "1" | "true" => true,
                "0" | "false" => false,
                _ => return Err(format!("FLOWLIGHT_EMBREE_ROBUST={r:?}: expected 0 or 1")),
            };
        }
        o.packets = Packets::from_env()?;
        Ok(o)
    }
}

/// The hit of a flat scene's ray/hit record.
#[inline]
fn triangle_hit(rh: abi::RTCRayHit) -> TriangleHit {
    TriangleHit {
        t: rh.ray.tfar,
        prim: rh.hit.prim_id,
        b1: rh.hit.u,
        b2: rh.hit.v,
    }
}

/// A packet with every lane inactive-looking (Embree reads only the valid lanes).
fn empty_packet<const N: usize>() -> abi::RTCRayHitN<N> {
    abi::RTCRayHitN {
        ray: abi::RTCRayN {
            org_x: [0.0; N],
            org_y: [0.0; N],
            org_z: [0.0; N],
            tnear: [0.0; N],
            dir_x: [0.0; N],
            dir_y: [0.0; N],
            dir_z: [1.0; N],
            time: [0.0; N],
            tfar: [-0.0; N],
            mask: [u32::MAX; N],
            id: [0; N],
            flags: [0; N],
        },
        hit: abi::RTCHitN {
            ng_x: [0.0; N],
            ng_y: [0.0; N],
            ng_z: [0.0; N],
            u: [0.0; N],
            v: [0.0; N],
            prim_id: [u32::MAX; N],
            geom_id: [u32::MAX; N],
            inst_id: [[u32::MAX; N]],
            inst_prim_id: [[u32::MAX; N]],
        },
    }
}

/// Fills the first `rays.len()` (≤ N) lanes of `ray` and returns their valid mask.
#[inline]
fn load_lanes<const N: usize>(ray: &mut abi::RTCRayN<N>, rays: &[Ray]) -> abi::ValidN<N> {
    debug_assert!(rays.len() <= N);
    let mut valid = abi::ValidN([0; N]);
    for (k, r) in rays.iter().enumerate() {
        let r = EmbreeScene::rtc_ray(r);
        valid.0[k] = -1;
        ray.org_x[k] = r.org_x;
        ray.org_y[k] = r.org_y;
        ray.org_z[k] = r.org_z;
        ray.tnear[k] = r.tnear;
        ray.dir_x[k] = r.dir_x;
        ray.dir_y[k] = r.dir_y;
        ray.dir_z[k] = r.dir_z;
        ray.tfar[k] = r.tfar;
    }
    valid
}

/// How [`Device::closest_batch`] traces a batch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum BatchMode {
    SingleRays,
    Packets,
    /// Packets through Embree's coherent traversal: camera rays of a tile in raster order.
    CoherentPackets,
}

impl BatchMode {
    fn of(packets: bool) -> BatchMode {
        if packets {
            BatchMode::Packets
        } else {
            BatchMode::SingleRays
        }
    }
}

/// The hit of an instanced scene's ray/hit record (one instancing level).
#[inline]
fn instance_hit(rh: abi::RTCRayHit) -> InstanceHit {
    InstanceHit {
        t: rh.ray.tfar,
        instance: rh.hit.inst_id[0],
        prim: rh.hit.prim_id,
        b1: rh.hit.u,
        b2: rh.hit.v,
    }
}

/// A committed Embree scene of one triangle mesh; `prim` of a hit indexes the triangles it
/// was built from.
pub struct EmbreeScene {
    dev: &'static Device,
    scene: RTCScene,
    triangles: usize,
    /// Batches go through 8-lane packets ([`Packets::resolve`]).
    packets: bool,
    /// How coherent batches are traced ([`SceneOptions::coherent`]).
    coherent: BatchMode,
}

// SAFETY: a committed Embree scene is read-only and may be queried from any thread.
unsafe impl Send for EmbreeScene {}
unsafe impl Sync for EmbreeScene {}

impl EmbreeScene {
    /// Builds and commits the scene of `triangles` (indices into `positions`).
    pub fn build(
        positions: &[Vec3],
        triangles: &[[u32; 3]],
        options: SceneOptions,
    ) -> Result<EmbreeScene, String> {
        let dev = device()?;
        let api = &dev.api;
        if let Some(bad) = triangles
            .iter()
            .flatten()
            .find(|&&i| i as usize >= positions.len())
        {
            return Err(format!(
                "triangle index {bad} out of range ({} vertices)",
                positions.len()
            ));
        }
        // SAFETY: every call gets valid handles; buffers are written within their sizes.
        unsafe {
            let scene = (api.new_scene)(dev.handle);
            dev.check("rtcNewScene")?;
            let packets = options.packets.resolve(triangles.len());
            let out = EmbreeScene {
                dev,
                scene,
                triangles: triangles.len(),
                packets,
                coherent: options.coherent_mode(BatchMode::of(packets)),
            };
            // Alpha-tested queries pass their filter in the call's arguments. The flag is set
            // only for scenes that need it, so that every other scene keeps Embree's default
            // kernels exactly as before.
            let mut flags = RTCSceneFlags::NONE;
            if options.hit_filter {
                flags |= RTCSceneFlags::FILTER_FUNCTION_IN_ARGUMENTS;
            }
            if options.robust {
                flags |= RTCSceneFlags::ROBUST;
            }
            (api.set_scene_flags)(scene, flags);
            (api.set_scene_build_quality)(scene, options.quality.raw());
            if !triangles.is_empty() {
                let geom = (api.new_geometry)(dev.handle, RTCGeometryType::TRIANGLE);
                dev.check("rtcNewGeometry")?;
                (api.set_geometry_build_quality)(geom, options.quality.raw());
                let vb = (api.set_new_geometry_buffer)(
                    geom,
                    RTCBufferType::VERTEX,
                    0,
                    RTCFormat::FLOAT3,
                    12,
                    positions.len(),
                ) as *mut f32;
                let ib = (api.set_new_geometry_buffer)(
                    geom,
                    RTCBufferType::INDEX,
                    0,
                    RTCFormat::UINT3,
                    12,
                    triangles.len(),
                ) as *mut u32;
                if vb.is_null() || ib.is_null() {
                    (api.release_geometry)(geom);
                    dev.check("rtcSetNewGeometryBuffer")?;
                    return Err("Embree: rtcSetNewGeometryBuffer returned no buffer".into());
                }
                let vs = std::slice::from_raw_parts_mut(vb, positions.len() * 3);
                for (d, p) in vs.chunks_exact_mut(3).zip(positions) {
                    d.copy_from_slice(&p.to_array());
                }
                let is = std::slice::from_raw_parts_mut(ib, triangles.len() * 3);
                for (d, t) in is.chunks_exact_mut(3).zip(triangles) {
                    d.copy_from_slice(t);
                }
                (api.commit_geometry)(geom);
                (api.attach_geometry)(scene, geom);
                (api.release_geometry)(geom);
                dev.check("attaching the triangle mesh")?;
            }
            (api.commit_scene)(scene);
            dev.check("rtcCommitScene")?;
            Ok(out)
        }
    }

    /// Builds from triangles given by their vertices (no sharing).
    pub fn build_soup(tris: &[[Vec3; 3]], options: SceneOptions) -> Result<EmbreeScene, String> {
        let positions: Vec<Vec3> = tris.iter().flatten().copied().collect();
        let idx: Vec<[u32; 3]> = (0..tris.len() as u32)
            .map(|i| [3 * i, 3 * i + 1, 3 * i + 2])
            .collect();
        Self::build(&positions, &idx, options)
    }

    pub fn triangle_count(&self) -> usize {
        self.triangles
    }

    /// A ray/hit record for `rtcIntersect1`: the ray of [`Self::rtc_ray`] and no hit yet.
    #[inline]
    fn rtc_ray_hit(ray: &Ray) -> abi::RTCRayHit {
        abi::RTCRayHit {
            ray: Self::rtc_ray(ray),
            hit: abi::RTCHit {
                ng_x: 0.0,
                ng_y: 0.0,
                ng_z: 0.0,
                u: 0.0,
                v: 0.0,
                prim_id: u32::MAX,
                geom_id: u32::MAX,
                inst_id: [u32::MAX],
                inst_prim_id: [u32::MAX],
            },
        }
    }

    #[inline]
    fn rtc_ray(ray: &Ray) -> RTCRay {
        // Valid hits have 0 < t < t_max; Embree's interval [tnear, tfar] is closed.
        let tfar = if ray.t_max.is_finite() && ray.t_max > 0.0 {
            f32::from_bits(ray.t_max.to_bits() - 1)
        } else if ray.t_max > 0.0 {
            ray.t_max
        } else {
            -0.0
        };
        RTCRay {
            org_x: ray.origin.x,
            org_y: ray.origin.y,
            org_z: ray.origin.z,
            tnear: f32::MIN_POSITIVE,
            dir_x: ray.dir.x,
            dir_y: ray.dir.y,
            dir_z: ray.dir.z,
            time: 0.0,
            tfar,
            mask: u32::MAX,
            id: 0,
            flags: 0,
        }
    }

    /// Closest hit with `0 < t < ray.t_max`.
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<TriangleHit> {
        self.dev
            .closest_hit(self.scene, ray, None)
            .map(triangle_hit)
    }

    /// Whether anything lies at `0 < t < ray.t_max`.
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.dev.any_hit(self.scene, ray, None)
    }

    /// [`EmbreeScene::intersect`] counting only the hits `accept` keeps (alpha testing),
    /// through an argument filter callback (Embree 4 `RTCIntersectArguments::filter`, invoked
    /// for every candidate hit; a rejected one leaves the ray unchanged).
    pub fn intersect_filtered(&self, ray: &Ray, accept: HitFilter) -> Option<TriangleHit> {
        let mut ctx = FilterContext::new(&accept);
        let mut args = ctx.arguments();
        self.dev
            .closest_hit(self.scene, ray, Some(&mut args))
            .map(triangle_hit)
    }

    /// [`EmbreeScene::occluded`] counting only the hits `accept` keeps.
    pub fn occluded_filtered(&self, ray: &Ray, accept: HitFilter) -> bool {
        let mut ctx = FilterContext::new(&accept);
        let mut args = ctx.arguments();
        self.dev.any_hit(self.scene, ray, Some(&mut args))
    }

    /// Whether batches go through 8-lane packets ([`SceneOptions::packets`]).
    pub fn uses_packets(&self) -> bool {
        self.packets
    }

    /// Closest hits of a batch of rays: `hits[i]` is `rays[i]`'s hit exactly as
    /// [`EmbreeScene::intersect`] finds it, as a compact hit (`instance` unknown). The FP mode
    /// is set once for the batch; the rays go 8 at a time through `rtcIntersect8` or one by
    /// one through `rtcIntersect1` ([`SceneOptions::packets`]).
    pub fn intersect_batch(&self, rays: &[Ray], hits: &mut [CompactHit]) {
        self.intersect_batch_in(BatchMode::of(self.packets), rays, hits)
    }

    /// [`EmbreeScene::intersect_batch`] for coherent rays (camera rays of a tile in raster
    /// order): 16-lane packets through Embree's coherent traversal, whatever the scene's
    /// size ([`SceneOptions::coherent`]). The same distances; a tie between two triangles at
    /// one distance may go the other way.
    pub fn intersect_coherent_batch(&self, rays: &[Ray], hits: &mut [CompactHit]) {
        self.intersect_batch_in(self.coherent, rays, hits)
    }

    fn intersect_batch_in(&self, mode: BatchMode, rays: &[Ray], hits: &mut [CompactHit]) {
        assert_eq!(rays.len(), hits.len(), "one hit per ray");
        self.dev.closest_batch(self.scene, mode, rays, |i, h| {
            hits[i] = h.map_or(CompactHit::MISS, |h| {
                CompactHit::from(TriangleHit {
                    t: h.t,
                    prim: h.prim,
                    b1: h.b1,
                    b2: h.b2,
                })
            });
        });
    }

    /// Shadow rays of a batch: `blocked[i]` is 1 where [`EmbreeScene::occluded`] of
    /// `rays[i]` holds, else 0; packets or single rays as [`EmbreeScene::intersect_batch`].
    pub fn occluded_batch(&self, rays: &[Ray], blocked: &mut [u8]) {
        self.dev
            .occluded_batch(self.scene, self.packets, rays, blocked);
    }

    /// Raw `rtcIntersect1` into caller memory, for the ABI test: `buf` must be at least
    /// 96 bytes, 16-aligned, and start with an `RTCRay`.
    ///
    /// # Safety
    /// `buf` must point to writable, 16-byte aligned memory of at least 96 bytes.
    #[doc(hidden)]
    pub unsafe fn intersect_raw(&self, buf: *mut u8) {
        (self.dev.api.intersect1)(self.scene, buf as *mut abi::RTCRayHit, std::ptr::null_mut())
    }

    /// The ray Embree is given for `ray` (for the ABI test).
    #[doc(hidden)]
    pub fn embree_ray(ray: &Ray) -> RTCRay {
        Self::rtc_ray(ray)
    }
}

/// A committed two-level Embree scene: one Embree scene per mesh ([`EmbreeScene`]) and a top
/// scene of `RTC_GEOMETRY_TYPE_INSTANCE` geometries, one per instance, each pointing at its
/// mesh's scene with an object-to-world transform. A mesh placed many times is stored once.
/// Hits name the instance (Embree's `instID`, the instance geometry's id in the top scene,
/// which is its index) and the triangle of its mesh (`primID`); Embree moves the ray to
/// object space without normalising its direction, so `t` is the world-space parameter.
pub struct EmbreeInstancedScene {
    dev: &'static Device,
    top: RTCScene,
    /// Kept alive while the top scene refers to them.
    meshes: Vec<EmbreeScene>,
    instances: usize,
    /// Batches go through 8-lane packets ([`Packets::resolve`] of the stored triangles).
    packets: bool,
    /// How coherent batches are traced ([`SceneOptions::coherent`]).
    coherent: BatchMode,
}

// SAFETY: as for `EmbreeScene`: committed scenes are read-only.
unsafe impl Send for EmbreeInstancedScene {}
unsafe impl Sync for EmbreeInstancedScene {}

impl EmbreeInstancedScene {
    /// Builds one Embree scene per mesh (`positions`, `triangles`) and the top scene of
    /// `instances` (mesh index, affine object-to-world matrix).
    pub fn build(
        meshes: &[(Vec<Vec3>, Vec<[u32; 3]>)],
        instances: &[(u32, Mat4)],
        options: SceneOptions,
    ) -> Result<EmbreeInstancedScene, String> {
        let dev = device()?;
        let api = &dev.api;
        let built = meshes
            .iter()
            .map(|(p, t)| EmbreeScene::build(p, t, options))
            .collect::<Result<Vec<_>, _>>()?;
        for (i, (m, x)) in instances.iter().enumerate() {
            if *m as usize >= built.len() {
                return Err(format!(
                    "instance {i}: mesh {m} does not exist ({} meshes)",
                    built.len()
                ));
            }
            if !x.is_finite() || x.row(3) != glam::Vec4::W {
                return Err(format!(
                    "instance {i}: transform is not a finite affine matrix"
                ));
            }
        }
        // SAFETY: valid handles; the transform is 16 column-major floats read during the call.
        unsafe {
            let top = (api.new_scene)(dev.handle);
            dev.check("rtcNewScene")?;
            let packets = options
                .packets
                .resolve(built.iter().map(|m| m.triangles).sum());
            let out = EmbreeInstancedScene {
                dev,
                top,
                packets,
                coherent: options.coherent_mode(BatchMode::of(packets)),
                meshes: built,
                instances: instances.len(),
            };
            let mut flags = RTCSceneFlags::NONE;
            if options.robust {
                flags |= RTCSceneFlags::ROBUST;
            }
            if options.hit_filter {
                flags |= RTCSceneFlags::FILTER_FUNCTION_IN_ARGUMENTS;
            }
            (api.set_scene_flags)(top, flags);
            (api.set_scene_build_quality)(top, options.quality.raw());
            for (i, (m, x)) in instances.iter().enumerate() {
                let geom = (api.new_geometry)(dev.handle, RTCGeometryType::INSTANCE);
                dev.check("rtcNewGeometry(INSTANCE)")?;
                (api.set_geometry_instanced_scene)(geom, out.meshes[*m as usize].scene);
                let cols = x.to_cols_array();
                (api.set_geometry_transform)(
                    geom,
                    0,
                    RTCFormat::FLOAT4X4_COLUMN_MAJOR,
                    cols.as_ptr() as *const c_void,
                );
                (api.commit_geometry)(geom);
                let id = (api.attach_geometry)(top, geom);
                (api.release_geometry)(geom);
                dev.check("attaching an instance")?;
                if id as usize != i {
                    return Err(format!("Embree gave instance {i} the geometry id {id}"));
                }
            }
            (api.commit_scene)(top);
            dev.check("rtcCommitScene (instances)")?;
            Ok(out)
        }
    }

    /// Triangles stored: each mesh's once.
    pub fn stored_triangle_count(&self) -> usize {
        self.meshes.iter().map(EmbreeScene::triangle_count).sum()
    }

    pub fn instance_count(&self) -> usize {
        self.instances
    }

    /// Closest hit with `0 < t < ray.t_max`.
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<InstanceHit> {
        self.dev.closest_hit(self.top, ray, None).map(instance_hit)
    }

    /// Whether batches go through 8-lane packets: [`SceneOptions::packets`] for the
    /// triangles stored (each mesh once).
    pub fn uses_packets(&self) -> bool {
        self.packets
    }

    /// Closest hits of a batch: `emit(i, hit)` with `rays[i]`'s hit exactly as
    /// [`EmbreeInstancedScene::intersect`] finds it, in order, in one FP mode switch, by
    /// packets or single rays as [`EmbreeScene::intersect_batch`].
    pub fn intersect_batch(&self, rays: &[Ray], emit: impl FnMut(usize, Option<InstanceHit>)) {
        self.dev
            .closest_batch(self.top, BatchMode::of(self.packets), rays, emit);
    }

    /// [`EmbreeInstancedScene::intersect_batch`] for coherent rays, as
    /// [`EmbreeScene::intersect_coherent_batch`].
    pub fn intersect_coherent_batch(
        &self,
        rays: &[Ray],
        emit: impl FnMut(usize, Option<InstanceHit>),
    ) {
        self.dev.closest_batch(self.top, self.coherent, rays, emit);
    }

    /// Shadow rays of a batch: `blocked[i]` is 1 where [`EmbreeInstancedScene::occluded`]
    /// of `rays[i]` holds, else 0.
    pub fn occluded_batch(&self, rays: &[Ray], blocked: &mut [u8]) {
        self.dev
            .occluded_batch(self.top, self.packets, rays, blocked);
    }

    /// Whether anything lies at `0 < t < ray.t_max`.
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.dev.any_hit(self.top, ray, None)
    }

    /// [`EmbreeInstancedScene::intersect`] counting only the hits `accept(instance, prim,
    /// u, v)` keeps (alpha testing through instances). Needs
    /// [`SceneOptions::hit_filter`], which is set on every mesh scene and the top scene.
    pub fn intersect_filtered(&self, ray: &Ray, accept: InstanceHitFilter) -> Option<InstanceHit> {
        let mut ctx = FilterContext::instanced(&accept);
        let mut args = ctx.arguments();
        self.dev
            .closest_hit(self.top, ray, Some(&mut args))
            .map(instance_hit)
    }

    /// [`EmbreeInstancedScene::occluded`] counting only the hits `accept` keeps.
    pub fn occluded_filtered(&self, ray: &Ray, accept: InstanceHitFilter) -> bool {
        let mut ctx = FilterContext::instanced(&accept);
        let mut args = ctx.arguments();
        self.dev.any_hit(self.top, ray, Some(&mut args))
    }
}

impl Drop for EmbreeInstancedScene {
    fn drop(&mut self) {
        // SAFETY: the top scene is not used after this; the mesh scenes drop after it.
        unsafe { (self.dev.api.release_scene)(self.top) }
    }
}

/// The ray query context handed to Embree for a filtered query: Embree's own
/// `RTCRayQueryContext` first (4.4 with instance arrays: `instID[1]`, `instPrimID[1]`; two
/// spare words in case a build has more), then the filter, which the callback finds by
/// casting the context pointer back (the layout Embree's tutorials use for user data).
#[repr(C)]
struct FilterContext<'a, 'f> {
    embree: [u32; 4],
    accept: Accept<'a, 'f>,
}

/// The filter of a filtered query: by triangle, or by (instance, triangle of its mesh).
enum Accept<'a, 'f> {
    Flat(&'a HitFilter<'f>),
    Instanced(&'a InstanceHitFilter<'f>),
}

impl<'a, 'f> FilterContext<'a, 'f> {
    fn new(accept: &'a HitFilter<'f>) -> Self {
        // rtcInitRayQueryContext: every instance ID invalid.
        FilterContext {
            embree: [u32::MAX; 4],
            accept: Accept::Flat(accept),
        }
    }

    fn instanced(accept: &'a InstanceHitFilter<'f>) -> Self {
        FilterContext {
            embree: [u32::MAX; 4],
            accept: Accept::Instanced(accept),
        }
    }

    /// The arguments of a filtered query with this context.
    fn arguments(&mut self) -> filter::IntersectArguments {
        filter::IntersectArguments {
            flags: RTCRayQueryFlags::INVOKE_ARGUMENT_FILTER,
            feature_mask: RTCFeatureFlags::RTC_FEATURE_FLAG_ALL,
            context: self as *mut FilterContext as *mut c_void,
            filter: Some(filter_callback),
            intersect: None,
            min_width_distance_factor: 0.0,
            _pad: [0; 4],
        }
    }
}

/// Argument structures for filtered queries.
mod filter {
    use embree4_sys::{RTCFeatureFlags, RTCFilterFunctionN, RTCRayQueryFlags};
    use std::ffi::c_void;

    /// `RTCIntersectArguments` / `RTCOccludedArguments` (identical layouts: flags, feature
    /// mask, context, filter, intersect/occluded callback), followed by
    /// `minWidthDistanceFactor` for libraries built with `RTC_MIN_WIDTH` (0 = off) and padding,
    /// so a library reading either layout reads initialised memory.
    #[repr(C)]
    pub struct IntersectArguments {
        pub flags: RTCRayQueryFlags,
        pub feature_mask: RTCFeatureFlags,
        pub context: *mut c_void,
        pub filter: RTCFilterFunctionN,
        pub intersect: Option<unsafe extern "C" fn(*const c_void)>,
        pub min_width_distance_factor: f32,
        pub _pad: [u32; 4],
    }

    const _: () = assert!(std::mem::offset_of!(IntersectArguments, filter) == 16);
    const _: () = assert!(
        std::mem::offset_of!(IntersectArguments, min_width_distance_factor)
            == std::mem::size_of::<embree4_sys::RTCIntersectArguments>()
    );
}

/// Embree's filter callback for filtered queries: for each valid lane of the `N`-wide
/// (structure-of-arrays) hit, asks the context's filter about `(primID, u, v)` (with
/// `instID` first for an instanced scene) and marks the
/// lane invalid (`valid[i] = 0`) when the ray passes through. A panic in the filter counts as
/// "keep the hit" (it must not unwind into Embree).
unsafe extern "C" fn filter_callback(args: *const embree4_sys::RTCFilterFunctionNArguments) {
    let a = &*args;
    let ctx = &*(a.context as *const FilterContext);
    let n = a.N as usize;
    let hit = a.hit as *const u32;
    // Rust code runs in the thread's own floating-point mode, not the query's: switched once
    // for the callback's N candidates.
    denormals::with_denormals_kept(|| {
        for i in 0..n {
            if *a.valid.add(i) == 0 {
                continue;
            }
            // RTCHitN: Ng_x[N], Ng_y[N], Ng_z[N], u[N], v[N], primID[N], geomID[N],
            // instID[1][N] (the instance stack when the hit was found), instPrimID[1][N].
            let u = f32::from_bits(*hit.add(3 * n + i));
            let v = f32::from_bits(*hit.add(4 * n + i));
            let prim = *hit.add(5 * n + i);
            let inst = *hit.add(7 * n + i);
            let keep =
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| match ctx.accept {
                    Accept::Flat(f) => f(prim, u, v),
                    Accept::Instanced(f) => f(inst, prim, u, v),
                }))
                .unwrap_or(true);
            if !keep {
                *a.valid.add(i) = 0;
            }
        }
    });
}

impl Drop for EmbreeScene {
    fn drop(&mut self) {
        // SAFETY: the scene is not used after this.
        unsafe { (self.dev.api.release_scene)(self.scene) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> (Vec<Vec3>, Vec<[u32; 3]>) {
        (
            vec![
                Vec3::new(-1.0, -1.0, 0.0),
                Vec3::new(1.0, -1.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::new(-1.0, 1.0, 0.0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    #[test]
    fn device_is_embree_4_4() {
        let d = device().unwrap();
        assert!(
            d.version >= 40400,
            "{} from {}",
            d.version_string(),
            d.library
        );
    }

    #[test]
    fn hits_and_barycentrics_and_t_range() {
        let (p, t) = quad();
        let s = EmbreeScene::build(&p, &t, SceneOptions::default()).unwrap();
        let ray = Ray {
            origin: Vec3::new(0.5, -0.25, -2.0),
            dir: Vec3::Z,
            t_max: f32::INFINITY,
        };
        let h = s.intersect(&ray).unwrap();
        assert_eq!(h.prim, 0);
        assert!((h.t - 2.0).abs() < 1e-6);
        let q = p[0] * (1.0 - h.b1 - h.b2) + p[1] * h.b1 + p[2] * h.b2;
        assert!((q - Vec3::new(0.5, -0.25, 0.0)).length() < 1e-6, "{q}");
        assert!(s.occluded(&ray));
        // A hit beyond t_max is not one. Whether a hit exactly at t_max counts differs
        // between Embree's ISA kernels (AVX2 and AVX-512 builds disagree), so nothing in the
        // renderer relies on it: shadow rays stop short of their target by the spawn offset.
        let short = Ray {
            t_max: 1.9999,
            ..ray
        };
        assert!(s.intersect(&short).is_none());
        assert!(!s.occluded(&short));
        let longer = Ray {
            t_max: 2.0001,
            ..ray
        };
        assert!(s.intersect(&longer).is_some());
        // Behind the origin: no hit.
        let away = Ray {
            dir: -Vec3::Z,
            ..ray
        };
        assert!(s.intersect(&away).is_none());
    }

    #[test]
    fn the_library_writes_the_4_4_hit_layout() {
        // The library writes instPrimID right after instID: byte 80..84 of RTCRayHit, past
        // the end of embree4-sys's 80-byte (4.2) struct.
        let (p, t) = quad();
        let s = EmbreeScene::build(&p, &t, SceneOptions::default()).unwrap();
        #[repr(C, align(16))]
        struct Buf([u8; 128]);
        let mut buf = Buf([0xAB; 128]);
        let ray = EmbreeScene::embree_ray(&Ray {
            origin: Vec3::new(0.5, -0.25, -2.0),
            dir: Vec3::Z,
            t_max: f32::INFINITY,
        });
        unsafe {
            std::ptr::write(buf.0.as_mut_ptr() as *mut RTCRay, ray);
            s.intersect_raw(buf.0.as_mut_ptr());
        }
        let geom = u32::from_ne_bytes(buf.0[72..76].try_into().unwrap());
        assert_eq!(geom, 0, "geomID at the 4.2 offset");
        let written: Vec<usize> = (80..128).filter(|&i| buf.0[i] != 0xAB).collect();
        assert_eq!(
            written,
            vec![80, 81, 82, 83],
            "bytes written past the 4.2 RTCRayHit"
        );
    }

    /// A bumpy sphere of 2·n·(n−1) triangles.
    fn bumpy_sphere(n: usize) -> Vec<[Vec3; 3]> {
        let at = |i: usize, j: usize| {
            let (th, ph) = (
                std::f32::consts::PI * i as f32 / n as f32,
                std::f32::consts::TAU * j as f32 / n as f32,
            );
            let r = 1.0 + 0.1 * (5.0 * th).sin() * (3.0 * ph).cos();
            Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()) * r
        };
        let mut tris = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                if i > 0 {
                    tris.push([a, b, d]);
                }
                if i + 1 < n {
                    tris.push([b, c, d]);
                }
            }
        }
        tris
    }

    /// Camera rays through a 61 × 61 grid (not a multiple of 16: partial packets), then
    /// incoherent rays with random `t_max`, some of them 0, negative or NaN.
    fn batch_rays() -> Vec<Ray> {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut u = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut rays: Vec<Ray> = (0..61 * 61)
            .map(|i| {
                let (x, y) = ((i % 61) as f32 / 60.0 - 0.5, (i / 61) as f32 / 60.0 - 0.5);
                Ray::new(
                    Vec3::new(0.0, 0.0, 4.0),
                    Vec3::new(x, y, -1.5).normalize(),
                    f32::INFINITY,
                )
            })
            .collect();
        for i in 0..3001 {
            let o = Vec3::new(u() - 0.5, u() - 0.5, u() - 0.5) * 6.0;
            let d = (Vec3::new(u(), u(), u()) - 0.5 - o * 0.1).normalize();
            let t_max = match i % 97 {
                0 => 0.0,
                1 => -1.0,
                2 => f32::NAN,
                _ if u() < 0.5 => f32::INFINITY,
                _ => 4.0 * u(),
            };
            rays.push(Ray::new(o, d, t_max));
        }
        rays
    }

    #[test]
    fn batches_return_exactly_the_single_ray_answers() {
        let tris = bumpy_sphere(40);
        let rays = batch_rays();
        let bits = |h: CompactHit| (h.t.to_bits(), h.prim, h.b1.to_bits(), h.b2.to_bits());
        for packets in [Packets::Always, Packets::Never] {
            let options = SceneOptions {
                packets,
                ..SceneOptions::default()
            };
            let s = EmbreeScene::build_soup(&tris, options).unwrap();
            assert_eq!(s.uses_packets(), packets == Packets::Always);
            let mut hits = vec![CompactHit::MISS; rays.len()];
            s.intersect_batch(&rays, &mut hits);
            let mut blocked = vec![7u8; rays.len()];
            s.occluded_batch(&rays, &mut blocked);
            let (mut n_hit, mut n_blocked) = (0, 0);
            for (i, ray) in rays.iter().enumerate() {
                let want = s.intersect(ray).map_or(CompactHit::MISS, CompactHit::from);
                assert_eq!(bits(hits[i]), bits(want), "{packets:?}, ray {i}: {ray:?}");
                assert_eq!(
                    blocked[i],
                    u8::from(s.occluded(ray)),
                    "{packets:?}, ray {i}"
                );
                n_hit += want.is_hit() as usize;
                n_blocked += blocked[i] as usize;
            }
            assert!(
                n_hit > 1500 && n_blocked >= n_hit,
                "{n_hit} hits, {n_blocked} blocked"
            );
        }
    }

    #[test]
    fn packets_follow_the_scene_size() {
        assert!(Packets::Auto.resolve(38));
        assert!(Packets::Auto.resolve(PACKET_MAX_TRIANGLES));
        assert!(!Packets::Auto.resolve(PACKET_MAX_TRIANGLES + 1));
        assert!(Packets::Always.resolve(10_000_000));
        assert!(!Packets::Never.resolve(1));
        assert_eq!(Packets::parse("auto"), Ok(Packets::Auto));
        assert_eq!(Packets::parse("always"), Ok(Packets::Always));
        assert!(Packets::parse("1").is_err(), "no undocumented aliases");
        assert_eq!(Packets::parse("never"), Ok(Packets::Never));
        assert!(Packets::parse("sometimes")
            .unwrap_err()
            .contains("auto, always or never"));
        let big = bumpy_sphere(40);
        let s = EmbreeScene::build_soup(&big[..8], SceneOptions::default()).unwrap();
        assert!(s.uses_packets(), "a small scene takes packets by default");
    }
}
