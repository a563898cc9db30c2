//! Plugin-side wrapper over the host's ray queries.

use crate::abi::{HitRecord, TracerTable};
use flowlight_core::geometry::{Ray, SurfaceHit};
use std::mem::MaybeUninit;

/// Ray queries answered by the host's intersector (BVH or Embree). One indirect call per
/// batch; the single-ray helpers are batches of one.
#[derive(Clone, Copy)]
pub struct Tracer<'a> {
    table: &'a TracerTable,
}

impl<'a> Tracer<'a> {
    pub fn new(table: &'a TracerTable) -> Self {
        Tracer { table }
    }

    pub fn table(&self) -> &'a TracerTable {
        self.table
    }

    /// Closest hit of each ray.
    pub fn intersect_batch(&self, rays: &[Ray], hits: &mut [HitRecord]) {
        assert_eq!(rays.len(), hits.len());
        // SAFETY: both buffers hold `rays.len()` elements for the duration of the call.
        unsafe {
            (self.table.intersect)(self.table.ctx, rays.as_ptr(), hits.as_mut_ptr(), rays.len())
        }
    }

    /// Occlusion of each ray (1 = blocked).
    pub fn occluded_batch(&self, rays: &[Ray], blocked: &mut [u8]) {
        assert_eq!(rays.len(), blocked.len());
        // SAFETY: both buffers hold `rays.len()` elements for the duration of the call.
        unsafe {
            (self.table.occluded)(
                self.table.ctx,
                rays.as_ptr(),
                blocked.as_mut_ptr(),
                rays.len(),
            )
        }
    }

    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<SurfaceHit> {
        let mut rec = MaybeUninit::<HitRecord>::uninit();
        // SAFETY: one ray in, one record out; the host always writes the record.
        let rec = unsafe {
            (self.table.intersect)(self.table.ctx, ray, rec.as_mut_ptr(), 1);
            rec.assume_init()
        };
        (rec.hit != 0).then_some(rec.surface)
    }

    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        let mut blocked = 0u8;
        // SAFETY: one ray in, one flag out.
        unsafe { (self.table.occluded)(self.table.ctx, ray, &mut blocked, 1) };
        blocked != 0
    }
}
