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
use flowlight_core::geometry::{barycentric_error, gamma, Ray, SurfaceHit};
use flowlight_core::light::{Emitter, PunctualLight};
use flowlight_core::material::{AlphaMode, Material, Texture};
use glam::{DVec3, Mat3, Mat4, Vec2, Vec3, Vec4};

/// How a glTF camera projects.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CameraProjection {
    /// `perspective.yfov`, in degrees.
    Perspective { fov_y_degrees: f32 },
    /// `orthographic.ymag`: half the height of the view in world units.
    Orthographic { half_height: f32 },
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
    /// Triangles whose material has an emissive factor but whose emission integrates to zero
    /// (a black emissive texture there): not lights.
    pub black_emitters: usize,
}

/// One placement of a range of stored triangles (module docs, "Instancing").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshInstance {
    /// Index into [`Scene::meshes`].
    pub mesh: u32,
    /// The mesh's stored triangles: `first_triangle .. first_triangle + triangle_count`.
    pub first_triangle: u32,
    pub triangle_count: u32,
    /// Virtual id of the instance's first triangle.
    pub first_virtual: u32,
    /// Index into [`Scene::emitters`] of this instance's emitters: a triangle whose
    /// `triangle_emitter` is r ≥ 0 is emitter `first_emitter + r`.
    pub first_emitter: u32,
    pub object_to_world: Mat4,
    pub world_to_object: Mat4,
    /// (M₃ₓ₃⁻¹)ᵀ: transforms normals.
    pub normal_matrix: Mat3,
    /// det M < 0: the winding and the tangent handedness flip.
    pub mirror: bool,
    /// The identity: the stored triangles are in world space (the meshes placed once).
    pub identity: bool,
}

impl MeshInstance {
    /// The identity placement of `mesh`.
    pub fn identity(mesh: u32, range: MeshRange, first_virtual: u32, first_emitter: u32) -> Self {
        MeshInstance {
            mesh,
            first_triangle: range.first_triangle,
            triangle_count: range.triangle_count,
            first_virtual,
            first_emitter,
            object_to_world: Mat4::IDENTITY,
            world_to_object: Mat4::IDENTITY,
            normal_matrix: Mat3::IDENTITY,
            mirror: false,
            identity: true,
        }
    }

    /// The placement of `mesh` by the affine `object_to_world`; `None` when it is not
    /// invertible or not finite.
    pub fn placed(
        mesh: u32,
        range: MeshRange,
        object_to_world: Mat4,
        first_virtual: u32,
        first_emitter: u32,
    ) -> Option<Self> {
        let linear = Mat3::from_mat4(object_to_world);
        let det = linear.determinant();
        if !(det.is_finite() && det != 0.0 && object_to_world.is_finite()) {
            return None;
        }
        let world_to_object = object_to_world.inverse();
        let normal_matrix = linear.inverse().transpose();
        (world_to_object.is_finite() && normal_matrix.is_finite()).then_some(MeshInstance {
            mesh,
            first_triangle: range.first_triangle,
            triangle_count: range.triangle_count,
            first_virtual,
            first_emitter,
            object_to_world,
            world_to_object,
            normal_matrix,
            mirror: det < 0.0,
            identity: false,
        })
    }
}

/// A range of stored triangles and vertices: one glTF mesh stored in local space, or all
/// meshes placed once (in world space).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MeshRange {
    pub first_triangle: u32,
    pub triangle_count: u32,
}

/// A stored triangle placed in world space, as the flattening loader would have stored it.
#[derive(Clone, Copy, Debug)]
struct Placed {
    /// Stored vertex indices, in world winding order (1 and 2 swapped under a mirror).
    idx: [usize; 3],
    p: [Vec3; 3],
    /// Extra position error of the object ↔ world transforms, per vertex (zero for the
    /// identity).
    p_error: [Vec3; 3],
    /// Whether barycentrics 1 and 2 swap.
    swap: bool,
    instance: Option<MeshInstance>,
}

/// A scene ready to render: meshes placed once in world space, meshes placed several times
/// once in local space with their [`MeshInstance`]s (module docs).
///
/// Normals: when a primitive has no NORMAL attribute, it gets flat per-face normals (as the
/// glTF spec requires), by duplicating its vertices per triangle.
#[derive(Clone, Debug, Default)]
pub struct Scene {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    /// TEXCOORD_0 per vertex (0 where a primitive has none).
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
    pub textures: Vec<TextureData>,
    /// Every camera node of the scene, in traversal order (the first is the default camera).
    pub cameras: Vec<CameraDesc>,
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
    /// `KHR_lights_punctual` lights of the default scene, placed by their nodes.
    pub punctual_lights: Vec<PunctualLight>,
    pub stats: LoadStats,
}

