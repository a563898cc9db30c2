//! Materials as the scene loader describes them, and the textures they read.
//!
//! # Textures
//!
//! A [`Texture`] is a view of host-owned texels in the image's own precision: 8-bit images stay
//! 8 bits per channel (1–4 channels, as decoded), 16-bit images 16 bits, float images `f32`.
//! Nothing is converted at load time; a lookup converts the few texels it reads:
//!
//! * colour textures (base colour, emissive) are sRGB-encoded (glTF 2.0 §3.9.6): the RGB
//!   channels are decoded with the sRGB EOTF, `c ≤ 0.04045 ? c/12.92 : ((c+0.055)/1.055)^2.4`
//!   (IEC 61966-2-1), for 8-bit texels through a 256-entry table; alpha is linear;
//! * data textures (metallic-roughness, normal, occlusion) are read linearly.
//!
//! Decoding happens per texel, before filtering, so that bilinear filtering interpolates
//! linear values, as GPU sRGB samplers do.
//!
//! A texture carries its glTF sampler: a wrap mode per axis ([`Wrap`]: REPEAT,
//! CLAMP_TO_EDGE, MIRRORED_REPEAT) and a [`Filter`]. glTF's minification filters with
//! mipmaps are treated as LINEAR (a path tracer with many samples per pixel averages the
//! footprint itself; there are no mip levels), NEAREST as NEAREST.
//!
//! Texel centres lie at `(i + ½) / width`; texture coordinates have their origin at the
//! top-left corner of the image, `v` pointing down (glTF 2.0 §3.7.2.1).
//!
//! # Texture references
//!
//! A [`TextureRef`] names a texture, the texture-coordinate set it reads (TEXCOORD_0 or _1)
//! and the `KHR_texture_transform` of the reference, stored as the 2×3 matrix
//! `M = T(offset) · R(rotation) · S(scale)`, so `uv' = M · (u, v, 1)`, with
//! `R = [[cos r, sin r], [−sin r, cos r]]`: the *transpose* of the matrix the extension's GLSL
//! listing writes. That listing is a known erratum (KhronosGroup/glTF#1563): with `v` pointing
//! down the image, its matrix turns the texture the other way from the one the extension's
//! prose and its sample model (TextureTransformTest, whose arrows must point at the "correct"
//! marker) mean, and three.js, Babylon.js and Blender's importer all use the transpose.
//!
//! # Resolving a material at a point
//!
//! [`Material::resolve`] multiplies the factors by their textures (glTF 2.0 §3.9.2): base
//! colour × base colour texture (sRGB) × `COLOR_0`; roughness × texture G and metallic ×
//! texture B of the metallic-roughness texture; emission × emissive texture (sRGB). The
//! occlusion texture is read by the loader but never applied: ambient occlusion is an
//! approximation for rasterisers of the visibility a path tracer computes by tracing rays,
//! and applying it too would darken cavities twice. Normal maps are applied by the host when
//! it builds the shading normal of a hit.
//!
//! The textures of the BRDF extensions multiply their factors the same way, each at its own
//! texture-coordinate set, transform and sampler, with the channels the extensions name:
//!
//! | texture | channel | multiplies |
//! |---|---|---|
//! | `transmissionTexture` (KHR_materials_transmission) | R | `transmission` |
//! | `specularTexture` (KHR_materials_specular) | A | `specular` |
//! | `specularColorTexture` (KHR_materials_specular, sRGB) | RGB | `specular_color` |
//! | `clearcoatTexture` (KHR_materials_clearcoat) | R | `clearcoat` |
//! | `clearcoatRoughnessTexture` (KHR_materials_clearcoat) | G | `clearcoat_roughness` |
//!
//! A texture without an alpha channel reads A = 1 (so an RGB `specularTexture` leaves the
//! factor as it is, as a GPU sampler would).
//!
//! `thicknessTexture` (KHR_materials_volume, G × `thicknessFactor`) is read and kept in
//! [`Material::thickness_texture`] but, like occlusion, never applied. The extension's
//! thickness is "the thickness of the volume beneath the surface", a baked stand-in for the
//! distance a refracted ray travels inside the mesh, for renderers that cannot trace it.
//! Flowlight traces it: the inside of a closed volumetric mesh is a homogeneous medium whose
//! Beer–Lambert transmittance exp(−σ_a s) uses the true segment length s between hits
//! ([`crate::bsdf::volume`]); the factor only decides *whether* the material is a volume
//! boundary (thickness > 0) or thin-walled (0), which must hold for the whole mesh, not per
//! texel. Multiplying it in would change nothing but that switch, and wrongly so where a
//! texel is 0.
//!
//! `clearcoatNormalTexture` is not loaded: the BSDF has one shading frame for every lobe
//! ([`crate::bsdf::Bsdf::eval`] takes directions in it), so the coat reflects about the same
//! (normal-mapped) shading normal as the base. The extension says a coat without its own
//! normal texture is *not* normal-mapped; Flowlight's coat follows the base normal map
//! instead. The loader warns when a file has a coat normal texture.

