//! The parameters of the glTF layer extensions `KHR_materials_sheen`,
//! `KHR_materials_diffuse_transmission`, `KHR_materials_iridescence` and
//! `KHR_materials_anisotropy`, kept in one
//! [`MaterialLayers`] of a [`Material`](crate::material::Material), and their textures.
//!
//! Defaults are the extensions' and switch each layer off: sheen colour black, diffuse
//! transmission factor 0, iridescence factor 0, anisotropy strength 0. A material without these extensions therefore
//! has `MaterialLayers::default()`, and [`crate::bsdf::gltf::lobes`] builds exactly the lobes
//! it built before the layers existed.
//!
//! Textures multiply their factors as the extensions say, each at its own texture-coordinate
//! set, transform and sampler:
//!
//! | texture | channel | multiplies |
//! |---|---|---|
//! | `sheenColorTexture` (sRGB) | RGB | `sheen_color` |
//! | `sheenRoughnessTexture` | A | `sheen_roughness` |
//! | `diffuseTransmissionTexture` | A | `diffuse_transmission` |
//! | `diffuseTransmissionColorTexture` (sRGB) | RGB | `diffuse_transmission_color` |
//! | `iridescenceTexture` | R | `iridescence` |
//! | `iridescenceThicknessTexture` | G | thickness = mix(min, max, G) |
//! | `anisotropyTexture` | RG, B | direction = RG · 2 − 1 (normalised), strength × B |
//!
//! Without a thickness texture the film is `iridescenceThicknessMaximum` thick (the
//! extension's rule); [`MaterialLayers::resolve`] writes the thickness at the point into
//! `iridescence_thickness_max`, which is what the BSDF reads.
//!
//! The anisotropy direction is (1, 0) or the texture's, rotated by `anisotropyRotation`
//! (counter-clockwise from the tangent), in the tangent frame (T, B) of the hit. The BSDF is
//! built in the frame `Frame::from_z(n_s)`, not in (T, B), so the host projects the direction
//! onto it before it builds the BSDF ([`MaterialLayers::orient_anisotropy`], which takes T and
//! B from [`crate::mesh::MeshView::tangent_frame`]).

use crate::geometry::Frame;
use crate::material::{Texture, TextureRef};
use crate::mesh::MeshView;
use crate::Rgb;
use glam::{Vec2, Vec3};

/// The layer extensions' factors and textures (module docs).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaterialLayers {
    /// KHR_materials_sheen sheenColorFactor (linear); black: no sheen layer.
    pub sheen_color: Rgb,
    /// KHR_materials_sheen sheenRoughnessFactor in [0, 1] (Charlie α = roughness²).
    pub sheen_roughness: f32,
    pub sheen_color_texture: TextureRef,
    pub sheen_roughness_texture: TextureRef,
    /// KHR_materials_diffuse_transmission diffuseTransmissionFactor in [0, 1]: the part of
    /// the diffuse base that is transmitted to the back side.
    pub diffuse_transmission: f32,
    /// diffuseTransmissionColorFactor (linear): the tint of the transmitted part.
    pub diffuse_transmission_color: Rgb,
    pub diffuse_transmission_texture: TextureRef,
    pub diffuse_transmission_color_texture: TextureRef,
    /// KHR_materials_iridescence iridescenceFactor in [0, 1] (0: no thin film).
    pub iridescence: f32,
    /// iridescenceIor: index of refraction of the film (1.3 by default).
    pub iridescence_ior: f32,
    /// iridescenceThicknessMinimum and -Maximum in nanometres (100 and 400 by default).
    pub iridescence_thickness_min: f32,
    pub iridescence_thickness_max: f32,
    pub iridescence_texture: TextureRef,
    pub iridescence_thickness_texture: TextureRef,
    /// KHR_materials_anisotropy anisotropyStrength in [0, 1] (0: isotropic).
    pub anisotropy_strength: f32,
    /// anisotropyRotation in radians, counter-clockwise from the tangent.
    pub anisotropy_rotation: f32,
    /// anisotropyTexture (linear): RG the direction in tangent space (× 2 − 1), B the
    /// strength.
    pub anisotropy_texture: TextureRef,
    /// The unit direction of the anisotropy: in the tangent frame (T, B) as
    /// [`MaterialLayers::resolve`] gives it, in the BSDF's local shading frame once the host
    /// has projected it there for [`crate::bsdf::Bsdf::from_material`].
    pub anisotropy_direction: [f32; 2],
}

