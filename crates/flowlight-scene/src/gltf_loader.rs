//! Walks a glTF 2.0 document's default scene into a [`Scene`].
//!
//! - Node transforms (TRS or matrix) are composed down the hierarchy; normals use the
//!   inverse-transpose and the winding is flipped under a negative determinant, so a
//!   counter-clockwise front face stays the front face.
//! - Instancing: the walk first collects every placement (node, and each
//!   `EXT_mesh_gpu_instancing` instance) of every mesh. A mesh placed once is flattened into
//!   world space; a mesh placed several times is loaded once, in its local space, and each
//!   placement becomes a [`MeshInstance`] (see [`crate::scene`]). The instance and
//!   virtual-triangle limits are checked from the accessors' counts before any geometry is
//!   decoded ([`MAX_INSTANCES`], [`MAX_VIRTUAL_TRIANGLES`], and the memory estimate against
//!   the memory available: [`crate::memory`]).
//! - Only triangle primitives are loaded: TRIANGLES as they are, TRIANGLE_STRIP and
//!   TRIANGLE_FAN converted to lists; points and lines are skipped with a warning and counted.
//! - Primitives without NORMAL are flat shaded (the glTF spec asks for flat normals then):
//!   their vertices stay shared, with zero normals, so the surface code takes each
//!   triangle's geometric normal as its shading normal. Only a flat primitive whose
//!   material has a normal map (per-corner tangents) gets its vertices duplicated per
//!   triangle, with the face normal at each corner.
//! - Only the materials and images that loaded primitives use are converted and decoded; an
//!   image used by several textures is decoded once and shared.
//! - Vertex attributes: TEXCOORD_0 and TEXCOORD_1, COLOR_0 (VEC3 or VEC4, float or
//!   normalized integers), TANGENT (or MikkTSpace tangents when the material has a normal map
//!   and the file none, see `corner_tangents`). An attribute no primitive has takes no memory.
//! - Texture references keep their `texCoord` and `KHR_texture_transform`; `alphaMode` and
//!   `alphaCutoff` are read for alpha testing (see `docs/gltf.md`).
//! - Degenerate triangles (a repeated index, a NaN or infinite vertex, zero area) are dropped
//!   and counted; an index beyond the vertex count is an error.
//! - Every remaining triangle whose emission, integrated over it (texture included), is
//!   non-zero becomes an [`Emitter`] ([`crate::lights::mean_emission`]).
//! - `KHR_lights_punctual` lights become [`flowlight_core::light::PunctualLight`]s placed by
//!   their node's world transform.
//! - Every node that places a camera (perspective or orthographic) is recorded in traversal
//!   order; the render config picks one ([`crate::config`], default: the first).

use crate::accessor::{read_floats, read_indices};
use crate::error::SceneError;
use crate::instancing::instance_transforms;
use crate::lights::{emission_strata, mean_emission, punctual_light};
use crate::material::{convert, MaterialOverride};
use crate::scene::{
    triangle_area, triangle_normal, CameraDesc, CameraProjection, MeshInstance, MeshRange, Scene,
};
use crate::source::GltfSource;
use crate::texture::{load_image, ImageData, Sampler, TextureData};
use flowlight_core::light::Emitter;
use flowlight_core::material::{AlphaMode, Material, TextureRef};
use flowlight_core::sampling::build_cdf;
use glam::{Mat3, Mat4, Vec2, Vec3};
use gltf::mesh::{Mode, Semantic};
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

/// Loads a `.gltf` (with external buffers or data URIs) or `.glb` file. `overrides` maps
/// material names to diffuse-model overrides (from the render config).
///
/// Never panics on malformed input: every failure is a [`SceneError`] naming the file.
pub fn load_gltf(
    path: &Path,
    overrides: &BTreeMap<String, MaterialOverride>,
) -> Result<Scene, SceneError> {
    // Everything below validates before it indexes; the unwind guard is a last resort so
    // that a bug or an unforeseen input in a dependency still reports instead of aborting.
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| load_inner(path, overrides))) {
        Ok(r) => r,
        Err(payload) => {
            let reason = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "panic".into());
            Err(SceneError::Internal {
                file: path.to_path_buf(),
                reason,
            })
        }
    }
}

struct Loader<'a> {
    src: GltfSource,
    overrides: &'a BTreeMap<String, MaterialOverride>,
    scene: Scene,
    /// glTF material index (None = default material) to scene material index.
    material_map: HashMap<Option<usize>, u32>,
    /// glTF image index to its decoded image (shared by the textures that use it).
    image_map: HashMap<usize, ImageData>,
    /// glTF texture index to scene texture index.
    texture_map: HashMap<usize, i32>,
    /// Whether some loaded primitive has vertex normals (NORMAL, or the face normals of an
    /// unwelded normal-mapped flat primitive), TEXCOORD_0, TEXCOORD_1, COLOR_0, tangents
    /// (read or computed).
    any_normal: bool,
    any_uv0: bool,
    any_uv1: bool,
    any_color: bool,
    any_tangent: bool,
}

/// A `KHR_texture_transform` as read from the file.
#[derive(Clone, Copy, Debug)]
struct Transform {
    offset: [f32; 2],
    rotation: f32,
    scale: [f32; 2],
    tex_coord: Option<u32>,
}

/// Parses a `KHR_texture_transform` object given as JSON (for the texture infos the `gltf`
/// crate does not type: normal and occlusion).
fn transform_from_json(v: Option<&gltf::json::Value>) -> Result<Option<Transform>, String> {
    let Some(v) = v else { return Ok(None) };
    let num = |x: &gltf::json::Value, what: &str| {
        x.as_f64()
            .map(|f| f as f32)
            .ok_or_else(|| format!("KHR_texture_transform.{what} is not a number"))
    };
    let pair = |key: &str, default: [f32; 2]| -> Result<[f32; 2], String> {
        match v.get(key) {
            None => Ok(default),
            Some(a) => match a.as_array().map(|a| a.as_slice()) {
                Some([x, y]) => Ok([num(x, key)?, num(y, key)?]),
                _ => Err(format!(
                    "KHR_texture_transform.{key} is not a pair of numbers"
                )),
            },
        }
    };
    let rotation = match v.get("rotation") {
        None => 0.0,
        Some(r) => num(r, "rotation")?,
    };
    let tex_coord = match v.get("texCoord") {
        None => None,
        Some(c) => Some(
            c.as_u64()
                .and_then(|c| u32::try_from(c).ok())
                .ok_or("KHR_texture_transform.texCoord is not a non-negative integer")?,
        ),
    };
    Ok(Some(Transform {
        offset: pair("offset", [0.0, 0.0])?,
        rotation,
        scale: pair("scale", [1.0, 1.0])?,
        tex_coord,
    }))
}

