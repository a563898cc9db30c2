//! Textures and images: a glTF texture becomes one scene texture (its image decoded once and
//! shared between the textures that use it), referenced through a texture-coordinate set and
//! an optional `KHR_texture_transform`.

use super::Loader;
use crate::error::SceneError;
use crate::texture::{load_image, Sampler, TextureData};
use flowlight_core::material::TextureRef;

/// A `KHR_texture_transform` as read from the file.
#[derive(Clone, Copy, Debug)]
pub(super) struct Transform {
    pub(super) offset: [f32; 2],
    pub(super) rotation: f32,
    pub(super) scale: [f32; 2],
    pub(super) tex_coord: Option<u32>,
}

/// Parses a `KHR_texture_transform` object given as JSON (for the texture infos the `gltf`
/// crate does not type: normal and occlusion).
pub(super) fn transform_from_json(
    v: Option<&gltf::json::Value>,
) -> Result<Option<Transform>, String> {
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

impl Loader<'_> {
    /// The scene texture for glTF texture `tex` (decoding its image on first use; images are
    /// shared between textures), as a reference through texture-coordinate set `tex_coord`
    /// with an optional `KHR_texture_transform`.
    pub(super) fn texture_ref(
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
}
