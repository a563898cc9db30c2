//! Metallic conductor of the glTF metallic-roughness workflow: GGX microfacet reflection with
//! Schlick's Fresnel, F(θ) = F0 + (1 − F0)(1 − cos θ)⁵, F0 = base colour.
//!
//! * Rough (α ≥ [`DELTA_ALPHA`]): Torrance–Sparrow
//!   f = D(ω_m) G2(ω_o, ω_i) F(ω_o·ω_m) / (4 |cos θ_o| |cos θ_i|), ω_m = normalize(ω_o + ω_i),
//!   sampled through visible normals with pdf D_ωo(ω_m) / (4 |ω_o·ω_m|)
//!   (pbrt-v4 §9.6.4–9.6.5; Heitz 2018). G2 is height-correlated (see [`super::microfacet`]).
//! * Smooth (α < [`DELTA_ALPHA`]): perfect mirror, a Dirac lobe with f = F / |cos θ_i| and
//!   discrete probability 1 (pbrt-v4 §9.3).
//!
//! Two-sided: for `wo.z < 0` both directions are mirrored through the surface (z negated).

use super::microfacet::Ggx;
use super::{BsdfSample, DELTA_ALPHA};
use crate::path::NodeType;
use crate::Rgb;
use glam::{Vec2, Vec3};

/// Schlick's Fresnel approximation for reflectance `f0` at normal incidence.
#[inline]
pub fn fresnel_schlick(f0: Rgb, cos_theta: f32) -> Rgb {
    let m = (1.0 - cos_theta.abs().min(1.0)).max(0.0);
    let m2 = m * m;
    let m5 = m2 * m2 * m;
    f0 + (Rgb::ONE + f0 * -1.0) * m5
}

#[derive(Clone, Copy, Debug)]
pub struct Conductor {
    /// Reflectance at normal incidence (the glTF base colour).
    pub f0: Rgb,
    /// GGX α (= perceptual roughness²).
    pub alpha: f32,
}

impl Conductor {
    #[inline]
    pub fn is_delta(&self) -> bool {
        self.alpha < DELTA_ALPHA
    }

    #[inline]
    fn ggx(&self) -> Ggx {
        Ggx::new(self.alpha)
    }

    /// Mirror both directions into the upper hemisphere of `wo`.
    #[inline]
    fn to_upper(wo: Vec3, wi: Vec3) -> (Vec3, Vec3) {
        if wo.z < 0.0 {
            (Vec3::new(wo.x, wo.y, -wo.z), Vec3::new(wi.x, wi.y, -wi.z))
        } else {
            (wo, wi)
        }
    }

    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        if self.is_delta() {
            return Rgb::ZERO;
        }
        let (wo, wi) = Self::to_upper(wo, wi);
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::ZERO;
        }
        let wm = wo + wi;
        if wm.length_squared() == 0.0 {
            return Rgb::ZERO;
        }
        let wm = wm.normalize();
        let ggx = self.ggx();
        let s = ggx.d(wm) * ggx.g2(wo, wi) / (4.0 * wo.z * wi.z);
        fresnel_schlick(self.f0, wo.dot(wm)) * s
    }

    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if self.is_delta() {
            return 0.0;
        }
        let (wo, wi) = Self::to_upper(wo, wi);
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let wm = wo + wi;
        if wm.length_squared() == 0.0 {
            return 0.0;
        }
        let wm = wm.normalize();
        let d = wo.dot(wm);
        if d <= 0.0 {
            return 0.0;
        }
        self.ggx().pdf_wm(wo, wm) / (4.0 * d)
    }

    /// `(eval, pdf)` sharing the hemisphere flip, the half vector and its normalisation, D and
    /// Λ(ω_o) ([`Ggx::d_g2_pdf_wm`]); each equals the separate function's value bit for bit.
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        if self.is_delta() {
            return (Rgb::ZERO, 0.0);
        }
        let (wo, wi) = Self::to_upper(wo, wi);
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return (Rgb::ZERO, 0.0);
        }
        let wm = wo + wi;
        if wm.length_squared() == 0.0 {
            return (Rgb::ZERO, 0.0);
        }
        let wm = wm.normalize();
        let (d, g2, pdf_wm) = self.ggx().d_g2_pdf_wm(wo, wi, wm);
        let c = wo.dot(wm);
        let f = fresnel_schlick(self.f0, c) * (d * g2 / (4.0 * wo.z * wi.z));
        let pdf = if c <= 0.0 { 0.0 } else { pdf_wm / (4.0 * c) };
        (f, pdf)
    }

    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        let below = wo.z < 0.0;
        let back = |w: Vec3| if below { Vec3::new(w.x, w.y, -w.z) } else { w };
        let wo = back(wo);
        if wo.z == 0.0 {
            return None;
        }
        if self.is_delta() {
            let wi = Vec3::new(-wo.x, -wo.y, wo.z);
            return Some(BsdfSample {
                wi: back(wi),
                f: fresnel_schlick(self.f0, wo.z) / wo.z,
                pdf: 1.0,
                node: NodeType::SpecularReflection,
                delta: true,
                eta: 1.0,
            });
        }
        let ggx = self.ggx();
        let (wi, wm, d, pdf) = ggx.sample_reflection(wo, u)?;
        if pdf.is_nan() || pdf <= 0.0 {
            return None;
        }
        let f = fresnel_schlick(self.f0, d) * (ggx.d(wm) * ggx.g2(wo, wi) / (4.0 * wo.z * wi.z));
        Some(BsdfSample {
            wi: back(wi),
            f,
            pdf,
            node: NodeType::GlossyReflection,
            delta: false,
            eta: 1.0,
        })
    }

    /// Albedo estimate for termination: the normal-incidence reflectance.
    #[inline]
    pub fn albedo(&self) -> f32 {
        self.f0.max_component()
    }
}

