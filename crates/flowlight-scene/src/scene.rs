//! The loaded scene: world-space triangle soup with per-triangle materials, the texture table,
//! the emitter table and the camera found in the file.

use flowlight_core::geometry::{barycentric_error, Ray, SurfaceHit};
use flowlight_core::light::{Emitter, PunctualLight};
use flowlight_core::material::{Material, Texture};
use flowlight_core::Rgb;
use glam::{DVec3, Vec2, Vec3};

/// A decoded texture in linear RGB, `width × height` texels, row-major, top row first.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureData {
    pub width: u32,
    pub height: u32,
    pub texels: Vec<Rgb>,
}

impl TextureData {
    /// A borrowed view for [`Material::base_color_at`]; valid while `self` lives.
    pub fn view(&self) -> Texture {
        Texture {
            width: self.width,
            height: self.height,
            texels: self.texels.as_ptr(),
        }
    }
}

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
    pub uvs: Vec<Vec2>,
    pub triangles: Vec<[u32; 3]>,
    pub triangle_material: Vec<u32>,
    pub materials: Vec<Material>,
    pub material_names: Vec<String>,
    pub textures: Vec<TextureData>,
    /// Every camera node of the scene, in traversal order (the first is the default camera).
    pub cameras: Vec<CameraDesc>,
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

    /// Texture views for [`Material::base_color_at`]; valid while `self` lives.
    pub fn texture_views(&self) -> Vec<Texture> {
        self.textures.iter().map(TextureData::view).collect()
    }

    /// The hit record for triangle `prim` hit by `ray` at parameter `t` with barycentrics
    /// `(b1, b2)` of vertices 1 and 2 (vertex 0 has `1 − b1 − b2`).
    ///
    /// `p` is interpolated from the vertices (not `ray.at(t)`), so its error bound is the
    /// barycentric one. `ns` is the normalised interpolated normal, flipped onto `ng`'s side;
    /// it falls back to `ng` where the interpolation vanishes.
    pub fn surface_hit(&self, _ray: &Ray, t: f32, prim: u32, b1: f32, b2: f32) -> SurfaceHit {
        let tri = self.triangles[prim as usize];
        let [i0, i1, i2] = tri.map(|i| i as usize);
        let (p0, p1, p2) = (self.positions[i0], self.positions[i1], self.positions[i2]);
        let b0 = 1.0 - b1 - b2;
        let b = [b0, b1, b2];
        let p = p0 * b0 + p1 * b1 + p2 * b2;
        let p_error = barycentric_error(b, p0, p1, p2);
        let ng = triangle_normal(p0, p1, p2).unwrap_or(Vec3::Z);
        let n = self.normals[i0] * b0 + self.normals[i1] * b1 + self.normals[i2] * b2;
        let mut ns = n.normalize_or_zero();
        if ns == Vec3::ZERO || !ns.is_finite() {
            ns = ng;
        } else if ns.dot(ng) < 0.0 {
            ns = -ns;
        }
        let uv = self.uvs[i0] * b0 + self.uvs[i1] * b1 + self.uvs[i2] * b2;
        SurfaceHit {
            t,
            p,
            p_error,
            ng,
            ns,
            uv,
            prim,
            material: self.triangle_material[prim as usize],
            emitter: self.triangle_emitter[prim as usize],
        }
    }
}