fn load_inner(
    path: &Path,
    overrides: &BTreeMap<String, MaterialOverride>,
) -> Result<Scene, SceneError> {
    let src = GltfSource::open(path)?;
    let mut loader = Loader {
        src,
        overrides,
        scene: Scene::default(),
        material_map: HashMap::new(),
        image_map: HashMap::new(),
        texture_map: HashMap::new(),
        any_normal: false,
        any_uv0: false,
        any_uv1: false,
        any_color: false,
        any_tangent: false,
    };
    loader.walk()?;
    loader.finish()
}

impl Loader<'_> {
    fn file(&self) -> PathBuf {
        self.src.file.clone()
    }

    fn walk(&mut self) -> Result<(), SceneError> {
        let doc = self.src.document.clone();
        let gscene = doc
            .default_scene()
            .or_else(|| doc.scenes().next())
            .ok_or_else(|| SceneError::NoScene { file: self.file() })?;
        enum Step<'d> {
            Enter(gltf::Node<'d>, Mat4),
            Exit(usize),
        }
        // (glTF mesh, its world placements) in traversal order; geometry is loaded after the
        // walk, once the number of placements of each mesh is known.
        let mut placements: Vec<(usize, Vec<Mat4>)> = Vec::new();
        let mut on_path = vec![false; doc.nodes().len()];
        let mut entered = vec![false; doc.nodes().len()];
        let mut stack: Vec<Step> = gscene
            .nodes()
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
            .map(|n| Step::Enter(n, Mat4::IDENTITY))
            .collect();
        while let Some(step) = stack.pop() {
            let (node, parent) = match step {
                Step::Enter(node, parent) => (node, parent),
                Step::Exit(i) => {
                    on_path[i] = false;
                    continue;
                }
            };
            let idx = node.index();
            if on_path[idx] {
                return Err(SceneError::Node {
                    file: self.file(),
                    node: idx,
                    reason: "the node hierarchy has a cycle".into(),
                });
            }
            // glTF requires the nodes to form disjoint trees: a node reached twice has several
            // parents (or is listed twice by one), and a chain of such nodes expands
            // exponentially (30 of them: 2^30 instances). Sharing is what meshes are for.
            if entered[idx] {
                return Err(SceneError::Node {
                    file: self.file(),
                    node: idx,
                    reason: "it is reached twice in the node hierarchy (a second parent, or a \
                             parent listing it twice); glTF nodes must form trees — share the \
                             mesh between two nodes instead"
                        .into(),
                });
            }
            entered[idx] = true;
            let local = Mat4::from_cols_array_2d(&node.transform().matrix());
            let world = parent * local;
            if !world.is_finite() {
                return Err(SceneError::Node {
                    file: self.file(),
                    node: idx,
                    reason: "its world transform is not finite".into(),
                });
            }
            if let Some(cam) = node.camera() {
                self.camera(&cam, &node, world)?;
            }
            if let Some(light) = node.light() {
                let l = punctual_light(&self.src.file, &light, world)?;
                if light.range().is_some() {
                    tracing::info!(file = %self.src.file.display(), "light {}: range is ignored (inverse-square fall-off)", light.index());
                }
                self.scene.punctual_lights.push(l);
            }
            if let Some(mesh) = node.mesh() {
                // One placement, or one per EXT_mesh_gpu_instancing instance.
                let transforms = instance_transforms(&mut self.src, &node, world)?;
                self.scene.stats.mesh_instances += transforms.len();
                placements.push((mesh.index(), transforms));
            }
            on_path[idx] = true;
            stack.push(Step::Exit(idx));
            for child in node.children().collect::<Vec<_>>().into_iter().rev() {
                stack.push(Step::Enter(child, world));
            }
        }
        self.geometry(&doc, &placements)
    }

    /// Loads the meshes of `placements`: a mesh placed once is flattened into world space
    /// (all of them form mesh 0, one identity instance); a mesh placed several times is
    /// stored once in its local space and gets one [`MeshInstance`] per placement. The
    /// limits ([`check_instancing_limits`]) are checked before any geometry is decoded.
    fn geometry(
        &mut self,
        doc: &gltf::Document,
        placements: &[(usize, Vec<Mat4>)],
    ) -> Result<(), SceneError> {
        let mesh_of = |i: usize| doc.meshes().nth(i);
        let mut uses: HashMap<usize, usize> = HashMap::new();
        for (m, ts) in placements {
            *uses.entry(*m).or_default() += ts.len();
        }
        check_instancing_limits(&self.src.file, doc, placements, &uses)?;
        let mut virtual_count: u32 = 0;
        // Meshes placed once, flattened in traversal order.
        let flat_start = self.scene.triangles.len() as u32;
        for (m, ts) in placements {
            if uses[m] != 1 {
                continue;
            }
            let Some(mesh) = mesh_of(*m) else { continue };
            for prim in mesh.primitives() {
                self.primitive(&mesh, &prim, ts[0])?;
            }
        }
        let flat = MeshRange {
            first_triangle: flat_start,
            triangle_count: self.scene.triangles.len() as u32 - flat_start,
        };
        if flat.triangle_count > 0 {
            self.scene.meshes.push(flat);
            self.scene
                .instances
                .push(MeshInstance::identity(0, flat, 0, 0));
            virtual_count = flat.triangle_count;
        }
        // Meshes placed several times: stored once, in local space.
        let mut stored: HashMap<usize, u32> = HashMap::new();
        for (m, ts) in placements {
            if uses[m] < 2 {
                continue;
            }
            let Some(mesh) = mesh_of(*m) else { continue };
            let index = match stored.get(m) {
                Some(&i) => i,
                None => {
                    let first = self.scene.triangles.len() as u32;
                    for prim in mesh.primitives() {
                        self.primitive(&mesh, &prim, Mat4::IDENTITY)?;
                    }
                    self.scene.meshes.push(MeshRange {
                        first_triangle: first,
                        triangle_count: self.scene.triangles.len() as u32 - first,
                    });
                    let i = (self.scene.meshes.len() - 1) as u32;
                    stored.insert(*m, i);
                    i
                }
            };
            let range = self.scene.meshes[index as usize];
            if range.triangle_count == 0 {
                continue;
            }
            for &t in ts {
                match MeshInstance::placed(index, range, t, virtual_count, 0) {
                    Some(inst) => {
                        self.scene.instances.push(inst);
                        self.scene.stats.instanced_placements += 1;
                        // Bounded by check_instancing_limits.
                        virtual_count += range.triangle_count;
                    }
                    None => self.scene.stats.singular_placements += 1,
                }
            }
        }
        if self.scene.stats.singular_placements > 0 {
            tracing::warn!(file = %self.src.file.display(), "{} placements of instanced meshes have a transform that cannot be inverted (zero scale); they are not rendered", self.scene.stats.singular_placements);
        }
        self.scene.stats.virtual_triangles = virtual_count as usize;
        Ok(())
    }

    /// Records the camera that `node` places (world transform `world`). Every camera node is
    /// kept, in traversal order; the render config chooses one ([`crate::config`]).
    fn camera(
        &mut self,
        cam: &gltf::Camera,
        node: &gltf::Node,
        world: Mat4,
    ) -> Result<(), SceneError> {
        let err = |reason: String| SceneError::Camera {
            file: self.file(),
            reason,
        };
        let index = cam.index();
        let (projection, aspect) = match cam.projection() {
            gltf::camera::Projection::Perspective(p) => {
                let yfov = p.yfov();
                if !(yfov > 0.0 && yfov < std::f32::consts::PI) {
                    return Err(err(format!(
                        "cameras[{index}].perspective.yfov: {yfov} is not in (0, π)"
                    )));
                }
                let aspect = p.aspect_ratio();
                if aspect.is_some_and(|a| !(a > 0.0 && a.is_finite())) {
                    return Err(err(format!(
                        "cameras[{index}].perspective.aspectRatio must be positive"
                    )));
                }
                (
                    CameraProjection::Perspective {
                        fov_y_degrees: yfov.to_degrees(),
                    },
                    aspect,
                )
            }
            gltf::camera::Projection::Orthographic(o) => {
                // The spec: xmag and ymag MUST NOT be zero and SHOULD NOT be negative; a
                // negative one would mirror the image, so only its magnitude is used.
                let mut mag = [0.0f32; 2];
                for (k, (key, v)) in [("xmag", o.xmag()), ("ymag", o.ymag())]
                    .into_iter()
                    .enumerate()
                {
                    if !(v != 0.0 && v.is_finite()) {
                        return Err(err(format!(
                            "cameras[{index}].orthographic.{key}: {v} must be finite and not zero"
                        )));
                    }
                    if v < 0.0 {
                        tracing::warn!(file = %self.src.file.display(), "cameras[{index}].orthographic.{key} is negative ({v}); its magnitude is used");
                    }
                    mag[k] = v.abs();
                }
                (
                    CameraProjection::Orthographic {
                        half_height: mag[1],
                    },
                    Some(mag[0] / mag[1]),
                )
            }
        };
        let position = world.transform_point3(Vec3::ZERO);
        let forward = world.transform_vector3(-Vec3::Z).normalize_or_zero();
        let up = world.transform_vector3(Vec3::Y).normalize_or_zero();
        if forward == Vec3::ZERO
            || up == Vec3::ZERO
            || forward.cross(up).length_squared() < 1e-12
            || !position.is_finite()
        {
            // A zero scale is valid glTF (it hides a node): such a camera cannot look anywhere,
            // so it is left out with a warning rather than failing the whole file.
            tracing::warn!(file = %self.src.file.display(), "node {} places cameras[{index}] with a degenerate transform (zero scale or a collapsed axis); that camera node is skipped", node.index());
            return Ok(());
        }
        self.scene.cameras.push(CameraDesc {
            index,
            name: cam.name().map(str::to_string),
            node: node.index(),
            node_name: node.name().map(str::to_string),
            position,
            forward,
            up,
            projection,
            aspect,
        });
        Ok(())
    }

    /// Scene material index for glTF material `m`, converting it (and decoding its base colour
    /// texture) on first use.
    fn material(&mut self, m: &gltf::Material) -> Result<u32, SceneError> {
        if let Some(&i) = self.material_map.get(&m.index()) {
            return Ok(i);
        }
        let name = match (m.index(), m.name()) {
            (None, _) => "default".to_string(),
            (Some(_), Some(n)) => n.to_string(),
            (Some(i), None) => format!("material{i}"),
        };
        let merr = |file: PathBuf, reason: String| SceneError::Material {
            file,
            material: name.clone(),
            reason,
        };
        let mut mat = match m.index() {
            None => Material::default(),
            Some(_) => convert(m).map_err(|e| merr(self.file(), e))?,
        };
        let pbr = m.pbr_metallic_roughness();
        mat.base_alpha = pbr.base_color_factor()[3];
        mat.alpha_mode = match m.alpha_mode() {
            gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
            gltf::material::AlphaMode::Mask => AlphaMode::Mask,
            gltf::material::AlphaMode::Blend => AlphaMode::Blend,
        };
        mat.alpha_cutoff = m.alpha_cutoff().unwrap_or(0.5);
        if !(mat.alpha_cutoff.is_finite() && mat.alpha_cutoff >= 0.0) {
            return Err(merr(
                self.file(),
                format!("alphaCutoff = {} must be finite and >= 0", mat.alpha_cutoff),
            ));
        }
        let tt = |i: &gltf::texture::Info| {
            i.texture_transform().map(|t| Transform {
                offset: t.offset(),
                rotation: t.rotation(),
                scale: t.scale(),
                tex_coord: t.tex_coord(),
            })
        };
        if let Some(info) = pbr.base_color_texture() {
            mat.base_color_texture =
                self.texture_ref(&info.texture(), info.tex_coord(), tt(&info), &name)?;
        }
        if let Some(info) = pbr.metallic_roughness_texture() {
            mat.metallic_roughness_texture =
                self.texture_ref(&info.texture(), info.tex_coord(), tt(&info), &name)?;
        }
        if let Some(info) = m.emissive_texture() {
            mat.emissive_texture =
                self.texture_ref(&info.texture(), info.tex_coord(), tt(&info), &name)?;
        }
        if let Some(n) = m.normal_texture() {
            let t = transform_from_json(n.extension_value("KHR_texture_transform"))
                .map_err(|e| merr(self.file(), format!("normalTexture: {e}")))?;
            let mut r = self.texture_ref(&n.texture(), n.tex_coord(), t, &name)?;
            r.scale = n.scale();
            if !r.scale.is_finite() {
                return Err(merr(
                    self.file(),
                    "normalTexture.scale is not finite".into(),
                ));
            }
            mat.normal_texture = r;
        }
        if let Some(o) = m.occlusion_texture() {
            let t = transform_from_json(o.extension_value("KHR_texture_transform"))
                .map_err(|e| merr(self.file(), format!("occlusionTexture: {e}")))?;
            let mut r = self.texture_ref(&o.texture(), o.tex_coord(), t, &name)?;
            r.scale = o.strength();
            mat.occlusion_texture = r;
        }
        self.extension_textures(m, &mut mat, &name)?;
        if let Some(o) = self.overrides.get(&name) {
            o.validate()
                .map_err(|e| merr(self.file(), format!("config override: {e}")))?;
            o.apply(&mut mat);
        }
        self.scene.materials.push(mat);
        self.scene.material_names.push(name);
        let i = (self.scene.materials.len() - 1) as u32;
        self.material_map.insert(m.index(), i);
        Ok(i)
    }

    /// The texture references of the BRDF extensions (transmission, volume thickness,
    /// specular, specular colour, clearcoat, clearcoat roughness); see
    /// [`crate::material::clearcoat_textures`] for the clearcoat ones.
    fn extension_textures(
        &mut self,
        m: &gltf::Material,
        mat: &mut Material,
        name: &str,
    ) -> Result<(), SceneError> {
        let mut info = |i: Option<gltf::texture::Info>| -> Result<TextureRef, SceneError> {
            let Some(i) = i else {
                return Ok(TextureRef::NONE);
            };
            let t = i.texture_transform().map(|t| Transform {
                offset: t.offset(),
                rotation: t.rotation(),
                scale: t.scale(),
                tex_coord: t.tex_coord(),
            });
            self.texture_ref(&i.texture(), i.tex_coord(), t, name)
        };
        if let Some(t) = m.transmission() {
            mat.transmission_texture = info(t.transmission_texture())?;
        }
        if let Some(v) = m.volume() {
            mat.thickness_texture = info(v.thickness_texture())?;
        }
        if let Some(s) = m.specular() {
            mat.specular_texture = info(s.specular_texture())?;
            mat.specular_color_texture = info(s.specular_color_texture())?;
        }
        let merr = |file: PathBuf, reason: String| SceneError::Material {
            file,
            material: name.to_string(),
            reason,
        };
        let count = self.src.document.textures().len();
        let coat =
            crate::material::clearcoat_textures(m, count).map_err(|e| merr(self.file(), e))?;
        for (slot, raw) in coat.into_iter().enumerate() {
            let Some(raw) = raw else { continue };
            let t = transform_from_json(raw.transform.as_ref())
                .map_err(|e| merr(self.file(), format!("KHR_materials_clearcoat: {e}")))?;
            let doc = self.src.document.clone();
            let tex = doc.textures().nth(raw.index).expect("index checked");
            let r = self.texture_ref(&tex, raw.tex_coord, t, name)?;
            if slot == 0 {
                mat.clearcoat_texture = r;
            } else {
                mat.clearcoat_roughness_texture = r;
            }
        }
        Ok(())
    }

    /// The scene texture for glTF texture `tex` (decoding its image on first use; images are
    /// shared between textures), as a reference through texture-coordinate set `tex_coord`
    /// with an optional `KHR_texture_transform`.
    fn texture_ref(
        &mut self,
        tex: &gltf::Texture,
        tex_coord: u32,
        transform: Option<Transform>,
        material: &str,
    ) -> Result<TextureRef, SceneError> {
        let index = match self.texture_map.get(&tex.index()) {
            Some(&t) => t,
            None => {
                let image = tex.source();
                let data = match self.image_map.get(&image.index()) {
                    Some(d) => d.clone(),
                    None => {
                        let d = load_image(&mut self.src, &image)?;
                        self.scene.stats.images_decoded += 1;
                        self.image_map.insert(image.index(), d.clone());
                        d
                    }
                };
                self.scene.textures.push(TextureData {
                    image: data,
                    sampler: Sampler::from_gltf(&tex.sampler()),
                });
                let t = (self.scene.textures.len() - 1) as i32;
                self.texture_map.insert(tex.index(), t);
                t
            }
        };
        let mut r = TextureRef::new(index, tex_coord);
        if let Some(t) = transform {
            r = r.with_transform(t.offset, t.rotation, t.scale);
            if let Some(c) = t.tex_coord {
                r.tex_coord = c;
            }
            if !r.transform.iter().all(|v| v.is_finite()) {
                return Err(SceneError::Material {
                    file: self.file(),
                    material: material.to_string(),
                    reason: format!(
                        "texture {}: KHR_texture_transform is not finite",
                        tex.index()
                    ),
                });
            }
        }
        if r.tex_coord > 1 {
            tracing::warn!(file = %self.src.file.display(), "material '{material}': texture {} reads TEXCOORD_{}; only sets 0 and 1 are loaded, it reads TEXCOORD_1", tex.index(), r.tex_coord);
            r.tex_coord = 1;
        }
        Ok(r)
    }

    fn primitive(
        &mut self,
        mesh: &gltf::Mesh,
        prim: &gltf::Primitive,
        world: Mat4,
    ) -> Result<(), SceneError> {
        let what = format!("mesh {} primitive {}", mesh.index(), prim.index());
        let mode = prim.mode();
        if !matches!(
            mode,
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            tracing::warn!(file = %self.src.file.display(), "{what}: mode {mode:?} is not triangles; skipped");
            self.scene.stats.skipped_primitives += 1;
            return Ok(());
        }
        let Some(pos_acc) = prim.get(&Semantic::Positions) else {
            tracing::warn!(file = %self.src.file.display(), "{what}: no POSITION attribute; skipped");
            self.scene.stats.skipped_no_position += 1;
            return Ok(());
        };
        let positions = read_floats::<3>(&mut self.src, &pos_acc)?;
        let n = positions.len();
        let count_err = |src: &GltfSource, acc: &gltf::Accessor, got: usize| SceneError::Accessor {
            file: src.file.clone(),
            accessor: acc.index(),
            reason: format!("{what}: has {got} elements but POSITION has {n}"),
        };
        let normals = match prim.get(&Semantic::Normals) {
            Some(acc) => {
                let v = read_floats::<3>(&mut self.src, &acc)?;
                if v.len() != n {
                    return Err(count_err(&self.src, &acc, v.len()));
                }
                Some(v)
            }
            None => None,
        };
        let material = prim.material();
        let read2 =
            |src: &mut GltfSource, sem: Semantic| -> Result<Option<Vec<[f32; 2]>>, SceneError> {
                match prim.get(&sem) {
                    Some(acc) => {
                        let v = read_floats::<2>(src, &acc)?;
                        if v.len() != n {
                            return Err(count_err(src, &acc, v.len()));
                        }
                        Ok(Some(v))
                    }
                    None => Ok(None),
                }
            };
        let uvs = read2(&mut self.src, Semantic::TexCoords(0))?;
        let uvs1 = read2(&mut self.src, Semantic::TexCoords(1))?;
        let colors: Option<Vec<[f32; 4]>> = match prim.get(&Semantic::Colors(0)) {
            Some(acc) => {
                let v: Vec<[f32; 4]> = match acc.dimensions() {
                    gltf::accessor::Dimensions::Vec3 => read_floats::<3>(&mut self.src, &acc)?
                        .into_iter()
                        .map(|[r, g, b]| [r, g, b, 1.0])
                        .collect(),
                    _ => read_floats::<4>(&mut self.src, &acc)?,
                };
                if v.len() != n {
                    return Err(count_err(&self.src, &acc, v.len()));
                }
                Some(v)
            }
            None => None,
        };
        if prim.get(&Semantic::Colors(1)).is_some() {
            tracing::warn!(file = %self.src.file.display(), "{what}: COLOR_1 and beyond are ignored (glTF materials only use COLOR_0)");
        }
        let file_tangents = match prim.get(&Semantic::Tangents) {
            Some(acc) => {
                let v = read_floats::<4>(&mut self.src, &acc)?;
                if v.len() != n {
                    return Err(count_err(&self.src, &acc, v.len()));
                }
                Some(v)
            }
            None => None,
        };
        let indices = match prim.indices() {
            Some(acc) => {
                let idx = read_indices(&mut self.src, &acc)?;
                if let Some(&bad) = idx.iter().find(|&&i| i as usize >= n) {
                    return Err(SceneError::Accessor {
                        file: self.file(),
                        accessor: acc.index(),
                        reason: format!("{what}: index {bad} is out of range ({n} vertices)"),
                    });
                }
                idx
            }
            None => (0..n as u32).collect(),
        };
        let mut tris: Vec<[u32; 3]> = match mode {
            Mode::Triangles => {
                if indices.len() % 3 != 0 {
                    tracing::warn!(file = %self.src.file.display(), "{what}: {} indices is not a multiple of 3; the rest is ignored", indices.len());
                }
                indices
                    .chunks_exact(3)
                    .map(|c| [c[0], c[1], c[2]])
                    .collect()
            }
            Mode::TriangleStrip => {
                self.scene.stats.converted_strips_fans += 1;
                (0..indices.len().saturating_sub(2))
                    .map(|i| {
                        if i % 2 == 0 {
                            [indices[i], indices[i + 1], indices[i + 2]]
                        } else {
                            [indices[i], indices[i + 2], indices[i + 1]]
                        }
                    })
                    .collect()
            }
            _ => {
                self.scene.stats.converted_strips_fans += 1;
                (0..indices.len().saturating_sub(2))
                    .map(|i| [indices[i + 1], indices[i + 2], indices[0]])
                    .collect()
            }
        };
        let linear = Mat3::from_mat4(world);
        if linear.determinant() < 0.0 {
            for t in &mut tris {
                t.swap(1, 2);
            }
        }
        let normal_matrix = linear.inverse().transpose();
        let wp: Vec<Vec3> = positions
            .iter()
            .map(|&p| world.transform_point3(Vec3::from_array(p)))
            .collect();
        let mat_index = self.material(&material)?;
        let mat = self.scene.materials[mat_index as usize];
        let emissive = mat.is_emissive();
        let nm_ok = normal_matrix.is_finite();
        let world_normals: Option<Vec<Vec3>> = normals.as_ref().map(|ns| {
            ns.iter()
                .map(|&v| {
                    if nm_ok {
                        (normal_matrix * Vec3::from_array(v)).normalize_or_zero()
                    } else {
                        Vec3::ZERO
                    }
                })
                .collect()
        });
        let corner_tangents = corner_tangents(
            &self.src.file,
            &what,
            &mat,
            &tris,
            &wp,
            world_normals.as_deref(),
            [uvs.as_deref(), uvs1.as_deref()],
            file_tangents.as_deref(),
            linear,
        );
        self.any_uv0 |= uvs.is_some();
        self.any_uv1 |= uvs1.is_some();
        self.any_color |= colors.is_some();
        self.any_tangent |= corner_tangents.is_some();
        let uv_at = |set: &Option<Vec<[f32; 2]>>, v: usize| {
            set.as_ref().map_or(Vec2::ZERO, |u| Vec2::from_array(u[v]))
        };
        let color_at = |v: usize| colors.as_ref().map_or([1.0; 4], |c| c[v]);

        let flat = world_normals.is_none();
        // A flat primitive keeps its vertices shared with zero normals: the interpolated
        // normal vanishes and `MeshView::surface_hit` takes the geometric normal, the face
        // normal the spec asks for. For a scan of shared vertices that is a sixth of the
        // vertex memory of duplicating them (the Stanford dragon: 437k vertices instead of
        // 2.6M, no normals to read at a hit). Normal mapping needs a tangent frame per corner
        // of a triangle, so a flat, normal-mapped primitive is unwelded, as before.
        let unweld = flat && corner_tangents.is_some();
        self.any_normal |= !flat || unweld;
        if flat {
            self.scene.stats.flat_shaded_primitives += 1;
        }
        // Which triangles are kept; the dropped ones are counted.
        let kept: Vec<bool> = tris
            .iter()
            .map(|&t| {
                let stats = &mut self.scene.stats;
                let [a, b, c] = t.map(|i| i as usize);
                let dropped = if a == b || b == c || a == c {
                    stats.dropped_repeated_index += 1;
                    true
                } else if !(wp[a].is_finite() && wp[b].is_finite() && wp[c].is_finite()) {
                    stats.dropped_non_finite += 1;
                    true
                } else if triangle_normal(wp[a], wp[b], wp[c]).is_none()
                    || (triangle_area(wp[a], wp[b], wp[c]) as f32) <= 0.0
                {
                    stats.dropped_zero_area += 1;
                    true
                } else {
                    false
                };
                if dropped {
                    stats.degenerate_dropped += 1;
                    stats.dropped_emitters += emissive as usize;
                }
                !dropped
            })
            .collect();
        let kept_triangles = || {
            tris.iter()
                .enumerate()
                .filter(|&(k, _)| kept[k])
                .map(|(k, &t)| (k, t))
        };
        if unweld {
            for (k, t) in kept_triangles() {
                let [a, b, c] = t.map(|i| i as usize);
                let face_n = triangle_normal(wp[a], wp[b], wp[c]).unwrap_or(Vec3::Z);
                let sc = &mut self.scene;
                let first = sc.positions.len() as u32;
                for (j, v) in [a, b, c].into_iter().enumerate() {
                    sc.positions.push(wp[v]);
                    sc.normals.push(face_n);
                    sc.uvs.push(uv_at(&uvs, v));
                    sc.uvs1.push(uv_at(&uvs1, v));
                    sc.colors.push(color_at(v));
                    sc.tangents.push(
                        corner_tangents
                            .as_ref()
                            .map_or([0.0; 4], |ct| ct[3 * k + j]),
                    );
                }
                sc.triangles.push([first, first + 1, first + 2]);
                sc.triangle_material.push(mat_index);
            }
            return Ok(());
        }
        // Shared vertices: those of kept triangles, in the file's order (a vertex that only
        // dropped triangles use may be non-finite, and takes no memory).
        let mut tv = vec![[0.0f32; 4]; n];
        if let Some(ct) = &corner_tangents {
            for (k, t) in tris.iter().enumerate() {
                for j in 0..3 {
                    tv[t[j] as usize] = ct[3 * k + j];
                }
            }
        }
        let mut used = vec![false; n];
        for (_, t) in kept_triangles() {
            for i in t {
                used[i as usize] = true;
            }
        }
        let sc = &mut self.scene;
        let mut remap = vec![u32::MAX; n];
        for v in (0..n).filter(|&v| used[v]) {
            remap[v] = sc.positions.len() as u32;
            sc.positions.push(wp[v]);
            sc.normals
                .push(world_normals.as_ref().map_or(Vec3::ZERO, |ns| ns[v]));
            sc.uvs.push(uv_at(&uvs, v));
            sc.uvs1.push(uv_at(&uvs1, v));
            sc.colors.push(color_at(v));
            sc.tangents.push(tv[v]);
        }
        for (_, t) in kept_triangles() {
            sc.triangles.push(t.map(|i| remap[i as usize]));
            sc.triangle_material.push(mat_index);
        }
        Ok(())
    }

    fn finish(mut self) -> Result<Scene, SceneError> {
        let file = self.file();
        let scene = &mut self.scene;
        // Attributes no primitive had take no memory, and a hit reads none of them (a scan
        // without normals or texture coordinates: three cache lines fewer each, per hit).
        if !self.any_normal {
            scene.normals = Vec::new();
        }
        if !self.any_uv0 {
            scene.uvs = Vec::new();
        }
        if !self.any_uv1 {
            scene.uvs1 = Vec::new();
        }
        if !self.any_color {
            scene.colors = Vec::new();
        }
        if !self.any_tangent {
            scene.tangents = Vec::new();
        }
        scene.sync_texture_views();
        if scene.triangles.is_empty() {
            return Err(SceneError::NoTriangles { file });
        }
        warn_if_beyond_f32_range(&file, scene);
        for name in self.overrides.keys() {
            if !scene.material_names.contains(name) {
                tracing::warn!(file = %file.display(), "material override '{name}' matches no loaded material");
            }
        }
        scene.triangle_emitter = vec![-1; scene.triangles.len()];
        // Each stored emissive triangle once (its radiance does not depend on where it is
        // placed), ranked within its mesh ...
        let views = scene.texture_views();
        let mut mesh_emitters: Vec<Vec<(usize, Emitter)>> = vec![Vec::new(); scene.meshes.len()];
        for (mi, range) in scene.meshes.iter().enumerate() {
            let first = range.first_triangle as usize;
            for prim in first..first + range.triangle_count as usize {
                let tri = scene.triangles[prim];
                let material = scene.triangle_material[prim];
                let m = &scene.materials[material as usize];
                if !m.is_emissive() {
                    continue;
                }
                let [p0, p1, p2] = tri.map(|i| scene.positions[i as usize]);
                let uv = tri.map(|i| scene.uvs.get(i as usize).copied().unwrap_or(Vec2::ZERO));
                // TEXCOORD_1 takes memory only when some primitive has it.
                let uv1 = if scene.uvs1.is_empty() {
                    uv
                } else {
                    tri.map(|i| scene.uvs1[i as usize])
                };
                let mut e = Emitter {
                    p0,
                    p1,
                    p2,
                    n: triangle_normal(p0, p1, p2).unwrap_or(Vec3::Z),
                    area: triangle_area(p0, p1, p2) as f32,
                    radiance: m.emission,
                    double_sided: m.two_sided_emission,
                    prim: prim as u32,
                    material,
                    uv0: uv,
                    uv1,
                };
                let strata = emission_strata(&e, &m.emissive_texture, &views);
                e.radiance = mean_emission(&e, strata, |uv| m.emission_at(uv, &views));
                if e.radiance.is_black() || e.power() <= 0.0 {
                    scene.stats.black_emitters += 1;
                    continue;
                }
                scene.triangle_emitter[prim] = mesh_emitters[mi].len() as i32;
                mesh_emitters[mi].push((prim, e));
            }
        }
        // ... then placed once per instance: each instance of an emissive mesh is its own
        // light, in world space, naming its virtual triangle.
        for inst in scene.instances.iter_mut() {
            inst.first_emitter = scene.emitters.len() as u32;
            for &(prim, e) in &mesh_emitters[inst.mesh as usize] {
                let local = (prim - inst.first_triangle as usize) as u32;
                let mut e = e;
                e.prim = inst.first_virtual + local;
                if !inst.identity {
                    let m = inst.object_to_world;
                    let (mut p, mut uv0, mut uv1) = ([e.p0, e.p1, e.p2], e.uv0, e.uv1);
                    if inst.mirror {
                        p.swap(1, 2);
                        uv0.swap(1, 2);
                        uv1.swap(1, 2);
                    }
                    let [p0, p1, p2] = p.map(|q| m.transform_point3(q));
                    e.p0 = p0;
                    e.p1 = p1;
                    e.p2 = p2;
                    e.uv0 = uv0;
                    e.uv1 = uv1;
                    e.n = triangle_normal(p0, p1, p2).unwrap_or(Vec3::Z);
                    e.area = triangle_area(p0, p1, p2) as f32;
                }
                scene.emitters.push(e);
            }
        }
        if !scene.emitters.is_empty() {
            let powers: Vec<f32> = scene.emitters.iter().map(Emitter::power).collect();
            scene.emitter_power_cdf = build_cdf(&powers).ok_or_else(|| SceneError::Primitive {
                file: file.clone(),
                reason: "the emitters' total power is not finite".into(),
            })?;
        }
        let virtual_triangles = scene.virtual_triangle_count();
        let s = &mut scene.stats;
        s.triangles = scene.triangles.len();
        s.vertices = scene.positions.len();
        s.virtual_triangles = virtual_triangles;
        if s.degenerate_dropped > 0 {
            tracing::warn!(
                file = %file.display(),
                "dropped {} degenerate triangles ({} zero-area, {} non-finite, {} repeated-index; {} of them emissive)",
                s.degenerate_dropped, s.dropped_zero_area, s.dropped_non_finite, s.dropped_repeated_index, s.dropped_emitters
            );
        }
        tracing::info!(
            file = %file.display(),
            "loaded {} triangles, {} vertices, {} materials, {} textures, {} emitters, {} punctual lights",
            s.triangles, s.vertices, scene.materials.len(), scene.textures.len(), scene.emitters.len(), scene.punctual_lights.len()
        );
        if s.instanced_placements > 0 {
            tracing::info!(
                file = %file.display(),
                "instancing: {} placements of {} meshes stored once show {} triangles",
                s.instanced_placements, scene.meshes.len() - usize::from(scene.instances[0].identity), s.virtual_triangles
            );
        }
        self.scene.files = self.src.referenced_files();
        Ok(self.scene)
    }
}