use crate::material_layers::MaterialLayers;
use crate::Rgb;
use glam::{Vec2, Vec4};
use std::sync::LazyLock;

/// Which diffuse model a non-metallic, non-transmissive material uses.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DiffuseModel {
    Lambert = 0,
    /// Oren–Nayar rough diffuse (the thesis renders with it); `oren_nayar_sigma` is its
    /// roughness in radians.
    OrenNayar = 1,
}

/// glTF `alphaMode`.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AlphaMode {
    /// Alpha is ignored.
    Opaque = 0,
    /// A surface point exists where alpha ≥ `alpha_cutoff`; rays pass through the rest.
    Mask = 1,
    /// Stochastic transparency: a ray passes with probability 1 − alpha.
    Blend = 2,
}

/// A reference from a material to a texture: which texture, which texture-coordinate set,
/// and the `KHR_texture_transform` of the reference.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TextureRef {
    /// Index into the texture table; -1 for none.
    pub index: i32,
    /// Texture-coordinate set: 0 (TEXCOORD_0) or 1 (TEXCOORD_1).
    pub tex_coord: u32,
    /// `uv' = (m[0] u + m[2] v + m[4], m[1] u + m[3] v + m[5])` (column-major 2×3).
    pub transform: [f32; 6],
    /// `normalTexture.scale` or `occlusionTexture.strength`; 1 for the other channels.
    pub scale: f32,
}

impl TextureRef {
    /// No texture.
    pub const NONE: TextureRef = TextureRef {
        index: -1,
        tex_coord: 0,
        transform: [1.0, 0.0, 0.0, 1.0, 0.0, 0.0],
        scale: 1.0,
    };

    /// A reference to texture `index` through texture-coordinate set `tex_coord`, untransformed.
    pub fn new(index: i32, tex_coord: u32) -> TextureRef {
        TextureRef {
            index,
            tex_coord,
            ..TextureRef::NONE
        }
    }

    /// Sets the `KHR_texture_transform` matrix `T(offset) · R(rotation) · S(scale)` with
    /// `R = [[cos r, sin r], [−sin r, cos r]]` (the transpose of the extension's GLSL listing,
    /// an erratum: see the module docs).
    pub fn with_transform(mut self, offset: [f32; 2], rotation: f32, scale: [f32; 2]) -> Self {
        let (s, c) = rotation.sin_cos();
        self.transform = [
            c * scale[0],
            -s * scale[0],
            s * scale[1],
            c * scale[1],
            offset[0],
            offset[1],
        ];
        self
    }

    #[inline]
    pub fn is_some(&self) -> bool {
        self.index >= 0
    }

    /// The transformed texture coordinate this reference reads, from the hit's sets.
    #[inline]
    pub fn coords(&self, uv: [Vec2; 2]) -> Vec2 {
        let p = uv[(self.tex_coord as usize).min(1)];
        let m = &self.transform;
        Vec2::new(
            m[0] * p.x + m[2] * p.y + m[4],
            m[1] * p.x + m[3] * p.y + m[5],
        )
    }

    /// The referenced texture, when there is one and it is in the table.
    #[inline]
    pub fn texture<'t>(&self, textures: &'t [Texture]) -> Option<&'t Texture> {
        usize::try_from(self.index)
            .ok()
            .and_then(|i| textures.get(i))
    }

    /// RGBA of the referenced texture at the hit (sRGB-decoded when `srgb`); `None` without
    /// a texture.
    #[inline]
    pub fn sample(&self, uv: [Vec2; 2], textures: &[Texture], srgb: bool) -> Option<Vec4> {
        self.texture(textures)
            .map(|t| t.sample(self.coords(uv), srgb))
    }
}

impl Default for TextureRef {
    fn default() -> Self {
        TextureRef::NONE
    }
}

