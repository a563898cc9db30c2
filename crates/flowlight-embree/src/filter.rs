//! Filtered queries (alpha testing): the query context that carries the filter, the
//! argument structure that installs Embree's filter callback, and the callback itself.

use embree4_sys::{RTCFeatureFlags, RTCFilterFunctionN, RTCRayQueryFlags};
use flowlight_core::denormals;
use flowlight_core::geometry::{HitFilter, InstanceHitFilter};
use std::ffi::c_void;

/// The ray query context handed to Embree for a filtered query: Embree's own
/// `RTCRayQueryContext` first (4.4 with instance arrays: `instID[1]`, `instPrimID[1]`; two
/// spare words in case a build has more), then the filter, which the callback finds by
/// casting the context pointer back (the layout Embree's tutorials use for user data).
#[repr(C)]
pub(crate) struct FilterContext<'a, 'f> {
    embree: [u32; 4],
    accept: Accept<'a, 'f>,
}

/// The filter of a filtered query: by triangle, or by (instance, triangle of its mesh).
enum Accept<'a, 'f> {
    Flat(&'a HitFilter<'f>),
    Instanced(&'a InstanceHitFilter<'f>),
}

impl<'a, 'f> FilterContext<'a, 'f> {
    pub(crate) fn new(accept: &'a HitFilter<'f>) -> Self {
        // rtcInitRayQueryContext: every instance ID invalid.
        FilterContext {
            embree: [u32::MAX; 4],
            accept: Accept::Flat(accept),
        }
    }

    pub(crate) fn instanced(accept: &'a InstanceHitFilter<'f>) -> Self {
        FilterContext {
            embree: [u32::MAX; 4],
            accept: Accept::Instanced(accept),
        }
    }

    /// The arguments of a filtered query with this context.
    pub(crate) fn arguments(&mut self) -> IntersectArguments {
        IntersectArguments {
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