/// Tangents per triangle corner (3 per entry of `tris`, world space, w = ±1): the TANGENT
/// attribute transformed by the node's linear part (w flipped under a mirroring transform,
/// since then n × t flips), or, when the material has a normal map and the file no tangents,
/// MikkTSpace tangents (the glTF 2.0 spec's choice, §3.7.2.1) from the world-space positions,
/// normals and the normal map's texture-coordinate set. MikkTSpace is given (u, 1 − v) so
/// that its bitangent points along −∂p/∂v, the normal map's +Y ("up" in the image).
/// `None` when neither applies.
#[allow(clippy::too_many_arguments)]
fn corner_tangents(
    file: &Path,
    what: &str,
    mat: &Material,
    tris: &[[u32; 3]],
    wp: &[Vec3],
    normals: Option<&[Vec3]>,
    uvs: [Option<&[[f32; 2]]>; 2],
    file_tangents: Option<&[[f32; 4]]>,
    linear: Mat3,
) -> Option<Vec<[f32; 4]>> {
    if let Some(ft) = file_tangents {
        let mirror = if linear.determinant() < 0.0 {
            -1.0
        } else {
            1.0
        };
        let tv: Vec<[f32; 4]> = ft
            .iter()
            .map(|t| {
                let x = (linear * Vec3::new(t[0], t[1], t[2])).normalize_or_zero();
                let w = if t[3] < 0.0 { -1.0 } else { 1.0 } * mirror;
                if x.is_finite() {
                    [x.x, x.y, x.z, w]
                } else {
                    [0.0; 4]
                }
            })
            .collect();
        return Some(
            tris.iter()
                .flat_map(|t| t.map(|i| tv[i as usize]))
                .collect(),
        );
    }
    if !mat.normal_texture.is_some() {
        return None;
    }
    let set = (mat.normal_texture.tex_coord as usize).min(1);
    let Some(uv) = uvs[set] else {
        tracing::warn!(file = %file.display(), "{what}: the normal map reads TEXCOORD_{set}, which the primitive lacks; normal map ignored");
        return None;
    };
    struct Mikk<'a> {
        tris: &'a [[u32; 3]],
        wp: &'a [Vec3],
        normals: Option<&'a [Vec3]>,
        uv: &'a [[f32; 2]],
        out: Vec<[f32; 4]>,
    }
    impl Mikk<'_> {
        fn vertex(&self, face: usize, vert: usize) -> usize {
            self.tris[face][vert] as usize
        }
    }
    impl bevy_mikktspace::Geometry for Mikk<'_> {
        fn num_faces(&self) -> usize {
            self.tris.len()
        }
        fn num_vertices_of_face(&self, _face: usize) -> usize {
            3
        }
        fn position(&self, face: usize, vert: usize) -> [f32; 3] {
            self.wp[self.vertex(face, vert)].to_array()
        }
        fn normal(&self, face: usize, vert: usize) -> [f32; 3] {
            match self.normals {
                Some(n) => n[self.vertex(face, vert)].to_array(),
                None => {
                    let [a, b, c] = self.tris[face].map(|i| self.wp[i as usize]);
                    triangle_normal(a, b, c).unwrap_or(Vec3::Z).to_array()
                }
            }
        }
        fn tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
            let t = self.uv[self.vertex(face, vert)];
            [t[0], 1.0 - t[1]]
        }
        fn set_tangent(
            &mut self,
            tangent: Option<bevy_mikktspace::TangentSpace>,
            face: usize,
            vert: usize,
        ) {
            if let Some(t) = tangent {
                self.out[3 * face + vert] = t.tangent_encoded();
            }
        }
    }
    let mut m = Mikk {
        tris,
        wp,
        normals,
        uv,
        out: vec![[0.0; 4]; tris.len() * 3],
    };
    if let Err(e) = bevy_mikktspace::generate_tangents(&mut m) {
        tracing::warn!(file = %file.display(), "{what}: MikkTSpace could not compute tangents ({e:?}); per-face tangents are used");
        return None;
    }
    Some(m.out)
}

