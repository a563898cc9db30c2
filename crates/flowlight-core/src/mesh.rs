//! Surface data from a compact hit: the scene's vertex buffers as borrowed slices
//! ([`MeshView`]) and the one function that turns (ray, triangle, barycentrics) into a
//! [`SurfaceHit`].
//!
//! The host's `flowlight_scene::Scene::surface_hit` and a plugin's lazy surface data (ABI 4:
//! batches of rays come back as [`CompactHit`]s, and the plugin rebuilds what shading needs
//! from the `SceneView`'s mesh data) both call [`MeshView::surface_hit`], so the two agree bit
//! for bit by construction.
//!
//! For a hit on virtual triangle `prim` with barycentrics (b₁, b₂) of its stored vertices 1
//! and 2 (b₀ = 1 − b₁ − b₂):
//!
//! * p = b₀p₀ + b₁p₁ + b₂p₂ from the world-space vertices (not o + t·d), with the error bound
//!   γ₇ Σ|bᵢpᵢ| (pbrt-v4 §6.8) plus, on an instance, the rounding of the two transforms
//!   between object and world space: per component γ₃(|M|·|p_obj| + |t|) for p = M p_obj and
//!   |M|·γ₃(|M⁻¹|·|p| + |M⁻¹t|) for the intersector's ray transform (pbrt-v4 §6.8.3);
//! * n_g the unit normal of the world winding (vertices 1 and 2 swap under a mirroring
//!   instance, det M < 0, and so do b₁ and b₂);
//! * n_s the normalised interpolated vertex normal (taken to world space by N = (M₃ₓ₃⁻¹)ᵀ and
//!   renormalised per vertex), perturbed by the material's tangent-space normal map
//!   (glTF 2.0 §3.9.3, [`MeshView::normal_mapped`]), lifted above n_g's horizon and bent so
//!   that the viewer is on n_g's side of it, then flipped onto n_g's side; n_g where the
//!   interpolation vanishes;
//! * TEXCOORD_0/1 and COLOR_0 interpolated by the stored barycentrics.
//!
//! Virtual triangle ids: instance `i` shows triangles `first_virtual .. first_virtual +
//! triangle_count` of its stored range (`flowlight_scene`'s module docs, "Instancing").

use crate::geometry::{barycentric_error, gamma, Ray, SurfaceHit, TriangleHit};
use crate::material::{Material, Texture};
use crate::specular_normal::{bends_for_metallic, valid_specular_normal};
use glam::{Mat3, Mat4, Vec2, Vec3, Vec4};

/// How many hits ahead [`MeshView::prefetch_surfaces`] asks for a hit's triangle record.
pub const SURFACE_PREFETCH_TRIANGLES: usize = 8;
/// Below this many triangles [`MeshView::prefetch_surfaces`] does nothing: index rows,
/// vertices and materials of 16k triangles take about 1 MiB, which the cache holds.
pub const SURFACE_PREFETCH_MIN_TRIANGLES: usize = 16 * 1024;
/// How many hits ahead [`MeshView::prefetch_surfaces`] asks for a hit's vertices (fewer than
/// [`SURFACE_PREFETCH_TRIANGLES`]: it reads the index row asked for earlier).
pub const SURFACE_PREFETCH_VERTICES: usize = 4;

mod tangent;

/// What a batched ray query returns per ray (ABI 4): enough to rebuild the surface data.
/// `prim == u32::MAX` (and `t = ∞`) when the ray escaped.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CompactHit {
    pub t: f32,
    /// Virtual triangle id.
    pub prim: u32,
    /// Barycentrics of the stored vertices 1 and 2.
    pub b1: f32,
    pub b2: f32,
    /// Index into the scene's instances of the placement hit, or `u32::MAX` when unknown (a
    /// scene without instancing); only a shortcut for [`MeshView::locate`].
    pub instance: u32,
}

/// A single-ray query's hit as a compact hit, its instance left unknown (`u32::MAX`: the
/// surface code locates it, [`MeshView::locate`]).
impl From<TriangleHit> for CompactHit {
    #[inline(always)]
    fn from(h: TriangleHit) -> CompactHit {
        CompactHit {
            t: h.t,
            prim: h.prim,
            b1: h.b1,
            b2: h.b2,
            instance: u32::MAX,
        }
    }
}

