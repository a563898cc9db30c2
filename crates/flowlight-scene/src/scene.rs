//! The loaded scene: triangle soup with per-triangle materials, the texture table, the
//! emitter table, the camera found in the file, and the mesh instances that place it.
//!
//! **Instancing.** A glTF mesh placed once is stored in world space; every such mesh together
//! is one *identity instance* (an ordinary scene has only that one and takes the single-level
//! path everywhere). A mesh placed several times (several nodes, or `EXT_mesh_gpu_instancing`)
//! is stored once, in its local space, and each placement is a [`MeshInstance`] with its
//! object-to-world matrix M. Ray queries and the plugin boundary see *virtual triangle ids*:
//! instance `i` shows triangles `first_virtual .. first_virtual + triangle_count`, virtual id
//! `v` is local triangle `v − first_virtual` of the instance's triangle range
//! ([`Scene::locate`]: a binary search over the instances, none for a scene with one). A
//! scene with only the identity instance has virtual id = stored triangle index, as before.
//!
//! A hit on an instance is rebuilt in world space from the stored vertices transformed as
//! the loader would have flattened them (`p = M p_obj`, normals by N = (M₃ₓ₃⁻¹)ᵀ and
//! renormalised, tangents by M₃ₓ₃ and renormalised, winding and barycentrics 1 ↔ 2 swapped
//! when det M < 0, tangent handedness flipped), so it is bit for bit the hit the flattened
//! triangle gives at the same barycentrics. Its position error adds the rounding of the two
//! transforms between object and world space (pbrt-v4 §6.8.3, "Transformations"):
//! per component, γ₃(|M|·|p_obj| + |t|) for p = M p_obj, and |M|·γ₃(|M⁻¹|·|p| + |M⁻¹t|)
//! for the intersector taking the ray into object space, |M| the element-wise absolute values.

use crate::texture::TextureData;
use flowlight_core::geometry::{Ray, SurfaceHit};
use flowlight_core::light::{Emitter, PunctualLight};
use flowlight_core::material::{AlphaMode, Material, Texture};
/// The placement types and the surface-hit helpers live in `flowlight-core` (plugins build
/// surface data from compact hits with the same code).
pub use flowlight_core::mesh::{
    bend_towards_viewer, lift_above, triangle_normal, MeshInstance, MeshRange,
};
use flowlight_core::mesh::{CompactHit, MeshView};
use glam::{DVec3, Vec2, Vec3};

/// How a glTF camera projects.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CameraProjection {
    /// `perspective.yfov`, in degrees.
    Perspective { fov_y_degrees: f32 },
    /// `orthographic.ymag`: half the height of the view in world units.
    Orthographic { half_height: f32 },
}

/// A named node of the default scene and where its world transform puts its origin: what
/// `[camera] focus_on` looks up.
#[derive(Clone, Debug, PartialEq)]
pub struct NamedNode {
    pub name: String,
    /// Index into the file's `nodes`.
    pub node: usize,
    pub position: Vec3,
}

/// A camera node found in the glTF file: a node that references one of its `cameras`.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraDesc {
    /// Index into the file's `cameras` array (what `[camera] index` selects).
    pub index: usize,
    /// The camera's `name`, if it has one.
    pub name: Option<String>,
    /// Index of the node that places it.
    pub node: usize,
    /// That node's `name`, if it has one.
    pub node_name: Option<String>,
    pub position: Vec3,
    /// Unit viewing direction (the camera node's local −Z in world space).
    pub forward: Vec3,
    /// Unit up vector (the camera node's local +Y in world space).
    pub up: Vec3,
    pub projection: CameraProjection,
    /// The aspect ratio the file asks for: `aspectRatio` (perspective, optional) or
    /// `xmag / ymag` (orthographic). The render config's image size wins.
    pub aspect: Option<f32>,
}

