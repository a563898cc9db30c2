//! Dielectric interface (glass, water): reflection and refraction with the exact unpolarised
//! Fresnel reflectance (pbrt-v4 §9.3.5, `FrDielectric`).
//!
//! `eta` is the relative index of refraction inside/outside; `wo.z < 0` means the ray arrives
//! from inside. Below, η' = η_i/η_o is the relative IOR of the side of ω_i over that of ω_o
//! (η' = eta when ω_o is outside and ω_i inside).
//!
//! * Smooth (α < [`DELTA_ALPHA`] or eta = 1): Dirac lobes (pbrt-v4 §9.5). Reflection is chosen
//!   with probability R = F(cos θ_o), refraction with T = 1 − R; f = R/|cos θ_i| resp.
//!   T/|cos θ_i|, so the throughput of either branch is 1 (before tint and radiance scaling).
//!   Total internal reflection gives R = 1.
//! * Rough: Walter et al. 2007, "Microfacet Models for Refraction through Rough Surfaces" with
//!   GGX, as in pbrt-v4 §9.7. Generalised half vector ω_m = normalize(η' ω_i + ω_o);
//!   f_r = D G2 F / (4 |cos θ_o cos θ_i|),
//!   f_t = D G2 (1 − F) |ω_i·ω_m| |ω_o·ω_m| / (|cos θ_i cos θ_o| (ω_i·ω_m + ω_o·ω_m/η')²).
//!   ω_m is sampled from the visible normals of ω_o; reflection/refraction is chosen with the
//!   Fresnel reflectance at ω_m. Jacobians: dω_m/dω_i = 1/(4|ω_o·ω_m|) for reflection and
//!   |ω_i·ω_m| / (ω_i·ω_m + ω_o·ω_m/η')² for refraction.
//!
//! **Radiance scaling.** In [`TransportMode::Radiance`] (camera paths, the default) the
//! transmitted part is multiplied by 1/η'² = (η_o/η_i)²: radiance arriving from the ω_i side is
//! compressed into the smaller solid angle of the ω_o side, L_o = (η_o/η_i)² L_i (pbrt-v4
//! §9.5.2). [`TransportMode::Importance`] (light paths) omits the factor. With the factor, a
//! camera path inside glass (ω_o inside) that refracts out gains throughput η² (e.g. 2.25); the
//! energy tests therefore use `Importance`, where R + T = 1 exactly.
//!
//! **Tint.** Following glTF `KHR_materials_transmission`, transmission is tinted by the base
//! colour; the specular reflection is not.

use super::microfacet::{reflect, Ggx};
use super::{BsdfSample, DELTA_ALPHA};
use crate::path::NodeType;
use crate::Rgb;
use glam::{Vec2, Vec3};

/// Which quantity a path carries: it decides the 1/η'² scaling of refraction.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum TransportMode {
    /// Camera paths carry radiance: transmission scaled by (η_o/η_i)².
    #[default]
    Radiance,
    /// Light paths carry importance: no scaling.
    Importance,
}

/// Exact Fresnel reflectance of a dielectric interface for `cos_i` = cos θ of the incident
/// direction (negative: from inside) and relative IOR `eta` = inside/outside.
#[inline]
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    let mut cos_i = cos_i.clamp(-1.0, 1.0);
    let mut eta = eta;
    if cos_i < 0.0 {
        eta = 1.0 / eta;
        cos_i = -cos_i;
    }
    let sin2_i = (1.0 - cos_i * cos_i).max(0.0);
    let sin2_t = sin2_i / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    let r_parl = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    (r_parl * r_parl + r_perp * r_perp) * 0.5
}

/// Refracts `wi` through the interface with normal `n` (either orientation) and relative IOR
/// `eta` (side opposite to `n`'s positive side over `n`'s side). Returns the refracted
/// direction and η' (IOR of the transmitted side over the incident side), or `None` on total
/// internal reflection.
#[inline]
pub fn refract(wi: Vec3, n: Vec3, eta: f32) -> Option<(Vec3, f32)> {
    let mut cos_i = n.dot(wi);
    let mut eta = eta;
    let mut n = n;
    if cos_i < 0.0 {
        eta = 1.0 / eta;
        cos_i = -cos_i;
        n = -n;
    }
    let sin2_i = (1.0 - cos_i * cos_i).max(0.0);
    let sin2_t = sin2_i / (eta * eta);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    Some((-wi / eta + (cos_i / eta - cos_t) * n, eta))
}