impl CompactHit {
    /// An escaped ray.
    pub const MISS: CompactHit = CompactHit {
        t: f32::INFINITY,
        prim: u32::MAX,
        b1: 0.0,
        b2: 0.0,
        instance: u32::MAX,
    };

    #[inline]
    pub fn is_hit(&self) -> bool {
        self.prim != u32::MAX
    }
}

/// A range of stored triangles: one glTF mesh stored in local space, or all meshes placed
/// once (in world space).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MeshRange {
    pub first_triangle: u32,
    pub triangle_count: u32,
}

/// One placement of a range of stored triangles (`flowlight_scene`'s "Instancing").
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshInstance {
    /// Index into the scene's meshes.
    pub mesh: u32,
    /// The mesh's stored triangles: `first_triangle .. first_triangle + triangle_count`.
    pub first_triangle: u32,
    pub triangle_count: u32,
    /// Virtual id of the instance's first triangle.
    pub first_virtual: u32,
    /// Index into the emitter table of this instance's emitters: a triangle whose
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

/// The scene's vertex and triangle buffers, borrowed. Per-vertex arrays other than
/// `positions` may be empty when no primitive has the attribute (`normals`, `uvs`, `uvs1`,
/// `colors`, `tangents`): a hit then reads nothing of them.
///
/// `triangle_emitter` is read only where the triangle's material is emissive
/// ([`Material::is_emissive`]), so every emitter triangle must have an emissive material (the
/// loader makes emitters of emissive triangles only): a hit on a scan reads its index row and
/// material, not a third per-triangle line.
#[derive(Clone, Copy, Debug, Default)]
pub struct MeshView<'a> {
    pub positions: &'a [Vec3],
    pub normals: &'a [Vec3],
    pub uvs: &'a [Vec2],
    pub uvs1: &'a [Vec2],
    pub colors: &'a [[f32; 4]],
    pub tangents: &'a [[f32; 4]],
    pub triangles: &'a [[u32; 3]],
    pub triangle_material: &'a [u32],
    pub triangle_emitter: &'a [i32],
    /// Sorted by `first_virtual`; empty means one identity instance of all triangles.
    pub instances: &'a [MeshInstance],
    pub materials: &'a [Material],
    pub textures: &'a [Texture],
    /// A promise that every virtual triangle id is its stored triangle's index under the
    /// identity (what [`MeshView::ids_are_stored`] checks), so [`MeshView::locate`] needs no
    /// search; `false` means unknown, and the search is made. A flattened scene of several
    /// meshes (the dragon on its floor under its lamp: three identity instances) would
    /// otherwise search the instances three times per hit: twice for the prefetch hints and
    /// once for the surface data.
    pub stored_ids: bool,
}

/// A stored triangle placed in world space, as the flattening loader would have stored it.
#[derive(Clone, Copy, Debug)]
pub struct Placed<'a> {
    /// Stored vertex indices, in world winding order (1 and 2 swapped under a mirror).
    pub idx: [usize; 3],
    pub p: [Vec3; 3],
    /// Extra position error of the object ↔ world transforms, per vertex (zero for the
    /// identity).
    pub p_error: [Vec3; 3],
    /// Whether barycentrics 1 and 2 swap.
    pub swap: bool,
    pub instance: Option<&'a MeshInstance>,
}

impl<'a> MeshView<'a> {
    /// The instance showing virtual triangle `prim` (`None`: the identity) and the index of
    /// the stored triangle. A binary search over the instances, none for a scene with one.
    #[inline]
    pub fn locate(&self, prim: u32) -> (Option<&'a MeshInstance>, usize) {
        if self.stored_ids {
            return (None, prim as usize);
        }
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
        Self::in_instance(inst, prim)
    }

