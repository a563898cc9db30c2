//! Lambertian diffuse reflection.

use super::BsdfSample;
use crate::path::NodeType;
use crate::sampling::{cosine_hemisphere_pdf, two_sided_cosine, two_sided_cosine_pdf};
use crate::Rgb;
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// f = albedo / π on the side of `wo`; two-sided (the hemisphere follows `wo`).
#[derive(Clone, Copy, Debug)]
pub struct Lambert {
    pub albedo: Rgb,
}

impl Lambert {
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        if wo.z * wi.z <= 0.0 {
            return Rgb::ZERO;
        }
        self.albedo * FRAC_1_PI
    }
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        two_sided_cosine_pdf(wo, wi)
    }

    /// `(eval, pdf)` with one side test for both (see [`super::Bsdf::eval_pdf`]); the same
    /// values, bit for bit.
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        if wo.z * wi.z <= 0.0 {
            return (Rgb::ZERO, 0.0);
        }
        (self.albedo * FRAC_1_PI, cosine_hemisphere_pdf(wi.z.abs()))
    }

    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        let (wi, pdf) = two_sided_cosine(wo, u)?;
        Some(BsdfSample {
            wi,
            f: self.albedo * FRAC_1_PI,
            pdf,
            node: NodeType::DiffuseReflection,
            delta: false,
            eta: 1.0,
        })
    }
}
