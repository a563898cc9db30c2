//! `KHR_materials_pbrSpecularGlossiness` (an archived extension older assets still use),
//! converted to the metallic-roughness material with `KHR_materials_specular` and
//! `KHR_materials_ior` that the renderer has, the conversion the `KHR_materials_specular`
//! specification gives for it ("Conversion from specular-glossiness"):
//!
//! | specular-glossiness | becomes |
//! |---|---|
//! | `diffuseFactor` (RGBA) | `baseColorFactor` (RGB and alpha) |
//! | `diffuseTexture` (sRGB RGBA) | `baseColorTexture` |
//! | `specularFactor` (RGB) | `specularColorFactor`, with `specularFactor` 1 and `ior` 0 |
//! | `glossinessFactor` g | `roughnessFactor` 1 − g |
//! | `specularGlossinessTexture` RGB (sRGB) | `specularColorTexture` |
//! | `specularGlossinessTexture` A | roughness 1 − g·A (a derived texture, below) |
//! | — | `metallicFactor` 0 |
//!
//! With ior 0 the dielectric's F0 is 1 ([`flowlight_core::bsdf::gltf::f0_from_ior`]), so
//! its specular colour *is* F0 = the specular colour, f90 = 1, as the extension's own BRDF
//! has it (Schlick from F0 = specular to 1). The diffuse base under it is weighted by the
//! energy that layer leaves (`flowlight_core::bsdf::gltf`, from the largest channel of F0),
//! which at normal incidence is the extension's `c_diff = diffuse · (1 − max(specular))`.
//!
//! The glossiness in the texture's alpha does not multiply a factor the way the
//! metallic-roughness texture's G does (roughness = factor × G): it is 1 − g·A. The loader
//! therefore derives a one-channel 16-bit image 1 − g·A from the texture's alpha
//! ([`roughness_image`]) and uses it, with roughness factor 1, as the metallic-roughness
//! texture (its grey value is read as G; metallic stays 0 × B = 0). Bilinear filtering of
//! 1 − g·A equals 1 − g·(filtered A), so the derived texture filters like the original.
//!
//! When the extension is present, the material's `pbrMetallicRoughness` (the fallback for
//! viewers without the extension) and its `KHR_materials_specular` / `KHR_materials_ior`
//! are replaced; the other extensions (clearcoat, emission, normal map) stay.

use crate::material::RawTextureInfo;
use crate::texture::{ImageData, Texels};
use flowlight_core::material::Material;
use flowlight_core::Rgb;

/// The extension's name.
pub const NAME: &str = "KHR_materials_pbrSpecularGlossiness";

/// A material's `KHR_materials_pbrSpecularGlossiness`, read and checked.
#[derive(Clone, Debug, PartialEq)]
pub struct SpecGloss {
    pub diffuse: [f32; 4],
    pub specular: [f32; 3],
    pub glossiness: f32,
    pub diffuse_texture: Option<RawTextureInfo>,
    pub specular_glossiness_texture: Option<RawTextureInfo>,
}

/// Reads `m`'s extension object, if it has one; the error names the field.
pub fn read(m: &gltf::Material, texture_count: usize) -> Result<Option<SpecGloss>, String> {
    match m.extension_value(NAME) {
        None => Ok(None),
        Some(v) => parse(v, texture_count).map(Some),
    }
}

