//! Plugin-side wrapper over the host's ray queries.

use crate::abi::{HitRecord, TracerTable};
use flowlight_core::geometry::{Ray, SurfaceHit};
use std::mem::MaybeUninit;

/// Ray queries answered by the host's intersector (BVH or Embree), one indirect call per ray.
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

    /// The closest surface `ray` hits before its `t_max`, or `None` when it escapes.
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<SurfaceHit> {
        let mut rec = MaybeUninit::<HitRecord>::uninit();
        // SAFETY: one ray in, one record out; the host always writes the record.
        let rec = unsafe {
            (self.table.intersect)(self.table.ctx, ray, rec.as_mut_ptr());
            rec.assume_init()
        };
        (rec.hit != 0).then_some(rec.surface)
    }

    /// Whether anything blocks `ray` before its `t_max` (a shadow ray).
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        // SAFETY: one ray in, one flag out.
        unsafe { (self.table.occluded)(self.table.ctx, ray) != 0 }
    }
}