#[derive(Clone, Copy, Debug)]
pub struct Dielectric {
    /// Transmission tint (glTF base colour).
    pub tint: Rgb,
    /// Relative IOR inside/outside.
    pub eta: f32,
    /// GGX α (= perceptual roughness²).
    pub alpha: f32,
    pub mode: TransportMode,
}

impl Dielectric {
    /// A dielectric for camera paths ([`TransportMode::Radiance`]).
    pub fn new(tint: Rgb, eta: f32, alpha: f32) -> Dielectric {
        let eta = if eta > 0.0 && eta.is_finite() {
            eta
        } else {
            1.5
        };
        Dielectric {
            tint,
            eta,
            alpha,
            mode: TransportMode::Radiance,
        }
    }

    #[inline]
    pub fn is_delta(&self) -> bool {
        self.eta == 1.0 || self.alpha < DELTA_ALPHA
    }

    /// Factor applied to transmission for η' = η_i/η_o.
    #[inline]
    fn transmission_scale(&self, etap: f32) -> Rgb {
        match self.mode {
            TransportMode::Radiance => self.tint / (etap * etap),
            TransportMode::Importance => self.tint,
        }
    }

    #[inline]
    fn ggx(&self) -> Ggx {
        Ggx::new(self.alpha)
    }

    /// Generalised half vector (facing +z), η', and whether the pair is a reflection; `None`
    /// for degenerate or back-facing configurations.
    #[inline]
    fn half_vector(&self, wo: Vec3, wi: Vec3) -> Option<(Vec3, f32, bool)> {
        let (co, ci) = (wo.z, wi.z);
        if co == 0.0 || ci == 0.0 {
            return None;
        }
        let reflect = co * ci > 0.0;
        let etap = if reflect {
            1.0
        } else if co > 0.0 {
            self.eta
        } else {
            1.0 / self.eta
        };
        let wm = wi * etap + wo;
        if wm.length_squared() == 0.0 {
            return None;
        }
        let mut wm = wm.normalize();
        if wm.z < 0.0 {
            wm = -wm;
        }
        // Discard back-facing microfacets.
        if wm.dot(wi) * ci < 0.0 || wm.dot(wo) * co < 0.0 {
            return None;
        }
        Some((wm, etap, reflect))
    }

    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        if self.is_delta() {
            return Rgb::ZERO;
        }
        let Some((wm, etap, is_reflect)) = self.half_vector(wo, wi) else {
            return Rgb::ZERO;
        };
        let ggx = self.ggx();
        let (co, ci) = (wo.z, wi.z);
        let f = fresnel_dielectric(wo.dot(wm), self.eta);
        if is_reflect {
            Rgb::splat(ggx.d(wm) * ggx.g2(wo, wi) * f / (4.0 * ci * co).abs())
        } else {
            let (dim, dom) = (wi.dot(wm), wo.dot(wm));
            let denom = (dim + dom / etap).powi(2) * ci * co;
            if denom == 0.0 {
                return Rgb::ZERO;
            }
            let ft = ggx.d(wm) * (1.0 - f) * ggx.g2(wo, wi) * (dim * dom / denom).abs();
            self.transmission_scale(etap) * ft
        }
    }

    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if self.is_delta() {
            return 0.0;
        }
        let Some((wm, etap, is_reflect)) = self.half_vector(wo, wi) else {
            return 0.0;
        };
        let r = fresnel_dielectric(wo.dot(wm), self.eta);
        let t = 1.0 - r;
        let pdf_wm = self.ggx().pdf_wm(wo, wm);
        if is_reflect {
            pdf_wm / (4.0 * wo.dot(wm).abs()) * r / (r + t)
        } else {
            let (dim, dom) = (wi.dot(wm), wo.dot(wm));
            let denom = (dim + dom / etap).powi(2);
            if denom == 0.0 {
                return 0.0;
            }
            pdf_wm * (dim.abs() / denom) * t / (r + t)
        }
    }

    /// `(eval, pdf)` sharing the generalised half vector, the Fresnel reflectance at ω_m, D,
    /// Λ(ω_o) ([`Ggx::d_g2_pdf_wm`]) and the refraction Jacobian's (ω_i·ω_m + ω_o·ω_m/η')²;
    /// each equals the separate function's value bit for bit.
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        if self.is_delta() {
            return (Rgb::ZERO, 0.0);
        }
        let Some((wm, etap, is_reflect)) = self.half_vector(wo, wi) else {
            return (Rgb::ZERO, 0.0);
        };
        let (d, g2, pdf_wm) = self.ggx().d_g2_pdf_wm(wo, wi, wm);
        let (co, ci) = (wo.z, wi.z);
        let dom = wo.dot(wm);
        let r = fresnel_dielectric(dom, self.eta);
        let t = 1.0 - r;
        if is_reflect {
            let f = Rgb::splat(d * g2 * r / (4.0 * ci * co).abs());
            (f, pdf_wm / (4.0 * dom.abs()) * r / (r + t))
        } else {
            let dim = wi.dot(wm);
            let q = (dim + dom / etap).powi(2);
            let denom = q * ci * co;
            let f = if denom == 0.0 {
                Rgb::ZERO
            } else {
                let ft = d * (1.0 - r) * g2 * (dim * dom / denom).abs();
                self.transmission_scale(etap) * ft
            };
            let pdf = if q == 0.0 {
                0.0
            } else {
                pdf_wm * (dim.abs() / q) * t / (r + t)
            };
            (f, pdf)
        }
    }

    /// Samples with `uc` choosing reflection vs. refraction and `u` the microfacet normal.
    #[inline]
    pub fn sample_with(&self, wo: Vec3, uc: f32, u: Vec2) -> Option<BsdfSample> {
        if wo.z == 0.0 {
            return None;
        }
        if self.is_delta() {
            return self.sample_smooth(wo, uc);
        }
        let ggx = self.ggx();
        let wm = ggx.sample_wm(wo, u);
        let dom = wo.dot(wm);
        let r = fresnel_dielectric(dom, self.eta);
        let t = 1.0 - r;
        let pdf_wm = ggx.pdf_wm(wo, wm);
        if uc < r / (r + t) {
            let wi = reflect(wo, wm).normalize();
            if wo.z * wi.z <= 0.0 {
                return None;
            }
            let pdf = pdf_wm / (4.0 * dom.abs()) * r / (r + t);
            let f = ggx.d(wm) * ggx.g2(wo, wi) * r / (4.0 * wi.z * wo.z).abs();
            (pdf > 0.0).then_some(BsdfSample {
                wi,
                f: Rgb::splat(f),
                pdf,
                node: NodeType::GlossyReflection,
                delta: false,
                eta: 1.0,
            })
        } else {
            let (wi, etap) = refract(wo, wm, self.eta)?;
            let wi = wi.normalize();
            if wo.z * wi.z >= 0.0 {
                return None;
            }
            let dim = wi.dot(wm);
            let denom = (dim + dom / etap).powi(2);
            if denom == 0.0 {
                return None;
            }
            let pdf = pdf_wm * (dim.abs() / denom) * t / (r + t);
            let ft = ggx.d(wm) * t * ggx.g2(wo, wi) * (dim * dom / (denom * wi.z * wo.z)).abs();
            (pdf > 0.0 && ft.is_finite()).then_some(BsdfSample {
                wi,
                f: self.transmission_scale(etap) * ft,
                pdf,
                node: NodeType::GlossyTransmission,
                delta: false,
                eta: etap,
            })
        }
    }

    /// Dirac reflection or refraction; `uc` chooses by R vs T.
    #[inline]
    fn sample_smooth(&self, wo: Vec3, uc: f32) -> Option<BsdfSample> {
        let r = fresnel_dielectric(wo.z, self.eta);
        let t = 1.0 - r;
        if uc < r / (r + t) {
            let wi = Vec3::new(-wo.x, -wo.y, wo.z);
            Some(BsdfSample {
                wi,
                f: Rgb::splat(r / wi.z.abs()),
                pdf: r / (r + t),
                node: NodeType::SpecularReflection,
                delta: true,
                eta: 1.0,
            })
        } else {
            let (wi, etap) = refract(wo, Vec3::Z, self.eta)?;
            let wi = wi.normalize();
            if wi.z == 0.0 {
                return None;
            }
            Some(BsdfSample {
                wi,
                f: self.transmission_scale(etap) * (t / wi.z.abs()),
                pdf: t / (r + t),
                node: NodeType::SpecularTransmission,
                delta: true,
                eta: etap,
            })
        }
    }

    /// Two-dimensional sampling (for callers without a third number): the reflect/refract
    /// choice uses the low-order bits of `u.x` (smooth: `u.x` itself). Prefer
    /// [`Dielectric::sample_with`].
    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        if self.is_delta() {
            return self.sample_smooth(wo, u.x);
        }
        let uc = (u.x * 4096.0).fract();
        self.sample_with(wo, uc, u)
    }

    /// Albedo estimate for termination: the tint's largest component.
    #[inline]
    pub fn albedo(&self) -> f32 {
        self.tint.max_component()
    }
}