/// Most mesh instances a scene may have (nodes with a mesh plus `EXT_mesh_gpu_instancing`
/// placements): 2²⁴. Each costs about [`BYTES_PER_INSTANCE`] in the scene, the two-level
/// BVH and Embree's instance geometry.
pub const MAX_INSTANCES: u64 = 1 << 24;
/// Most triangles a scene may show, every instance's counted: virtual triangle ids are
/// `u32`, and `u32::MAX` means "no triangle".
pub const MAX_VIRTUAL_TRIANGLES: u64 = u32::MAX as u64 - 1;
/// Estimated resident bytes per stored triangle: its vertices' attributes and indices in the
/// scene, and the BVH's or Embree's copy and nodes. Measured on a sphere with unshared
/// vertices (three per triangle, the worst case): 133 bytes in the scene, 147 in the BVH,
/// 145 in Embree (`examples/instancing_memory.rs` of the host).
pub const BYTES_PER_STORED_TRIANGLE: u64 = 280;
/// Estimated resident bytes per instance: the scene's [`MeshInstance`] (≈ 200), the
/// two-level BVH's entry and node (≈ 140) and Embree's instance geometry (a few hundred).
pub const BYTES_PER_INSTANCE: u64 = 512;

/// Triangles primitive `prim` will have, from its accessors' counts (nothing decoded).
fn primitive_triangles(prim: &gltf::Primitive) -> u64 {
    let Some(pos) = prim.get(&Semantic::Positions) else {
        return 0;
    };
    let n = prim.indices().map_or(pos.count(), |i| i.count()) as u64;
    match prim.mode() {
        Mode::Triangles => n / 3,
        Mode::TriangleStrip | Mode::TriangleFan => n.saturating_sub(2),
        _ => 0,
    }
}

