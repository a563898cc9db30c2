//! Plugin-side view of the scene: safe slices over the host's tables.

use crate::abi::{MeshTables, SceneView};
use flowlight_core::bsdf::Bsdf;
use flowlight_core::camera::Camera;
use flowlight_core::geometry::{Ray, SurfaceHit};
use flowlight_core::light::{Emitter, Lights, PunctualLight};
use flowlight_core::material::{Material, ResolvedMaterial, Texture};
use flowlight_core::material_layers::MaterialLayers;
use flowlight_core::mesh::{CompactHit, MeshView};
use glam::{Vec2, Vec3};
use std::borrow::Cow;

pub use flowlight_core::mesh::{
    SURFACE_PREFETCH_MIN_TRIANGLES, SURFACE_PREFETCH_TRIANGLES, SURFACE_PREFETCH_VERTICES,
};

/// The scene as plugins see it. Borrowed from the host for the plugin instance's lifetime.
#[derive(Clone, Copy)]
pub struct Scene<'a> {
    /// The camera, with the image size it renders.
    pub camera: Camera,
    /// The materials (a hit's `material` indexes them).
    pub materials: &'a [Material],
    /// The textures the materials sample.
    pub textures: &'a [Texture],
    /// Every light: emitters, punctual lights and the environment, with their power CDF.
    pub lights: Lights<'a>,
    /// Lower corner of the scene's bounding box (world space).
    pub bounds_min: Vec3,
    /// Upper corner of the scene's bounding box (world space).
    pub bounds_max: Vec3,
    /// The vertex and triangle buffers: [`Scene::surface`] builds surface data from the
    /// compact hits of batched queries. Empty in scenes built by hand for shading tests.
    pub mesh: MeshView<'a>,
    /// Per material, its BSDF when no texture enters it ([`constant_bsdfs`]): [`Scene::bsdf`]
    /// copies it instead of building the same lobes at every hit. Empty (every BSDF built per
    /// hit) until the plugin glue attaches the table it owns; the result is the same bit for
    /// bit either way.
    pub material_bsdfs: &'a [Option<Bsdf>],
    /// A sphere (centre, radius) holding every point an area light can be sampled at, where
    /// every light is an area emitter ([`light_bound`]); `None` where a punctual light or an
    /// environment can light a point from any side, and in scenes built by hand.
    /// [`Scene::lights_behind`] reads it.
    pub light_bound: Option<(Vec3, f32)>,
}

/// The sphere of [`Scene::light_bound`] for these lights: the emitters' vertices' bounding
/// box's centre and the largest distance from it to a vertex, widened past the rounding of
/// a sampled point (a barycentric combination of the vertices). `None` without emitters or
/// with a punctual light or an environment.
pub fn light_bound(lights: &Lights) -> Option<(Vec3, f32)> {
    if lights.emitters.is_empty() || !lights.punctual.is_empty() || lights.environment.is_present()
    {
        return None;
    }
    let points = || lights.emitters.iter().flat_map(|e| [e.p0, e.p1, e.p2]);
    let (lo, hi) = points().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
        (lo.min(p), hi.max(p))
    });
    let centre = (lo + hi) * 0.5;
    let radius = points().map(|p| p.distance(centre)).fold(0.0f32, f32::max);
    let scale = lo.abs().max(hi.abs()).max_element();
    let radius = radius * (1.0 + 1e-4) + 16.0 * f32::EPSILON * scale;
    (centre.is_finite() && radius.is_finite()).then_some((centre, radius))
}

