//! Walks a glTF 2.0 document's default scene into a [`Scene`].
//!
//! - Node transforms (TRS or matrix) are composed down the hierarchy; normals use the
//!   inverse-transpose and the winding is flipped under a negative determinant, so a
//!   counter-clockwise front face stays the front face.
//! - Instancing: the walk first collects every placement (node, and each
//!   `EXT_mesh_gpu_instancing` instance) of every mesh. A mesh placed once is flattened into
//!   world space; a mesh placed several times is loaded once, in its local space, and each
//!   placement becomes a [`MeshInstance`](crate::MeshInstance) (see [`crate::scene`]). The instance and
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
//!   non-zero becomes an [`Emitter`](flowlight_core::light::Emitter) ([`crate::lights::mean_emission`]).
//! - `KHR_lights_punctual` lights become [`flowlight_core::light::PunctualLight`]s placed by
//!   their node's world transform.
//! - Every node that places a camera (perspective or orthographic) is recorded in traversal
//!   order; the render config picks one ([`crate::config`], default: the first).

use crate::error::SceneError;
use crate::load_options::{LoadOptions, MissingTextures};
use crate::material::MaterialOverride;
use crate::scene::Scene;
use crate::source::GltfSource;
use crate::texture::ImageData;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

mod camera;
mod emitters;
mod limits;
mod materials;
mod nodes;
mod other_models;
mod primitive;
mod tangents;
mod textures;

pub use limits::{
    BYTES_PER_INSTANCE, BYTES_PER_STORED_TRIANGLE, MAX_COORDINATE, MAX_INSTANCES,
    MAX_VIRTUAL_TRIANGLES, MIN_EXTENT,
};

/// Loads a `.gltf` (with external buffers or data URIs) or `.glb` file. `overrides` maps
/// material names to diffuse-model overrides (from the render config); every other
/// [`LoadOptions`] value is its default.
///
/// Never panics on malformed input: every failure is a [`SceneError`] naming the file.
pub fn load_gltf(
    path: &Path,
    overrides: &BTreeMap<String, MaterialOverride>,
) -> Result<Scene, SceneError> {
    load_gltf_with(path, &LoadOptions::with_overrides(overrides))
}

/// [`load_gltf`] with every option of the render config ([`LoadOptions`]).
pub fn load_gltf_with(path: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
    // Everything below validates before it indexes; the unwind guard is a last resort so
    // that a bug or an unforeseen input in a dependency still reports instead of aborting.
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| load_inner(path, options))) {
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

/// The state of one load: the file, the scene being built and what was converted already.
/// Its methods live in the submodules by concept (nodes, geometry, materials, textures,
/// cameras, emitters).
struct Loader<'a> {
    src: GltfSource,
    overrides: &'a BTreeMap<String, MaterialOverride>,
    /// `[textures] missing`: refuse the file, or drop a texture whose image cannot be read.
    missing_textures: MissingTextures,
    /// `[render] multiscatter`, set on every material.
    multiscatter: bool,
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

fn load_inner(path: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
    let src = GltfSource::open(path)?;
    let mut loader = Loader {
        src,
        overrides: options.overrides,
        missing_textures: options.missing_textures,
        multiscatter: options.multiscatter,
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
}
