//! Plugin-side wrapper over the host's ray queries.
//!
//! Two kinds of call cross the boundary: one ray per call (`intersect`, `occluded`: the full
//! `SurfaceHit` comes back, which ERPT's chains and the mutations use), and batches (ABI 4:
//! `intersect_batch`, `occluded_batch`), which pay one indirect call per batch and return
//! compact hits; the plugin builds the surface data it shades from them with
//! [`crate::Scene::surface`]. A batch's answers are exactly its rays' single-ray answers.

use crate::abi::{batch, HitRecord, TracerTable};
use flowlight_core::geometry::{Ray, SurfaceHit};
use flowlight_core::mesh::CompactHit;
use std::mem::MaybeUninit;

/// Ray queries answered by the host's intersector (BVH or Embree).
#[derive(Clone, Copy)]
pub struct Tracer<'a> {
    table: &'a TracerTable,
}

impl<'a> Tracer<'a> {
    /// Ray queries through the host's `table` (the SDK's glue builds it).
    pub fn new(table: &'a TracerTable) -> Self {
        Tracer { table }
    }

    /// The raw table, to hand on to another plugin (e.g. a mutation).
    pub fn table(&self) -> &'a TracerTable {
        self.table
    }

    /// Whether the render's budget ran out or Ctrl-C was pressed while this unit runs (ABI
    /// 6). Once it answers true the host discards the unit's deposits: an integrator whose
    /// units can run long (ERPT's chains) asks now and then and returns at once. A clock read
    /// and an indirect call: ask every few hundred steps, not every ray.
    #[inline]
    pub fn should_stop(&self) -> bool {
        // SAFETY: no arguments beyond the host's context.
        unsafe { (self.table.should_stop)(self.table.ctx) != 0 }
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

    /// Closest hits of `rays`, one per ray, into `hits` (resized to `rays.len()`), in one call.
    /// `coherent` tells the host the rays are coherent (camera rays of a tile, in raster
    /// order), so it may use packet traversal.
    pub fn intersect_batch(&self, rays: &[Ray], coherent: bool, hits: &mut Vec<CompactHit>) {
        hits.clear();
        hits.resize(rays.len(), CompactHit::MISS);
        if rays.is_empty() {
            return;
        }
        let flags = if coherent { batch::COHERENT } else { 0 };
        // SAFETY: `rays.len()` rays in, as many writable records out.
        unsafe {
            (self.table.intersect_batch)(
                self.table.ctx,
                rays.as_ptr(),
                rays.len(),
                flags,
                hits.as_mut_ptr(),
            )
        }
    }

    /// Whether each of `rays` is blocked before its `t_max`, into `blocked` (resized to
    /// `rays.len()`; 1 = blocked), in one call.
    pub fn occluded_batch(&self, rays: &[Ray], blocked: &mut Vec<u8>) {
        blocked.clear();
        blocked.resize(rays.len(), 0);
        if rays.is_empty() {
            return;
        }
        // SAFETY: `rays.len()` rays in, as many writable flags out.
        unsafe {
            (self.table.occluded_batch)(
                self.table.ctx,
                rays.as_ptr(),
                rays.len(),
                blocked.as_mut_ptr(),
            )
        }
    }
}
