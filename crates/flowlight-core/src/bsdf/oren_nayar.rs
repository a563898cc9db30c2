//! Oren–Nayar rough diffuse reflection, the qualitative ("fast") model.
//!
//! f = R/π · (A + B · max(0, cos(φ_i − φ_o)) · sin α · tan β), α = max(θ_i, θ_o),
//! β = min(θ_i, θ_o), A = 1 − σ²/(2(σ² + 0.33)), B = 0.45 σ²/(σ² + 0.09), σ the standard
//! deviation of the facet slope angle in radians (Oren & Nayar 1994, eq. 30; pbrt-v3 §8.4.2).
//! Sampled by the cosine-weighted hemisphere. Two-sided like [`super::Lambert`]: the lit
//! hemisphere follows `wo`.

use super::BsdfSample;
use crate::path::NodeType;
use crate::sampling::{cosine_hemisphere_pdf, two_sided_cosine, two_sided_cosine_pdf};
use crate::Rgb;
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

#[derive(Clone, Copy, Debug)]
pub struct OrenNayar {
    pub albedo: Rgb,
    pub a: f32,
    pub b: f32,
}

impl OrenNayar {
    /// Oren–Nayar with roughness `sigma` in radians (σ = 0 is Lambert).
    pub fn new(albedo: Rgb, sigma: f32) -> OrenNayar {
        let s2 = if sigma.is_finite() {
            sigma * sigma
        } else {
            0.0
        };
        OrenNayar {
            albedo,
            a: 1.0 - s2 / (2.0 * (s2 + 0.33)),
            b: 0.45 * s2 / (s2 + 0.09),
        }
    }

    #[inline]
    fn factor(&self, wo: Vec3, wi: Vec3) -> f32 {
        if self.b == 0.0 {
            // Lambert (σ = 0, the glTF default): A = 1. The general formula gives the same
            // wherever f is evaluated (both cosines non-zero), after two roots and divisions.
            return self.a;
        }
        let sin_i = (1.0 - wi.z * wi.z).max(0.0).sqrt();
        let sin_o = (1.0 - wo.z * wo.z).max(0.0).sqrt();
        let mut max_cos = 0.0;
        if sin_i > 1e-4 && sin_o > 1e-4 {
            // cos(φi − φo) = (wi.x wo.x + wi.y wo.y) / (sin θi sin θo).
            max_cos = ((wi.x * wo.x + wi.y * wo.y) / (sin_i * sin_o)).clamp(0.0, 1.0);
        }
        let (sin_alpha, tan_beta) = if wi.z.abs() > wo.z.abs() {
            (sin_o, sin_i / wi.z.abs())
        } else {
            (sin_i, sin_o / wo.z.abs())
        };
        self.a + self.b * max_cos * sin_alpha * tan_beta
    }

    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        if wo.z * wi.z <= 0.0 {
            return Rgb::ZERO;
        }
        self.albedo * (FRAC_1_PI * self.factor(wo, wi))
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
        (
            self.albedo * (FRAC_1_PI * self.factor(wo, wi)),
            cosine_hemisphere_pdf(wi.z.abs()),
        )
    }

    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        let (wi, pdf) = two_sided_cosine(wo, u)?;
        Some(BsdfSample {
            wi,
            f: self.albedo * (FRAC_1_PI * self.factor(wo, wi)),
            pdf,
            node: NodeType::DiffuseReflection,
            delta: false,
            eta: 1.0,
        })
    }

    /// Albedo estimate for termination.
    #[inline]
    pub fn albedo(&self) -> f32 {
        self.albedo.max_component()
    }
}

#[cfg(test)]
mod tests {
    use super::super::testutil::*;
    use super::super::{Component, Lambert};
    use super::*;

    fn on(sigma: f32, albedo: Rgb) -> Component {
        Component::OrenNayar(OrenNayar::new(albedo, sigma))
    }

    #[test]
    fn coefficients_match_pbrt() {
        let m = OrenNayar::new(Rgb::ONE, 0.3);
        let s2 = 0.09f32;
        assert!((m.a - (1.0 - s2 / (2.0 * (s2 + 0.33)))).abs() < 1e-6);
        assert!((m.b - 0.45 * s2 / (s2 + 0.09)).abs() < 1e-6);
        let l = OrenNayar::new(Rgb::ONE, 0.0);
        assert_eq!((l.a, l.b), (1.0, 0.0));
        // σ = 0 reduces to Lambert.
        let wo = dir(0.7, 0.2);
        let wi = dir(1.2, 2.5);
        let lam = Lambert { albedo: Rgb::ONE };
        assert!((l.eval(wo, wi).r - lam.eval(wo, wi).r).abs() < 1e-6);
        // Retro-reflection is brighter than forward scattering for rough surfaces.
        let wo = dir(1.0, 0.0);
        assert!(m.eval(wo, dir(1.0, 0.0)).r > m.eval(wo, dir(1.0, std::f32::consts::PI)).r);
    }

    #[test]
    fn sampled_values_match_eval_and_pdf() {
        for sigma in [0.3, 1.0] {
            let c = on(sigma, Rgb::new(0.9, 0.5, 0.2));
            for wo in test_directions_both_sides() {
                check_sample_consistency(&c, wo, 4000, 11);
            }
        }
    }

    #[test]
    fn pdf_integrates_to_one() {
        for sigma in [0.3, 1.0] {
            let c = on(sigma, Rgb::ONE);
            for wo in [dir(0.4, 0.3), flip(dir(1.3, 1.0))] {
                let p = check_pdf_integral(&c, wo, 400, 20_000, 12);
                assert!((p - 1.0).abs() < 0.01, "σ {sigma}: ∫pdf = {p}");
            }
        }
    }

    #[test]
    fn energy_is_consistent_and_bounded() {
        for sigma in [0.3, 1.0] {
            let c = on(sigma, Rgb::ONE);
            for wo in [dir(0.2, 0.3), dir(1.0, 1.0), flip(dir(1.5, 2.0))] {
                check_energy(&c, wo, 400, 100_000, 13, 0.02);
            }
        }
    }

    #[test]
    fn reciprocal() {
        for sigma in [0.3, 1.0] {
            check_reciprocity(&on(sigma, Rgb::new(0.3, 0.6, 0.9)), 14);
        }
    }
}
