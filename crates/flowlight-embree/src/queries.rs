//! The queries a scene answers through the device: one ray (`rtcIntersect1`,
//! `rtcOccluded1`) or a batch, by single rays or by packets of 8 or 16 lanes
//! (`rtcIntersect8/16`, `rtcOccluded8`), in one floating-point mode switch per batch.

use crate::abi;
use crate::device::{Device, IntersectN};
use crate::filter;
use crate::scene::EmbreeScene;
use embree4_sys::{RTCFeatureFlags, RTCRayQueryFlags, RTCScene};
use flowlight_core::denormals;
use flowlight_core::geometry::{InstanceHit, Ray, TriangleHit};
use std::ffi::c_void;

impl Device {
    /// `rtcIntersect1` of `ray` against the committed `scene`, with filter `args` when given
    /// (their context must outlive the call): the hit record, or `None` for a miss.
    #[inline]
    pub(crate) fn closest_hit(
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
    pub(crate) fn any_hit(
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
    pub(crate) fn closest_batch(
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
    pub(crate) fn occluded_batch(
        &self,
        scene: RTCScene,
        packets: bool,
        rays: &[Ray],
        blocked: &mut [u8],
    ) {
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
}

/// The hit of a flat scene's ray/hit record.
#[inline]
pub(crate) fn triangle_hit(rh: abi::RTCRayHit) -> TriangleHit {
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
pub(crate) enum BatchMode {
    SingleRays,
    Packets,
    /// Packets through Embree's coherent traversal: camera rays of a tile in raster order.
    CoherentPackets,
}

impl BatchMode {
    pub(crate) fn of(packets: bool) -> BatchMode {
        if packets {
            BatchMode::Packets
        } else {
            BatchMode::SingleRays
        }
    }
}

/// The hit of an instanced scene's ray/hit record (one instancing level).
#[inline]
pub(crate) fn instance_hit(rh: abi::RTCRayHit) -> InstanceHit {
    InstanceHit {
        t: rh.ray.tfar,
        instance: rh.hit.inst_id[0],
        prim: rh.hit.prim_id,
        b1: rh.hit.u,
        b2: rh.hit.v,
    }
}
