//! `KHR_materials_unlit`: a surface that shows its base colour whatever the lighting
//! (baked-lighting scans, backdrops, UI planes). The extension defines the colour a
//! rasteriser writes, `baseColorFactor × baseColorTexture × COLOR_0`, with no light
//! computation; its path-tracing reading is a surface that *emits* its base colour towards
//! the viewer and scatters nothing. So an unlit material becomes:
//!
//! * emission = `baseColorFactor` (RGB), emissive texture = `baseColorTexture` (both sRGB
//!   colour textures, read at the same `texCoord` and transform), emissive strength 1, and the vertex colours (below);
//! * a BSDF that scatters nothing: base colour factor 0 (the base colour *texture* stays,
//!   so that `alphaMode` MASK/BLEND still read its alpha), metallic 0, specular 0,
//!   transmission and clearcoat 0;
//! * emission from both faces when the material is `doubleSided` (a rasteriser shows both
//!   faces of such a material in its colour), from the front face otherwise (it culls the
//!   back face).
//!
//! **It casts light.** Its triangles are area lights like any emissive triangle: sampled by
//! next-event estimation, starting light paths, reflected by mirrors and glossy surfaces and
//! lighting diffuse ones. The alternative, a surface that camera rays see but nothing else
//! does, is not one light-transport problem but two: the camera-side samplers (MCPT) and
//! the light-side ones (light tracing, BDPT, ERPT's and the Metropolis samplers' light
//! subpaths) would have to treat it differently, could not agree on one image, and the
//! convergence tests that compare them would fail by design; a mirror in front of an unlit
//! backdrop would show it black. An unlit surface's radiance is at most 1 (its colour), the
//! brightness of a white sky, so the light it adds is what a white-ish object of its
//! size would reflect under such a sky. The cost is that a scan with lighting baked into
//! its colours adds that light to the scene once more; to render such a scan as a lit
//! surface instead, remove the extension from the file.
//!
//! `COLOR_0` multiplies the emission, as it multiplies the extension's colour: the emitter
//! table stores each emissive triangle's vertex colours, filled for unlit materials only
//! (`Scene::unlit_materials`; glTF's `emissiveFactor` and `emissiveTexture` are not multiplied
//! by vertex colours), and every emitted radiance (a camera ray's hit, next-event
//! estimation, a light subpath's start) is read through
//! `flowlight_core::light::Emitter::emission_at`, which multiplies them in, so the hit side
//! and the light side agree for MIS and for the light-side samplers.

use flowlight_core::material::Material;
use flowlight_core::Rgb;

/// The extension's name.
pub const NAME: &str = "KHR_materials_unlit";

/// Whether `m` is unlit.
pub fn is_unlit(m: &gltf::Material) -> bool {
    m.extension_value(NAME).is_some()
}

/// Turns converted material `mat` (textures assigned) into the unlit emitter of the module
/// docs; `double_sided` is the material's glTF `doubleSided`.
pub fn make_unlit(mat: &mut Material, double_sided: bool) {
    mat.emission = mat.base_color;
    mat.emissive_texture = mat.base_color_texture;
    mat.two_sided_emission = double_sided as u32;
    mat.base_color = Rgb::ZERO;
    mat.metallic = 0.0;
    mat.metallic_roughness_texture = flowlight_core::material::TextureRef::NONE;
    mat.specular = 0.0;
    mat.specular_texture = flowlight_core::material::TextureRef::NONE;
    mat.transmission = 0.0;
    mat.transmission_texture = flowlight_core::material::TextureRef::NONE;
    mat.clearcoat = 0.0;
    mat.clearcoat_texture = flowlight_core::material::TextureRef::NONE;
}

#[cfg(test)]
mod tests {
    use super::*;
    use flowlight_core::bsdf::Bsdf;
    use flowlight_core::material::TextureRef;
    use glam::{Vec2, Vec3};

    #[test]
    fn unlit_emits_its_base_colour_and_scatters_nothing() {
        let mut m = Material {
            base_color: Rgb::new(0.2, 0.5, 0.9),
            base_color_texture: TextureRef::new(3, 1),
            metallic: 1.0,
            roughness: 0.3,
            transmission: 0.5,
            clearcoat: 1.0,
            ..Material::default()
        };
        make_unlit(&mut m, true);
        assert_eq!(m.emission, Rgb::new(0.2, 0.5, 0.9));
        assert_eq!(m.emissive_texture, TextureRef::new(3, 1));
        assert_eq!(
            m.base_color_texture,
            TextureRef::new(3, 1),
            "alpha still read"
        );
        assert_eq!(m.two_sided_emission, 1);
        assert!(m.is_emissive());
        let bsdf = Bsdf::from_material(&m, m.base_color);
        let wo = Vec3::new(0.2, 0.1, 0.9).normalize();
        for i in 0..16 {
            let u = Vec2::new((i as f32 + 0.5) / 16.0, 0.37);
            if let Some(s) = bsdf.sample(wo, 0.5, u) {
                assert!(s.f.is_black(), "{s:?}");
            }
            let wi = Vec3::new(u.x - 0.5, 0.3, 0.8).normalize();
            assert!(bsdf.eval(wo, wi).is_black());
        }
        let mut one_sided = Material::default();
        make_unlit(&mut one_sided, false);
        assert_eq!(one_sided.two_sided_emission, 0);
        assert_eq!(one_sided.emission, Rgb::splat(0.8));
    }
}