    /// Whether the instances make every virtual triangle id its stored index, placed by the
    /// identity: none at all, or identity placements only, the first from id 0, each showing
    /// its stored triangles at their own ids. Then [`MeshView::locate`]'s search finds, for
    /// any `prim`, an identity instance with `first_triangle == first_virtual ≤ prim`, and
    /// so gives `(None, prim)`: what [`MeshView::stored_ids`] returns without searching.
    pub fn ids_are_stored(instances: &[MeshInstance]) -> bool {
        instances.first().is_none_or(|i| i.first_virtual == 0)
            && instances
                .iter()
                .all(|i| i.identity && i.first_triangle == i.first_virtual)
    }

    /// This view with [`MeshView::stored_ids`] set where [`MeshView::ids_are_stored`] holds
    /// (a scan of the instances: once per view, not per hit).
    pub fn with_stored_ids_checked(mut self) -> Self {
        self.stored_ids = Self::ids_are_stored(self.instances);
        self
    }

    #[inline]
    fn in_instance(inst: &'a MeshInstance, prim: u32) -> (Option<&'a MeshInstance>, usize) {
        let tri = inst.first_triangle as usize + prim.saturating_sub(inst.first_virtual) as usize;
        (Some(inst).filter(|i| !i.identity), tri)
    }

    /// [`MeshView::locate`] with the intersector's instance index as a shortcut (checked: a
    /// wrong or missing index falls back to the search).
    #[inline]
    pub fn locate_hit(&self, prim: u32, instance: u32) -> (Option<&'a MeshInstance>, usize) {
        match self.instances.get(instance as usize) {
            Some(i) if i.first_virtual <= prim && prim - i.first_virtual < i.triangle_count => {
                Self::in_instance(i, prim)
            }
            _ => self.locate(prim),
        }
    }

