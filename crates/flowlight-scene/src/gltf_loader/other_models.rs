//! Materials of the shading models other than metallic-roughness, converted to it after the
//! metallic-roughness reading: `KHR_materials_pbrSpecularGlossiness` ([`crate::spec_gloss`],
//! with its derived roughness texture) and `KHR_materials_unlit` ([`crate::unlit`]).

use super::textures::transform_from_json;
use super::Loader;
use crate::error::SceneError;
use crate::material::RawTextureInfo;
use crate::spec_gloss;
use crate::texture::TextureData;
use flowlight_core::material::{Material, TextureRef};

impl Loader<'_> {
    /// Applies the specular-glossiness conversion and then the unlit one, where `m` has
    /// those extensions.
    pub(super) fn other_shading_models(
        &mut self,
        m: &gltf::Material,
        mat: &mut Material,
        name: &str,
    ) -> Result<(), SceneError> {
        let merr = |file, reason| SceneError::Material {
            file,
            material: name.to_string(),
            reason,
        };
        let count = self.src.document.textures().len();
        let sg = spec_gloss::read(m, count).map_err(|e| merr(self.file(), e))?;
        if let Some(sg) = sg {
            sg.apply_factors(mat);
            mat.base_color_texture = match &sg.diffuse_texture {
                Some(raw) => self.raw_texture_ref(raw, name)?,
                None => TextureRef::NONE,
            };
            mat.specular_texture = TextureRef::NONE;
            (mat.specular_color_texture, mat.metallic_roughness_texture) =
                match &sg.specular_glossiness_texture {
                    Some(raw) => {
                        let r = self.raw_texture_ref(raw, name)?;
                        let rough = self.roughness_from_glossiness(r, sg.glossiness);
                        // The derived texture holds 1 − g·A whole; the factor multiplies it.
                        if rough.is_some() {
                            mat.roughness = 1.0;
                        }
                        (r, rough)
                    }
                    None => (TextureRef::NONE, TextureRef::NONE),
                };
        }
        if crate::unlit::is_unlit(m) {
            crate::unlit::make_unlit(mat, m.double_sided());
        }
        Ok(())
    }

    /// The texture reference of an extension's raw texture info.
    fn raw_texture_ref(
        &mut self,
        raw: &RawTextureInfo,
        name: &str,
    ) -> Result<TextureRef, SceneError> {
        let t = transform_from_json(raw.transform.as_ref()).map_err(|e| SceneError::Material {
            file: self.file(),
            material: name.to_string(),
            reason: format!("{}: {e}", spec_gloss::NAME),
        })?;
        let doc = self.src.document.clone();
        let tex = doc.textures().nth(raw.index).expect("index checked");
        self.texture_ref(&tex, raw.tex_coord, t, name)
    }

    /// A texture of 1 − `glossiness` · A from the image of specular-glossiness texture
    /// reference `r` ([`spec_gloss::roughness_image`]), with `r`'s sampler, coordinates and
    /// transform; none where `r` has none (a dropped texture).
    fn roughness_from_glossiness(&mut self, r: TextureRef, glossiness: f32) -> TextureRef {
        let Some(source) = usize::try_from(r.index)
            .ok()
            .and_then(|i| self.scene.textures.get(i))
        else {
            return TextureRef::NONE;
        };
        let derived = TextureData {
            image: spec_gloss::roughness_image(&source.image, glossiness),
            sampler: source.sampler,
        };
        self.scene.textures.push(derived);
        TextureRef {
            index: (self.scene.textures.len() - 1) as i32,
            ..r
        }
    }
}