#[cfg(test)]
mod tests {
    use super::super::testutil::*;
    use super::super::{Component, NARROW_GLOSSY_ALPHA};
    use super::*;
    use crate::path::NodeClass;
    use crate::rng::Rng;

    fn diel(alpha: f32, mode: TransportMode) -> Dielectric {
        Dielectric {
            mode,
            ..Dielectric::new(Rgb::ONE, 1.5, alpha)
        }
    }

    fn comp(alpha: f32, mode: TransportMode) -> Component {
        Component::Dielectric(diel(alpha, mode))
    }

    #[test]
    fn fresnel_and_refraction_basics() {
        // Normal incidence: ((η − 1)/(η + 1))² = 0.04 for η = 1.5, from either side.
        assert!((fresnel_dielectric(1.0, 1.5) - 0.04).abs() < 1e-6);
        assert!((fresnel_dielectric(-1.0, 1.5) - 0.04).abs() < 1e-6);
        assert!((fresnel_dielectric(0.0, 1.5) - 1.0).abs() < 1e-6);
        // Total internal reflection beyond the critical angle asin(1/1.5) ≈ 41.8°.
        assert_eq!(fresnel_dielectric(-(50f32.to_radians().cos()), 1.5), 1.0);
        assert!(fresnel_dielectric(-(40f32.to_radians().cos()), 1.5) < 1.0);
        assert!(refract(flip(dir(50f32.to_radians(), 0.0)), Vec3::Z, 1.5).is_none());
        // Snell's law.
        let wo = dir(0.8, 0.4);
        let (wt, etap) = refract(wo, Vec3::Z, 1.5).unwrap();
        assert_eq!(etap, 1.5);
        let sin_t = (1.0 - wt.z * wt.z).sqrt();
        assert!((0.8f32.sin() - 1.5 * sin_t).abs() < 1e-5 && wt.z < 0.0);
        assert!((wt.length() - 1.0).abs() < 1e-5);
    }

