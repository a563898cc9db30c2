//! A flat scene: one committed Embree triangle mesh answering closest-hit and any-hit
//! queries, single, filtered (alpha testing) or in batches.

use crate::abi;
use crate::device::{device, Device};
use crate::filter::FilterContext;
use crate::queries::{triangle_hit, BatchMode};
use crate::SceneOptions;
use embree4_sys::{RTCBufferType, RTCFormat, RTCGeometryType, RTCRay, RTCScene, RTCSceneFlags};
use flowlight_core::geometry::{HitFilter, Ray, TriangleHit};
use flowlight_core::mesh::CompactHit;
use glam::Vec3;

/// A committed Embree scene of one triangle mesh; `prim` of a hit indexes the triangles it
/// was built from.
pub struct EmbreeScene {
    pub(crate) dev: &'static Device,
    pub(crate) scene: RTCScene,
    pub(crate) triangles: usize,
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
    pub(crate) fn rtc_ray_hit(ray: &Ray) -> abi::RTCRayHit {
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
    pub(crate) fn rtc_ray(ray: &Ray) -> RTCRay {
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
impl Drop for EmbreeScene {
    fn drop(&mut self) {
        // SAFETY: the scene is not used after this.
        unsafe { (self.dev.api.release_scene)(self.scene) }
    }
}
