//! Materials as the scene loader describes them, and the textures they read.

use crate::Rgb;
use glam::Vec2;

/// Which diffuse model a non-metallic, non-transmissive material uses.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DiffuseModel {
    Lambert = 0,
    /// Oren–Nayar rough diffuse (the thesis renders with it); `oren_nayar_sigma` is its
    /// roughness in radians.
    OrenNayar = 1,
}

/// A glTF metallic-roughness material with the transmission and emission extensions.
/// The BSDF it stands for is built by [`crate::bsdf::Bsdf::from_material`].
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// Linear base colour factor.
    pub base_color: Rgb,
    /// Index into the texture table, multiplied with `base_color`; -1 for none.
    pub base_color_texture: i32,
    pub diffuse_model: DiffuseModel,
    pub oren_nayar_sigma: f32,
    /// glTF metallic factor in [0, 1]: weight of the GGX conductor against the diffuse base.
    pub metallic: f32,
    /// glTF perceptual roughness in [0, 1]; GGX α = roughness². 0 is a perfect mirror.
    pub roughness: f32,
    /// KHR_materials_transmission factor in [0, 1]: weight of the dielectric.
    pub transmission: f32,
    /// KHR_materials_ior (1.5 by default).
    pub ior: f32,
    /// Emitted radiance (emissive factor × KHR_materials_emissive_strength).
    pub emission: Rgb,
    /// 1 when both faces emit; 0 (default) when only the front, counter-clockwise face does,
    /// like the one-sided area lights of Mitsuba and pbrt. glTF's `doubleSided` does not set
    /// it (every surface scatters on both sides anyway): a lamp a hair below a ceiling would
    /// otherwise light the gap above it. Set it with extras `{"flowlight": {"two_sided_emission": true}}`.
    pub two_sided_emission: u32,
    // glTF BRDF extension parameters
    /// KHR_materials_specular specularFactor in [0, 1]: strength of the dielectric specular
    /// layer (f90 = specular, f0 = min(F0(ior) · specular_color, 1) · specular). 1 by default.
    pub specular: f32,
    /// KHR_materials_specular specularColorFactor (linear, may exceed 1): tints the dielectric
    /// F0. White by default.
    pub specular_color: Rgb,
    /// KHR_materials_volume thicknessFactor: 0 (default) is thin-walled (transmission passes
    /// straight through); > 0 makes transmission refract and the mesh a closed volume.
    pub thickness: f32,
    /// KHR_materials_volume attenuationColor: colour that white light has after travelling
    /// `attenuation_distance` inside the volume. White by default.
    pub attenuation_color: Rgb,
    /// KHR_materials_volume attenuationDistance (world units); infinite (default): no
    /// absorption.
    pub attenuation_distance: f32,
    /// KHR_materials_clearcoat clearcoatFactor in [0, 1] (0: no coat).
    pub clearcoat: f32,
    /// KHR_materials_clearcoat clearcoatRoughnessFactor in [0, 1]; GGX α = roughness².
    pub clearcoat_roughness: f32,
}

impl Default for Material {
    fn default() -> Self {
        Material {
            base_color: Rgb::splat(0.8),
            base_color_texture: -1,
            diffuse_model: DiffuseModel::Lambert,
            oren_nayar_sigma: 0.0,
            metallic: 0.0,
            roughness: 1.0,
            transmission: 0.0,
            ior: 1.5,
            emission: Rgb::ZERO,
            two_sided_emission: 0,
            specular: 1.0,
            specular_color: Rgb::ONE,
            thickness: 0.0,
            attenuation_color: Rgb::ONE,
            attenuation_distance: f32::INFINITY,
            clearcoat: 0.0,
            clearcoat_roughness: 0.0,
        }
    }
}

impl Material {
    #[inline]
    pub fn is_emissive(&self) -> bool {
        !self.emission.is_black()
    }

    /// Emitted radiance at a point with texture coordinates `uv` (sets TEXCOORD_0 and
    /// TEXCOORD_1). The emissive factor times the emissive texture where the material has one.
    #[inline]
    pub fn emission_at(&self, uv: [Vec2; 2], textures: &[Texture]) -> Rgb {
        let _ = (uv, textures);
        self.emission
    }

    /// Base colour at texture coordinate `uv`.
    #[inline]
    pub fn base_color_at(&self, uv: Vec2, textures: &[Texture]) -> Rgb {
        match usize::try_from(self.base_color_texture)
            .ok()
            .and_then(|i| textures.get(i))
        {
            Some(t) => self.base_color * t.lookup(uv),
            None => self.base_color,
        }
    }
}

/// A linear-RGB texture owned by the host; plugins read it through this view.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct Texture {
    pub width: u32,
    pub height: u32,
    /// `width × height` texels, row-major, top row first. Valid while the scene lives.
    pub texels: *const Rgb,
}

// SAFETY: textures are immutable for the whole render; the host keeps the texels alive.
unsafe impl Send for Texture {}
unsafe impl Sync for Texture {}

impl Texture {
    #[inline]
    fn texel(&self, x: i64, y: i64) -> Rgb {
        let x = x.rem_euclid(self.width as i64) as usize;
        let y = y.rem_euclid(self.height as i64) as usize;
        // SAFETY: indices are wrapped into range; the host guarantees the buffer's size.
        unsafe { *self.texels.add(y * self.width as usize + x) }
    }

    /// Bilinear lookup with repeat wrapping (glTF's default sampler).
    pub fn lookup(&self, uv: Vec2) -> Rgb {
        if self.width == 0 || self.height == 0 || self.texels.is_null() {
            return Rgb::ONE;
        }
        let x = uv.x * self.width as f32 - 0.5;
        let y = uv.y * self.height as f32 - 0.5;
        if !(x.is_finite() && y.is_finite()) {
            return Rgb::ONE;
        }
        let x0 = x.floor();
        let y0 = y.floor();
        let fx = x - x0;
        let fy = y - y0;
        let (x0, y0) = (x0 as i64, y0 as i64);
        self.texel(x0, y0) * ((1.0 - fx) * (1.0 - fy))
            + self.texel(x0 + 1, y0) * (fx * (1.0 - fy))
            + self.texel(x0, y0 + 1) * ((1.0 - fx) * fy)
            + self.texel(x0 + 1, y0 + 1) * (fx * fy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texture_lookup_wraps_and_interpolates() {
        let texels = [Rgb::splat(0.0), Rgb::splat(1.0)];
        let t = Texture {
            width: 2,
            height: 1,
            texels: texels.as_ptr(),
        };
        assert!((t.lookup(Vec2::new(0.25, 0.5)).r - 0.0).abs() < 1e-6);
        assert!((t.lookup(Vec2::new(0.75, 0.5)).r - 1.0).abs() < 1e-6);
        assert!((t.lookup(Vec2::new(0.5, 0.5)).r - 0.5).abs() < 1e-6);
        assert!((t.lookup(Vec2::new(1.25, 0.5)).r - 0.0).abs() < 1e-6);
        let m = Material {
            base_color_texture: 0,
            base_color: Rgb::splat(0.5),
            ..Default::default()
        };
        assert!((m.base_color_at(Vec2::new(0.75, 0.5), &[t]).g - 0.5).abs() < 1e-6);
    }
}