impl CameraDesc {
    /// `0 "Main" (node 3 "CameraNode")`: how errors and logs name this camera.
    pub fn label(&self) -> String {
        let quoted =
            |n: &Option<String>| n.as_ref().map(|n| format!(" \"{n}\"")).unwrap_or_default();
        format!(
            "{}{} (node {}{}, {})",
            self.index,
            quoted(&self.name),
            self.node,
            quoted(&self.node_name),
            match self.projection {
                CameraProjection::Perspective { .. } => "perspective",
                CameraProjection::Orthographic { .. } => "orthographic",
            }
        )
    }
}

/// What the loader saw and dropped.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LoadStats {
    /// Triangles kept (= `Scene::triangles.len()`).
    pub triangles: usize,
    /// Vertices kept (= `Scene::positions.len()`).
    pub vertices: usize,
    /// Triangles dropped in total (sum of the three reasons below).
    pub degenerate_dropped: usize,
    /// ... because their area is zero (collinear or coincident vertices, or too small for f32).
    pub dropped_zero_area: usize,
    /// ... because a vertex is NaN or infinite.
    pub dropped_non_finite: usize,
    /// ... because two of their indices are equal.
    pub dropped_repeated_index: usize,
    /// Emissive triangles dropped with the degenerate ones (zero-area lights).
    pub dropped_emitters: usize,
    /// Primitives skipped because their mode is points or lines.
    pub skipped_primitives: usize,
    /// Primitives skipped because they have no POSITION attribute.
    pub skipped_no_position: usize,
    /// Triangle strips and fans converted to triangle lists.
    pub converted_strips_fans: usize,
    /// Primitives without normals, given flat per-face normals.
    pub flat_shaded_primitives: usize,
    /// Mesh instances (nodes with a mesh) loaded.
    pub mesh_instances: usize,
    /// Placements of meshes stored once in local space (a mesh placed by several nodes, or
    /// by `EXT_mesh_gpu_instancing`): the non-identity entries of `Scene::instances`.
    pub instanced_placements: usize,
    /// Triangles the scene shows: every instance's triangles counted per instance (what a
    /// flattened scene would store); = `triangles` without instancing.
    pub virtual_triangles: usize,
    /// Placements skipped because their transform cannot be inverted (a zero scale hides a
    /// node).
    pub singular_placements: usize,
    /// Images decoded (only those used by loaded materials).
    pub images_decoded: usize,
    /// Textures dropped because their image file cannot be read (`[textures] missing =
    /// "warn"`).
    pub textures_dropped: usize,
    /// Triangles whose material has an emissive factor but whose emission integrates to zero
    /// (a black emissive texture there): not lights.
    pub black_emitters: usize,
}