/// [`read`] from the extension's JSON object.
pub fn parse(v: &gltf::json::Value, texture_count: usize) -> Result<SpecGloss, String> {
    let obj = v
        .as_object()
        .ok_or_else(|| format!("{NAME} is not a JSON object"))?;
    let unit = |key: &str, x: &gltf::json::Value| -> Result<f32, String> {
        let f = x
            .as_f64()
            .ok_or_else(|| format!("{NAME}.{key} is not a number"))? as f32;
        if !(0.0..=1.0).contains(&f) {
            return Err(format!("{NAME}.{key} = {f} is outside [0, 1]"));
        }
        Ok(f)
    };
    let array = |key: &str, default: &[f32]| -> Result<Vec<f32>, String> {
        let Some(x) = obj.get(key) else {
            return Ok(default.to_vec());
        };
        let a = x
            .as_array()
            .filter(|a| a.len() == default.len())
            .ok_or_else(|| format!("{NAME}.{key} is not an array of {} numbers", default.len()))?;
        a.iter().map(|x| unit(key, x)).collect()
    };
    let d = array("diffuseFactor", &[1.0; 4])?;
    let s = array("specularFactor", &[1.0; 3])?;
    let glossiness = match obj.get("glossinessFactor") {
        None => 1.0,
        Some(x) => unit("glossinessFactor", x)?,
    };
    Ok(SpecGloss {
        diffuse: [d[0], d[1], d[2], d[3]],
        specular: [s[0], s[1], s[2]],
        glossiness,
        diffuse_texture: raw_texture_info(v, "diffuseTexture", texture_count)?,
        specular_glossiness_texture: raw_texture_info(
            v,
            "specularGlossinessTexture",
            texture_count,
        )?,
    })
}

/// A texture reference of the extension (index, `texCoord`, `KHR_texture_transform`),
/// checked against the document's `texture_count`.
fn raw_texture_info(
    obj: &gltf::json::Value,
    key: &str,
    texture_count: usize,
) -> Result<Option<RawTextureInfo>, String> {
    obj.get(key)
        .map(|v| crate::material::parse_texture_info(v, &format!("{NAME}.{key}"), texture_count))
        .transpose()
}

impl SpecGloss {
    /// Sets `m`'s factors to the converted ones (module docs); textures are the loader's.
    pub fn apply_factors(&self, m: &mut Material) {
        let [r, g, b, a] = self.diffuse;
        m.base_color = Rgb::new(r, g, b);
        m.base_alpha = a;
        m.metallic = 0.0;
        m.roughness = 1.0 - self.glossiness;
        m.specular = 1.0;
        m.specular_color = Rgb::from_array(self.specular);
        m.ior = 0.0;
    }
}