/// A glTF metallic-roughness material with the transmission and emission extensions.
/// The BSDF it stands for is built by [`crate::bsdf::Bsdf::from_material`].
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// Linear base colour factor.
    pub base_color: Rgb,
    /// Base colour texture (sRGB), multiplied with `base_color`.
    pub base_color_texture: TextureRef,
    /// Alpha of `baseColorFactor`.
    pub base_alpha: f32,
    /// glTF `alphaMode` and `alphaCutoff`.
    pub alpha_mode: AlphaMode,
    pub alpha_cutoff: f32,
    /// Metallic-roughness texture (linear): G multiplies `roughness`, B `metallic`.
    pub metallic_roughness_texture: TextureRef,
    /// Tangent-space normal map (linear); `scale` is `normalTexture.scale`.
    pub normal_texture: TextureRef,
    /// Occlusion texture; read, never applied (see the module docs).
    pub occlusion_texture: TextureRef,
    /// Emissive texture (sRGB), multiplied with `emission`.
    pub emissive_texture: TextureRef,
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
    // Textures of the BRDF extensions (see the module docs, "Resolving a material").
    /// KHR_materials_transmission transmissionTexture (linear): R multiplies `transmission`.
    pub transmission_texture: TextureRef,
    /// KHR_materials_volume thicknessTexture (linear, G); read, never applied (module docs).
    pub thickness_texture: TextureRef,
    /// KHR_materials_specular specularTexture (linear): A multiplies `specular`.
    pub specular_texture: TextureRef,
    /// KHR_materials_specular specularColorTexture (sRGB): RGB multiplies `specular_color`.
    pub specular_color_texture: TextureRef,
    /// KHR_materials_clearcoat clearcoatTexture (linear): R multiplies `clearcoat`.
    pub clearcoat_texture: TextureRef,
    /// KHR_materials_clearcoat clearcoatRoughnessTexture (linear): G multiplies
    /// `clearcoat_roughness`.
    pub clearcoat_roughness_texture: TextureRef,
    /// 1 when the metal's GGX reflection gets multiple-scattering energy compensation
    /// (`[render] multiscatter`, [`crate::bsdf::multiscatter`]); 0 (default): single
    /// scattering, as the glTF specification.
    pub multiscatter: u32,
    /// Sheen, diffuse transmission, iridescence and anisotropy ([`crate::material_layers`]).
    pub layers: MaterialLayers,
}

impl Default for Material {
    fn default() -> Self {
        Material {
            base_color: Rgb::splat(0.8),
            base_color_texture: TextureRef::NONE,
            base_alpha: 1.0,
            alpha_mode: AlphaMode::Opaque,
            alpha_cutoff: 0.5,
            metallic_roughness_texture: TextureRef::NONE,
            normal_texture: TextureRef::NONE,
            occlusion_texture: TextureRef::NONE,
            emissive_texture: TextureRef::NONE,
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
            transmission_texture: TextureRef::NONE,
            thickness_texture: TextureRef::NONE,
            specular_texture: TextureRef::NONE,
            specular_color_texture: TextureRef::NONE,
            clearcoat_texture: TextureRef::NONE,
            clearcoat_roughness_texture: TextureRef::NONE,
            multiscatter: 0,
            layers: MaterialLayers::default(),
        }
    }
}

/// A material evaluated at one surface point: factors times textures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResolvedMaterial {
    /// The material with `metallic`, `roughness`, `emission`, `transmission`, `specular`,
    /// `specular_color`, `clearcoat` and `clearcoat_roughness` textured; pass it with
    /// `base` to [`crate::bsdf::Bsdf::from_material`].
    pub material: Material,
    /// Base colour: factor × texture × vertex colour.
    pub base: Rgb,
    /// Alpha: factor × texture alpha × vertex colour alpha.
    pub alpha: f32,
}

impl Material {
    #[inline]
    pub fn is_emissive(&self) -> bool {
        !self.emission.is_black()
    }

    /// Emitted radiance at a point with texture coordinates `uv` (sets TEXCOORD_0 and
    /// TEXCOORD_1): the emissive factor (× strength) times the sRGB-decoded emissive texture
    /// at its own texture-coordinate set and transform, where the material has one.
    #[inline]
    pub fn emission_at(&self, uv: [Vec2; 2], textures: &[Texture]) -> Rgb {
        match self.emissive_texture.sample(uv, textures, true) {
            Some(t) if !self.emission.is_black() => self.emission * Rgb::new(t.x, t.y, t.z),
            _ => self.emission,
        }
    }

    /// Base colour and alpha at a point: factor × sRGB-decoded texture × vertex colour
    /// `color` (COLOR_0, RGBA; (1, 1, 1, 1) when the mesh has none).
    #[inline]
    pub fn base_rgba_at(&self, uv: [Vec2; 2], color: [f32; 4], textures: &[Texture]) -> (Rgb, f32) {
        let t = self
            .base_color_texture
            .sample(uv, textures, true)
            .unwrap_or(Vec4::ONE);
        let base = self.base_color * Rgb::new(t.x * color[0], t.y * color[1], t.z * color[2]);
        (base, self.base_alpha * t.w * color[3])
    }