    #[test]
    fn classes() {
        assert!(comp(0.0, TransportMode::Radiance).is_delta());
        assert_eq!(comp(0.0, TransportMode::Radiance).class(), NodeClass::Alpha);
        assert!(!comp(0.01, TransportMode::Radiance).is_delta());
        assert_eq!(
            comp(0.01, TransportMode::Radiance).class(),
            NodeClass::Alpha
        );
        assert_eq!(
            comp(NARROW_GLOSSY_ALPHA, TransportMode::Radiance).class(),
            NodeClass::Beta
        );
        // Index-matched: a pass-through Dirac lobe.
        let d = Dielectric::new(Rgb::ONE, 1.0, 0.5);
        assert!(d.is_delta());
        let s = d.sample_with(dir(0.5, 0.5), 0.5, Vec2::splat(0.5)).unwrap();
        assert!((s.wi + dir(0.5, 0.5)).length() < 1e-5);
    }

    #[test]
    fn smooth_reflection_plus_transmission_is_one() {
        let mut r = Rng::new(31, 0);
        for mode in [TransportMode::Importance, TransportMode::Radiance] {
            let d = diel(0.0, mode);
            for wo in test_directions_both_sides() {
                let fr = fresnel_dielectric(wo.z, 1.5);
                let n = 20_000;
                let (mut n_refl, mut sum) = (0usize, 0.0f64);
                for _ in 0..n {
                    let s = d
                        .sample_with(wo, r.uniform(), r.uniform2())
                        .expect("smooth sample");
                    assert!(s.delta);
                    let t = (s.f * (s.wi.z.abs() / s.pdf)).g;
                    if s.node == NodeType::SpecularReflection {
                        n_refl += 1;
                        assert!((s.wi - Vec3::new(-wo.x, -wo.y, wo.z)).length() < 1e-5);
                        assert!((t - 1.0).abs() < 1e-5);
                        sum += t as f64;
                    } else {
                        assert_eq!(s.node, NodeType::SpecularTransmission);
                        assert!(s.wi.z * wo.z < 0.0);
                        // Snell: η_o sin θ_o = η_i sin θ_i.
                        let (eo, ei) = if wo.z > 0.0 { (1.0, 1.5) } else { (1.5, 1.0) };
                        let so = (1.0 - wo.z * wo.z).sqrt();
                        let si = (1.0 - s.wi.z * s.wi.z).sqrt();
                        assert!((eo * so - ei * si).abs() < 1e-4);
                        let expected = match mode {
                            TransportMode::Importance => 1.0,
                            TransportMode::Radiance => (eo / ei) * (eo / ei),
                        };
                        assert!((t - expected).abs() < 1e-4, "throughput {t} vs {expected}");
                        sum += (t / expected) as f64;
                    }
                }
                // Reflection is chosen with probability R, so R + T = 1 in expectation.
                let p_refl = n_refl as f64 / n as f64;
                let tol = 4.0 * (fr as f64 * (1.0 - fr as f64) / n as f64).sqrt() + 1e-3;
                assert!(
                    (p_refl - fr as f64).abs() < tol,
                    "wo {wo:?}: P(refl) {p_refl} vs R {fr}"
                );
                assert!((sum / n as f64 - 1.0).abs() < 1e-4);
            }
        }
        // Total internal reflection: everything reflects.
        let d = diel(0.0, TransportMode::Radiance);
        let wo = flip(dir(1.0, 0.3));
        for _ in 0..100 {
            let s = d.sample_with(wo, r.uniform(), r.uniform2()).unwrap();
            assert_eq!(s.node, NodeType::SpecularReflection);
            assert!(((s.f * (s.wi.z.abs() / s.pdf)).r - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn sampled_values_match_eval_and_pdf() {
        for alpha in [0.1, 0.5] {
            for mode in [TransportMode::Radiance, TransportMode::Importance] {
                let c = Component::Dielectric(Dielectric {
                    tint: Rgb::new(0.9, 0.7, 0.4),
                    ..diel(alpha, mode)
                });
                for wo in test_directions_both_sides() {
                    let ok = check_sample_consistency(&c, wo, 3000, 32);
                    assert!(ok > 1000, "alpha {alpha}: only {ok} samples succeeded");
                }
            }
        }
    }

    #[test]
    fn pdf_integrates_to_at_most_one() {
        for alpha in [0.1f32, 0.5] {
            let c = comp(alpha, TransportMode::Radiance);
            let n = if alpha < 0.2 { 900 } else { 400 };
            for wo in [
                dir(0.3, 0.2),
                flip(dir(0.3, 0.2)),
                flip(dir(1.2, 1.0)),
                dir(1.4, 1.0),
            ] {
                let p = check_pdf_integral(&c, wo, n, 100_000, 33);
                assert!(p > 0.5, "alpha {alpha} wo {wo:?}: ∫pdf = {p}");
                if alpha < 0.2 && wo.z.abs() > 0.9 {
                    assert!(p > 0.97, "alpha {alpha} wo {wo:?}: ∫pdf = {p}");
                }
            }
        }
    }

    #[test]
    fn energy_is_consistent_and_bounded() {
        for alpha in [0.1f32, 0.5] {
            let c = comp(alpha, TransportMode::Importance);
            let n = if alpha < 0.2 { 900 } else { 400 };
            for wo in [
                dir(0.3, 0.2),
                flip(dir(0.3, 0.2)),
                flip(dir(1.2, 1.0)),
                dir(1.4, 1.0),
            ] {
                let e = check_energy(&c, wo, n, 100_000, 34, 0.02);
                if alpha < 0.2 && wo.z.abs() > 0.9 {
                    assert!(e[0] > 0.95, "alpha {alpha} wo {wo:?}: {}", e[0]);
                }
            }
        }
    }

    #[test]
    fn radiance_scaling_is_one_over_eta_squared() {
        let rad = diel(0.3, TransportMode::Radiance);
        let imp = diel(0.3, TransportMode::Importance);
        let mut r = Rng::new(35, 0);
        let mut seen = [false; 2];
        for _ in 0..2000 {
            let a = uniform_dir(&mut r);
            let b = uniform_dir(&mut r);
            let (fr, fi) = (rad.eval(a, b).r, imp.eval(a, b).r);
            if fi == 0.0 {
                continue;
            }
            let expected = if a.z * b.z > 0.0 {
                1.0
            } else if a.z > 0.0 {
                1.0 / 2.25
            } else {
                2.25
            };
            seen[(a.z * b.z < 0.0) as usize] = true;
            assert!((fr / fi - expected).abs() < 1e-4 * expected);
        }
        assert!(seen[0] && seen[1]);
    }

    /// A sample's `eta` is the index of `wi`'s side over `wo`'s for a refraction and 1 for a
    /// reflection, and it is exactly what the radiance scaling took: the radiance-mode
    /// throughput times η'² equals the importance-mode throughput (smooth and rough).
    #[test]
    fn sample_eta_undoes_the_radiance_scaling() {
        for alpha in [0.0, 0.3] {
            let rad = diel(alpha, TransportMode::Radiance);
            let imp = diel(alpha, TransportMode::Importance);
            let mut r = Rng::new(37, 0);
            let mut seen = [false; 3];
            for _ in 0..4000 {
                let wo = uniform_dir(&mut r);
                let (uc, u) = (r.uniform(), r.uniform2());
                let (Some(sr), Some(si)) = (rad.sample_with(wo, uc, u), imp.sample_with(wo, uc, u))
                else {
                    continue;
                };
                let refracted = wo.z * sr.wi.z < 0.0;
                let expected = match (refracted, wo.z > 0.0) {
                    (false, _) => 1.0,
                    (true, true) => 1.5,
                    (true, false) => 1.0 / 1.5,
                };
                seen[if !refracted {
                    0
                } else if wo.z > 0.0 {
                    1
                } else {
                    2
                }] = true;
                assert!(
                    (sr.eta - expected).abs() < 1e-6,
                    "α {alpha}: eta {}",
                    sr.eta
                );
                let tr = sr.f.r * sr.wi.z.abs() / sr.pdf * sr.eta * sr.eta;
                let ti = si.f.r * si.wi.z.abs() / si.pdf;
                assert!((tr / ti - 1.0).abs() < 1e-4, "α {alpha}: {tr} vs {ti}");
            }
            assert_eq!(seen, [true; 3], "α {alpha}");
        }
    }

    fn uniform_dir(r: &mut Rng) -> Vec3 {
        crate::sampling::uniform_sphere(r.uniform2())
    }

    #[test]
    fn reflection_is_reciprocal_and_transmission_generalised_reciprocal() {
        for alpha in [0.1, 0.5] {
            check_reciprocity(&comp(alpha, TransportMode::Radiance), 36);
            // Refraction (generalised reciprocity, Veach 1997 §5.2): in radiance mode
            // f(ωo, ωi)/η_o² = f(ωi, ωo)/η_i².
            let d = diel(alpha, TransportMode::Radiance);
            let ior = |w: Vec3| if w.z > 0.0 { 1.0 } else { 1.5f32 };
            let mut r = Rng::new(37, 0);
            let mut nonzero = 0;
            for _ in 0..2000 {
                let a = uniform_dir(&mut r);
                let mut b = uniform_dir(&mut r);
                b.z = -b.z.abs() * a.z.signum();
                let fab = d.eval(a, b).r / (ior(a) * ior(a));
                let fba = d.eval(b, a).r / (ior(b) * ior(b));
                assert!(
                    (fab - fba).abs() <= 1e-3 * fab.max(fba) + 1e-6,
                    "{fab} vs {fba}"
                );
                nonzero += (fab > 0.0) as usize;
            }
            assert!(nonzero > 100);
        }
    }
}
