//! The translucent diffuse base of `KHR_materials_diffuse_transmission`: the extension mixes
//! the diffuse BRDF with a Lambertian BTDF to the back side,
//!
//!   f_base = (1 − t_d) ρ/π (same side) + t_d C_t/π (opposite sides),
//!
//! t_d the diffuseTransmissionFactor, C_t the diffuseTransmissionColorFactor. Both parts sit
//! under the specular layer and carry the material's energy coupling
//! (1 − E_d(|μ_o|))(1 − E_d(|μ_i|)) / (1 − Ē_d) of [the module docs](super), so the reflected
//! and transmitted light together are at most (1 − m)(1 − t)(1 − E_d(μ_o)) · max(ρ, C_t)
//! and the sum with the specular layer stays ≤ 1. The value is symmetric in ω_o and ω_i
//! (each part is), so the lobe is reciprocal, and both light and camera paths use it alike.
//!
//! The lobe ([`GltfLobeKind::TranslucentDiffuse`]) keeps the reflection tint
//! (1 − m)(1 − t)(1 − t_d) ρ in `f0` and the transmission tint (1 − m)(1 − t) t_d C_t in `f90`.
//! It samples a side with probability proportional to the tints' largest channels (`u.x`
//! split and rescaled) and a cosine-weighted direction on it, so the density of ω_i is
//! P(side) |cos θ_i| / π.

use super::super::BsdfSample;
use super::{GltfLobe, GltfLobeKind};
use crate::path::NodeType;
use crate::sampling::{cosine_hemisphere_pdf, rescaled, two_sided_cosine};
use crate::Rgb;
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

impl GltfLobe {
    /// The probability of sampling the reflection (same side); the transmission takes the
    /// rest.
    #[inline]
    fn reflect_probability(&self) -> f32 {
        let (r, t) = (self.f0.max_component(), self.f90.max_component());
        if r + t > 0.0 {
            r / (r + t)
        } else {
            1.0
        }
    }

    /// The translucent base's raw value (without `scale` and the layers above) and density.
    #[inline]
    pub(super) fn translucent_eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        debug_assert_eq!(self.kind, GltfLobeKind::TranslucentDiffuse);
        let sh = &self.shared;
        if wo.z == 0.0 || wi.z == 0.0 || sh.diffuse_norm <= 0.0 || wi.z.is_nan() {
            return (Rgb::ZERO, 0.0);
        }
        let k = sh.diffuse_coupling(wo.z, wi.z);
        let p_r = self.reflect_probability();
        let cos_pdf = cosine_hemisphere_pdf(wi.z.abs());
        if wo.z * wi.z > 0.0 {
            (self.diffuse.eval(wo, wi) * self.f0 * k, p_r * cos_pdf)
        } else {
            (self.f90 * (FRAC_1_PI * k), (1.0 - p_r) * cos_pdf)
        }
    }

    /// A side chosen by `u.x`, a cosine-weighted direction on it; the raw value (the caller
    /// finishes it) and the density.
    pub(super) fn sample_translucent(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        let p_r = self.reflect_probability();
        let reflect = u.x < p_r;
        let ux = if reflect {
            rescaled(u.x, 0.0, p_r)
        } else {
            rescaled(u.x, p_r, 1.0 - p_r)
        };
        let (mut wi, _) = two_sided_cosine(wo, Vec2::new(ux, u.y))?;
        if !reflect {
            wi.z = -wi.z;
        }
        let (f, pdf) = self.translucent_eval_pdf(wo, wi);
        (pdf > 0.0).then_some(BsdfSample {
            wi,
            f,
            pdf,
            node: if reflect {
                NodeType::DiffuseReflection
            } else {
                NodeType::DiffuseTransmission
            },
            delta: false,
            eta: 1.0,
        })
    }
}