    /// Virtual triangle `prim` placed in world space, and its stored triangle index.
    #[inline]
    pub fn place(&self, prim: u32, instance: u32) -> (Placed<'a>, usize) {
        let (inst, tri) = self.locate_hit(prim, instance);
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
                    instance: Some(m),
                }
            }
        };
        (placed, tri)
    }

    /// Asks the cache for the first lines [`MeshView::surface_hit`] reads of a hit on `prim`:
    /// its stored triangle's index row and material (its emitter rank only matters on
    /// emissive materials, few triangles, and is not asked for). Step one of two; a hint, a
    /// no-op off x86-64. On an 871k-triangle scan those loads miss the cache, and in a batch
    /// of hits one after another each miss would wait for the last (`ac60800`; docs/performance.md).
    #[inline]
    pub fn prefetch_triangle(&self, prim: u32, instance: u32) {
        let (_, tri) = self.locate_hit(prim, instance);
        prefetch(self.triangles.get(tri));
        prefetch(self.triangle_material.get(tri));
    }

    /// Step two of [`MeshView::prefetch_triangle`], once its lines have had time to arrive:
    /// the three vertices' attributes that every hit reads (positions, normals, texture
    /// coordinates and colours where the mesh has them; tangents only serve normal maps).
    #[inline]
    pub fn prefetch_vertices(&self, prim: u32, instance: u32) {
        let (_, tri) = self.locate_hit(prim, instance);
        let Some(idx) = self.triangles.get(tri) else {
            return;
        };
        let idx = idx.map(|i| i as usize);
        // Positions always; the other arrays only where the scene has them (a scan has
        // normals at most), each test once per triangle rather than once per vertex.
        for i in idx {
            prefetch(self.positions.get(i));
        }
        if !self.normals.is_empty() {
            for i in idx {
                prefetch(self.normals.get(i));
            }
        }
        if !(self.uvs.is_empty() && self.uvs1.is_empty() && self.colors.is_empty()) {
            for i in idx {
                prefetch(self.uvs.get(i));
                prefetch(self.uvs1.get(i));
                prefetch(self.colors.get(i));
            }
        }
    }

    /// Cache hints for a loop that builds the surface of `hits[k]` at its step `k`: call it
    /// at each step before that. It asks for the triangle records of the hit
    /// [`SURFACE_PREFETCH_TRIANGLES`] steps ahead and the vertices of the one
    /// [`SURFACE_PREFETCH_VERTICES`] ahead, whose records it asked for earlier, so that the
    /// cache misses of a large mesh's surface data overlap with the shading of the hits
    /// before them instead of stalling each hit in turn. Changes no result.
    /// Meshes of fewer than [`SURFACE_PREFETCH_MIN_TRIANGLES`] triangles stay in the cache
    /// anyway and get no hints.
    #[inline]
    pub fn prefetch_surfaces(&self, hits: &[CompactHit], k: usize) {
        if self.triangles.len() < SURFACE_PREFETCH_MIN_TRIANGLES {
            return;
        }
        let triangle = |j: usize| {
            if let Some(h) = hits.get(j).filter(|h| h.is_hit()) {
                self.prefetch_triangle(h.prim, h.instance);
            }
        };
        let vertices = |j: usize| {
            if let Some(h) = hits.get(j).filter(|h| h.is_hit()) {
                self.prefetch_vertices(h.prim, h.instance);
            }
        };
        if k == 0 {
            (0..SURFACE_PREFETCH_TRIANGLES).for_each(triangle);
            (0..SURFACE_PREFETCH_VERTICES).for_each(vertices);
        }
        triangle(k + SURFACE_PREFETCH_TRIANGLES);
        vertices(k + SURFACE_PREFETCH_VERTICES);
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

    /// TEXCOORD_0, TEXCOORD_1 and COLOR_0 of stored vertices `tri` at barycentrics `b`.
    #[inline]
    pub fn attributes_of(&self, tri: [usize; 3], b: [f32; 3]) -> ([Vec2; 2], [f32; 4]) {
        let uv0 = Self::lerp(self.uvs, tri, b).unwrap_or(Vec2::ZERO);
        let uv1 = Self::lerp(self.uvs1, tri, b).unwrap_or(Vec2::ZERO);
        let color = if self.colors.is_empty() {
            [1.0; 4]
        } else {
            let [c0, c1, c2] = tri.map(|i| Vec4::from_array(self.colors[i]));
            (c0 * b[0] + c1 * b[1] + c2 * b[2]).to_array()
        };
        ([uv0, uv1], color)
    }

    /// The surface data of `hit` (module docs); `ray` is the query's (its direction bends
    /// normal-mapped shading normals towards the viewer).
    #[inline]
    pub fn surface_hit(&self, ray: &Ray, hit: &CompactHit) -> SurfaceHit {
        let (t, prim, b1, b2) = (hit.t, hit.prim, hit.b1, hit.b2);
        let (placed, tri) = self.place(prim, hit.instance);
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
        let (uv, color) = self.attributes_of(placed.idx, b);
        let material = self.triangle_material[tri];
        // No vertex normals in the scene: the interpolation would vanish, as it does on a
        // flat primitive's zero normals, and n_s is n_g (without normalising a zero vector).
        let mut ns = if self.normals.is_empty() {
            Vec3::ZERO
        } else {
            let normal = |i: usize| match placed.instance {
                None => self.normals[i],
                Some(m) => (m.normal_matrix * self.normals[i]).normalize_or_zero(),
            };
            (normal(i0) * b[0] + normal(i1) * b[1] + normal(i2) * b[2]).normalize_or_zero()
        };
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
                    // A metal's mirror reflection of the viewer kept above the surface
                    // (`specular_normal`'s module docs say why only a metal's).
                    let metallic = self.materials.get(material as usize).map_or(0.0, |m| {
                        let t = m
                            .metallic_roughness_texture
                            .sample(uv, self.textures, false);
                        m.metallic * t.map_or(1.0, |t| t.z)
                    });
                    if let Some(wo) = (-ray.dir).try_normalize() {
                        if bends_for_metallic(metallic) {
                            ns = valid_specular_normal(ng, wo, ns);
                        }
                    }
                }
            }
            if ns.dot(ng) < 0.0 {
                ns = -ns;
            }
        }
        // Only emissive materials have emitter triangles (the type's docs); a view without a
        // material table (a mesh built by hand) reads the rank of every hit.
        let rank = match self.materials.get(material as usize) {
            Some(m) if !m.is_emissive() => -1,
            _ => self.triangle_emitter[tri],
        };
        let emitter = match (placed.instance, rank) {
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
        let (placed, tri) = self.place(prim, u32::MAX);
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
        let tex = r.sample(uv, self.textures, false)?;
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
            match placed.instance {
                None => t,
                Some(m) => m.object_to_world.transform_vector3(t).normalize_or_zero(),
            }
        };
        let w = match placed.instance {
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
        let uvs = if set == 1 { self.uvs1 } else { self.uvs };
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

/// Unit normal of the triangle from its winding, computed so that neither tiny nor large
/// coordinates underflow or overflow. `None` for a degenerate triangle.
///
/// Every hit computes it, so the common case takes no division but one reciprocal square
/// root's: where |e₁ × e₂|² lies in [2⁻¹⁰⁰, 2¹⁰⁰] no product in it overflowed, and any that
/// underflowed is below 2⁻¹²⁶, some 2⁻⁷⁶ of the result, so the cross product of the raw
/// edges is as accurate as that of scaled ones. Otherwise (tiny, huge, degenerate or
/// non-finite triangles) the edges are scaled by their largest component first.
#[inline]
pub fn triangle_normal(p0: Vec3, p1: Vec3, p2: Vec3) -> Option<Vec3> {
    let e1 = p1 - p0;
    let e2 = p2 - p0;
    let c = e1.cross(e2);
    let len2 = c.length_squared();
    // 2^±100: exact powers of two, far inside f32's normal range.
    const HI: f32 = (1u128 << 100) as f32;
    const LO: f32 = 1.0 / HI;
    if (LO..=HI).contains(&len2) {
        return Some(c * len2.sqrt().recip());
    }
    triangle_normal_scaled(e1, e2)
}

/// [`triangle_normal`] of edges `e1`, `e2` scaled by their largest component.
#[cold]
fn triangle_normal_scaled(e1: Vec3, e2: Vec3) -> Option<Vec3> {
    let s = e1.abs().max_element().max(e2.abs().max_element());
    if !(s > 0.0 && s.is_finite()) {
        return None;
    }
    let c = (e1 / s).cross(e2 / s);
    let len = c.length();
    (len > 0.0 && len.is_finite()).then(|| c / len)
}

/// Error bound of a vertex `p` = M `q` placed by instance `m` (module docs): the forward
/// transform's rounding and the intersector's transform of the ray into object space, taken
/// back to world space.
pub fn transform_error(m: &MeshInstance, q: Vec3, p: Vec3) -> Vec3 {
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

/// Asks the cache for the line holding `value`; a hint (a prefetch never faults), a no-op
/// off x86-64 or for `None`.
#[inline(always)]
fn prefetch<T>(value: Option<&T>) {
    #[cfg(target_arch = "x86_64")]
    if let Some(v) = value {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        // SAFETY: `prefetcht0` only hints the cache; it reads nothing architecturally and
        // never faults, and the pointer comes from a live reference anyway.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(v as *const T as *const i8) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = value;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The prefetch hints index nothing: prims past the last triangle, misses and index rows
    /// naming vertices past the buffers (a malformed view) are skipped, not panics. Surface
    /// data checks its input elsewhere; a hint must never be the place a render dies.
    #[test]
    fn prefetch_hints_never_index_out_of_bounds() {
        let positions = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let normals = [Vec3::Z; 3];
        let triangles = [[0u32, 1, 2], [0, 1, 7], [u32::MAX, 2, 1]];
        let view = MeshView {
            positions: &positions,
            normals: &normals,
            uvs: &[],
            uvs1: &[],
            colors: &[],
            tangents: &[],
            triangles: &triangles,
            triangle_material: &[0, 0],
            triangle_emitter: &[-1],
            instances: &[],
            materials: &[],
            textures: &[],
            stored_ids: false,
        };
        for prim in [0, 1, 2, 3, 1000, u32::MAX - 1, u32::MAX] {
            for instance in [0, 5, u32::MAX] {
                view.prefetch_triangle(prim, instance);
                view.prefetch_vertices(prim, instance);
            }
        }
    }

    /// The unit normal of random triangles at every scale from 2⁻⁶⁰ to 2⁶⁰ (both sides of
    /// the unscaled fast path's range, and far into the scaled path's) is within a few float
    /// roundings of the f64 cross product, and degenerate or non-finite ones give `None`.
    #[test]
    fn triangle_normal_is_accurate_at_every_scale() {
        let mut rng = crate::rng::Rng::new(7, 0);
        let mut v = || Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 2.0 - 1.0;
        for e in -60..=60 {
            let scale = 2f32.powi(e);
            for _ in 0..200 {
                let (q0, q1, q2) = (v(), v(), v());
                let [p0, p1, p2] = [q0, q1, q2].map(|q| q * scale);
                let d = |a: Vec3, b: Vec3| a.as_dvec3() - b.as_dvec3();
                let c = d(p1, p0).cross(d(p2, p0));
                if c.length() <= 1e-3 * d(p1, p0).length() * d(p2, p0).length() {
                    continue; // nearly degenerate: the f32 edges' own rounding dominates
                }
                let want = c.normalize();
                let got = triangle_normal(p0, p1, p2).expect("non-degenerate");
                let err = (got.as_dvec3() - want).length();
                assert!(
                    err < 1e-4,
                    "scale 2^{e}: {got} against {want} (error {err})"
                );
                assert!((got.length() - 1.0).abs() < 4.0 * f32::EPSILON);
            }
        }
        let p = Vec3::new(1.0, 2.0, 3.0);
        assert_eq!(triangle_normal(p, p, p), None);
        assert_eq!(triangle_normal(Vec3::ZERO, Vec3::X, 2.0 * Vec3::X), None);
        assert_eq!(triangle_normal(Vec3::ZERO, Vec3::X, Vec3::NAN), None);
        assert_eq!(
            triangle_normal(Vec3::ZERO, Vec3::X * f32::MAX, Vec3::Y * f32::MAX),
            Some(Vec3::Z)
        );
        assert_eq!(
            triangle_normal(Vec3::ZERO, Vec3::X * 1e-30, Vec3::Y * 1e-30),
            Some(Vec3::Z)
        );
    }

    /// The promise of `stored_ids` is kept exactly where the search would give the same
    /// answer: identity placements of stored triangles at their own ids, from id 0. Every
    /// prim (also past the last triangle) then locates as the search locates it; offset or
    /// transformed placements, or a first instance not at id 0, are refused.
    #[test]
    fn stored_ids_locate_as_the_search_does() {
        let range = |first_triangle, triangle_count| MeshRange {
            first_triangle,
            triangle_count,
        };
        let flat = [
            MeshInstance::identity(0, range(0, 5), 0, 0),
            MeshInstance::identity(1, range(5, 2), 5, 0),
            MeshInstance::identity(2, range(7, 3), 7, 1),
        ];
        let moved = Mat4::from_translation(Vec3::X);
        let refused: [&[MeshInstance]; 3] = [
            // The same mesh shown again at virtual ids past the stored triangles.
            &[
                MeshInstance::identity(0, range(0, 5), 0, 0),
                MeshInstance::identity(0, range(0, 5), 5, 0),
            ],
            &[MeshInstance::placed(0, range(0, 5), moved, 0, 0).unwrap()],
            &[MeshInstance::identity(0, range(0, 5), 2, 0)],
        ];
        assert!(MeshView::ids_are_stored(&[]));
        assert!(MeshView::ids_are_stored(&flat));
        for instances in refused {
            assert!(!MeshView::ids_are_stored(instances));
        }
        let search = MeshView {
            instances: &flat,
            ..MeshView::default()
        };
        let promised = search.with_stored_ids_checked();
        assert!(promised.stored_ids && !search.stored_ids);
        for prim in [0, 4, 5, 6, 7, 9, 10, 1000, u32::MAX] {
            let (a, ta) = search.locate(prim);
            let (b, tb) = promised.locate(prim);
            assert_eq!((a.is_none(), ta), (b.is_none(), tb), "prim {prim}");
        }
    }
}