#[cfg(test)]
mod tests {
    use super::super::testutil::*;
    use super::super::{Component, NARROW_GLOSSY_ALPHA};
    use super::*;
    use crate::path::NodeClass;
    use crate::rng::Rng;

    fn cond(alpha: f32, f0: Rgb) -> Component {
        Component::Conductor(Conductor { f0, alpha })
    }

    #[test]
    fn classes() {
        assert!(cond(0.0, Rgb::ONE).is_delta());
        assert_eq!(cond(0.0, Rgb::ONE).class(), NodeClass::Alpha);
        assert!(!cond(0.02, Rgb::ONE).is_delta());
        assert_eq!(cond(0.02, Rgb::ONE).class(), NodeClass::Alpha);
        assert_eq!(cond(NARROW_GLOSSY_ALPHA, Rgb::ONE).class(), NodeClass::Beta);
        assert_eq!(cond(0.8, Rgb::ONE).class(), NodeClass::Beta);
    }

    #[test]
    fn sampled_values_match_eval_and_pdf() {
        for alpha in [0.05, 0.3, 0.8] {
            let c = cond(alpha, Rgb::new(0.95, 0.64, 0.54));
            for wo in test_directions_both_sides() {
                let ok = check_sample_consistency(&c, wo, 4000, 21);
                assert!(
                    ok > 1000,
                    "alpha {alpha} wo {wo:?}: only {ok} samples succeeded"
                );
            }
        }
    }

    #[test]
    fn pdf_integrates_to_at_most_one() {
        for alpha in [0.05f32, 0.3, 0.8] {
            let c = cond(alpha, Rgb::ONE);
            let n = if alpha < 0.1 { 1000 } else { 400 };
            // Only samples reflected below the horizon are lost, so ∫pdf is the success rate.
            for wo in [dir(0.3, 0.2), flip(dir(0.3, 0.2)), dir(1.4, 1.0)] {
                check_pdf_integral(&c, wo, n, 100_000, 22);
            }
            // Near the normal a narrow lobe loses (almost) nothing; GGX's long tail sends about
            // 8 % of α = 0.3 reflections below the horizon.
            if alpha < 0.1 {
                let p = check_pdf_integral(&c, Vec3::Z, n, 100_000, 23);
                assert!((p - 1.0).abs() < 0.01, "alpha {alpha}: ∫pdf = {p}");
            }
        }
    }

    #[test]
    fn energy_is_consistent_and_bounded() {
        for alpha in [0.05f32, 0.3, 0.8] {
            let c = cond(alpha, Rgb::ONE);
            let n = if alpha < 0.1 { 1000 } else { 400 };
            for wo in [dir(0.3, 0.2), flip(dir(0.9, 1.0)), dir(1.4, 2.0)] {
                let e = check_energy(&c, wo, n, 100_000, 24, 0.02);
                // Single scattering loses energy, more for rougher lobes; little near the
                // normal for a narrow one.
                if alpha < 0.1 && wo.z.abs() > 0.9 {
                    assert!(e[0] > 0.95, "alpha {alpha}: albedo {}", e[0]);
                }
            }
        }
        // A coloured conductor reflects at most its Schlick curve.
        let c = cond(0.3, Rgb::new(0.9, 0.5, 0.1));
        let e = check_energy(&c, dir(0.2, 0.0), 400, 100_000, 25, 0.02);
        assert!(e[2] < e[1] && e[1] < e[0]);
    }

    #[test]
    fn reciprocal() {
        for alpha in [0.05, 0.3, 0.8] {
            check_reciprocity(&cond(alpha, Rgb::new(0.9, 0.6, 0.3)), 26);
        }
    }

    #[test]
    fn smooth_mirror_reflects_with_fresnel_throughput() {
        let f0 = Rgb::new(0.9, 0.6, 0.1);
        let c = cond(0.0, f0);
        let mut r = Rng::new(27, 0);
        for wo in test_directions_both_sides() {
            let s = c.sample(wo, r.uniform2()).expect("mirror sample");
            assert!(s.delta && s.node == NodeType::SpecularReflection);
            let mirror = Vec3::new(-wo.x, -wo.y, wo.z);
            assert!((s.wi - mirror).length() < 1e-5, "{:?} vs {mirror:?}", s.wi);
            let t = s.f * (s.wi.z.abs() / s.pdf);
            let fr = fresnel_schlick(f0, wo.z);
            for (a, b) in t.to_array().into_iter().zip(fr.to_array()) {
                assert!((a - b).abs() < 1e-5, "throughput {t:?} vs F {fr:?}");
            }
            assert!(c.eval(wo, mirror).is_black() && c.pdf(wo, mirror) == 0.0);
        }
        // Schlick: F0 at normal incidence, 1 at grazing.
        assert!((fresnel_schlick(f0, 1.0).g - 0.6).abs() < 1e-6);
        assert!((fresnel_schlick(f0, 0.0).b - 1.0).abs() < 1e-6);
    }
}
