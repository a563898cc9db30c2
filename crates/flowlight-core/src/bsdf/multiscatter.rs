//! Multiple-scattering energy compensation for the glTF material's rough metal (Kulla & Conty
//! 2017, "Revisiting Physically Based Shading at Imageworks", SIGGRAPH course notes), an
//! option (`[render] multiscatter = true`, [`crate::material::Material::multiscatter`]) that
//! is off by default, so that images stay the glTF specification's.
//!
//! The GGX lobe of [`super::gltf`] is single scattering: light that a microfacet reflects
//! onto another is lost, so a white rough metal reflects only E₁(μ_o) = ∫ D G2/(4 μ_o μ_i)
//! μ_i dω_i of the light (0.91 at roughness 0.5, 0.32 at roughness 1, near normal view;
//! [`super::albedo`]). Kulla & Conty add a lobe that returns the missing energy,
//!
//!   f_ms(ω_o, ω_i) = m · F_ms · (1 − E₁(μ_o)) (1 − E₁(μ_i)) / (π (1 − Ē₁)),
//!
//! Ē₁ = 2 ∫ E₁(μ) μ dμ. Its albedo is ∫ f_ms μ_i dω_i = m F_ms (1 − E₁(μ_o)) exactly (with the
//! tables' exact average, see [`super::albedo`]), so a white metal (F = 1) reflects
//! E₁(μ_o) + 1 − E₁(μ_o) = 1 at every angle. It is symmetric in ω_o and ω_i (reciprocal) and
//! separable, so it is sampled cosine-weighted. A coloured metal loses some light at each of
//! the k extra bounces: with the hemispherical average F̄ = 2 ∫ F(μ) μ dμ of its Fresnel
//! (F̄ = f0 + (1 − f0)/21 for Schlick from f0 = ρ to f90 = 1) the light scattered k + 1 ≥ 2
//! times sums to F̄ Ē₁ Σₖ (F̄ (1 − Ē₁))ᵏ − F̄ Ē₁, and spread over the lobe's average
//! 1 − Ē₁ that gives the colour factor
//!
//!   F_ms = F̄² Ē₁ / (1 − F̄ (1 − Ē₁))   (per channel; F_ms = 1 for F̄ = 1).
//!
//! Only the metal is compensated (weight m, the metallic factor): the dielectric layer's
//! missing energy already goes to the diffuse base through its energy coupling
//! ([`super::gltf`]), which makes a white dielectric reflect exactly 1; compensating it too
//! would exceed 1. Under a clearcoat the lobe is attenuated like the base, by
//! A(μ_o) A(μ_i). A Dirac metal (α < [`super::DELTA_ALPHA`]) loses nothing and gets no lobe.
//!
//! The lobe is one more component of the material's mixture ([`super::Bsdf`]), chosen with
//! probability p proportional to its average albedo against the other lobes' (clamped to
//! [0.05, 0.5]); the other components' weights are scaled by 1 − p and their values by
//! 1/(1 − p), so the mixture's value is unchanged plus f_ms.

use super::albedo::{average, directional};
use super::gltf::{GltfParams, GltfShared, COAT_F0};
use super::{Bsdf, BsdfSample, Component, DELTA_ALPHA};
use crate::path::NodeType;
use crate::sampling::{two_sided_cosine, two_sided_cosine_pdf};
use crate::Rgb;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// The multiple-scattering lobe of a rough metal (module docs).
#[derive(Clone, Copy, Debug)]
pub struct MultiScatter {
    /// m F_ms / (π (1 − Ē₁)) per channel, times `scale`.
    pub tint: Rgb,
    /// GGX α of the metal.
    pub alpha: f32,
    /// Clearcoat factor and α (the attenuation A(μ)); coat 0 for none.
    pub coat: f32,
    pub coat_alpha: f32,
    /// Albedo estimate in [0, 1] for termination (of the value, scale included).
    pub albedo: f32,
}

/// Kulla & Conty's colour factor F_ms for the hemispherical Fresnel average `f_avg` and
/// GGX average albedo `e_avg`.
#[inline]
pub fn fresnel_ms(f_avg: f32, e_avg: f32) -> f32 {
    let d = 1.0 - f_avg * (1.0 - e_avg);
    if d > 0.0 {
        f_avg * f_avg * e_avg / d
    } else {
        1.0
    }
}