    /// Base colour at texture coordinate `uv` (used for both sets), without vertex colour.
    #[inline]
    pub fn base_color_at(&self, uv: Vec2, textures: &[Texture]) -> Rgb {
        self.base_rgba_at([uv, uv], [1.0; 4], textures).0
    }

    /// Alpha at a point (for MASK and BLEND), from the base colour factor, texture and
    /// vertex colour.
    #[inline]
    pub fn alpha_at(&self, uv: [Vec2; 2], color: [f32; 4], textures: &[Texture]) -> f32 {
        let t = self
            .base_color_texture
            .sample(uv, textures, false)
            .map_or(1.0, |t| t.w);
        self.base_alpha * t * color[3]
    }

    /// The material at a point: every factor multiplied by its texture (see the module docs).
    #[inline]
    pub fn resolve(
        &self,
        uv: [Vec2; 2],
        color: [f32; 4],
        textures: &[Texture],
    ) -> ResolvedMaterial {
        let (base, alpha) = self.base_rgba_at(uv, color, textures);
        let mut m = *self;
        if let Some(t) = self.metallic_roughness_texture.sample(uv, textures, false) {
            m.roughness = self.roughness * t.y;
            m.metallic = self.metallic * t.z;
        }
        m.emission = self.emission_at(uv, textures);
        let linear = |r: &TextureRef| r.sample(uv, textures, false);
        if let Some(t) = linear(&self.transmission_texture) {
            m.transmission = self.transmission * t.x;
        }
        if let Some(t) = linear(&self.specular_texture) {
            m.specular = self.specular * t.w;
        }
        if let Some(t) = self.specular_color_texture.sample(uv, textures, true) {
            m.specular_color = self.specular_color * Rgb::new(t.x, t.y, t.z);
        }
        if let Some(t) = linear(&self.clearcoat_texture) {
            m.clearcoat = self.clearcoat * t.x;
        }
        if let Some(t) = linear(&self.clearcoat_roughness_texture) {
            m.clearcoat_roughness = self.clearcoat_roughness * t.y;
        }
        m.layers = self.layers.resolve(uv, textures);
        ResolvedMaterial {
            material: m,
            base,
            alpha,
        }
    }
}

/// How a texture coordinate outside [0, 1] is mapped back (glTF sampler `wrapS`/`wrapT`).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wrap {
    Repeat = 0,
    ClampToEdge = 1,
    MirroredRepeat = 2,
}

impl Wrap {
    /// Texel index `i` mapped into `0..n`.
    #[inline]
    fn apply(self, i: i64, n: i64) -> i64 {
        match self {
            Wrap::Repeat => i.rem_euclid(n),
            Wrap::ClampToEdge => i.clamp(0, n - 1),
            Wrap::MirroredRepeat => {
                let m = i.rem_euclid(2 * n);
                if m >= n {
                    2 * n - 1 - m
                } else {
                    m
                }
            }
        }
    }
}

/// Texture filtering (glTF `magFilter`/`minFilter`; mipmapped minification counts as linear).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Filter {
    /// Bilinear interpolation of the four nearest texels.
    Linear = 0,
    /// The texel the coordinate falls in.
    Nearest = 1,
}

/// The storage precision of a texture's channels.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TexelFormat {
    /// `u8` per channel, value / 255.
    U8 = 0,
    /// `u16` per channel, value / 65535.
    U16 = 1,
    /// `f32` per channel, linear (never sRGB-decoded).
    F32 = 2,
}

impl TexelFormat {
    /// Bytes per channel.
    pub fn bytes(self) -> usize {
        match self {
            TexelFormat::U8 => 1,
            TexelFormat::U16 => 2,
            TexelFormat::F32 => 4,
        }
    }
}

/// The sRGB EOTF (IEC 61966-2-1): encoded value in [0, 1] to linear.
#[inline]
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// The sRGB EOTF of every 8-bit code value.
static SRGB8: LazyLock<[f32; 256]> =
    LazyLock::new(|| std::array::from_fn(|i| srgb_to_linear(i as f32 / 255.0)));

/// A texture owned by the host, with its sampler; plugins read it through this view.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct Texture {
    pub width: u32,
    pub height: u32,
    /// 1 (grey), 2 (grey, alpha), 3 (RGB) or 4 (RGBA).
    pub channels: u32,
    pub format: TexelFormat,
    pub wrap_s: Wrap,
    pub wrap_t: Wrap,
    pub filter: Filter,
    /// `width × height × channels` values of `format`, row-major, top row first, aligned
    /// for `format`. Valid while the scene lives.
    pub texels: *const u8,
}

// SAFETY: textures are immutable for the whole render; the host keeps the texels alive.
unsafe impl Send for Texture {}
unsafe impl Sync for Texture {}

