//! Materials: each glTF material a loaded primitive uses is converted once
//! ([`crate::material::convert`]), with its alpha mode, its texture references (core and
//! extension textures) and the render config's override applied.

use super::textures::{transform_from_json, Transform};
use super::Loader;
use crate::error::SceneError;
use crate::material::convert;
use flowlight_core::material::{AlphaMode, Material, TextureRef};
use std::path::PathBuf;

impl Loader<'_> {
    /// Scene material index for glTF material `m`, converting it (and decoding its base colour
    /// texture) on first use.
    pub(super) fn material(&mut self, m: &gltf::Material) -> Result<u32, SceneError> {
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
        self.other_shading_models(m, &mut mat, &name)?;
        mat.multiscatter = self.multiscatter as u32;
        if let Some(o) = self.overrides.get(&name) {
            o.validate()
                .map_err(|e| merr(self.file(), format!("config override: {e}")))?;
            o.apply(&mut mat);
        }
        self.scene.materials.push(mat);
        self.scene.material_names.push(name);
        self.scene.unlit_materials.push(crate::unlit::is_unlit(m));
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
        let layers =
            crate::material_layers::layer_textures(m, count).map_err(|e| merr(self.file(), e))?;
        for (slot, raw) in layers {
            let t = transform_from_json(raw.transform.as_ref())
                .map_err(|e| merr(self.file(), format!("{slot:?} texture: {e}")))?;
            let doc = self.src.document.clone();
            let tex = doc.textures().nth(raw.index).expect("index checked");
            let r = self.texture_ref(&tex, raw.tex_coord, t, name)?;
            crate::material_layers::assign(&mut mat.layers, slot, r);
        }
        Ok(())
    }
}