/// Unit normal of the triangle from its winding, computed so that neither tiny nor large
/// coordinates underflow or overflow: the edges are scaled by their largest component first.
/// `None` for a degenerate triangle.
pub fn triangle_normal(p0: Vec3, p1: Vec3, p2: Vec3) -> Option<Vec3> {
    let e1 = p1 - p0;
    let e2 = p2 - p0;
    let s = e1.abs().max_element().max(e2.abs().max_element());
    if !(s > 0.0 && s.is_finite()) {
        return None;
    }
    let c = (e1 / s).cross(e2 / s);
    let len = c.length();
    (len > 0.0 && len.is_finite()).then(|| c / len)
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
    /// the stored triangle.
    #[inline]
    pub fn locate(&self, prim: u32) -> (Option<&MeshInstance>, usize) {
        let inst = match self.instances.len() {
            0 => return (None, prim as usize),
            1 => &self.instances[0],
            _ => {
                let k = self
                    .instances
                    .partition_point(|i| i.first_virtual <= prim)
                    .saturating_sub(1);
                &self.instances[k]
            }
        };
        let tri = inst.first_triangle as usize + prim.saturating_sub(inst.first_virtual) as usize;
        (Some(inst).filter(|i| !i.identity), tri)
    }

    /// The world-space vertices of virtual triangle `prim`, counter-clockwise from its front
    /// (a mirrored instance's vertices 1 and 2 swapped, as the flattening loader stores them).
    pub fn world_triangle(&self, prim: u32) -> [Vec3; 3] {
        self.place(prim).0.p
    }

    /// Virtual triangle `prim` placed in world space, and its stored triangle index.
    #[inline]
    fn place(&self, prim: u32) -> (Placed, usize) {
        let (inst, tri) = self.locate(prim);
        let idx = self.triangles[tri].map(|i| i as usize);
        let placed = match inst {
            None => Placed {
                idx,
                p: idx.map(|i| self.positions[i]),
                p_error: [Vec3::ZERO; 3],
                swap: false,
                instance: None,
            },
            Some(m) => {
                let idx = if m.mirror {
                    [idx[0], idx[2], idx[1]]
                } else {
                    idx
                };
                let local = idx.map(|i| self.positions[i]);
                let p = local.map(|q| m.object_to_world.transform_point3(q));
                Placed {
                    idx,
                    p,
                    p_error: [0, 1, 2].map(|k| transform_error(m, local[k], p[k])),
                    swap: m.mirror,
                    instance: Some(*m),
                }
            }
        };
        (placed, tri)
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

    /// Barycentric interpolation of per-vertex `values` over triangle `tri`.
    #[inline]
    fn lerp<T>(values: &[T], tri: [usize; 3], b: [f32; 3]) -> Option<T>
    where
        T: Copy + std::ops::Mul<f32, Output = T> + std::ops::Add<Output = T>,
    {
        let [i0, i1, i2] = tri;
        Some(*values.get(i0)? * b[0] + *values.get(i1)? * b[1] + *values.get(i2)? * b[2])
    }

    /// TEXCOORD_0, TEXCOORD_1 and COLOR_0 of virtual triangle `prim` at barycentrics
    /// `(b1, b2)` (of its stored vertices 1 and 2, as intersectors report them).
    #[inline]
    pub fn attributes(&self, prim: u32, b1: f32, b2: f32) -> ([Vec2; 2], [f32; 4]) {
        let tri = self.triangles[self.locate(prim).1].map(|i| i as usize);
        self.attributes_of(tri, [1.0 - b1 - b2, b1, b2])
    }

    #[inline]
    fn attributes_of(&self, tri: [usize; 3], b: [f32; 3]) -> ([Vec2; 2], [f32; 4]) {
        let uv0 = Self::lerp(&self.uvs, tri, b).unwrap_or(Vec2::ZERO);
        let uv1 = Self::lerp(&self.uvs1, tri, b).unwrap_or(Vec2::ZERO);
        let color = if self.colors.is_empty() {
            [1.0; 4]
        } else {
            let [c0, c1, c2] = tri.map(|i| Vec4::from_array(self.colors[i]));
            (c0 * b[0] + c1 * b[1] + c2 * b[2]).to_array()
        };
        ([uv0, uv1], color)
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
        let (uv, color) = self.attributes_of(idx, [1.0 - b1 - b2, b1, b2]);
        let alpha = m.alpha_at(uv, color, &self.texture_table);
        match m.alpha_mode {
            AlphaMode::Opaque => false,
            AlphaMode::Mask => alpha < m.alpha_cutoff,
            AlphaMode::Blend => blend_hash(ray, prim) >= alpha,
        }
    }

    /// The hit record for virtual triangle `prim` hit by `ray` at parameter `t` with
    /// barycentrics `(b1, b2)` of its stored vertices 1 and 2 (vertex 0 has `1 − b1 − b2`).
    ///
    /// `p` is interpolated from the (world-space) vertices (not `ray.at(t)`), so its error
    /// bound is the barycentric one, plus the instance transform's (module docs). `ns` is
    /// the normalised interpolated normal, perturbed by the material's normal map when it
    /// has one (see [`Scene::normal_mapped`]), flipped onto `ng`'s side; it falls back to
    /// `ng` where the interpolation vanishes.
    pub fn surface_hit(&self, ray: &Ray, t: f32, prim: u32, b1: f32, b2: f32) -> SurfaceHit {
        let (placed, tri) = self.place(prim);
        let b0 = 1.0 - b1 - b2;
        // Barycentrics in the placed (world winding) vertex order.
        let b = if placed.swap {
            [b0, b2, b1]
        } else {
            [b0, b1, b2]
        };
        let [i0, i1, i2] = placed.idx;
        let [p0, p1, p2] = placed.p;
        let p = p0 * b[0] + p1 * b[1] + p2 * b[2];
        let mut p_error = barycentric_error(b, p0, p1, p2);
        if placed.instance.is_some() {
            p_error += placed.p_error[0] * b[0].abs()
                + placed.p_error[1] * b[1].abs()
                + placed.p_error[2] * b[2].abs();
            // The bound's own rounding, generously.
            p_error *= 1.0 + 4.0 * f32::EPSILON;
        }
        let ng = triangle_normal(p0, p1, p2).unwrap_or(Vec3::Z);
        let normal = |i: usize| match &placed.instance {
            None => self.normals[i],
            Some(m) => (m.normal_matrix * self.normals[i]).normalize_or_zero(),
        };
        let n = normal(i0) * b[0] + normal(i1) * b[1] + normal(i2) * b[2];
        let (uv, color) = self.attributes_of(placed.idx, b);
        let material = self.triangle_material[tri];
        let mut ns = n.normalize_or_zero();
        if ns == Vec3::ZERO || !ns.is_finite() {
            ns = ng;
        } else {
            let mapped = self
                .materials
                .get(material as usize)
                .is_some_and(|m| m.normal_texture.is_some());
            if mapped {
                if let Some(mut mapped) = self.normal_mapped_placed(&placed, tri, b, ns, uv) {
                    // A mesh whose normals oppose its winding has its whole frame flipped.
                    if ns.dot(ng) < 0.0 {
                        mapped = -mapped;
                    }
                    ns = bend_towards_viewer(lift_above(mapped, ng), ng, -ray.dir);
                }
            }
            if ns.dot(ng) < 0.0 {
                ns = -ns;
            }
        }
        let rank = self.triangle_emitter[tri];
        let emitter = match (&placed.instance, rank) {
            (Some(m), r) if r >= 0 => m.first_emitter as i32 + r,
            _ => rank,
        };
        SurfaceHit {
            t,
            p,
            p_error,
            ng,
            ns,
            uv: uv[0],
            uv1: uv[1],
            color,
            prim,
            material,
            emitter,
        }
    }

    /// The shading normal of virtual triangle `prim` at barycentrics `b` (of its stored
    /// vertices) perturbed by its material's tangent-space normal map (glTF 2.0 §3.9.3):
    ///
    /// n' = normalize(x·T + y·B + z·N), (x, y, z) = ((2r − 1)·s, (2g − 1)·s, 2b − 1),
    ///
    /// with `s` = `normalTexture.scale`, N = `n` (the interpolated world-space normal), T
    /// the interpolated vertex tangent made orthogonal to N (Gram–Schmidt) and B = w · N × T.
    /// Without vertex tangents T is the triangle's ∂p/∂u and w chosen so that B points along
    /// −∂p/∂v (the normal map's +Y is "up" in the image, where v grows downwards). `None`
    /// when the frame degenerates. Instances' tangents are taken to world space by the
    /// linear part (handedness flipped under a mirror).
    pub fn normal_mapped(&self, prim: u32, b: [f32; 3], n: Vec3, uv: [Vec2; 2]) -> Option<Vec3> {
        let (placed, tri) = self.place(prim);
        let b = if placed.swap { [b[0], b[2], b[1]] } else { b };
        self.normal_mapped_placed(&placed, tri, b, n, uv)
    }

    fn normal_mapped_placed(
        &self,
        placed: &Placed,
        tri: usize,
        b: [f32; 3],
        n: Vec3,
        uv: [Vec2; 2],
    ) -> Option<Vec3> {
        let m = self
            .materials
            .get(*self.triangle_material.get(tri)? as usize)?;
        let r = &m.normal_texture;
        let tex = r.sample(uv, &self.texture_table, false)?;
        let (t, w) = match self.vertex_tangent(placed, b) {
            Some((t, w)) if t.length_squared() > 1e-12 => (t, w),
            _ => self.face_tangent(placed, r.tex_coord as usize, n)?,
        };
        let w = if w < 0.0 { -1.0 } else { 1.0 };
        let t = (t - n * n.dot(t)).try_normalize()?;
        let bt = n.cross(t) * w;
        let x = (2.0 * tex.x - 1.0) * r.scale;
        let y = (2.0 * tex.y - 1.0) * r.scale;
        let z = 2.0 * tex.z - 1.0;
        (t * x + bt * y + n * z).try_normalize()
    }

    /// The interpolated world-space vertex tangent and the handedness of vertex 0; `None`
    /// without tangents.
    fn vertex_tangent(&self, placed: &Placed, b: [f32; 3]) -> Option<(Vec3, f32)> {
        let ts = placed.idx.map(|i| self.tangents.get(i).copied());
        let [Some(t0), Some(t1), Some(t2)] = ts else {
            return None;
        };
        let v = |t: [f32; 4]| {
            let t = Vec3::new(t[0], t[1], t[2]);
            match &placed.instance {
                None => t,
                Some(m) => m.object_to_world.transform_vector3(t).normalize_or_zero(),
            }
        };
        let w = match &placed.instance {
            Some(m) if m.mirror => -t0[3],
            _ => t0[3],
        };
        Some((v(t0) * b[0] + v(t1) * b[1] + v(t2) * b[2], w))
    }

    /// World-space ∂p/∂u of the triangle in texture-coordinate set `set`, and the
    /// handedness that makes w · n × ∂p/∂u point along −∂p/∂v; `None` when the mapping is
    /// degenerate.
    fn face_tangent(&self, placed: &Placed, set: usize, n: Vec3) -> Option<(Vec3, f32)> {
        let tri = placed.idx;
        let uvs = if set == 1 { &self.uvs1 } else { &self.uvs };
        let [u0, u1, u2] = [uvs.get(tri[0])?, uvs.get(tri[1])?, uvs.get(tri[2])?];
        let [p0, p1, p2] = placed.p;
        let (dp1, dp2) = (p1 - p0, p2 - p0);
        let (d1, d2) = (*u1 - *u0, *u2 - *u0);
        let det = d1.x * d2.y - d1.y * d2.x;
        if det.is_nan() || det.abs() <= 1e-20 {
            return None;
        }
        let dpdu = (dp1 * d2.y - dp2 * d1.y) / det;
        let dpdv = (dp2 * d1.x - dp1 * d2.x) / det;
        let w = if n.cross(dpdu).dot(-dpdv) < 0.0 {
            -1.0
        } else {
            1.0
        };
        dpdu.is_finite().then_some((dpdu, w))
    }
}

/// Error bound of a vertex `p` = M `q` placed by instance `m` (module docs): the forward
/// transform's rounding and the intersector's transform of the ray into object space, taken
/// back to world space.
fn transform_error(m: &MeshInstance, q: Vec3, p: Vec3) -> Vec3 {
    let g3 = gamma(3);
    let abs3 = |a: Mat4| {
        Mat3::from_cols(
            a.x_axis.truncate().abs(),
            a.y_axis.truncate().abs(),
            a.z_axis.truncate().abs(),
        )
    };
    let (l, li) = (abs3(m.object_to_world), abs3(m.world_to_object));
    let t = m.object_to_world.w_axis.truncate().abs();
    let ti = m.world_to_object.w_axis.truncate().abs();
    let forward = (l * q.abs() + t) * g3;
    let inverse = l * ((li * p.abs() + ti) * g3);
    forward + inverse
}

/// `n` moved along `ng` until it lies at least ε = 10⁻³ above `ng`'s horizon (a normal map
/// may tilt the normal below the geometric surface; mirroring it back would turn it around).
pub fn lift_above(n: Vec3, ng: Vec3) -> Vec3 {
    const EPS: f32 = 1e-3;
    let d = n.dot(ng);
    if d >= EPS {
        return n;
    }
    (n + ng * (EPS - d)).try_normalize().unwrap_or(ng)
}

/// Bends a perturbed shading normal `ns` (on `ng`'s side) so that the viewer direction `wo`
/// lies on the same side of it as of `ng`: otherwise the shading frame would see the viewer
/// from below, and light would leak through the surface. The normal is moved along ±`wo`
/// until `|ns · wo| ≥ ε` (ε = 10⁻³, before renormalising), which keeps it on `ng`'s side.
pub fn bend_towards_viewer(ns: Vec3, ng: Vec3, wo: Vec3) -> Vec3 {
    const EPS: f32 = 1e-3;
    let Some(wo) = wo.try_normalize() else {
        return ns;
    };
    let side = if ng.dot(wo) < 0.0 { -1.0 } else { 1.0 };
    let d = side * ns.dot(wo);
    if d >= EPS {
        return ns;
    }
    (ns + wo * (side * (EPS - d))).try_normalize().unwrap_or(ng)
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
