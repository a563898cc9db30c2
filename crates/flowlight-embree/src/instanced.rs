//! An instanced scene: one Embree scene per mesh and a top scene of instance geometries
//! placing them, so that a mesh placed many times is stored once.

use crate::device::{device, Device};
use crate::filter::FilterContext;
use crate::queries::{instance_hit, BatchMode};
use crate::{EmbreeScene, SceneOptions};
use embree4_sys::{RTCFormat, RTCGeometryType, RTCScene, RTCSceneFlags};
use flowlight_core::geometry::{InstanceHit, InstanceHitFilter, Ray};
use glam::{Mat4, Vec3};
use std::ffi::c_void;

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