impl Texture {
    /// Bytes of texel storage this texture views.
    pub fn texel_bytes(&self) -> usize {
        self.width as usize * self.height as usize * self.channels as usize * self.format.bytes()
    }

    #[inline]
    fn channel(&self, i: usize, srgb: bool) -> f32 {
        // SAFETY: `i` < width·height·channels (callers wrap indices into range); the host
        // guarantees the buffer's size and alignment for `format`.
        unsafe {
            match self.format {
                TexelFormat::U8 => {
                    let v = *self.texels.add(i);
                    if srgb {
                        SRGB8[v as usize]
                    } else {
                        v as f32 * (1.0 / 255.0)
                    }
                }
                TexelFormat::U16 => {
                    let v = *(self.texels as *const u16).add(i) as f32 * (1.0 / 65535.0);
                    if srgb {
                        srgb_to_linear(v)
                    } else {
                        v
                    }
                }
                TexelFormat::F32 => *(self.texels as *const f32).add(i),
            }
        }
    }

    /// RGBA of texel `(x, y)` after wrapping, colour channels sRGB-decoded when `srgb`.
    #[inline]
    fn texel(&self, x: i64, y: i64, srgb: bool) -> Vec4 {
        let x = self.wrap_s.apply(x, self.width as i64) as usize;
        let y = self.wrap_t.apply(y, self.height as i64) as usize;
        let c = self.channels as usize;
        let i = (y * self.width as usize + x) * c;
        match c {
            1 => {
                let l = self.channel(i, srgb);
                Vec4::new(l, l, l, 1.0)
            }
            2 => {
                let l = self.channel(i, srgb);
                Vec4::new(l, l, l, self.channel(i + 1, false))
            }
            3 => Vec4::new(
                self.channel(i, srgb),
                self.channel(i + 1, srgb),
                self.channel(i + 2, srgb),
                1.0,
            ),
            _ => Vec4::new(
                self.channel(i, srgb),
                self.channel(i + 1, srgb),
                self.channel(i + 2, srgb),
                self.channel(i + 3, false),
            ),
        }
    }

    /// RGBA at texture coordinate `uv` with this texture's wrap modes and filter; colour
    /// channels sRGB-decoded (before filtering) when `srgb`. (1, 1, 1, 1) for an empty
    /// texture or a non-finite coordinate.
    pub fn sample(&self, uv: Vec2, srgb: bool) -> Vec4 {
        if self.width == 0
            || self.height == 0
            || self.texels.is_null()
            || !(1..=4).contains(&self.channels)
        {
            return Vec4::ONE;
        }
        let x = uv.x * self.width as f32;
        let y = uv.y * self.height as f32;
        // Far outside the texture f32 has no fractional bits left; such coordinates are junk.
        if !(x.is_finite() && y.is_finite() && x.abs() < 1e9 && y.abs() < 1e9) {
            return Vec4::ONE;
        }
        match self.filter {
            Filter::Nearest => self.texel(x.floor() as i64, y.floor() as i64, srgb),
            Filter::Linear => {
                let (x, y) = (x - 0.5, y - 0.5);
                let (x0, y0) = (x.floor(), y.floor());
                let (fx, fy) = (x - x0, y - y0);
                let (x0, y0) = (x0 as i64, y0 as i64);
                self.texel(x0, y0, srgb) * ((1.0 - fx) * (1.0 - fy))
                    + self.texel(x0 + 1, y0, srgb) * (fx * (1.0 - fy))
                    + self.texel(x0, y0 + 1, srgb) * ((1.0 - fx) * fy)
                    + self.texel(x0 + 1, y0 + 1, srgb) * (fx * fy)
            }
        }
    }