/// The roughness image 1 − `glossiness` · A of a specular-glossiness texture's image (A = 1
/// where it has no alpha), one 16-bit channel, for the metallic-roughness slot (module docs).
pub fn roughness_image(image: &ImageData, glossiness: f32) -> ImageData {
    let c = image.channels as usize;
    let texels = (image.width * image.height) as usize;
    let alpha = |i: usize| -> f32 {
        if c != 2 && c != 4 {
            return 1.0;
        }
        let k = i * c + c - 1;
        match &image.texels {
            Texels::U8(v) => v[k] as f32 / 255.0,
            Texels::U16(v) => v[k] as f32 / 65535.0,
            Texels::F32(v) => v[k].clamp(0.0, 1.0),
        }
    };
    let out: Vec<u16> = (0..texels)
        .map(|i| {
            let r = (1.0 - glossiness * alpha(i)).clamp(0.0, 1.0);
            (r * 65535.0).round() as u16
        })
        .collect();
    ImageData {
        width: image.width,
        height: image.height,
        channels: 1,
        texels: Texels::U16(out.into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use flowlight_core::bsdf::Bsdf;

    fn json(text: &str) -> gltf::json::Value {
        gltf::json::deserialize::from_str(text).unwrap()
    }

    #[test]
    fn factors_convert_as_the_specular_extension_says() {
        let sg = parse(
            &json(
                r#"{"diffuseFactor": [0.5, 0.4, 0.3, 0.8], "specularFactor": [0.9, 0.6, 0.2],
                   "glossinessFactor": 0.75}"#,
            ),
            0,
        )
        .unwrap();
        let mut m = Material {
            metallic: 1.0,
            ..Material::default()
        };
        sg.apply_factors(&mut m);
        assert_eq!(m.base_color, Rgb::new(0.5, 0.4, 0.3));
        assert_eq!(m.base_alpha, 0.8);
        assert_eq!(
            (m.metallic, m.roughness, m.specular, m.ior),
            (0.0, 0.25, 1.0, 0.0)
        );
        assert_eq!(m.specular_color, Rgb::new(0.9, 0.6, 0.2));
        // Defaults: diffuse 1, specular 1, glossiness 1.
        let d = parse(&json("{}"), 0).unwrap();
        assert_eq!(
            (d.diffuse, d.specular, d.glossiness),
            ([1.0; 4], [1.0; 3], 1.0)
        );
    }

    #[test]
    fn a_black_diffuse_white_specular_material_is_a_white_mirror() {
        // F0 = specular colour: a white specular, black diffuse, glossiness 1 reflects
        // everything (Schlick from 1 to 1), like a white metal.
        let sg = parse(
            &json(r#"{"diffuseFactor": [0, 0, 0, 1], "specularFactor": [1, 1, 1]}"#),
            0,
        )
        .unwrap();
        let mut m = Material::default();
        sg.apply_factors(&mut m);
        let bsdf = Bsdf::from_material(&m, m.base_color);
        let wo = glam::Vec3::new(0.3, 0.0, 1.0).normalize();
        let s = bsdf.sample(wo, 0.5, glam::Vec2::new(0.3, 0.7)).unwrap();
        assert!(s.delta);
        let throughput = s.f * (s.wi.z.abs() / s.pdf);
        assert!((throughput.r - 1.0).abs() < 1e-5, "{throughput:?}");
        // A mid-grey specular's F0 is that grey.
        let sg = parse(
            &json(r#"{"diffuseFactor": [0, 0, 0, 1], "specularFactor": [0.5, 0.5, 0.5]}"#),
            0,
        )
        .unwrap();
        sg.apply_factors(&mut m);
        let bsdf = Bsdf::from_material(&m, m.base_color);
        let wo = glam::Vec3::Z;
        let s = bsdf.sample(wo, 0.5, glam::Vec2::new(0.3, 0.7)).unwrap();
        let throughput = s.f * (s.wi.z.abs() / s.pdf);
        assert!((throughput.g - 0.5).abs() < 1e-4, "{throughput:?}");
    }

    #[test]
    fn bad_values_are_named() {
        let e = parse(&json(r#"{"glossinessFactor": 2}"#), 0).unwrap_err();
        assert!(e.contains("glossinessFactor") && e.contains(NAME), "{e}");
        let e = parse(&json(r#"{"diffuseFactor": [1, 1, 1]}"#), 0).unwrap_err();
        assert!(e.contains("diffuseFactor"), "{e}");
        let e = parse(&json(r#"{"diffuseTexture": {"index": 3}}"#), 2).unwrap_err();
        assert!(e.contains("diffuseTexture.index = 3"), "{e}");
    }

    #[test]
    fn roughness_image_is_one_minus_glossiness_times_alpha() {
        let rgba = ImageData {
            width: 2,
            height: 1,
            channels: 4,
            texels: Texels::U8(vec![9, 9, 9, 255, 9, 9, 9, 51].into()),
        };
        let r = roughness_image(&rgba, 0.5);
        assert_eq!((r.width, r.height, r.channels), (2, 1, 1));
        let Texels::U16(v) = &r.texels else {
            panic!("16-bit")
        };
        assert_eq!(v[0], (0.5f32 * 65535.0).round() as u16);
        assert_eq!(v[1], ((1.0 - 0.5 * 0.2f32) * 65535.0).round() as u16);
        // No alpha: A = 1.
        let rgb = ImageData {
            width: 1,
            height: 1,
            channels: 3,
            texels: Texels::U8(vec![1, 2, 3].into()),
        };
        let Texels::U16(v) = roughness_image(&rgb, 0.25).texels else {
            panic!("16-bit")
        };
        assert_eq!(v[0], (0.75f32 * 65535.0).round() as u16);
    }
}
