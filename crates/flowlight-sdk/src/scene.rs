//! Plugin-side view of the scene: safe slices over the host's tables.

use crate::abi::{MeshTables, SceneView};
use flowlight_core::bsdf::Bsdf;
use flowlight_core::camera::Camera;
use flowlight_core::geometry::{Ray, SurfaceHit};
use flowlight_core::light::{Emitter, Lights, PunctualLight};
use flowlight_core::material::{Material, ResolvedMaterial, Texture};
use flowlight_core::mesh::{CompactHit, MeshView};
use glam::Vec3;

/// The scene as plugins see it. Borrowed from the host for the plugin instance's lifetime.
#[derive(Clone, Copy)]
pub struct Scene<'a> {
    pub camera: Camera,
    pub materials: &'a [Material],
    pub textures: &'a [Texture],
    pub lights: Lights<'a>,
    pub bounds_min: Vec3,
    pub bounds_max: Vec3,
    /// The vertex and triangle buffers: [`Scene::surface`] builds surface data from the
    /// compact hits of batched queries. Empty in scenes built by hand for shading tests.
    pub mesh: MeshView<'a>,
}

unsafe fn slice<'a, T>(ptr: *const T, len: usize) -> &'a [T] {
    // SAFETY: the caller upholds this function's contract (its `# Safety` section, or the
    // ABI rules in `abi.rs` for the C entry points).
    unsafe {
        if ptr.is_null() || len == 0 {
            &[]
        } else {
            std::slice::from_raw_parts(ptr, len)
        }
    }
}

impl<'a> Scene<'a> {
    /// # Safety
    /// The view's pointers must be valid for `'a` (the host guarantees this for the lifetime
    /// of a plugin instance).
    pub unsafe fn from_view(v: &SceneView) -> Scene<'a> {
        // SAFETY: the caller upholds this function's contract (its `# Safety` section, or the
        // ABI rules in `abi.rs` for the C entry points).
        unsafe {
            let emitters: &'a [Emitter] = slice(v.emitters, v.emitter_count);
            let punctual: &'a [PunctualLight] = slice(v.punctual_lights, v.punctual_count);
            let light_count =
                v.emitter_count + v.punctual_count + usize::from(v.environment.is_present());
            let materials: &'a [Material] = slice(v.materials, v.material_count);
            let textures: &'a [Texture] = slice(v.textures, v.texture_count);
            let m = &v.mesh;
            let mesh = MeshView {
                positions: slice(m.positions, m.vertex_count),
                normals: slice(m.normals, m.vertex_count),
                uvs: slice(m.uvs, m.vertex_count),
                uvs1: slice(m.uvs1, m.uvs1_count),
                colors: slice(m.colors, m.colors_count),
                tangents: slice(m.tangents, m.tangents_count),
                triangles: slice(m.triangles, m.triangle_count),
                triangle_material: slice(m.triangle_material, m.triangle_count),
                triangle_emitter: slice(m.triangle_emitter, m.triangle_count),
                instances: slice(m.instances, m.instance_count),
                materials,
                textures,
            };
            Scene {
                camera: v.camera,
                materials,
                textures,
                lights: Lights {
                    emitters,
                    punctual,
                    environment: v.environment,
                    power_cdf: slice(v.light_power_cdf, light_count),
                    materials,
                    textures,
                },
                bounds_min: v.bounds_min,
                bounds_max: v.bounds_max,
                mesh,
            }
        }
    }

    /// Builds the view a host passes across the boundary for these tables.
    pub fn to_view(&self) -> SceneView {
        SceneView {
            camera: self.camera,
            materials: self.materials.as_ptr(),
            material_count: self.materials.len(),
            textures: self.textures.as_ptr(),
            texture_count: self.textures.len(),
            emitters: self.lights.emitters.as_ptr(),
            emitter_count: self.lights.emitters.len(),
            punctual_lights: self.lights.punctual.as_ptr(),
            punctual_count: self.lights.punctual.len(),
            environment: self.lights.environment,
            light_power_cdf: self.lights.power_cdf.as_ptr(),
            bounds_min: self.bounds_min,
            bounds_max: self.bounds_max,
            mesh: mesh_tables(&self.mesh),
        }
    }

    /// The surface data of a compact hit of `ray` (from [`crate::Tracer::intersect_batch`]):
    /// exactly the `SurfaceHit` the host's single-ray `intersect` returns for that ray.
    #[inline]
    pub fn surface(&self, ray: &Ray, hit: &CompactHit) -> SurfaceHit {
        self.mesh.surface_hit(ray, hit)
    }

    #[inline]
    pub fn material(&self, hit: &SurfaceHit) -> &'a Material {
        &self.materials[hit.material as usize]
    }

    /// The material at a hit with its textures and vertex colour applied.
    #[inline]
    pub fn resolve(&self, hit: &SurfaceHit) -> ResolvedMaterial {
        self.material(hit)
            .resolve(hit.uvs(), hit.color, self.textures)
    }

    /// The BSDF at a hit (textures and vertex colour applied; the hit's shading normal is
    /// already normal-mapped by the host).
    #[inline]
    pub fn bsdf(&self, hit: &SurfaceHit) -> Bsdf {
        let r = self.resolve(hit);
        Bsdf::from_material(&r.material, r.base)
    }

    /// Radius of the scene's bounding sphere.
    pub fn radius(&self) -> f32 {
        (self.bounds_max - self.bounds_min).length() * 0.5
    }
}

/// The raw tables of a mesh view (what a host puts in its [`SceneView`]).
pub fn mesh_tables(m: &MeshView) -> MeshTables {
    MeshTables {
        positions: m.positions.as_ptr(),
        normals: m.normals.as_ptr(),
        uvs: m.uvs.as_ptr(),
        vertex_count: m.positions.len(),
        uvs1: m.uvs1.as_ptr(),
        uvs1_count: m.uvs1.len(),
        colors: m.colors.as_ptr(),
        colors_count: m.colors.len(),
        tangents: m.tangents.as_ptr(),
        tangents_count: m.tangents.len(),
        triangles: m.triangles.as_ptr(),
        triangle_material: m.triangle_material.as_ptr(),
        triangle_emitter: m.triangle_emitter.as_ptr(),
        triangle_count: m.triangles.len(),
        instances: m.instances.as_ptr(),
        instance_count: m.instances.len(),
    }
}