    /// Linear RGB at `uv` (colour channels taken as stored).
    pub fn lookup(&self, uv: Vec2) -> Rgb {
        let v = self.sample(uv, false);
        Rgb::new(v.x, v.y, v.z)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tex(w: u32, h: u32, channels: u32, texels: &[u8]) -> Texture {
        assert_eq!(texels.len(), (w * h * channels) as usize);
        Texture {
            width: w,
            height: h,
            channels,
            format: TexelFormat::U8,
            wrap_s: Wrap::Repeat,
            wrap_t: Wrap::Repeat,
            filter: Filter::Linear,
            texels: texels.as_ptr(),
        }
    }

    #[test]
    fn texture_lookup_wraps_and_interpolates() {
        let texels = [0u8, 255];
        let t = tex(2, 1, 1, &texels);
        assert!((t.lookup(Vec2::new(0.25, 0.5)).r - 0.0).abs() < 1e-6);
        assert!((t.lookup(Vec2::new(0.75, 0.5)).r - 1.0).abs() < 1e-6);
        assert!((t.lookup(Vec2::new(0.5, 0.5)).r - 0.5).abs() < 1e-6);
        assert!((t.lookup(Vec2::new(1.25, 0.5)).r - 0.0).abs() < 1e-6);
        let m = Material {
            base_color_texture: TextureRef::new(0, 0),
            base_color: Rgb::splat(0.5),
            ..Default::default()
        };
        // sRGB 255 decodes to 1.
        assert!((m.base_color_at(Vec2::new(0.75, 0.5), &[t]).g - 0.5).abs() < 1e-6);
    }

    #[test]
    fn wrap_modes_per_axis() {
        // Four texels 0, 1, 2, 3 (×60) in a row, nearest filtering.
        let texels = [0u8, 60, 120, 180];
        let mut t = tex(4, 1, 1, &texels);
        t.filter = Filter::Nearest;
        let at = |t: &Texture, u: f32| (t.sample(Vec2::new(u, 0.5), false).x * 255.0).round();
        // u = 1.125 is texel 4.5 → index 4.
        t.wrap_s = Wrap::Repeat;
        assert_eq!(at(&t, 1.125), 0.0);
        assert_eq!(at(&t, -0.125), 180.0);
        t.wrap_s = Wrap::ClampToEdge;
        assert_eq!(at(&t, 1.125), 180.0);
        assert_eq!(at(&t, -3.0), 0.0);
        t.wrap_s = Wrap::MirroredRepeat;
        // Index 4 mirrors to 3, 5 to 2, 8 back to 0, −1 to 0, −2 to 1.
        assert_eq!(at(&t, 1.125), 180.0);
        assert_eq!(at(&t, 1.375), 120.0);
        assert_eq!(at(&t, 2.125), 0.0);
        assert_eq!(at(&t, -0.125), 0.0);
        assert_eq!(at(&t, -0.375), 60.0);
        // The T axis keeps its own mode: a 1×2 column clamped in v, repeated in u.
        let col = [10u8, 200];
        let mut c = tex(1, 2, 1, &col);
        c.filter = Filter::Nearest;
        c.wrap_t = Wrap::ClampToEdge;
        let v = |c: &Texture, v: f32| (c.sample(Vec2::new(7.3, v), false).x * 255.0).round();
        assert_eq!(v(&c, 1.9), 200.0);
        assert_eq!(v(&c, -0.9), 10.0);
        c.wrap_t = Wrap::Repeat;
        assert_eq!(v(&c, 1.9), 200.0);
        assert_eq!(v(&c, 1.1), 10.0);
    }

    #[test]
    fn linear_filter_clamps_at_the_edge_and_nearest_does_not_blend() {
        let texels = [0u8, 255];
        let mut t = tex(2, 1, 1, &texels);
        t.wrap_s = Wrap::ClampToEdge;
        // At u = 0.0 the four-texel footprint is texels −1 and 0, both clamped to texel 0.
        assert!(t.sample(Vec2::new(0.0, 0.5), false).x.abs() < 1e-6);
        // Repeat blends with the far edge: half of texel 1.
        t.wrap_s = Wrap::Repeat;
        assert!((t.sample(Vec2::new(0.0, 0.5), false).x - 0.5).abs() < 1e-6);
        t.filter = Filter::Nearest;
        assert_eq!(t.sample(Vec2::new(0.49, 0.5), false).x, 0.0);
        assert_eq!(t.sample(Vec2::new(0.51, 0.5), false).x, 1.0);
    }

    #[test]
    fn srgb_decode_table_matches_the_eotf_and_alpha_stays_linear() {
        assert_eq!(srgb_to_linear(0.0), 0.0);
        assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-6);
        assert!((srgb_to_linear(0.5) - 0.214_041).abs() < 1e-5);
        // An RGBA texel (128, 10, 255, 128): colour decoded, alpha not.
        let texels = [128u8, 10, 255, 128];
        let mut t = tex(1, 1, 4, &texels);
        t.filter = Filter::Nearest;
        let s = t.sample(Vec2::new(0.5, 0.5), true);
        assert!((s.x - srgb_to_linear(128.0 / 255.0)).abs() < 1e-7, "{s}");
        assert!((s.x - 0.2158).abs() < 1e-3);
        assert!((s.y - 10.0 / 255.0 / 12.92).abs() < 1e-7);
        assert!((s.z - 1.0).abs() < 1e-6);
        assert!((s.w - 128.0 / 255.0).abs() < 1e-6);
        let l = t.sample(Vec2::new(0.5, 0.5), false);
        assert!((l.x - 128.0 / 255.0).abs() < 1e-6);
        // Decoding happens before filtering: halfway between 0 and 255 is 0.5 linear, not
        // the decode of 127.5.
        let pair = [0u8, 255];
        let p = tex(2, 1, 1, &pair);
        assert!((p.sample(Vec2::new(0.5, 0.5), true).x - 0.5).abs() < 1e-6);
    }