/// The BSDF of each material whose BSDF is the same at every hit without vertex colour: one
/// that samples none of the textures [`Material::resolve`] reads for the BSDF (base colour,
/// metallic-roughness, transmission, specular, specular colour, clearcoat and its roughness;
/// emission and normal maps do not enter the BSDF). `None` for the others.
pub fn constant_bsdfs(materials: &[Material], textures: &[Texture]) -> Box<[Option<Bsdf>]> {
    materials
        .iter()
        .map(|m| {
            let textured = [
                &m.base_color_texture,
                &m.metallic_roughness_texture,
                &m.transmission_texture,
                &m.specular_texture,
                &m.specular_color_texture,
                &m.clearcoat_texture,
                &m.clearcoat_roughness_texture,
            ]
            .into_iter()
            .chain(m.layers.textures())
            .any(|t| t.texture(textures).is_some())
                // An anisotropic lobe is oriented by the hit's tangent.
                || m.layers.anisotropy_strength > 0.0;
            (!textured).then(|| {
                let r = m.resolve([Vec2::ZERO; 2], [1.0; 4], textures);
                Bsdf::from_material(&r.material, r.base)
            })
        })
        .collect()
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
                normals: slice(m.normals, m.normals_count),
                uvs: slice(m.uvs, m.uvs_count),
                uvs1: slice(m.uvs1, m.uvs1_count),
                colors: slice(m.colors, m.colors_count),
                tangents: slice(m.tangents, m.tangents_count),
                triangles: slice(m.triangles, m.triangle_count),
                triangle_material: slice(m.triangle_material, m.triangle_count),
                triangle_emitter: slice(m.triangle_emitter, m.triangle_count),
                instances: slice(m.instances, m.instance_count),
                materials,
                textures,
                stored_ids: false,
            }
            .with_stored_ids_checked();
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
                material_bsdfs: &[],
                light_bound: None,
            }
            .with_light_bound()
        }
    }

    /// This scene with [`Scene::light_bound`] computed from its lights (one pass over the
    /// emitters).
    pub fn with_light_bound(mut self) -> Self {
        self.light_bound = light_bound(&self.lights);
        self
    }

    /// True where no light sample can reach the side of the surface at `p` that the outgoing
    /// direction is on (`wo_z`, its cosine with the shading normal `ns`): every light is an
    /// area emitter inside [`Scene::light_bound`] and that sphere lies wholly on the other side
    /// of the plane through `p`, by a margin far above the rounding of a connection's
    /// direction. Then every connection from `p` has ω_o and ω_i on two sides, where a BSDF
    /// that only reflects is zero ([`flowlight_core::bsdf::Bsdf::is_zero_between`]): a
    /// sampler can skip the light sample (drawing its numbers all the same) and lose nothing.
    /// False where `wo_z` is 0 or NaN, or without a bound.
    #[inline]
    pub fn lights_behind(&self, p: Vec3, ns: Vec3, wo_z: f32) -> bool {
        let Some((centre, radius)) = self.light_bound else {
            return false;
        };
        let side = if wo_z > 0.0 {
            1.0
        } else if wo_z < 0.0 {
            -1.0
        } else {
            return false;
        };
        let to_centre = centre - p;
        // A thousandth of the distance (|x| ≤ 2 max |xᵢ|) plus the rounding of p and of a
        // sampled point's coordinates.
        let margin = 1e-3 * (2.0 * to_centre.abs().max_element() + radius)
            + 16.0 * f32::EPSILON * (p.abs().max_element() + centre.abs().max_element() + radius);
        side * to_centre.dot(ns) + radius < -margin
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

    /// Cache hints for a loop that calls [`Scene::surface`] on `hits[k]` at its step `k`:
    /// call it at each step before that call ([`MeshView::prefetch_surfaces`], which says
    /// how far ahead it asks and for which meshes). Changes no result.
    #[inline]
    pub fn prefetch_surfaces(&self, hits: &[CompactHit], k: usize) {
        self.mesh.prefetch_surfaces(hits, k);
    }

    /// The material of a hit, its textures not applied.
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

    /// The table's BSDF of `material` (from [`constant_bsdfs`]) where it is the BSDF at a
    /// point of vertex colour `color`: the material has an entry and the colour is white.
    #[inline]
    pub fn constant_bsdf(&self, material: u32, color: [f32; 4]) -> Option<&'a Bsdf> {
        if color != [1.0; 4] {
            return None;
        }
        self.material_bsdfs.get(material as usize)?.as_ref()
    }

    /// Builds [`constant_bsdfs`] for this scene and points [`Scene::material_bsdfs`] at it.
    ///
    /// # Safety
    /// The returned table must outlive every copy of this scene (the plugin glue keeps it in
    /// the instance, dropped after the integrator or mutation that holds the scene). Moving
    /// the box does not move the slice.
    pub unsafe fn attach_constant_bsdfs(&mut self) -> Box<[Option<Bsdf>]> {
        let table = constant_bsdfs(self.materials, self.textures);
        // SAFETY: the caller keeps `table` alive for as long as the scene (above).
        self.material_bsdfs = unsafe { &*(&*table as *const [Option<Bsdf>]) };
        table
    }

    /// The BSDF at a hit (textures and vertex colour applied; the hit's shading normal is
    /// already normal-mapped by the host): borrowed from the scene's table where the
    /// material's BSDF is the same at every point, built otherwise. Borrowing saves a copy of
    /// the `Bsdf` per vertex (936 bytes since it holds five glTF lobes; at 456 bytes the copy
    /// was 2.4% of a Cornell box render: `memmove` under the tracer's vertex, perf).
    #[inline]
    pub fn bsdf(&self, hit: &SurfaceHit) -> Cow<'a, Bsdf> {
        if let Some(b) = self.constant_bsdf(hit.material, hit.color) {
            return Cow::Borrowed(b);
        }
        let mut r = self.resolve(hit);
        self.orient_layers(&mut r.material.layers, hit.prim, hit.p, hit.ns);
        Cow::Owned(Bsdf::from_material(&r.material, r.base))
    }

    /// [`MaterialLayers::orient_anisotropy`] over this scene's mesh: the anisotropy direction
    /// from the tangent frame at `p` of triangle `prim` onto the BSDF's local frame.
    #[inline]
    pub fn orient_layers(&self, layers: &mut MaterialLayers, prim: u32, p: Vec3, ns: Vec3) {
        layers.orient_anisotropy(&self.mesh, prim, p, ns);
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
        vertex_count: m.positions.len(),
        normals: m.normals.as_ptr(),
        normals_count: m.normals.len(),
        uvs: m.uvs.as_ptr(),
        uvs_count: m.uvs.len(),
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

#[cfg(test)]
mod tests {
    use super::*;
    use flowlight_core::geometry::Frame;
    use flowlight_core::light::Environment;
    use flowlight_core::material::{TexelFormat, TextureRef, Wrap};
    use flowlight_core::rng::Rng;
    use flowlight_core::sampling::uniform_sphere;
    use flowlight_core::Rgb;

    fn emitter(p0: Vec3, p1: Vec3, p2: Vec3) -> Emitter {
        let n = (p1 - p0).cross(p2 - p0);
        Emitter {
            p0,
            p1,
            p2,
            n: n.normalize(),
            area: 0.5 * n.length(),
            radiance: Rgb::ONE,
            double_sided: 1,
            prim: 0,
            material: u32::MAX,
            uv0: [Vec2::ZERO; 3],
            uv1: [Vec2::ZERO; 3],
            color: [Rgb::ONE; 3],
            vertex_colored: 0,
        }
    }

    /// Where `lights_behind` says every light is behind, every sampled light point is
    /// strictly on the other side of the shading plane from ω_o, as the connection computes
    /// it (its direction in the shading frame), so a reflection-only BSDF is zero there: at
    /// random points, normals and sides around a small lamp and a large one far from the
    /// origin. It says so often, and never with ω_o in the plane, for a lamp in front, or
    /// with a punctual light or an environment in the scene.
    #[test]
    fn lights_behind_means_every_light_point_is_across_the_surface() {
        let mut r = Rng::new(3, 0);
        for (offset, size) in [(Vec3::ZERO, 0.2), (Vec3::new(3000.0, -500.0, 40.0), 50.0)] {
            let es = [
                emitter(offset, offset + Vec3::X * size, offset + Vec3::Z * size),
                emitter(
                    offset + Vec3::X * size,
                    offset + Vec3::new(size, 0.0, size),
                    offset + Vec3::Z * size,
                ),
            ];
            let cdf = [0.5, 1.0];
            let lights = Lights::area_only(&es, &cdf);
            let bound = light_bound(&lights).unwrap();
            let scene = Scene {
                camera: Camera::look_along(Vec3::Z, -Vec3::Z, Vec3::Y, 60.0, 4, 4),
                materials: &[],
                textures: &[],
                lights,
                bounds_min: Vec3::ZERO,
                bounds_max: Vec3::ONE,
                mesh: MeshView::default(),
                material_bsdfs: &[],
                light_bound: Some(bound),
            };
            let (mut behind, mut checked) = (0, 0);
            for _ in 0..20_000 {
                let p = offset + uniform_sphere(r.uniform2()) * (size * 4.0 * r.uniform());
                let ns = uniform_sphere(r.uniform2());
                let wo_z = r.uniform() - 0.5;
                if !scene.lights_behind(p, ns, wo_z) {
                    continue;
                }
                behind += 1;
                let frame = flowlight_core::geometry::Frame::from_z(ns);
                for _ in 0..20 {
                    let ls = scene.lights.sample(r.uniform(), r.uniform2()).unwrap();
                    let inc = scene.lights.incident(&ls, p);
                    let Some(inc) = inc else { continue };
                    let wi_z = frame.to_local(inc.wi).z;
                    assert!(wo_z * wi_z < 0.0, "p {p:?} ns {ns:?} wo {wo_z}: wi {wi_z}");
                    checked += 1;
                }
            }
            assert!(behind > 2000 && checked > 10_000, "{behind} {checked}");
            // ω_o in the plane, or NaN: not decided by the sides.
            let below = offset - Vec3::Y * size;
            assert!(scene.lights_behind(below, -Vec3::Y, 0.5));
            assert!(!scene.lights_behind(below, -Vec3::Y, -0.5));
            assert!(!scene.lights_behind(below, -Vec3::Y, 0.0));
            assert!(!scene.lights_behind(below, -Vec3::Y, f32::NAN));
            // A lamp in the plane of the point is not behind it.
            assert!(!scene.lights_behind(offset - Vec3::X * size, Vec3::Y, 0.5));
        }
        let es = [emitter(Vec3::ZERO, Vec3::X, Vec3::Z)];
        let point = [PunctualLight::point(Vec3::Y, Rgb::ONE)];
        let mut lights = Lights::area_only(&es, &[0.5, 1.0]);
        lights.punctual = &point;
        assert_eq!(light_bound(&lights), None);
        let mut lights = Lights::area_only(&es, &[0.5, 1.0]);
        lights.environment = Environment::constant(Rgb::ONE);
        assert_eq!(light_bound(&lights), None);
        assert_eq!(light_bound(&Lights::area_only(&[], &[])), None);
    }

    /// The cached BSDF of an untextured material is the per-hit BSDF bit for bit (values,
    /// densities and samples over random directions); a material with a texture that enters the
    /// BSDF has no cached one.
    #[test]
    fn constant_bsdfs_equal_the_per_hit_bsdfs() {
        let texel = [200u8, 100, 50, 255];
        let textures = [Texture {
            width: 1,
            height: 1,
            channels: 4,
            format: TexelFormat::U8,
            wrap_s: Wrap::Repeat,
            wrap_t: Wrap::Repeat,
            filter: flowlight_core::material::Filter::Nearest,
            texels: texel.as_ptr(),
        }];
        let tex = TextureRef {
            index: 0,
            ..TextureRef::NONE
        };
        let mut materials = vec![Material::default()];
        for (metallic, roughness, transmission, clearcoat) in [
            (0.0, 1.0, 0.0, 0.0),
            (1.0, 0.3, 0.0, 0.0),
            (0.0, 0.0, 1.0, 0.0),
            (0.2, 0.5, 0.3, 0.7),
        ] {
            materials.push(Material {
                base_color: Rgb::new(0.7, 0.4, 0.2),
                metallic,
                roughness,
                transmission,
                thickness: transmission,
                clearcoat,
                clearcoat_roughness: 0.2,
                ..Material::default()
            });
        }
        let textured = [
            Material {
                base_color_texture: tex,
                ..Material::default()
            },
            Material {
                metallic_roughness_texture: tex,
                ..Material::default()
            },
            Material {
                clearcoat_roughness_texture: tex,
                ..Material::default()
            },
        ];
        let plain = materials.len();
        materials.extend(textured);
        let table = constant_bsdfs(&materials, &textures);
        assert!(table[plain..].iter().all(Option::is_none));
        let mut rng = Rng::new(5, 0);
        for (m, cached) in materials.iter().zip(&table[..plain]) {
            let cached = cached.expect("an untextured material has a constant BSDF");
            let r = m.resolve([Vec2::ZERO; 2], [1.0; 4], &textures);
            let built = Bsdf::from_material(&r.material, r.base);
            for _ in 0..200 {
                let dir = |rng: &mut Rng| {
                    let u = rng.uniform2();
                    let z = 1.0 - 2.0 * u.x;
                    let r = (1.0 - z * z).max(0.0).sqrt();
                    let phi = std::f32::consts::TAU * u.y;
                    Vec3::new(r * phi.cos(), r * phi.sin(), z)
                };
                let (wo, wi) = (dir(&mut rng), dir(&mut rng));
                assert_eq!(cached.eval(wo, wi), built.eval(wo, wi));
                assert_eq!(cached.pdf(wo, wi).to_bits(), built.pdf(wo, wi).to_bits());
                let (uc, u) = (rng.uniform(), rng.uniform2());
                let (a, b) = (cached.sample(wo, uc, u), built.sample(wo, uc, u));
                assert_eq!(a.map(|s| (s.wi, s.f, s.pdf)), b.map(|s| (s.wi, s.f, s.pdf)));
            }
            assert_eq!(cached.albedo().to_bits(), built.albedo().to_bits());
        }
    }

    /// An anisotropic material's direction, given in the tangent frame, comes out in the
    /// BSDF's local frame `Frame::from_z(n_s)`: along the vertex tangent for (1, 0), along the
    /// bitangent for (0, 1); an isotropic material's layers are left as they are.
    #[test]
    fn orient_layers_projects_the_tangent_direction_onto_the_shading_frame() {
        let positions = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let normals = [Vec3::Z; 3];
        let tangents = [[0.6, 0.8, 0.0, 1.0]; 3];
        let scene = Scene {
            camera: Camera::look_along(Vec3::Z, -Vec3::Z, Vec3::Y, 60.0, 4, 4),
            materials: &[],
            textures: &[],
            lights: Lights::area_only(&[], &[]),
            bounds_min: Vec3::ZERO,
            bounds_max: Vec3::ONE,
            mesh: MeshView {
                positions: &positions,
                normals: &normals,
                tangents: &tangents,
                triangles: &[[0, 1, 2]],
                triangle_material: &[0],
                triangle_emitter: &[-1],
                ..MeshView::default()
            },
            material_bsdfs: &[],
            light_bound: None,
        };
        let p = Vec3::new(0.2, 0.3, 0.0);
        let frame = Frame::from_z(Vec3::Z);
        let t = Vec3::new(0.6, 0.8, 0.0);
        for (dir, want) in [([1.0, 0.0], t), ([0.0, 1.0], Vec3::Z.cross(t))] {
            let mut l = MaterialLayers {
                anisotropy_strength: 0.5,
                anisotropy_direction: dir,
                ..MaterialLayers::default()
            };
            scene.orient_layers(&mut l, 0, p, Vec3::Z);
            let [x, y] = l.anisotropy_direction;
            let got = frame.to_world(Vec3::new(x, y, 0.0));
            assert!((got - want).length() < 1e-5, "{dir:?}: {got} vs {want}");
        }
        let mut iso = MaterialLayers::default();
        scene.orient_layers(&mut iso, 0, p, Vec3::Z);
        assert_eq!(iso, MaterialLayers::default());
    }
}