/// A scene ready to render: meshes placed once in world space, meshes placed several times
/// once in local space with their [`MeshInstance`]s (module docs).
///
/// Normals: when a primitive has no NORMAL attribute it is flat shaded (as the glTF spec
/// requires): its vertices stay shared with zero normals, and the surface code takes each
/// triangle's geometric normal instead (a normal-mapped one has its vertices duplicated per
/// triangle, carrying the face normal).
#[derive(Clone, Debug, Default)]
pub struct Scene {
    pub positions: Vec<Vec3>,
    /// Vertex normals (zero where a primitive is flat shaded); empty when no primitive has
    /// any, as in a scan without NORMAL: the surface code then takes the geometric normal.
    pub normals: Vec<Vec3>,
    /// TEXCOORD_0 per vertex (0 where a primitive has none); empty when no primitive has it.
    pub uvs: Vec<Vec2>,
    /// TEXCOORD_1 per vertex; empty when no primitive has a second set.
    pub uvs1: Vec<Vec2>,
    /// COLOR_0 per vertex, linear RGBA; empty when no primitive has vertex colours.
    pub colors: Vec<[f32; 4]>,
    /// Tangents per vertex (xyz unit, w = ±1 handedness: bitangent = w · n × t), from the
    /// TANGENT attribute or MikkTSpace; empty when no primitive has a normal map. Zero
    /// where a primitive has none.
    pub tangents: Vec<[f32; 4]>,
    pub triangles: Vec<[u32; 3]>,
    pub triangle_material: Vec<u32>,
    pub materials: Vec<Material>,
    pub material_names: Vec<String>,
    /// Per material: whether it is unlit (`KHR_materials_unlit`), whose emission takes the
    /// vertex colours (`crate::unlit`). Shorter than `materials` (a scene built by hand):
    /// the rest are not.
    pub unlit_materials: Vec<bool>,
    pub textures: Vec<TextureData>,
    /// Every camera node of the scene, in traversal order (the first is the default camera).
    pub cameras: Vec<CameraDesc>,
    /// Every named node of the default scene, in traversal order.
    pub named_nodes: Vec<NamedNode>,
    /// Views of `textures` (see [`Scene::sync_texture_views`]).
    pub texture_table: Vec<Texture>,
    pub emitters: Vec<Emitter>,
    /// CDF over `Emitter::power()`; empty when there are no emitters.
    pub emitter_power_cdf: Vec<f32>,
    /// Per stored triangle: its emitter's index among its mesh's emitters, or -1; instance i
    /// shows emitter `instances[i].first_emitter + r` there. Without instancing, r is the
    /// index into `emitters`.
    pub triangle_emitter: Vec<i32>,
    /// The stored meshes: `meshes[0]` is every mesh placed once (world space), when there is
    /// one; then each mesh placed several times (local space).
    pub meshes: Vec<MeshRange>,
    /// The placements, sorted by `first_virtual`. Empty (in a scene built by hand) means one
    /// identity instance of all triangles.
    pub instances: Vec<MeshInstance>,
    /// The first virtual triangle of each object, ascending: an object is one placement of a
    /// glTF mesh (a node, or one `EXT_mesh_gpu_instancing` instance), the meshes placed once
    /// first in node traversal order, then each placement of an instanced mesh. Empty in a
    /// scene built by hand (one object). [`Scene::object_of`] reads it.
    pub object_first_virtual: Vec<u32>,
    /// `KHR_lights_punctual` lights of the default scene, placed by their nodes.
    pub punctual_lights: Vec<PunctualLight>,
    pub stats: LoadStats,
    /// The files the scene was read from besides itself (buffers and images named by a
    /// relative URI), for the check that no output overwrites one of them.
    pub files: Vec<std::path::PathBuf>,
}

/// Area of the triangle, in double precision.
pub fn triangle_area(p0: Vec3, p1: Vec3, p2: Vec3) -> f64 {
    let (p0, p1, p2) = (p0.as_dvec3(), p1.as_dvec3(), p2.as_dvec3());
    0.5 * (p1 - p0).cross(p2 - p0).length()
}

impl Scene {
    /// Vertices of each *stored* triangle, for acceleration-structure builds: world space
    /// for the meshes placed once, local space for instanced ones (see [`Scene::meshes`]).
    /// Without instancing, the world-space triangles.
    pub fn triangle_vertices(&self) -> Vec<[Vec3; 3]> {
        self.triangles
            .iter()
            .map(|t| t.map(|i| self.positions[i as usize]))
            .collect()
    }

    /// The object (index into [`Scene::object_first_virtual`]) that virtual triangle `prim`
    /// belongs to: the last object starting at or before it; 0 without the table.
    pub fn object_of(&self, prim: u32) -> u32 {
        (self
            .object_first_virtual
            .partition_point(|&first| first <= prim) as u32)
            .saturating_sub(1)
    }

    /// Number of virtual triangles (every instance's, counted per instance); the number of
    /// stored triangles without instancing.
    pub fn virtual_triangle_count(&self) -> usize {
        self.instances.last().map_or(self.triangles.len(), |i| {
            i.first_virtual as usize + i.triangle_count as usize
        })
    }

    /// Whether some mesh is stored once for several placements (the two-level path).
    pub fn is_instanced(&self) -> bool {
        self.instances.iter().any(|i| !i.identity)
    }

