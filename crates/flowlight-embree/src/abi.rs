//! Layouts of the structures that cross into Embree, as the 4.4 library uses them.

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
