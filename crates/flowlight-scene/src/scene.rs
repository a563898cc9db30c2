//! The loaded scene: world-space triangle soup with per-triangle materials, the texture table,
//! the emitter table and the camera found in the file.

use crate::texture::TextureData;
use flowlight_core::geometry::{barycentric_error, Ray, SurfaceHit};
use flowlight_core::light::{Emitter, PunctualLight};
use flowlight_core::material::{AlphaMode, Material, Texture};
use glam::{DVec3, Vec2, Vec3, Vec4};

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
    /// Images decoded (only those used by loaded materials).
    pub images_decoded: usize,
    /// Triangles whose material has an emissive factor but whose emission integrates to zero
    /// (a black emissive texture there): not lights.
    pub black_emitters: usize,
}

/// A scene ready to render: every vertex in world space.
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
    /// Per triangle: index into `emitters`, or -1.
    pub triangle_emitter: Vec<i32>,
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
    /// World-space vertices of each triangle, for acceleration-structure builds.
    pub fn triangle_vertices(&self) -> Vec<[Vec3; 3]> {
        self.triangles
            .iter()
            .map(|t| t.map(|i| self.positions[i as usize]))
            .collect()
    }

    /// Axis-aligned bounds `(min, max)` of all triangles; `None` for an empty scene.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for t in &self.triangles {
            for &i in t {
                let p = self.positions[i as usize].as_dvec3();
                lo = lo.min(p);
                hi = hi.max(p);
            }
        }
        (!self.triangles.is_empty()).then(|| (lo.as_vec3(), hi.as_vec3()))
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

    /// TEXCOORD_0, TEXCOORD_1 and COLOR_0 of triangle `prim` at barycentrics `(b1, b2)`.
    #[inline]
    pub fn attributes(&self, prim: u32, b1: f32, b2: f32) -> ([Vec2; 2], [f32; 4]) {
        let tri = self.triangles[prim as usize].map(|i| i as usize);
        let b = [1.0 - b1 - b2, b1, b2];
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

    /// Whether a ray passes through triangle `prim` at barycentrics `(b1, b2)`: alpha MASK
    /// below the cutoff, or alpha BLEND with probability 1 − α. The BLEND decision is a hash
    /// of the ray (origin and direction bits) and the triangle, so a ray query is
    /// deterministic and every intersector answers alike.
    pub fn passes_through(&self, ray: &Ray, prim: u32, b1: f32, b2: f32) -> bool {
        let Some(m) = self
            .triangle_material
            .get(prim as usize)
            .and_then(|&i| self.materials.get(i as usize))
        else {
            return false;
        };
        if m.alpha_mode == AlphaMode::Opaque {
            return false;
        }
        let (uv, color) = self.attributes(prim, b1, b2);
        let alpha = m.alpha_at(uv, color, &self.texture_table);
        match m.alpha_mode {
            AlphaMode::Opaque => false,
            AlphaMode::Mask => alpha < m.alpha_cutoff,
            AlphaMode::Blend => blend_hash(ray, prim) >= alpha,
        }
    }

    /// The hit record for triangle `prim` hit by `ray` at parameter `t` with barycentrics
    /// `(b1, b2)` of vertices 1 and 2 (vertex 0 has `1 − b1 − b2`).
    ///
    /// `p` is interpolated from the vertices (not `ray.at(t)`), so its error bound is the
    /// barycentric one. `ns` is the normalised interpolated normal, perturbed by the
    /// material's normal map when it has one (see [`Scene::normal_mapped`]), flipped onto
    /// `ng`'s side; it falls back to `ng` where the interpolation vanishes.
    pub fn surface_hit(&self, ray: &Ray, t: f32, prim: u32, b1: f32, b2: f32) -> SurfaceHit {
        let tri = self.triangles[prim as usize];
        let [i0, i1, i2] = tri.map(|i| i as usize);
        let (p0, p1, p2) = (self.positions[i0], self.positions[i1], self.positions[i2]);
        let b0 = 1.0 - b1 - b2;
        let b = [b0, b1, b2];
        let p = p0 * b0 + p1 * b1 + p2 * b2;
        let p_error = barycentric_error(b, p0, p1, p2);
        let ng = triangle_normal(p0, p1, p2).unwrap_or(Vec3::Z);
        let n = self.normals[i0] * b0 + self.normals[i1] * b1 + self.normals[i2] * b2;
        let (uv, color) = self.attributes(prim, b1, b2);
        let material = self.triangle_material[prim as usize];
        let mut ns = n.normalize_or_zero();
        if ns == Vec3::ZERO || !ns.is_finite() {
            ns = ng;
        } else {
            let mapped = self
                .materials
                .get(material as usize)
                .is_some_and(|m| m.normal_texture.is_some());
            if mapped {
                if let Some(mut mapped) = self.normal_mapped(prim, b, ns, uv) {
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
            emitter: self.triangle_emitter[prim as usize],
        }
    }

    /// The shading normal of triangle `prim` at barycentrics `b` perturbed by its material's
    /// tangent-space normal map (glTF 2.0 §3.9.3):
    ///
    /// n' = normalize(x·T + y·B + z·N), (x, y, z) = ((2r − 1)·s, (2g − 1)·s, 2b − 1),
    ///
    /// with `s` = `normalTexture.scale`, N = `n` (the interpolated normal), T the
    /// interpolated vertex tangent made orthogonal to N (Gram–Schmidt) and B = w · N × T.
    /// Without vertex tangents T is the triangle's ∂p/∂u and w chosen so that B points along
    /// −∂p/∂v (the normal map's +Y is "up" in the image, where v grows downwards). `None`
    /// when the frame degenerates.
    pub fn normal_mapped(&self, prim: u32, b: [f32; 3], n: Vec3, uv: [Vec2; 2]) -> Option<Vec3> {
        let m = self
            .materials
            .get(*self.triangle_material.get(prim as usize)? as usize)?;
        let r = &m.normal_texture;
        let tex = r.sample(uv, &self.texture_table, false)?;
        let tri = self.triangles[prim as usize].map(|i| i as usize);
        let (t, w) = match self.vertex_tangent(tri, b) {
            Some((t, w)) if t.length_squared() > 1e-12 => (t, w),
            _ => self.face_tangent(tri, r.tex_coord as usize, n)?,
        };
        let w = if w < 0.0 { -1.0 } else { 1.0 };
        let t = (t - n * n.dot(t)).try_normalize()?;
        let bt = n.cross(t) * w;
        let x = (2.0 * tex.x - 1.0) * r.scale;
        let y = (2.0 * tex.y - 1.0) * r.scale;
        let z = 2.0 * tex.z - 1.0;
        (t * x + bt * y + n * z).try_normalize()
    }

    /// The interpolated vertex tangent and the handedness of vertex 0; `None` without
    /// tangents.
    fn vertex_tangent(&self, tri: [usize; 3], b: [f32; 3]) -> Option<(Vec3, f32)> {
        let ts = tri.map(|i| self.tangents.get(i).copied());
        let [Some(t0), Some(t1), Some(t2)] = ts else {
            return None;
        };
        let v = |t: [f32; 4]| Vec3::new(t[0], t[1], t[2]);
        Some((v(t0) * b[0] + v(t1) * b[1] + v(t2) * b[2], t0[3]))
    }

    /// ∂p/∂u of the triangle in texture-coordinate set `set`, and the handedness that makes
    /// w · n × ∂p/∂u point along −∂p/∂v; `None` when the mapping is degenerate.
    fn face_tangent(&self, tri: [usize; 3], set: usize, n: Vec3) -> Option<(Vec3, f32)> {
        let uvs = if set == 1 { &self.uvs1 } else { &self.uvs };
        let [u0, u1, u2] = [uvs.get(tri[0])?, uvs.get(tri[1])?, uvs.get(tri[2])?];
        let [p0, p1, p2] = tri.map(|i| self.positions[i]);
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