impl MultiScatter {
    /// The lobe of `p`'s metal and its average albedo (before the selection weight); `None`
    /// where it would be zero (no metal, a Dirac metal, or no energy lost).
    pub fn new(p: &GltfParams) -> Option<(MultiScatter, f32)> {
        let unit = |x: f32| {
            if x.is_finite() {
                x.clamp(0.0, 1.0)
            } else {
                0.0
            }
        };
        let m = unit(p.metallic);
        let alpha = unit(p.roughness).powi(2);
        if m <= 0.0 || alpha < DELTA_ALPHA {
            return None;
        }
        let (e_avg, _) = average(alpha);
        let lost = 1.0 - e_avg;
        if lost <= 1e-4 {
            return None;
        }
        let f_ms = |rho: f32| {
            let rho = unit(rho);
            fresnel_ms(rho + (1.0 - rho) / 21.0, e_avg)
        };
        let colour = Rgb::new(f_ms(p.base.r), f_ms(p.base.g), f_ms(p.base.b)) * m;
        let c = unit(p.clearcoat);
        let coat_alpha = unit(p.clearcoat_roughness).powi(2);
        // Average albedo: m F_ms (1 − Ē₁), times the coat's average attenuation squared.
        let coat_avg = if c > 0.0 {
            c * super::albedo::schlick_average(COAT_F0, 1.0, coat_alpha)
        } else {
            0.0
        };
        let estimate = colour.max_component() * lost * (1.0 - coat_avg).powi(2);
        let lobe = MultiScatter {
            tint: colour * (1.0 / (PI * lost)),
            alpha,
            coat: c,
            coat_alpha,
            albedo: 1.0,
        };
        (estimate > 0.0 && estimate.is_finite()).then_some((lobe, estimate))
    }

    /// A(μ_o) A(μ_i) of the coat above (1 without one).
    #[inline]
    fn coat_attenuation(&self, mu_o: f32, mu_i: f32) -> f32 {
        if self.coat <= 0.0 {
            return 1.0;
        }
        let sh = GltfShared {
            coat: self.coat,
            coat_alpha: self.coat_alpha,
            alpha: self.alpha,
            diel_f0: 0.0,
            diel_f90: 0.0,
            diffuse_norm: 0.0,
        };
        sh.coat_attenuation(mu_o) * sh.coat_attenuation(mu_i)
    }

    /// f_ms (module docs), zero unless `wo` and `wi` are strictly on one side.
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        if wo.z * wi.z <= 0.0 {
            return Rgb::ZERO;
        }
        let (mu_o, mu_i) = (wo.z.abs(), wi.z.abs());
        let (eo, _) = directional(self.alpha, mu_o);
        let (ei, _) = directional(self.alpha, mu_i);
        let k = (1.0 - eo).max(0.0) * (1.0 - ei).max(0.0) * self.coat_attenuation(mu_o, mu_i);
        self.tint * k
    }

    /// Cosine-weighted density on `wo`'s side.
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        two_sided_cosine_pdf(wo, wi)
    }

    /// `(eval, pdf)` together.
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        (self.eval(wo, wi), self.pdf(wo, wi))
    }

    /// A cosine-weighted direction on `wo`'s side.
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        let (wi, pdf) = two_sided_cosine(wo, u)?;
        (pdf > 0.0).then(|| BsdfSample {
            wi,
            f: self.eval(wo, wi),
            pdf,
            node: NodeType::GlossyReflection,
            delta: false,
            eta: 1.0,
        })
    }
}