    #[test]
    fn sixteen_bit_and_float_texels() {
        let texels: [u16; 2] = [0, 65535];
        let mut t = tex(2, 1, 1, &[0, 0]);
        t.format = TexelFormat::U16;
        t.texels = texels.as_ptr() as *const u8;
        assert!((t.sample(Vec2::new(0.5, 0.5), false).x - 0.5).abs() < 1e-6);
        assert_eq!(t.texel_bytes(), 4);
        let f: [f32; 3] = [0.25, 2.0, 4.0];
        let mut g = tex(1, 1, 3, &[0, 0, 0]);
        g.format = TexelFormat::F32;
        g.texels = f.as_ptr() as *const u8;
        // Float texels are linear even when asked for sRGB.
        assert_eq!(
            g.sample(Vec2::new(0.5, 0.5), true),
            Vec4::new(0.25, 2.0, 4.0, 1.0)
        );
    }

    #[test]
    fn texture_transform_lands_on_the_expected_texel() {
        // 4×4 texels numbered 0..16 row by row.
        let texels: Vec<u8> = (0..16u8).map(|i| i * 10).collect();
        let mut t = tex(4, 4, 1, &texels);
        t.filter = Filter::Nearest;
        let texel = |r: &TextureRef, uv: Vec2| {
            (r.sample([uv, Vec2::ZERO], &[t], false).unwrap().x * 255.0 / 10.0).round() as i32
        };
        // Offset (0.5, 0.25): uv (0.1, 0.1) → (0.6, 0.35) = texel (2, 1) = 6.
        let r = TextureRef::new(0, 0).with_transform([0.5, 0.25], 0.0, [1.0, 1.0]);
        assert_eq!(texel(&r, Vec2::new(0.1, 0.1)), 6);
        // Scale (0.5, 0.5) then offset (0.5, 0.5): uv (0.9, 0.1) → (0.95, 0.55) = texel (3, 2).
        let r = TextureRef::new(0, 0).with_transform([0.5, 0.5], 0.0, [0.5, 0.5]);
        assert_eq!(texel(&r, Vec2::new(0.9, 0.1)), 11);
        // Rotation by 90°: (u, v) → (v, −u) (the transpose of the extension's GLSL listing,
        // KhronosGroup/glTF#1563); offset (0, 1) brings it back: uv (0.1, 0.6) → (0.6, 0.9) =
        // texel (2, 3) = 14. The listing's own matrix, (u, v) → (−v, u), lands on (0.4, 0.1)
        // (after REPEAT) = texel 1 instead.
        let r = TextureRef::new(0, 0).with_transform(
            [0.0, 1.0],
            std::f32::consts::FRAC_PI_2,
            [1.0, 1.0],
        );
        let c = r.coords([Vec2::new(0.1, 0.6), Vec2::ZERO]);
        assert!((c - Vec2::new(0.6, 0.9)).length() < 1e-6, "{c}");
        assert_eq!(texel(&r, Vec2::new(0.1, 0.6)), 14);
        // Rotation with non-uniform scale, T · R · S: scale (0.5, 0.25) first, then rotate by
        // 30°: (0.4, 0.8) → (0.2, 0.2) → (0.2 cos + 0.2 sin, −0.2 sin + 0.2 cos) + offset.
        let r30 = std::f32::consts::FRAC_PI_6;
        let r = TextureRef::new(0, 0).with_transform([0.1, 0.3], r30, [0.5, 0.25]);
        let c = r.coords([Vec2::new(0.4, 0.8), Vec2::ZERO]);
        let (s30, c30) = r30.sin_cos();
        let want = Vec2::new(0.2 * c30 + 0.2 * s30 + 0.1, -0.2 * s30 + 0.2 * c30 + 0.3);
        assert!((c - want).length() < 1e-6, "{c} vs {want}");
        // A texCoord override reads the second set.
        let r = TextureRef::new(0, 1);
        assert_eq!(
            (r.sample([Vec2::ZERO, Vec2::new(0.9, 0.9)], &[t], false)
                .unwrap()
                .x
                * 25.5)
                .round(),
            15.0
        );
    }