/// Refuses, before any geometry is decoded, a scene whose instance count or instanced
/// (virtual) triangle count exceeds [`MAX_INSTANCES`] / [`MAX_VIRTUAL_TRIANGLES`], or whose
/// estimated geometry memory (stored triangles × [`BYTES_PER_STORED_TRIANGLE`] + instances ×
/// [`BYTES_PER_INSTANCE`]) exceeds the memory available ([`crate::memory`]: `MemAvailable`,
/// the memory cgroup's limit, `RLIMIT_AS`).
fn check_instancing_limits(
    file: &Path,
    doc: &gltf::Document,
    placements: &[(usize, Vec<Mat4>)],
    uses: &HashMap<usize, usize>,
) -> Result<(), SceneError> {
    let mesh_tris: HashMap<usize, u64> = uses
        .keys()
        .filter_map(|&m| {
            let mesh = doc.meshes().nth(m)?;
            Some((m, mesh.primitives().map(|p| primitive_triangles(&p)).sum()))
        })
        .collect();
    let instances: u64 = placements.iter().map(|(_, t)| t.len() as u64).sum();
    let virtual_tris: u64 = placements
        .iter()
        .map(|(m, t)| mesh_tris.get(m).copied().unwrap_or(0) * t.len() as u64)
        .sum();
    // Every mesh is stored once: flattened when placed once, in local space otherwise.
    let stored: u64 = uses.keys().filter_map(|m| mesh_tris.get(m)).sum();
    let err = |reason: String| SceneError::Limit {
        file: file.to_path_buf(),
        reason,
    };
    if instances > MAX_INSTANCES {
        return Err(err(format!(
            "{instances} mesh instances exceed the limit of {MAX_INSTANCES}"
        )));
    }
    if virtual_tris > MAX_VIRTUAL_TRIANGLES {
        return Err(err(format!(
            "{instances} mesh instances show {virtual_tris} triangles, beyond the limit of {MAX_VIRTUAL_TRIANGLES} (32-bit triangle ids)"
        )));
    }
    let need = stored * BYTES_PER_STORED_TRIANGLE + instances * BYTES_PER_INSTANCE;
    if let Some(avail) = available_memory() {
        if need > avail {
            return Err(err(format!(
                "{stored} stored triangles and {instances} mesh instances need about {} MiB ({need} bytes) but {} MiB is available",
                need >> 20,
                avail >> 20
            )));
        }
    }
    Ok(())
}