impl Default for MaterialLayers {
    fn default() -> Self {
        MaterialLayers {
            sheen_color: Rgb::ZERO,
            sheen_roughness: 0.0,
            sheen_color_texture: TextureRef::NONE,
            sheen_roughness_texture: TextureRef::NONE,
            diffuse_transmission: 0.0,
            diffuse_transmission_color: Rgb::ONE,
            diffuse_transmission_texture: TextureRef::NONE,
            diffuse_transmission_color_texture: TextureRef::NONE,
            iridescence: 0.0,
            iridescence_ior: 1.3,
            iridescence_thickness_min: 100.0,
            iridescence_thickness_max: 400.0,
            iridescence_texture: TextureRef::NONE,
            iridescence_thickness_texture: TextureRef::NONE,
            anisotropy_strength: 0.0,
            anisotropy_rotation: 0.0,
            anisotropy_texture: TextureRef::NONE,
            anisotropy_direction: [1.0, 0.0],
        }
    }
}

impl MaterialLayers {
    /// Projects an anisotropic material's direction from the tangent frame at point `p` of
    /// triangle `prim` of `mesh` (shading normal `ns`) onto the BSDF's local frame
    /// `Frame::from_z(ns)`, as [`crate::bsdf::Bsdf::from_material`] reads it (module docs).
    /// Where the mesh gives no tangent frame, the local frame's own axes stand for it. Nothing
    /// changes for an isotropic material.
    #[inline]
    pub fn orient_anisotropy(&mut self, mesh: &MeshView, prim: u32, p: Vec3, ns: Vec3) {
        if self.anisotropy_strength.is_nan() || self.anisotropy_strength <= 0.0 {
            return;
        }
        let frame = Frame::from_z(ns);
        let [dx, dy] = self.anisotropy_direction;
        let set = self.anisotropy_texture.tex_coord as usize;
        let d = match mesh.tangent_frame(prim, p, ns, set) {
            Some((t, b)) => t * dx + b * dy,
            None => frame.x * dx + frame.y * dy,
        };
        let l = frame.to_local(d);
        self.anisotropy_direction = [l.x, l.y];
    }

    /// The texture references, for the test whether a material's BSDF is the same at every
    /// point.
    pub fn textures(&self) -> [&TextureRef; 7] {
        [
            &self.anisotropy_texture,
            &self.sheen_color_texture,
            &self.sheen_roughness_texture,
            &self.diffuse_transmission_texture,
            &self.diffuse_transmission_color_texture,
            &self.iridescence_texture,
            &self.iridescence_thickness_texture,
        ]
    }

    /// The layers at a point: every factor times its texture (module docs). A layer that is
    /// off (its factor 0 or black) reads no texture.
    #[inline]
    pub fn resolve(&self, uv: [Vec2; 2], textures: &[Texture]) -> MaterialLayers {
        let mut l = *self;
        let linear = |r: &TextureRef| r.sample(uv, textures, false);
        let srgb = |r: &TextureRef| r.sample(uv, textures, true);
        if !self.sheen_color.is_black() {
            if let Some(t) = srgb(&self.sheen_color_texture) {
                l.sheen_color = self.sheen_color * Rgb::new(t.x, t.y, t.z);
            }
            if let Some(t) = linear(&self.sheen_roughness_texture) {
                l.sheen_roughness = self.sheen_roughness * t.w;
            }
        }
        if self.diffuse_transmission > 0.0 {
            if let Some(t) = linear(&self.diffuse_transmission_texture) {
                l.diffuse_transmission = self.diffuse_transmission * t.w;
            }
            if let Some(t) = srgb(&self.diffuse_transmission_color_texture) {
                l.diffuse_transmission_color =
                    self.diffuse_transmission_color * Rgb::new(t.x, t.y, t.z);
            }
        }
        if self.anisotropy_strength > 0.0 {
            let (s, c) = self.anisotropy_rotation.sin_cos();
            let (mut dx, mut dy) = (1.0, 0.0);
            if let Some(t) = linear(&self.anisotropy_texture) {
                (dx, dy) = (2.0 * t.x - 1.0, 2.0 * t.y - 1.0);
                l.anisotropy_strength = self.anisotropy_strength * t.z;
            }
            let len = (dx * dx + dy * dy).sqrt();
            if len > 0.0 && len.is_finite() {
                (dx, dy) = (dx / len, dy / len);
            } else {
                (dx, dy) = (1.0, 0.0);
            }
            l.anisotropy_direction = [c * dx - s * dy, s * dx + c * dy];
        }
        if self.iridescence > 0.0 {
            if let Some(t) = linear(&self.iridescence_texture) {
                l.iridescence = self.iridescence * t.x;
            }
            if let Some(t) = linear(&self.iridescence_thickness_texture) {
                let (lo, hi) = (
                    self.iridescence_thickness_min,
                    self.iridescence_thickness_max,
                );
                l.iridescence_thickness_max = lo + (hi - lo) * t.y;
            }
        }
        l
    }
}