    #[test]
    fn resolve_multiplies_factors_by_textures() {
        // One RGBA texel: metallic-roughness (_, G = 128, B = 64), linear.
        let mr = [0u8, 128, 64, 255];
        // One sRGB base colour texel with alpha.
        let bc = [255u8, 128, 0, 51];
        // Emissive texture: black left half, white right half.
        let em = [0u8, 255];
        let mut ts = [tex(1, 1, 4, &mr), tex(1, 1, 4, &bc), tex(2, 1, 1, &em)];
        for t in &mut ts {
            t.filter = Filter::Nearest;
        }
        let m = Material {
            base_color: Rgb::new(0.5, 1.0, 1.0),
            base_alpha: 0.5,
            base_color_texture: TextureRef::new(1, 0),
            metallic: 1.0,
            roughness: 0.5,
            metallic_roughness_texture: TextureRef::new(0, 0),
            emission: Rgb::splat(4.0),
            emissive_texture: TextureRef::new(2, 1),
            ..Default::default()
        };
        let uv = [Vec2::new(0.5, 0.5), Vec2::new(0.25, 0.5)];
        let r = m.resolve(uv, [1.0, 0.5, 1.0, 0.5], &ts);
        assert!((r.material.roughness - 0.5 * 128.0 / 255.0).abs() < 1e-6);
        assert!((r.material.metallic - 64.0 / 255.0).abs() < 1e-6);
        assert!((r.base.r - 0.5).abs() < 1e-6);
        assert!((r.base.g - 0.5 * srgb_to_linear(128.0 / 255.0)).abs() < 1e-6);
        assert_eq!(r.base.b, 0.0);
        assert!((r.alpha - 0.5 * 0.2 * 0.5).abs() < 1e-6);
        assert_eq!(m.alpha_at(uv, [1.0, 0.5, 1.0, 0.5], &ts), r.alpha);
        // Emissive texture read through TEXCOORD_1: black half emits nothing.
        assert!(r.material.emission.is_black());
        let lit = m.emission_at([Vec2::ZERO, Vec2::new(0.75, 0.5)], &ts);
        assert_eq!(lit, Rgb::splat(4.0));
        // Without textures, the factors as they are.
        let plain = Material::default().resolve(uv, [1.0; 4], &ts);
        assert_eq!(plain.material, Material::default());
        assert_eq!(plain.base, Rgb::splat(0.8));
    }

    #[test]
    fn resolve_multiplies_the_extension_factors_by_their_channels() {
        // One RGBA texel (R = 51, G = 102, B = 153, A = 204) read by every extension texture,
        // each through its own channel; a second texture (all zero) through TEXCOORD_1.
        let px = [51u8, 102, 153, 204];
        let zero = [0u8; 4];
        let mut ts = [tex(1, 1, 4, &px), tex(1, 1, 4, &zero)];
        for t in &mut ts {
            t.filter = Filter::Nearest;
        }
        let m = Material {
            transmission: 0.5,
            transmission_texture: TextureRef::new(0, 0),
            specular: 0.8,
            specular_texture: TextureRef::new(0, 0),
            specular_color: Rgb::new(2.0, 1.0, 0.5),
            specular_color_texture: TextureRef::new(0, 0),
            clearcoat: 0.9,
            clearcoat_texture: TextureRef::new(0, 0),
            clearcoat_roughness: 0.6,
            clearcoat_roughness_texture: TextureRef::new(0, 0),
            thickness: 0.25,
            thickness_texture: TextureRef::new(1, 1),
            ..Default::default()
        };
        let uv = [Vec2::splat(0.5), Vec2::splat(0.5)];
        let r = m.resolve(uv, [1.0; 4], &ts).material;
        let lin = |v: u8| v as f32 / 255.0;
        assert!(
            (r.transmission - 0.5 * lin(51)).abs() < 1e-6,
            "{}",
            r.transmission
        );
        assert!((r.specular - 0.8 * lin(204)).abs() < 1e-6, "{}", r.specular);
        let want = Rgb::new(
            2.0 * srgb_to_linear(lin(51)),
            srgb_to_linear(lin(102)),
            0.5 * srgb_to_linear(lin(153)),
        );
        let (g, w) = (r.specular_color.to_array(), want.to_array());
        assert!((0..3).all(|i| (g[i] - w[i]).abs() < 1e-6), "{g:?} vs {w:?}");
        assert!((r.clearcoat - 0.9 * lin(51)).abs() < 1e-6);
        assert!((r.clearcoat_roughness - 0.6 * lin(102)).abs() < 1e-6);
        // The thickness texture (all zero here) is read but never applied.
        assert_eq!(r.thickness, 0.25);
        // The second set reads the zero texture: every factor goes to 0.
        let z = Material {
            transmission_texture: TextureRef::new(1, 1),
            specular_texture: TextureRef::new(1, 1),
            clearcoat_texture: TextureRef::new(1, 1),
            ..m
        }
        .resolve(uv, [1.0; 4], &ts)
        .material;
        assert_eq!((z.transmission, z.specular, z.clearcoat), (0.0, 0.0, 0.0));
    }
}