use crate::memory::available_memory;

/// Largest coordinate magnitude the ray/triangle arithmetic takes without overflow: the
/// watertight test and the error bounds multiply three coordinates (x³ < f32::MAX ≈ 3.4e38).
pub const MAX_COORDINATE: f32 = 1e12;
/// Smallest scene extent whose triangle arithmetic stays clear of subnormal numbers (the
/// products of three edge lengths, 1e-38).
pub const MIN_EXTENT: f32 = 1e-12;

/// Logs one warning when the scene's coordinates are so large, or its extent so small, that
/// f32 ray tracing loses hits (issue: a Cornell box scaled to 1e14 rendered black with the
/// BVH and lost its lamp with Embree, silently).
fn warn_if_beyond_f32_range(file: &Path, scene: &Scene) {
    let Some((lo, hi)) = scene.bounds() else {
        return;
    };
    let largest = lo.abs().max(hi.abs()).max_element();
    let extent = (hi - lo).max_element();
    if largest > MAX_COORDINATE {
        tracing::warn!(
            file = %file.display(),
            "coordinates reach {largest:e}, beyond {MAX_COORDINATE:e}: f32 ray/triangle arithmetic overflows there and hits are lost; scale the scene down (e.g. a root node with scale {:e})",
            MAX_COORDINATE / largest
        );
    } else if extent < MIN_EXTENT {
        tracing::warn!(
            file = %file.display(),
            "the scene is {extent:e} across, below {MIN_EXTENT:e}: f32 ray/triangle arithmetic underflows and hits are lost; scale the scene up"
        );
    }
}
