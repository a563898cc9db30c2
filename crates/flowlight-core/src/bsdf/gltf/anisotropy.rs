//! The anisotropic specular layer of `KHR_materials_anisotropy`: the glTF specular lobe
//! (Schlick Fresnel, height-correlated Smith G2) with an anisotropic GGX distribution
//! ([`super::super::anisotropic_ggx`]) stretched along the anisotropy direction.
//!
//! The extension gives a strength s (× texture B) and a direction in the tangent frame
//! (T, B, N): the texture's (R, G)·2 − 1, else (1, 0), rotated by `anisotropyRotation`. With
//! α = roughness²,
//!
//!   α_t = mix(α, 1, s²) along the direction,   α_b = max(α, 10⁻³) across it,
//!
//! so s = 0 is the isotropic lobe and roughness 1 shows no anisotropy. The direction reaches
//! the BSDF in its local shading frame (`z` = shading normal, x and y the frame of
//! `Frame::from_z`): the host projects the tangent-frame direction onto that frame where it
//! builds the BSDF at a hit (`flowlight_sdk::scene::Scene::bsdf`). The lobe evaluates in the
//! frame rotated so that x is the direction: x' = c x + s y, y' = −s x + c y.
//!
//! The diffuse base's energy coupling keeps the isotropic albedo tables at α = α_b: the
//! stretched lobe reflects no more than the isotropic one of the smaller roughness
//! (single-scattering GGX loses more energy the rougher it is), so the base receives at least
//! what it should and the white furnace stays ≤ 1 (`tests_layers.rs`).

use super::super::anisotropic_ggx::AnisoGgx;
use super::super::BsdfSample;
use super::{flip, to_upper, GltfLobe};
use crate::path::NodeType;
use crate::Rgb;
use glam::{Vec2, Vec3};

/// The anisotropic roughnesses and the direction (unit, in the local shading frame's x-y
/// plane) of a specular lobe; `strength` 0 (the default): isotropic.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Anisotropy {
    pub strength: f32,
    /// α along the direction (α_t) and across it (α_b).
    pub alpha_t: f32,
    pub alpha_b: f32,
    /// cos and sin of the direction's angle from the local x axis.
    pub cos: f32,
    pub sin: f32,
}

impl Anisotropy {
    /// The anisotropy of strength `s` (clamped to [0, 1]) along the local direction `dir`
    /// (normalised; the x axis where it is zero or not finite) for base α.
    pub fn new(s: f32, dir: Vec2, alpha: f32) -> Anisotropy {
        let s = if s.is_finite() {
            s.clamp(0.0, 1.0)
        } else {
            0.0
        };
        let d = dir.try_normalize().unwrap_or(Vec2::X);
        Anisotropy {
            strength: s,
            alpha_t: alpha + (1.0 - alpha) * s * s,
            alpha_b: alpha.max(1e-3),
            cos: d.x,
            sin: d.y,
        }
    }

    #[inline]
    pub fn is_some(&self) -> bool {
        self.strength > 0.0
    }

    #[inline]
    fn ggx(&self) -> AnisoGgx {
        AnisoGgx::new(self.alpha_t, self.alpha_b)
    }

    /// `w` in the frame whose x axis is the direction.
    #[inline]
    fn aligned(&self, w: Vec3) -> Vec3 {
        Vec3::new(
            self.cos * w.x + self.sin * w.y,
            -self.sin * w.x + self.cos * w.y,
            w.z,
        )
    }

    /// The inverse of [`Anisotropy::aligned`].
    #[inline]
    fn unaligned(&self, w: Vec3) -> Vec3 {
        Vec3::new(
            self.cos * w.x - self.sin * w.y,
            self.sin * w.x + self.cos * w.y,
            w.z,
        )
    }

    /// α standing for the lobe in the node classes (Λα/Λβ): the geometric mean.
    #[inline]
    pub fn class_alpha(&self) -> f32 {
        (self.alpha_t * self.alpha_b).sqrt()
    }
}

impl GltfLobe {
    /// The anisotropic specular lobe's raw value and density at (`wo`, `wi`).
    pub(super) fn anisotropic_eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        let a = &self.aniso;
        let (wo, wi) = to_upper(wo, wi);
        let (wo, wi) = (a.aligned(wo), a.aligned(wi));
        let ggx = a.ggx();
        match ggx.reflection(wo, wi) {
            Some((s, c)) => (self.fresnel(c) * s, ggx.reflection_pdf(wo, wi)),
            None => (Rgb::ZERO, 0.0),
        }
    }

    /// A reflection through a sampled visible normal of the anisotropic lobe; raw value.
    pub(super) fn sample_anisotropic(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        let a = &self.aniso;
        let below = wo.z < 0.0;
        let up = a.aligned(if below { flip(wo) } else { wo });
        let (wr, _, _, pdf) = a.ggx().sample_reflection(up, u)?;
        let wi = a.unaligned(wr);
        let wi = if below { flip(wi) } else { wi };
        let f = self.anisotropic_eval_pdf(wo, wi).0;
        Some(BsdfSample {
            wi,
            f,
            pdf,
            node: NodeType::GlossyReflection,
            delta: false,
            eta: 1.0,
        })
    }
}
