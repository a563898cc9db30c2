//! Textures and images: a glTF texture becomes one scene texture (its image decoded once and
//! shared between the textures that use it), referenced through a texture-coordinate set and
//! an optional `KHR_texture_transform`.

use super::Loader;
use crate::error::SceneError;
use crate::load_options::MissingTextures;
use crate::texture::{load_image_or_unreadable, Sampler, TextureData, UnreadableImage};
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
            // A texture dropped because its image file cannot be read (warned already).
            Some(&t) if t < 0 => return Ok(TextureRef::NONE),
            Some(&t) => t,
            None => {
                let doc = self.src.document.clone();
                let image = doc
                    .images()
                    .nth(self.texture_image(tex, material)?)
                    .expect("image index checked");
                let data = match self.image_map.get(&image.index()) {
                    Some(d) => d.clone(),
                    None => {
                        let d = match load_image_or_unreadable(&mut self.src, &image)? {
                            Ok(d) => d,
                            Err(unreadable) => {
                                return self.drop_unreadable(tex, &image, unreadable, material)
                            }
                        };
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

    /// A texture whose image file cannot be read: an error naming it (the default), or with
    /// `[textures] missing = "warn"` no texture and one warning line naming the file
    /// ([`crate::load_options`]).
    fn drop_unreadable(
        &mut self,
        tex: &gltf::Texture,
        image: &gltf::Image,
        unreadable: UnreadableImage,
        material: &str,
    ) -> Result<TextureRef, SceneError> {
        if self.missing_textures == MissingTextures::Error {
            return Err(SceneError::Image {
                file: self.file(),
                image: image.index(),
                reason: unreadable.reason,
            });
        }
        tracing::warn!(
            file = %self.src.file.display(),
            "material '{material}': texture {} dropped: {} ([textures] missing = \"warn\")",
            tex.index(),
            unreadable.reason
        );
        self.scene.stats.textures_dropped += 1;
        self.texture_map.insert(tex.index(), -1);
        Ok(TextureRef::NONE)
    }

    /// The index of the image texture `tex` shows: the `EXT_texture_webp` source where the texture has one
    /// (WebP is decoded, and the core `source` is then only a fallback for viewers without the
    /// extension, or absent), else the core `source`; an error naming the texture when it has
    /// neither.
    fn texture_image(&self, tex: &gltf::Texture, material: &str) -> Result<usize, SceneError> {
        let err = |reason: String| SceneError::Material {
            file: self.file(),
            material: material.to_string(),
            reason: format!("texture {}: {reason}", tex.index()),
        };
        if let Some(webp) = tex.extension_value("EXT_texture_webp") {
            let index = webp
                .get("source")
                .and_then(|i| i.as_u64())
                .and_then(|i| usize::try_from(i).ok())
                .ok_or_else(|| {
                    err("EXT_texture_webp.source is missing or not a non-negative integer".into())
                })?;
            let count = self.src.document.images().len();
            if index >= count {
                return Err(err(format!(
                    "EXT_texture_webp.source = {index} is out of range ({count} images)"
                )));
            }
            return Ok(index);
        }
        tex.source()
            .map(|i| i.index())
            .ok_or_else(|| err("has no source image (and no EXT_texture_webp source)".into()))
    }
}
