//! Walks a glTF 2.0 document's default scene into a world-space [`Scene`].
//!
//! - Node transforms (TRS or matrix) are composed down the hierarchy; normals use the
//!   inverse-transpose and the winding is flipped under a negative determinant, so a
//!   counter-clockwise front face stays the front face.
//! - Only triangle primitives are loaded: TRIANGLES as they are, TRIANGLE_STRIP and
//!   TRIANGLE_FAN converted to lists; points and lines are skipped with a warning and counted.
//! - Primitives without NORMAL get flat per-face normals by duplicating their vertices (the glTF
//!   spec asks for flat normals then).
//! - Only the materials and images that loaded primitives use are converted and decoded.
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
use crate::lights::{mean_emission, punctual_light};
use crate::material::{convert, MaterialOverride};
use crate::scene::{triangle_area, triangle_normal, CameraDesc, CameraProjection, Scene};
use crate::source::GltfSource;
use crate::texture::load_image;
use flowlight_core::light::Emitter;
use flowlight_core::material::Material;
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
    /// glTF image index to scene texture index.
    image_map: HashMap<usize, i32>,
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
        let mut on_path = vec![false; doc.nodes().len()];
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
                for placed in instance_transforms(&mut self.src, &node, world)? {
                    self.scene.stats.mesh_instances += 1;
                    for prim in mesh.primitives() {
                        self.primitive(&mesh, &prim, placed)?;
                    }
                }
            }
            on_path[idx] = true;
            stack.push(Step::Exit(idx));
            for child in node.children().collect::<Vec<_>>().into_iter().rev() {
                stack.push(Step::Enter(child, world));
            }
        }
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
        if let Some(info) = m.pbr_metallic_roughness().base_color_texture() {
            let image = info.texture().source();
            let ti = match self.image_map.get(&image.index()) {
                Some(&t) => t,
                None => {
                    let data = load_image(&mut self.src, &image, true)?;
                    self.scene.textures.push(data);
                    self.scene.stats.images_decoded += 1;
                    let t = (self.scene.textures.len() - 1) as i32;
                    self.image_map.insert(image.index(), t);
                    t
                }
            };
            mat.base_color_texture = ti;
        }
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
        let uv_set = material
            .pbr_metallic_roughness()
            .base_color_texture()
            .map_or(0, |t| t.tex_coord());
        let uvs = match prim.get(&Semantic::TexCoords(uv_set)) {
            Some(acc) => {
                let v = read_floats::<2>(&mut self.src, &acc)?;
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
        let emissive = self.scene.materials[mat_index as usize].is_emissive();

        let base = self.scene.positions.len();
        let flat = normals.is_none();
        if flat {
            self.scene.stats.flat_shaded_primitives += 1;
        } else {
            let ns = normals.as_deref().unwrap_or_default();
            let nm_ok = normal_matrix.is_finite();
            self.scene.positions.extend_from_slice(&wp);
            self.scene.normals.extend(ns.iter().map(|&v| {
                if nm_ok {
                    (normal_matrix * Vec3::from_array(v)).normalize_or_zero()
                } else {
                    Vec3::ZERO
                }
            }));
            match &uvs {
                Some(uv) => self
                    .scene
                    .uvs
                    .extend(uv.iter().map(|&t| Vec2::from_array(t))),
                None => self.scene.uvs.extend(std::iter::repeat_n(Vec2::ZERO, n)),
            }
        }
        let stats = &mut self.scene.stats;
        for t in tris {
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
                continue;
            }
            if flat {
                let face_n = triangle_normal(wp[a], wp[b], wp[c]).unwrap_or(Vec3::Z);
                let first = self.scene.positions.len() as u32;
                for v in [a, b, c] {
                    self.scene.positions.push(wp[v]);
                    self.scene.normals.push(face_n);
                    self.scene.uvs.push(
                        uvs.as_ref()
                            .map_or(Vec2::ZERO, |uv| Vec2::from_array(uv[v])),
                    );
                }
                self.scene.triangles.push([first, first + 1, first + 2]);
            } else {
                self.scene.triangles.push(t.map(|i| i + base as u32));
            }
            self.scene.triangle_material.push(mat_index);
        }
        Ok(())
    }

    fn finish(mut self) -> Result<Scene, SceneError> {
        let file = self.file();
        let scene = &mut self.scene;
        if scene.triangles.is_empty() {
            return Err(SceneError::NoTriangles { file });
        }
        for name in self.overrides.keys() {
            if !scene.material_names.contains(name) {
                tracing::warn!(file = %file.display(), "material override '{name}' matches no loaded material");
            }
        }
        scene.triangle_emitter = vec![-1; scene.triangles.len()];
        let views = scene.texture_views();
        for (prim, tri) in scene.triangles.iter().enumerate() {
            let material = scene.triangle_material[prim];
            let m = &scene.materials[material as usize];
            if !m.is_emissive() {
                continue;
            }
            let [p0, p1, p2] = tri.map(|i| scene.positions[i as usize]);
            // One uv set is loaded today; both sets of the emitter carry it.
            let uv = tri.map(|i| scene.uvs[i as usize]);
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
                uv1: uv,
            };
            e.radiance = mean_emission(&e, |uv| m.emission_at(uv, &views));
            if e.radiance.is_black() || e.power() <= 0.0 {
                scene.stats.black_emitters += 1;
                continue;
            }
            scene.triangle_emitter[prim] = scene.emitters.len() as i32;
            scene.emitters.push(e);
        }
        if !scene.emitters.is_empty() {
            let powers: Vec<f32> = scene.emitters.iter().map(Emitter::power).collect();
            scene.emitter_power_cdf = build_cdf(&powers).ok_or_else(|| SceneError::Primitive {
                file: file.clone(),
                reason: "the emitters' total power is not finite".into(),
            })?;
        }
        let s = &mut scene.stats;
        s.triangles = scene.triangles.len();
        s.vertices = scene.positions.len();
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
        Ok(self.scene)
    }
}