    /// The instance showing virtual triangle `prim` (`None`: the identity) and the index of
    /// the stored triangle ([`MeshView::locate`]).
    #[inline]
    pub fn locate(&self, prim: u32) -> (Option<&MeshInstance>, usize) {
        self.mesh().locate(prim)
    }

    /// The vertex and triangle buffers as borrowed slices: what plugins get in the scene
    /// view (ABI 4) to build surface data from compact hits.
    #[inline]
    pub fn mesh(&self) -> MeshView<'_> {
        MeshView {
            positions: &self.positions,
            normals: &self.normals,
            uvs: &self.uvs,
            uvs1: &self.uvs1,
            colors: &self.colors,
            tangents: &self.tangents,
            triangles: &self.triangles,
            triangle_material: &self.triangle_material,
            triangle_emitter: &self.triangle_emitter,
            instances: &self.instances,
            materials: &self.materials,
            textures: &self.texture_table,
            // Unknown: checking would scan the instances at every call.
            stored_ids: false,
        }
    }

    /// The world-space vertices of virtual triangle `prim`, counter-clockwise from its front
    /// (a mirrored instance's vertices 1 and 2 swapped, as the flattening loader stores them).
    pub fn world_triangle(&self, prim: u32) -> [Vec3; 3] {
        self.mesh().place(prim, u32::MAX).0.p
    }

    /// World-space bounds of the mesh instances' triangles, `(min, max)`; `None` for an empty
    /// scene. An instance contributes the eight corners of its mesh's local box transformed
    /// (a box around its triangles, at most √3 times wider under rotation), so the cost is
    /// per instance, not per instanced vertex.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        let mut grow = |p: Vec3| {
            let p = p.as_dvec3();
            lo = lo.min(p);
            hi = hi.max(p);
        };
        if self.instances.is_empty() {
            for t in &self.triangles {
                for &i in t {
                    grow(self.positions[i as usize]);
                }
            }
        } else {
            // Each mesh's vertices once, then its box's corners per placement.
            let mut mesh_box = vec![None::<(Vec3, Vec3)>; self.meshes.len().max(1)];
            for inst in &self.instances {
                let tris =
                    &self.triangles[inst.first_triangle as usize..][..inst.triangle_count as usize];
                if inst.identity {
                    for t in tris {
                        for &i in t {
                            grow(self.positions[i as usize]);
                        }
                    }
                    continue;
                }
                let b = mesh_box.get_mut(inst.mesh as usize).and_then(|b| {
                    if b.is_none() {
                        let mut l = Vec3::INFINITY;
                        let mut h = Vec3::NEG_INFINITY;
                        for &i in tris.iter().flatten() {
                            l = l.min(self.positions[i as usize]);
                            h = h.max(self.positions[i as usize]);
                        }
                        *b = (!tris.is_empty()).then_some((l, h));
                    }
                    *b
                });
                if let Some((l, h)) = b {
                    for c in 0..8 {
                        let corner = Vec3::new(
                            if c & 1 == 0 { l.x } else { h.x },
                            if c & 2 == 0 { l.y } else { h.y },
                            if c & 4 == 0 { l.z } else { h.z },
                        );
                        grow(inst.object_to_world.transform_point3(corner));
                    }
                }
            }
        }
        lo.x.is_finite().then(|| (lo.as_vec3(), hi.as_vec3()))
    }

    /// Texture views for [`Material::resolve`]; valid while `self` (or a clone: the texel
    /// storage is shared) lives.
    pub fn texture_views(&self) -> Vec<Texture> {
        self.textures.iter().map(TextureData::view).collect()
    }

    /// Rebuilds [`Scene::texture_table`] from `textures`; the loader calls it, and so must
    /// whoever edits `textures` by hand.
    pub fn sync_texture_views(&mut self) {
        self.texture_table = self.texture_views();
    }

    /// Whether any material uses alpha MASK or BLEND, i.e. whether ray queries must test
    /// alpha.
    pub fn has_alpha(&self) -> bool {
        self.materials
            .iter()
            .any(|m| m.alpha_mode != AlphaMode::Opaque)
    }

    /// TEXCOORD_0, TEXCOORD_1 and COLOR_0 of virtual triangle `prim` at barycentrics
    /// `(b1, b2)` (of its stored vertices 1 and 2, as intersectors report them).
    #[inline]
    pub fn attributes(&self, prim: u32, b1: f32, b2: f32) -> ([Vec2; 2], [f32; 4]) {
        let tri = self.triangles[self.locate(prim).1].map(|i| i as usize);
        self.mesh().attributes_of(tri, [1.0 - b1 - b2, b1, b2])
    }

    /// Whether a ray passes through virtual triangle `prim` at barycentrics `(b1, b2)`: alpha
    /// MASK below the cutoff, or alpha BLEND with probability 1 − α. The BLEND decision is a
    /// hash of the ray (origin and direction bits) and the virtual triangle, so a ray query
    /// is deterministic, every intersector answers alike, and each instance decides on its
    /// own.
    pub fn passes_through(&self, ray: &Ray, prim: u32, b1: f32, b2: f32) -> bool {
        let tri = self.locate(prim).1;
        let Some(m) = self
            .triangle_material
            .get(tri)
            .and_then(|&i| self.materials.get(i as usize))
        else {
            return false;
        };
        if m.alpha_mode == AlphaMode::Opaque {
            return false;
        }
        let idx = self.triangles[tri].map(|i| i as usize);
        let (uv, color) = self.mesh().attributes_of(idx, [1.0 - b1 - b2, b1, b2]);
        let alpha = m.alpha_at(uv, color, &self.texture_table);
        match m.alpha_mode {
            AlphaMode::Opaque => false,
            AlphaMode::Mask => alpha < m.alpha_cutoff,
            AlphaMode::Blend => blend_hash(ray, prim) >= alpha,
        }
    }

    /// The hit record for virtual triangle `prim` hit by `ray` at parameter `t` with
    /// barycentrics `(b1, b2)` of its stored vertices 1 and 2 (vertex 0 has `1 − b1 − b2`):
    /// [`MeshView::surface_hit`], the code plugins run on compact hits too.
    ///
    /// `p` is interpolated from the (world-space) vertices (not `ray.at(t)`), so its error
    /// bound is the barycentric one, plus the instance transform's (module docs). `ns` is
    /// the normalised interpolated normal, perturbed by the material's normal map when it
    /// has one (see [`Scene::normal_mapped`]), flipped onto `ng`'s side; it falls back to
    /// `ng` where the interpolation vanishes.
    pub fn surface_hit(&self, ray: &Ray, t: f32, prim: u32, b1: f32, b2: f32) -> SurfaceHit {
        let hit = CompactHit {
            t,
            prim,
            b1,
            b2,
            instance: u32::MAX,
        };
        self.mesh().surface_hit(ray, &hit)
    }

    /// The shading normal of virtual triangle `prim` perturbed by its normal map:
    /// [`MeshView::normal_mapped`].
    pub fn normal_mapped(&self, prim: u32, b: [f32; 3], n: Vec3, uv: [Vec2; 2]) -> Option<Vec3> {
        self.mesh().normal_mapped(prim, b, n, uv)
    }
}

/// A uniform number in [0, 1) from the bits of `ray` and `prim` (splitmix64 finaliser over
/// a running mix), for stochastic transparency.
pub fn blend_hash(ray: &Ray, prim: u32) -> f32 {
    let mix = |mut z: u64| {
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    };
    let mut h = 0x9e37_79b9_7f4a_7c15u64 ^ prim as u64;
    for v in [
        ray.origin.x,
        ray.origin.y,
        ray.origin.z,
        ray.dir.x,
        ray.dir.y,
        ray.dir.z,
    ] {
        h = mix(h ^ v.to_bits() as u64).wrapping_add(0x9e37_79b9_7f4a_7c15);
    }
    (mix(h) >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
}