impl Bsdf {
    /// This glTF material's mixture with the metal's multiple-scattering lobe added (module
    /// docs); itself where `p` has no such lobe or a component is not a glTF lobe.
    pub fn with_multiscatter(self, p: &GltfParams) -> Bsdf {
        let Some((mut lobe, estimate)) = MultiScatter::new(p) else {
            return self;
        };
        if self.count >= super::MAX_COMPONENTS
            || !self
                .components()
                .all(|(c, _)| matches!(c, Component::Gltf(_)))
        {
            return self;
        }
        // The other lobes' average albedo: Σ wᵢ × (their albedo estimate / wᵢ).
        let others: f32 = self.components().map(|(c, w)| c.albedo() * w).sum();
        let share = (estimate / (estimate + others)).clamp(0.05, 0.5);
        let mut out = self;
        for (c, w) in out.components.iter_mut().flatten() {
            if let Component::Gltf(l) = c {
                l.scale /= 1.0 - share;
            }
            *w *= 1.0 - share;
        }
        lobe.tint *= 1.0 / share;
        lobe.albedo = (estimate / share).clamp(0.0, 1.0);
        out.components[out.count] = Some((Component::MultiScatter(lobe), share));
        out.count += 1;
        out.summarise()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::testutil::{
        check_energy, check_sample_consistency, gltf_params, sampled_albedo, sphere_integrals,
    };

    fn metal(base: Rgb, roughness: f32) -> GltfParams {
        GltfParams {
            base,
            metallic: 1.0,
            roughness,
            ..gltf_params()
        }
    }

    fn bsdf(p: &GltfParams, multiscatter: bool) -> Bsdf {
        let (ls, n) = super::super::gltf::lobes(p);
        let b = Bsdf::from_gltf_lobes(&ls[..n]);
        if multiscatter {
            b.with_multiscatter(p)
        } else {
            b
        }
    }

    fn wo_at(theta: f32) -> Vec3 {
        Vec3::new(theta.sin(), 0.0, theta.cos())
    }

    /// The white furnace: a white rough conductor reflects less than 1 without the lobe and
    /// 1 with it, at every roughness and angle.
    #[test]
    fn white_rough_metal_reflects_everything_with_the_lobe() {
        for rough in [0.3f32, 0.6, 1.0] {
            let p = metal(Rgb::ONE, rough);
            for theta in [0.1f32, 0.7, 1.2] {
                let wo = wo_at(theta);
                let (single, _) = sampled_albedo(&bsdf(&p, false), wo, 40_000, 3);
                let (multi, se) = sampled_albedo(&bsdf(&p, true), wo, 40_000, 4);
                let e1 = directional(rough * rough, wo.z).0 as f64;
                assert!(
                    (single[0] - e1).abs() < 0.01,
                    "r {rough} θ {theta}: {single:?} vs {e1}"
                );
                assert!(
                    (multi[0] - 1.0).abs() < 0.01 + 4.0 * se[0],
                    "r {rough} θ {theta}: {multi:?}"
                );
                if rough >= 0.6 {
                    assert!(single[0] < 0.97, "r {rough}: {single:?}");
                }
                // Stratified integration agrees (the lobe's value, not only its samples).
                let (_, num) = sphere_integrals(&bsdf(&p, true), wo, 300, 5);
                assert!((num[0] - 1.0).abs() < 0.02, "r {rough} θ {theta}: {num:?}");
            }
        }
    }

    #[test]
    fn coloured_and_coated_metals_sample_consistently_and_conserve_energy() {
        let gold = Rgb::new(1.0, 0.78, 0.34);
        let variants = [
            metal(gold, 0.7),
            GltfParams {
                metallic: 0.5,
                ..metal(gold, 0.5)
            },
            GltfParams {
                clearcoat: 1.0,
                // Wide enough for the stratified grid of `check_energy` at grazing angles.
                clearcoat_roughness: 0.5,
                ..metal(Rgb::ONE, 0.8)
            },
        ];
        for (i, p) in variants.iter().enumerate() {
            let b = bsdf(p, true);
            assert!(
                b.components()
                    .any(|(c, _)| matches!(c, Component::MultiScatter(_))),
                "variant {i}"
            );
            for theta in [0.2f32, 1.0, 1.4] {
                for wo in [wo_at(theta), -wo_at(theta)] {
                    assert!(check_sample_consistency(&b, wo, 2000, 7 + i as u64) > 1000);
                }
                check_energy(&b, wo_at(theta), 200, 30_000, 9, 0.02);
            }
            // Compensation only adds: every channel reflects at least as much as before.
            let wo = wo_at(0.6);
            let (before, _) = sampled_albedo(&bsdf(p, false), wo, 20_000, 11);
            let (after, _) = sampled_albedo(&b, wo, 20_000, 11);
            for c in 0..3 {
                assert!(
                    after[c] >= before[c] - 0.01,
                    "variant {i}: {before:?} {after:?}"
                );
            }
        }
    }

    #[test]
    fn no_lobe_without_a_rough_metal() {
        assert!(MultiScatter::new(&gltf_params()).is_none(), "dielectric");
        assert!(MultiScatter::new(&metal(Rgb::ONE, 0.0)).is_none(), "mirror");
        let p = metal(Rgb::ONE, 0.5);
        let b = bsdf(&p, true);
        assert_eq!(b.components().count(), 2);
        let weights: f32 = b.components().map(|(_, w)| w).sum();
        assert!((weights - 1.0).abs() < 1e-6);
        // F_ms = 1 for a white metal, less for a coloured one.
        assert!((fresnel_ms(1.0, 0.7) - 1.0).abs() < 1e-6);
        assert!(fresnel_ms(0.5, 0.7) < 0.5);
    }
}
