//! The glTF 2.0 metallic-roughness material (glTF 2.0 specification, Appendix B "BRDF
//! implementation") with `KHR_materials_ior`, `KHR_materials_specular`,
//! `KHR_materials_transmission`, `KHR_materials_volume` and `KHR_materials_clearcoat`, as a
//! mixture of lobes for [`super::Bsdf`].
//!
//! Notation: ρ base colour, m metallic, α = roughness², η ior, s / C specular factor / colour,
//! t transmission, c / α_c clearcoat factor / clearcoat roughness², h = normalize(ω_o + ω_i),
//! D and G2 the GGX distribution and height-correlated Smith masking-shadowing of
//! [`super::microfacet`] (the spec's V = G2 / (4 |cos θ_o| |cos θ_i|)), w₅ = (1 − |ω_o·h|)⁵.
//!
//! **Specular layer** (dielectric and metal share α, so the spec's `mix(dielectric, metal, m)`
//! of their specular parts is one GGX lobe with a mixed Schlick Fresnel):
//!
//!   f_S = F_S(ω_o·h) D G2 / (4 |cos θ_o| |cos θ_i|),   F_S = f0_S + (f90_S − f0_S) w₅,
//!   f0_S = (1 − m)(1 − t_v) f0_d + m ρ,   f90_S = (1 − m)(1 − t_v) f90_d + m,
//!   f0_d = min(((η − 1)/(η + 1))² C, 1) s,   f90_d = s     (KHR_materials_specular),
//!
//! with t_v = t for a volumetric transmissive material (its reflection belongs to the
//! refraction lobe below) and 0 otherwise. η = 1.5, s = 1, C = 1 give the core spec's
//! F0 = 0.04. The metal part is the spec's `conductor_fresnel(ρ, specular_brdf)` exactly.
//!
//! **Diffuse base, energy-coupled.** The spec writes the dielectric as
//! `fresnel_mix = (1 − F(V·H)) ρ/π + F(V·H) D V`. That mix is reciprocal but *not* energy
//! conserving: the diffuse weight 1 − F(V·H) stays near 1 − F0 for most ω_i while the specular
//! lobe reflects up to E(μ_o) ≫ F0 at grazing view, so a white material reflects more than it
//! receives (directional albedo 1.20 at θ_o = 80°, roughness 0.3, η = 1.5; see
//! `spec_fresnel_mix_gains_energy_at_grazing`). Here the diffuse base is weighted by the energy
//! the layer leaves, symmetrically in ω_o and ω_i (Kelemen & Szirmay-Kalos 2001, "A microfacet
//! based coupled specular-matte BRDF model with importance sampling"; Kulla & Conty 2017):
//!
//!   f_D = (1 − m)(1 − t) ρ/π · (1 − E_d(μ_o)) (1 − E_d(μ_i)) / (1 − Ē_d),
//!
//! where E_d(μ) = f0 (E₁ − E₅)(μ) + f90 E₅(μ) is the directional albedo of the dielectric
//! specular lobe for the largest channel f0 = max f0_d, f90 = f90_d ([`super::albedo`]), and
//! Ē_d = 2 ∫ E_d μ dμ. Then ∫ f_D cos θ_i dω_i = (1 − m)(1 − t) ρ (1 − E_d(μ_o)) exactly, and
//! the opaque dielectric's albedo is E_S(μ_o) + ρ (1 − E_d(μ_o)) ≤ 1, = 1 for a white one.
//! The specular highlight is the spec's; only the diffuse weight differs. Oren–Nayar (a
//! Flowlight override) replaces ρ/π by the Oren–Nayar value under the same coupling.
//!
//! **Thin-walled transmission** (`KHR_materials_transmission` without `KHR_materials_volume`,
//! or thickness 0): the spec's `specular_btdf` for a thin surface, where light leaves on the
//! other side without bending. With ω_i' = ω_i mirrored through the surface plane and
//! h' = normalize(ω_o + ω_i'):
//!
//!   f_T = (1 − m) t ρ (1 − F_d(ω_o·h')) D(h') G2(ω_o, ω_i') / (4 |cos θ_o| |cos θ_i|),
//!
//! F_d the max-channel dielectric Schlick Fresnel. Per microfacet the reflected F and the
//! transmitted (1 − F) sum to one, so reflection + thin transmission never exceed the lobe's
//! single-scattering albedo E₁; f_T(ω_o, ω_i) = f_T(ω_i, ω_o).
//!
//! **Volumetric transmission** (`KHR_materials_volume` with thickness > 0): a rough or smooth
//! dielectric interface (Walter et al. 2007, [`super::Dielectric`], exact Fresnel, tinted by
//! ρ) with weight (1 − m) t; Beer–Lambert absorption inside is [`super::volume`].
//!
//! **Clearcoat** (`KHR_materials_clearcoat`): a GGX layer with F0 = 0.04 (ior 1.5), f90 = 1,
//! weight c and α_c over everything else. The spec attenuates the base by 1 − c F(N·V), which
//! is not reciprocal; here the base is attenuated on the way in and out,
//!
//!   f = c F_c(ω_o·h) D_c G2_c / (4 |cos θ_o| |cos θ_i|) + A(μ_o) A(μ_i) f_base,
//!   A(μ) = 1 − c E_c(μ),  E_c = 0.04 (E₁ − E₅) + E₅ at α_c,
//!
//! which is reciprocal and conserves energy (c E_c(μ_o) + A(μ_o) · 1 ≤ 1).
//!
//! **Mixture.** Every lobe is a [`GltfLobe`] in the material's mixture; lobe i is chosen with
//! probability wᵢ (proportional to an estimate of its hemispherical albedo, floored at a tenth
//! of the largest) and its value carries 1/wᵢ (`scale`), so Σ wᵢ fᵢ is exactly the material's
//! BSDF and one component's `eval` alone is the untangled estimate (w f / p_m = f). Roughness 0
//! makes the specular, coat and thin lobes Dirac lobes (α < [`super::DELTA_ALPHA`]).
//! Sampling: cosine-weighted for the diffuse base, GGX visible normals (Heitz 2018) for the
//! reflection and thin-transmission lobes; `eval`/`pdf` are exactly the sampled values.
//!
//! Limits: single scattering only (a white rough metal loses the GGX multiple-scattering
//! energy: 9 % at roughness 0.5 and 68 % at roughness 1, near normal view); transmission and coat attenuation are
//! applied on both faces alike.

use super::albedo::{
    average, schlick_albedo, schlick_albedo_at, schlick_albedo_pair, schlick_average, Roughness,
};
use super::microfacet::Ggx;
use super::{BsdfSample, Dielectric, Lambert, OrenNayar, DELTA_ALPHA};
use crate::path::NodeType;
use crate::sampling::{cosine_hemisphere_pdf, rescaled, two_sided_cosine, two_sided_cosine_pdf};
use crate::Rgb;
use glam::{Vec2, Vec3};

/// Clearcoat normal-incidence reflectance (ior 1.5).
pub const COAT_F0: f32 = 0.04;

/// Which part of the glTF material a lobe is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GltfLobeKind {
    /// The clearcoat GGX layer.
    Coat,
    /// The specular layer (dielectric + metal reflection).
    Specular,
    /// The energy-coupled diffuse base.
    Diffuse,
    /// Thin-walled transmission (no bending).
    ThinTransmission,
    /// A refracting dielectric interface (volumetric transmission).
    Refraction,
}

/// Material-wide data every lobe needs: the coat attenuation and the coupling of the diffuse
/// base to the dielectric specular layer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GltfShared {
    /// Clearcoat factor c (0: no coat).
    pub coat: f32,
    /// Clearcoat GGX α_c.
    pub coat_alpha: f32,
    /// Base GGX α.
    pub alpha: f32,
    /// Max-channel dielectric Schlick f0 and f90.
    pub diel_f0: f32,
    pub diel_f90: f32,
    /// 1 / (1 − Ē_d), 0 when the dielectric layer leaves nothing to the base.
    pub diffuse_norm: f32,
}

impl GltfShared {
    /// Coat attenuation A(μ) = 1 − c E_c(μ).
    #[inline]
    pub fn coat_attenuation(&self, mu: f32) -> f32 {
        if self.coat <= 0.0 {
            return 1.0;
        }
        (1.0 - self.coat * schlick_albedo(COAT_F0, 1.0, self.coat_alpha, mu)).max(0.0)
    }

    /// A(μ_o) A(μ_i) for a coated material, the two lookups sharing their roughness
    /// coordinate ([`super::albedo::directional_pair`]); the same value as the product of two
    /// [`GltfShared::coat_attenuation`] calls, bit for bit.
    #[inline]
    fn coat_attenuation_pair(&self, mu_o: f32, mu_i: f32) -> f32 {
        let (eo, ei) = schlick_albedo_pair(COAT_F0, 1.0, self.coat_alpha, mu_o, mu_i);
        (1.0 - self.coat * eo).max(0.0) * (1.0 - self.coat * ei).max(0.0)
    }

    /// Directional albedo E_d(μ) of the dielectric specular layer (largest channel).
    #[inline]
    pub fn dielectric_albedo(&self, mu: f32) -> f32 {
        schlick_albedo(self.diel_f0, self.diel_f90, self.alpha, mu)
    }

    /// The diffuse base's coupling (1 − E_d(μ_o)) (1 − E_d(μ_i)) / (1 − Ē_d), its two albedo
    /// lookups sharing their roughness coordinate.
    ///
    /// Without a dielectric layer (`KHR_materials_specular` factor 0: f0 = f90 = 0, as in the
    /// Lambertian Cornell box) the lookups are skipped: E_d = 0·(E₁ − E₅) + 0·E₅ is ±0 for the
    /// finite table values every non-NaN α reads (a NaN μ reads the μ = 1 column, as `min`
    /// drops NaN), so each factor (1 − E_d).max(0) is exactly 1 and the coupling is exactly
    /// 1/(1 − Ē_d), the value the lookups give, bit for bit.
    #[inline]
    fn diffuse_coupling(&self, mu_o: f32, mu_i: f32) -> f32 {
        if self.without_layer() {
            return self.diffuse_norm;
        }
        let (eo, ei) = schlick_albedo_pair(self.diel_f0, self.diel_f90, self.alpha, mu_o, mu_i);
        (1.0 - eo).max(0.0) * (1.0 - ei).max(0.0) * self.diffuse_norm
    }

    /// Whether [`GltfShared::diffuse_coupling`] skips its lookups (no dielectric layer).
    #[inline]
    fn without_layer(&self) -> bool {
        self.diel_f0 == 0.0 && self.diel_f90 == 0.0 && !self.alpha.is_nan()
    }

    /// The ω_o terms of [`GltfShared::diffuse_coupling`]: the factor 1 − E_d(μ_o) (1 where
    /// the coupling has no lookups) and the roughness coordinate of the lookups.
    #[inline]
    fn outgoing_coupling(&self, mu_o: f32) -> (f32, Roughness) {
        let rough = Roughness::new(self.alpha);
        if self.without_layer() {
            return (1.0, rough);
        }
        let eo = schlick_albedo_at(self.diel_f0, self.diel_f90, rough, mu_o);
        ((1.0 - eo).max(0.0), rough)
    }

    /// [`GltfShared::diffuse_coupling`] from the ω_o terms in `at`: the same value, bit for
    /// bit, since a lookup of the pair equals the lookup alone
    /// ([`super::albedo::directional_pair`]) and the product is taken in the same order.
    #[inline]
    fn diffuse_coupling_with(&self, at: &PairOutgoing, mu_i: f32) -> f32 {
        if self.without_layer() {
            return self.diffuse_norm;
        }
        let ei = schlick_albedo_at(self.diel_f0, self.diel_f90, at.rough, mu_i);
        at.base_o * (1.0 - ei).max(0.0) * self.diffuse_norm
    }

    /// Max-channel dielectric Schlick Fresnel at cos = `c`.
    #[inline]
    fn diel_fresnel(&self, c: f32) -> f32 {
        self.diel_f0 + (self.diel_f90 - self.diel_f0) * w5(c)
    }
}

/// (1 − |c|)⁵.
#[inline]
fn w5(c: f32) -> f32 {
    let m = (1.0 - c.abs().min(1.0)).max(0.0);
    let m2 = m * m;
    m2 * m2 * m
}

/// Schlick's Fresnel with colour f0 and f90.
#[inline]
pub fn schlick_f0_f90(f0: Rgb, f90: Rgb, c: f32) -> Rgb {
    let w = w5(c);
    f0 * (1.0 - w) + f90 * w
}

/// The coat attenuation A(μ_o) A(μ_i) of one (ω_o, ω_i) pair, computed by the first lobe of a
/// mixture pass that needs it and reused by the others with the same coat (c, α_c): the lobes
/// of one material all have the same, so a coated material looks its coat albedo up twice per
/// pass instead of twice per lobe. Make a new one for every pair.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct CoatAttenuation {
    /// (c, α_c) bits of the value held, if any.
    key: Option<(u32, u32)>,
    value: f32,
}

impl CoatAttenuation {
    #[inline]
    fn get(&mut self, shared: &GltfShared, wo: Vec3, wi: Vec3) -> f32 {
        let key = (shared.coat.to_bits(), shared.coat_alpha.to_bits());
        if self.key != Some(key) {
            self.value = shared.coat_attenuation_pair(wo.z, wi.z);
            self.key = Some(key);
        }
        self.value
    }
}

/// Both directions mirrored into the upper hemisphere of `wo`.
#[inline]
fn to_upper(wo: Vec3, wi: Vec3) -> (Vec3, Vec3) {
    if wo.z < 0.0 {
        (flip(wo), flip(wi))
    } else {
        (wo, wi)
    }
}

#[inline]
fn flip(w: Vec3) -> Vec3 {
    Vec3::new(w.x, w.y, -w.z)
}

/// One lobe of the glTF material (see the module docs for the formulas).
#[derive(Clone, Copy, Debug)]
pub struct GltfLobe {
    pub kind: GltfLobeKind,
    /// 1 / (selection weight): the mixture Σ wᵢ fᵢ is the material's BSDF.
    pub scale: f32,
    /// GGX α of this lobe (coat: α_c; diffuse: unused).
    pub alpha: f32,
    /// Specular and coat: Schlick f0. Diffuse, thin transmission: the tint (weights folded
    /// in). Refraction: the weight (all channels equal).
    pub f0: Rgb,
    /// Specular and coat: Schlick f90.
    pub f90: Rgb,
    /// Diffuse: the Oren–Nayar factors (a = 1, b = 0 is Lambert), albedo unused.
    pub diffuse: OrenNayar,
    /// Refraction: the interface.
    pub dielectric: Dielectric,
    pub shared: GltfShared,
    /// Albedo estimate in [0, 1] for termination (of this lobe's value, scale included).
    pub albedo: f32,
}

impl GltfLobe {
    /// A lobe with the neutral values for the fields its kind does not use.
    pub fn new(kind: GltfLobeKind, shared: GltfShared) -> GltfLobe {
        GltfLobe {
            kind,
            scale: 1.0,
            alpha: shared.alpha,
            f0: Rgb::ZERO,
            f90: Rgb::ZERO,
            diffuse: OrenNayar::new(Rgb::ONE, 0.0),
            dielectric: Dielectric::new(Rgb::ONE, 1.5, shared.alpha),
            shared,
            albedo: 1.0,
        }
    }

    #[inline]
    pub fn is_delta(&self) -> bool {
        match self.kind {
            GltfLobeKind::Diffuse => false,
            GltfLobeKind::Refraction => self.dielectric.is_delta(),
            _ => self.alpha < DELTA_ALPHA,
        }
    }

    /// This lobe as a [`Lambert`] component with the same values bit for bit, where it is a
    /// plain diffuse base: unit scale, no coat, no dielectric layer above it (f0 = f90 = 0,
    /// so the energy coupling is exactly `diffuse_norm`, here 1) and Lambert's factors
    /// (σ = 0: A = 1, B = 0). Its value (1/π · A) · tint · 1 · 1 is then tint · 1/π, what
    /// `Lambert::eval` computes, and both sample the same cosine lobe with the same density.
    pub fn as_lambert(&self) -> Option<Lambert> {
        let sh = &self.shared;
        let plain = self.kind == GltfLobeKind::Diffuse
            && self.scale == 1.0
            && sh.coat <= 0.0
            && sh.diel_f0 == 0.0
            && sh.diel_f90 == 0.0
            && !sh.alpha.is_nan()
            && sh.diffuse_norm == 1.0
            && self.diffuse.albedo == Rgb::ONE
            && self.diffuse.a == 1.0
            && self.diffuse.b == 0.0
            && self.albedo == self.f0.max_component().clamp(0.0, 1.0);
        plain.then_some(Lambert { albedo: self.f0 })
    }

    /// GGX α deciding the class (Λα / Λβ); `None` for the diffuse base.
    #[inline]
    pub fn class_alpha(&self) -> Option<f32> {
        match self.kind {
            GltfLobeKind::Diffuse => None,
            GltfLobeKind::Refraction => Some(self.dielectric.alpha),
            _ => Some(self.alpha),
        }
    }

    /// Coat attenuation on the way in and out; 1 for the coat itself.
    #[inline]
    fn attenuation(&self, wo: Vec3, wi: Vec3) -> f32 {
        if self.kind == GltfLobeKind::Coat || self.shared.coat <= 0.0 {
            return 1.0;
        }
        self.shared.coat_attenuation_pair(wo.z, wi.z)
    }

    /// [`GltfLobe::attenuation`] through a mixture pass's [`CoatAttenuation`].
    #[inline]
    fn attenuation_with(&self, wo: Vec3, wi: Vec3, coat: &mut CoatAttenuation) -> f32 {
        if self.kind == GltfLobeKind::Coat || self.shared.coat <= 0.0 {
            return 1.0;
        }
        coat.get(&self.shared, wo, wi)
    }

    /// The lobe's value from its raw value: times `scale` and the coat attenuation, black
    /// left as it is. [`GltfLobe::eval`] and the samplers both end with it, so that a
    /// sampled value is `eval` at the sampled direction by construction.
    #[inline]
    fn finish(&self, f: Rgb, wo: Vec3, wi: Vec3) -> Rgb {
        if f.is_black() {
            return f;
        }
        f * (self.scale * self.attenuation(wo, wi))
    }

    /// The GGX reflection value D G2 / (4 μ_o μ_i) and ω_o·h for upper-hemisphere `wo`, `wi`.
    #[inline]
    fn ggx_reflection(&self, wo: Vec3, wi: Vec3) -> Option<(f32, f32)> {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return None;
        }
        let wm = (wo + wi).try_normalize()?;
        let ggx = Ggx::new(self.alpha);
        Some((ggx.d(wm) * ggx.g2(wo, wi) / (4.0 * wo.z * wi.z), wo.dot(wm)))
    }

    /// [`GltfLobe::ggx_reflection`] and [`GltfLobe::ggx_pdf`] together (value, ω_o·h,
    /// density), sharing the half vector, D and Λ(ω_o); `None` where the value is `None`
    /// (the density is 0 there too).
    #[inline]
    fn ggx_reflection_pdf(&self, wo: Vec3, wi: Vec3) -> Option<(f32, f32, f32)> {
        // The `_with` form's own side test, first, so that a refused pair skips Λ's sqrt.
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return None;
        }
        self.ggx_reflection_pdf_with(Ggx::new(self.alpha).lambda(wo), wo, wi)
    }

    /// [`GltfLobe::ggx_reflection_pdf`] with Λ(ω_o) given ([`Ggx::lambda`] of `wo`), for
    /// upper-hemisphere `wo`; the same results, bit for bit.
    #[inline]
    fn ggx_reflection_pdf_with(
        &self,
        lambda_o: f32,
        wo: Vec3,
        wi: Vec3,
    ) -> Option<(f32, f32, f32)> {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return None;
        }
        let wm = (wo + wi).try_normalize()?;
        let (d, g2, pdf_wm) = Ggx::new(self.alpha).d_g2_pdf_wm_with(lambda_o, wo, wi, wm);
        let c = wo.dot(wm);
        let pdf = if c <= 0.0 { 0.0 } else { pdf_wm / (4.0 * c) };
        Some((d * g2 / (4.0 * wo.z * wi.z), c, pdf))
    }

    /// Density of the GGX visible-normal reflection for upper-hemisphere `wo`, `wi`.
    #[inline]
    fn ggx_pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let Some(wm) = (wo + wi).try_normalize() else {
            return 0.0;
        };
        let d = wo.dot(wm);
        if d <= 0.0 {
            return 0.0;
        }
        Ggx::new(self.alpha).pdf_wm(wo, wm) / (4.0 * d)
    }

    /// The lobe's value without `scale` and coat attenuation.
    #[inline]
    fn raw_eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        match self.kind {
            GltfLobeKind::Coat | GltfLobeKind::Specular => {
                if self.is_delta() {
                    return Rgb::ZERO;
                }
                let (wo, wi) = to_upper(wo, wi);
                match self.ggx_reflection(wo, wi) {
                    Some((s, c)) => schlick_f0_f90(self.f0, self.f90, c) * s,
                    None => Rgb::ZERO,
                }
            }
            GltfLobeKind::Diffuse => self.raw_diffuse(wo, wi),
            GltfLobeKind::ThinTransmission => {
                if self.is_delta() || wo.z * wi.z >= 0.0 {
                    return Rgb::ZERO;
                }
                let (wo, wi) = to_upper(wo, flip(wi));
                match self.ggx_reflection(wo, wi) {
                    Some((s, c)) => self.f0 * ((1.0 - self.shared.diel_fresnel(c)).max(0.0) * s),
                    None => Rgb::ZERO,
                }
            }
            GltfLobeKind::Refraction => self.dielectric.eval(wo, wi) * self.f0,
        }
    }

    /// The diffuse base's raw value (energy-coupled Oren–Nayar or Lambert).
    #[inline]
    fn raw_diffuse(&self, wo: Vec3, wi: Vec3) -> Rgb {
        self.raw_diffuse_with(None, wo, wi)
    }

    /// [`GltfLobe::raw_diffuse`], with the ω_o terms of the coupling where the caller has
    /// them ([`PairOutgoing`]); the same value, bit for bit.
    #[inline(always)]
    fn raw_diffuse_with(&self, at: Option<&PairOutgoing>, wo: Vec3, wi: Vec3) -> Rgb {
        let sh = &self.shared;
        if wo.z * wi.z <= 0.0 || sh.diffuse_norm <= 0.0 {
            return Rgb::ZERO;
        }
        let k = match at {
            Some(at) => sh.diffuse_coupling_with(at, wi.z),
            None => sh.diffuse_coupling(wo.z, wi.z),
        };
        self.diffuse.eval(wo, wi) * self.f0 * k
    }

    /// [`GltfLobe::raw_eval`] and [`GltfLobe::pdf`] in one pass: one `to_upper` flip, one
    /// half vector, D and Λ(ω_o) once ([`GltfLobe::ggx_reflection_pdf`]), one side test for
    /// the diffuse base. Both equal the separate values bit for bit.
    #[inline]
    fn raw_eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        const NONE: (Rgb, f32) = (Rgb::ZERO, 0.0);
        match self.kind {
            GltfLobeKind::Coat | GltfLobeKind::Specular => {
                if self.is_delta() {
                    return NONE;
                }
                let (wo, wi) = to_upper(wo, wi);
                match self.ggx_reflection_pdf(wo, wi) {
                    Some((s, c, pdf)) => (schlick_f0_f90(self.f0, self.f90, c) * s, pdf),
                    None => NONE,
                }
            }
            GltfLobeKind::Diffuse => {
                // two_sided_cosine_pdf's own side test, which raw_diffuse repeats.
                if wo.z * wi.z <= 0.0 {
                    return NONE;
                }
                (self.raw_diffuse(wo, wi), cosine_hemisphere_pdf(wi.z.abs()))
            }
            GltfLobeKind::ThinTransmission => {
                if self.is_delta() || wo.z * wi.z >= 0.0 {
                    return NONE;
                }
                let (wo, wi) = to_upper(wo, flip(wi));
                match self.ggx_reflection_pdf(wo, wi) {
                    Some((s, c, pdf)) => (
                        self.f0 * ((1.0 - self.shared.diel_fresnel(c)).max(0.0) * s),
                        pdf,
                    ),
                    None => NONE,
                }
            }
            GltfLobeKind::Refraction => {
                let (f, pdf) = self.dielectric.eval_pdf(wo, wi);
                (f * self.f0, pdf)
            }
        }
    }

    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        self.finish(self.raw_eval(wo, wi), wo, wi)
    }

    /// `(eval, pdf)` in one pass ([`super::Bsdf::eval_pdf`]); the same values, bit for bit.
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        self.eval_pdf_with(wo, wi, &mut CoatAttenuation::default())
    }

    /// [`GltfLobe::eval_pdf`] with the coat attenuation of a mixture pass.
    #[inline]
    pub(crate) fn eval_pdf_with(
        &self,
        wo: Vec3,
        wi: Vec3,
        coat: &mut CoatAttenuation,
    ) -> (Rgb, f32) {
        let (f, pdf) = self.raw_eval_pdf(wo, wi);
        if f.is_black() {
            return (f, pdf);
        }
        (f * (self.scale * self.attenuation_with(wo, wi, coat)), pdf)
    }

    /// `(eval, pdf)` at the direction of `s`, a non-Dirac sample of this lobe from `wo`,
    /// reusing what the sample already holds where it is provably the same: the value of
    /// the diffuse and GGX reflection lobes (both [`GltfLobe::finish`] the raw value at the
    /// sampled direction, as `eval` does) and the diffuse base's cosine density (the side
    /// test is the one `two_sided_cosine_pdf` makes). The GGX density is recomputed: the
    /// sample's comes from the sampled normal, not from the half vector of ω_o and ω_i, and
    /// differs in the last bits. The refracting lobe is evaluated anew.
    #[inline]
    pub(crate) fn eval_pdf_sampled(
        &self,
        wo: Vec3,
        s: &BsdfSample,
        coat: &mut CoatAttenuation,
    ) -> (Rgb, f32) {
        if s.delta {
            return self.eval_pdf_with(wo, s.wi, coat);
        }
        match self.kind {
            GltfLobeKind::Diffuse if wo.z * s.wi.z > 0.0 => (s.f, s.pdf),
            GltfLobeKind::Coat | GltfLobeKind::Specular | GltfLobeKind::ThinTransmission => {
                (s.f, self.pdf(wo, s.wi))
            }
            _ => self.eval_pdf_with(wo, s.wi, coat),
        }
    }

    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        match self.kind {
            GltfLobeKind::Coat | GltfLobeKind::Specular => {
                if self.is_delta() {
                    return 0.0;
                }
                let (wo, wi) = to_upper(wo, wi);
                self.ggx_pdf(wo, wi)
            }
            GltfLobeKind::Diffuse => two_sided_cosine_pdf(wo, wi),
            GltfLobeKind::ThinTransmission => {
                if self.is_delta() || wo.z * wi.z >= 0.0 {
                    return 0.0;
                }
                let (wo, wi) = to_upper(wo, flip(wi));
                self.ggx_pdf(wo, wi)
            }
            GltfLobeKind::Refraction => self.dielectric.pdf(wo, wi),
        }
    }

    /// Samples with `uc` for the refraction lobe's reflect/refract choice and `u` for the
    /// direction.
    pub fn sample_with(&self, wo: Vec3, uc: f32, u: Vec2) -> Option<BsdfSample> {
        if wo.z == 0.0 {
            return None;
        }
        let mut s = match self.kind {
            GltfLobeKind::Coat | GltfLobeKind::Specular | GltfLobeKind::ThinTransmission => {
                self.sample_ggx(wo, u)?
            }
            GltfLobeKind::Diffuse => {
                let (wi, pdf) = two_sided_cosine(wo, u)?;
                BsdfSample {
                    wi,
                    f: self.raw_eval(wo, wi),
                    pdf,
                    node: NodeType::DiffuseReflection,
                    delta: false,
                    eta: 1.0,
                }
            }
            GltfLobeKind::Refraction => {
                let mut s = self.dielectric.sample_with(wo, uc, u)?;
                s.f *= self.f0;
                s
            }
        };
        s.f = self.finish(s.f, wo, s.wi);
        (s.pdf > 0.0 && s.pdf.is_finite()).then_some(s)
    }

    /// Two-number sampling: the refraction lobe takes its discrete choice from the low bits
    /// of `u.x`, like [`Dielectric::sample`].
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        let uc = if self.is_delta() {
            u.x
        } else {
            (u.x * 4096.0).fract()
        };
        self.sample_with(wo, uc, u)
    }

    /// Reflection through a visible normal (specular, coat), mirrored to the other side for
    /// thin transmission; Dirac lobes for α < [`DELTA_ALPHA`].
    fn sample_ggx(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        let thin = self.kind == GltfLobeKind::ThinTransmission;
        let (wi, c, pdf, delta) = self.sample_ggx_direction(wo, u)?;
        let f = if delta {
            let fr = if thin {
                self.f0 * (1.0 - self.shared.diel_fresnel(c)).max(0.0)
            } else {
                schlick_f0_f90(self.f0, self.f90, c)
            };
            // ω_o's cosine in the upper frame, as `sample_ggx_direction` flips it.
            let up_z = if wo.z < 0.0 { -wo.z } else { wo.z };
            fr / up_z
        } else {
            self.raw_eval(wo, wi)
        };
        let node = match (delta, thin) {
            (true, false) => NodeType::SpecularReflection,
            (true, true) => NodeType::SpecularTransmission,
            (false, false) => NodeType::GlossyReflection,
            (false, true) => NodeType::GlossyTransmission,
        };
        Some(BsdfSample {
            wi,
            f,
            pdf,
            node,
            delta,
            eta: 1.0,
        })
    }

    /// The direction of [`GltfLobe::sample_ggx`] without its value: (ω_i, ω_o·h in the upper
    /// frame, density, Dirac).
    #[inline]
    fn sample_ggx_direction(&self, wo: Vec3, u: Vec2) -> Option<(Vec3, f32, f32, bool)> {
        let thin = self.kind == GltfLobeKind::ThinTransmission;
        let below = wo.z < 0.0;
        let back = |w: Vec3| if below { flip(w) } else { w };
        let up = back(wo);
        // The sampled reflection in the upper frame, the returned direction, and ω_o·h.
        let (wr, c, pdf, delta) = if self.is_delta() {
            (Vec3::new(-up.x, -up.y, up.z), up.z, 1.0, true)
        } else {
            let (wr, _, c, pdf) = Ggx::new(self.alpha).sample_reflection(up, u)?;
            (wr, c, pdf, false)
        };
        Some((back(if thin { flip(wr) } else { wr }), c, pdf, delta))
    }
}

/// The two lobes of an opaque glTF material without clearcoat: a rough (non-Dirac) specular
/// layer over the energy-coupled diffuse base, in that order, each with its selection
/// weight. That is what [`lobes`] makes of almost every production material (and of the
/// dragon's and its floor's): metallic-roughness with roughness > 0, no transmission, no
/// coat. [`super::Bsdf`] evaluates and samples such a mixture here, in one pass with the kind
/// of each lobe known, instead of walking its components (matching the component enum and
/// then the lobe kind at every step, the coat attenuation looked up through a cache, the
/// sample copied through the stack): the walk's own code was about a fifth of the
/// instructions of a BSDF sample on the dragon (callgrind). Every result is the walk's, bit
/// for bit: the same operations on the same values in the same order.
#[derive(Clone, Copy, Debug)]
pub(crate) struct OpaquePair<'a> {
    pub spec: &'a GltfLobe,
    pub spec_weight: f32,
    pub diffuse: &'a GltfLobe,
    pub diffuse_weight: f32,
}

impl<'a> OpaquePair<'a> {
    /// Whether the two lobes are one: a specular lobe with α ≥ [`DELTA_ALPHA`] and then the
    /// diffuse base, neither under a coat (`coat <= 0`, so a NaN coat keeps the walk).
    pub fn holds(&self) -> bool {
        self.spec.kind == GltfLobeKind::Specular
            && !self.spec.is_delta()
            && self.spec.shared.coat <= 0.0
            && self.diffuse.kind == GltfLobeKind::Diffuse
            && self.diffuse.shared.coat <= 0.0
    }

    /// What every evaluation of the pair at `wo` computes alike, for
    /// [`OpaquePair::eval_pdf_with`] and [`OpaquePair::sample_with`] at that `wo`.
    #[inline]
    pub fn outgoing(&self, wo: Vec3) -> PairOutgoing {
        let (base_o, rough) = self.diffuse.shared.outgoing_coupling(wo.z);
        PairOutgoing {
            // Λ depends on squares only, so Λ(ω_o) is also Λ of the upper-frame ω_o.
            lambda_o: Ggx::new(self.spec.alpha).lambda(wo),
            base_o,
            rough,
        }
    }

    /// The specular lobe's (eval, pdf): [`GltfLobe::eval_pdf_with`] for a non-Dirac specular
    /// lobe without coat, whose attenuation is 1 (so its factor is `scale · 1 = scale`).
    /// Always inlined: as a call it returned its value and density through the stack, which
    /// the caller reloaded wider than they were stored (a store-forwarding stall on every
    /// diffuse sample, 13% of `sample_with`'s samples on the dragon, perf).
    #[inline(always)]
    fn spec_eval_pdf(&self, at: &PairOutgoing, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        let l = self.spec;
        let (wo, wi) = to_upper(wo, wi);
        let (f, pdf) = match l.ggx_reflection_pdf_with(at.lambda_o, wo, wi) {
            Some((s, c, pdf)) => (schlick_f0_f90(l.f0, l.f90, c) * s, pdf),
            None => return (Rgb::ZERO, 0.0),
        };
        if f.is_black() {
            return (f, pdf);
        }
        (f * l.scale, pdf)
    }

    /// The diffuse base's value at a pair on one side (`wo.z · wi.z > 0`), finished as
    /// [`GltfLobe::finish`] does without a coat.
    #[inline]
    fn diffuse_value(&self, at: &PairOutgoing, wo: Vec3, wi: Vec3) -> Rgb {
        let f = self.diffuse.raw_diffuse_with(Some(at), wo, wi);
        if f.is_black() {
            return f;
        }
        f * self.diffuse.scale
    }

    /// The mixture (eval, pdf) from the lobes' terms, summed as the walk sums them: from
    /// zero (value) and −0 (density), specular first.
    #[inline]
    fn mix(&self, spec: (Rgb, f32), diffuse: (Rgb, f32)) -> (Rgb, f32) {
        let mut f = Rgb::ZERO;
        let mut pdf = -0.0f32;
        f += spec.0 * self.spec_weight;
        pdf += spec.1 * self.spec_weight;
        f += diffuse.0 * self.diffuse_weight;
        pdf += diffuse.1 * self.diffuse_weight;
        (f, pdf)
    }

    /// [`super::Bsdf::eval_pdf`] of the pair, with `at` = [`OpaquePair::outgoing`]`(wo)`.
    #[inline]
    pub fn eval_pdf_with(&self, at: &PairOutgoing, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        let diffuse = if wo.z * wi.z <= 0.0 {
            (Rgb::ZERO, 0.0)
        } else {
            (
                self.diffuse_value(at, wo, wi),
                cosine_hemisphere_pdf(wi.z.abs()),
            )
        };
        self.mix(self.spec_eval_pdf(at, wo, wi), diffuse)
    }

    /// [`super::Bsdf::sample`] of the pair: the lobe chosen by `u.x` as the walk chooses it
    /// (the specular lobe below its weight), its direction sampled with `u.x` rescaled as the
    /// walk rescales it and `u.y`, and the mixture's value and density there. Neither lobe
    /// takes a discrete number, so `u_component` is not used. `at` is
    /// [`OpaquePair::outgoing`]`(wo)`.
    #[inline]
    pub fn sample_with(
        &self,
        at: &PairOutgoing,
        wo: Vec3,
        _u_component: f32,
        u: Vec2,
    ) -> Option<BsdfSample> {
        if wo.z == 0.0 {
            return None;
        }
        // The walk's running sum after the first weight is 0 + w₀.
        let spec_end = 0.0 + self.spec_weight;
        let specular = u.x < spec_end;
        let u = if specular {
            Vec2::new(rescaled(u.x, 0.0, self.spec_weight), u.y)
        } else {
            Vec2::new(rescaled(u.x, spec_end, self.diffuse_weight), u.y)
        };
        let s = if specular {
            // The walk's lobe sample computes the lobe's value there, which the mixture's
            // evaluation computes again; only its direction and density are needed here.
            let (wi, _, pdf_wi, _) = self.spec.sample_ggx_direction(wo, u)?;
            if !(pdf_wi > 0.0 && pdf_wi.is_finite()) {
                return None;
            }
            let (f, pdf) = self.eval_pdf_with(at, wo, wi);
            BsdfSample {
                wi,
                f,
                pdf,
                node: NodeType::GlossyReflection,
                delta: false,
                eta: 1.0,
            }
        } else {
            // `two_sided_cosine` refuses a zero density, so the sample's own density is
            // positive and finite, as the lobe's sampler requires.
            let (wi, pdf_wi) = two_sided_cosine(wo, u)?;
            // The walk takes the chosen diffuse lobe's terms from the sample where the pair
            // is on one side, and evaluates it (to zero) elsewhere.
            let diffuse = if wo.z * wi.z > 0.0 {
                (self.diffuse_value(at, wo, wi), pdf_wi)
            } else {
                (Rgb::ZERO, 0.0)
            };
            let (f, pdf) = self.mix(self.spec_eval_pdf(at, wo, wi), diffuse);
            BsdfSample {
                wi,
                f,
                pdf,
                node: NodeType::DiffuseReflection,
                delta: false,
                eta: 1.0,
            }
        };
        (s.pdf > 0.0).then_some(s)
    }
}

/// The terms of an [`OpaquePair`]'s evaluations that depend on ω_o alone: the specular
/// lobe's Smith Λ(ω_o) (a square root and a division), the diffuse coupling's factor
/// 1 − E_d(μ_o) (a lookup in each of two albedo tables) and the roughness coordinate of
/// those lookups (a square root), which the lookups at μ_i share. A path vertex evaluates its BSDF at one ω_o for
/// its light connection and its BSDF sample, and for every branch of a split
/// ([`super::Bsdf::at`]), so they are computed once per vertex instead of once per call.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct PairOutgoing {
    lambda_o: f32,
    base_o: f32,
    /// The base roughness's coordinate in the albedo tables, for the lookups at μ_i.
    rough: Roughness,
}

/// The glTF material's parameters, sanitised (factors in [0, 1], finite).
#[derive(Clone, Copy, Debug)]
pub struct GltfParams {
    pub base: Rgb,
    pub metallic: f32,
    pub roughness: f32,
    pub ior: f32,
    pub specular: f32,
    pub specular_color: Rgb,
    pub transmission: f32,
    /// True with `KHR_materials_volume` and thickness > 0: transmission refracts.
    pub volumetric: bool,
    pub clearcoat: f32,
    pub clearcoat_roughness: f32,
    /// Oren–Nayar σ in radians (0: Lambert).
    pub oren_nayar_sigma: f32,
}

/// Normal-incidence reflectance ((η − 1)/(η + 1))² of ior η (η = 0 gives 1, as
/// KHR_materials_specular's specular-glossiness conversion intends).
#[inline]
pub fn f0_from_ior(ior: f32) -> f32 {
    let r = (ior - 1.0) / (ior + 1.0);
    if r.is_finite() {
        (r * r).min(1.0)
    } else {
        1.0
    }
}

/// The lobes (each with its selection weight, summing to one) of a glTF material; at most
/// four. An empty list means the material scatters nothing.
pub fn lobes(p: &GltfParams) -> ([(GltfLobe, f32); 4], usize) {
    let unit = |x: f32| {
        if x.is_finite() {
            x.clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    let clamp_rgb = |c: Rgb| Rgb::new(unit(c.r), unit(c.g), unit(c.b));
    let base = clamp_rgb(p.base);
    let m = unit(p.metallic);
    let alpha = unit(p.roughness).powi(2);
    let t = unit(p.transmission);
    let s = unit(p.specular);
    let spec_color = {
        let c = p.specular_color;
        let f = |x: f32| if x.is_finite() { x.max(0.0) } else { 1.0 };
        Rgb::new(f(c.r), f(c.g), f(c.b))
    };
    let ior = if p.ior.is_finite() && p.ior >= 0.0 {
        p.ior
    } else {
        1.5
    };
    let c = unit(p.clearcoat);
    let coat_alpha = unit(p.clearcoat_roughness).powi(2);
    let volumetric = p.volumetric && t > 0.0;
    let t_v = if volumetric { t } else { 0.0 };

    let f0_ior = f0_from_ior(ior);
    let f0_d = {
        let x = spec_color * f0_ior;
        Rgb::new(x.r.min(1.0), x.g.min(1.0), x.b.min(1.0)) * s
    };
    let diel_f0 = f0_d.max_component();
    let diel_f90 = s;
    let e_d = schlick_average(diel_f0, diel_f90, alpha);
    let shared = GltfShared {
        coat: c,
        coat_alpha,
        alpha,
        diel_f0,
        diel_f90,
        diffuse_norm: if 1.0 - e_d > 1e-4 {
            1.0 / (1.0 - e_d)
        } else {
            0.0
        },
    };
    let (a1, a5) = average(alpha);
    let coat_avg = if c > 0.0 {
        c * schlick_average(COAT_F0, 1.0, coat_alpha)
    } else {
        0.0
    };
    let att = (1.0 - coat_avg).powi(2);

    let mut out: [(GltfLobe, f32); 4] = [(GltfLobe::new(GltfLobeKind::Diffuse, shared), 0.0); 4];
    let mut n = 0;
    let mut push = |lobe: GltfLobe, estimate: f32| {
        if estimate > 0.0 && estimate.is_finite() {
            out[n] = (lobe, estimate);
            n += 1;
        }
    };

    if c > 0.0 {
        let mut l = GltfLobe::new(GltfLobeKind::Coat, shared);
        l.alpha = coat_alpha;
        l.f0 = Rgb::splat(c * COAT_F0);
        l.f90 = Rgb::splat(c);
        push(l, coat_avg);
    }
    {
        let k = (1.0 - m) * (1.0 - t_v);
        let mut l = GltfLobe::new(GltfLobeKind::Specular, shared);
        l.f0 = f0_d * k + base * m;
        l.f90 = Rgb::splat(diel_f90 * k + m);
        let e = l.f0 * (a1 - a5) + l.f90 * a5;
        push(l, att * e.max_component());
    }
    {
        let tint = base * ((1.0 - m) * (1.0 - t));
        let mut l = GltfLobe::new(GltfLobeKind::Diffuse, shared);
        l.f0 = tint;
        l.diffuse = OrenNayar::new(Rgb::ONE, p.oren_nayar_sigma.max(0.0));
        if shared.diffuse_norm > 0.0 {
            push(l, att * tint.max_component() * (1.0 - e_d));
        }
    }
    if t > 0.0 && m < 1.0 {
        if volumetric {
            let mut l = GltfLobe::new(GltfLobeKind::Refraction, shared);
            let w = (1.0 - m) * t;
            l.f0 = Rgb::splat(w);
            l.dielectric = Dielectric::new(base, if ior > 0.0 { ior } else { 1.5 }, alpha);
            push(l, att * w * (0.04 + 0.96 * base.max_component()));
        } else {
            let mut l = GltfLobe::new(GltfLobeKind::ThinTransmission, shared);
            l.f0 = base * ((1.0 - m) * t);
            push(l, att * l.f0.max_component() * (a1 - e_d).max(0.0));
        }
    }

    let largest = out[..n].iter().map(|&(_, e)| e).fold(0.0f32, f32::max);
    let floor = 0.1 * largest;
    let total: f32 = out[..n].iter().map(|&(_, e)| e.max(floor)).sum();
    for (lobe, e) in out[..n].iter_mut() {
        let w = e.max(floor) / total;
        lobe.scale = 1.0 / w;
        lobe.albedo = (*e / w).clamp(0.0, 1.0);
        *e = w;
    }
    (out, n)
}

#[cfg(test)]
mod tests {
    use super::super::testutil::*;
    use super::super::{Bsdf, Component};
    use super::*;
    use crate::material::Material;
    use crate::rng::Rng;
    use std::f64::consts::PI;

    /// Each lobe alone (scale 1), as a component.
    fn lobe_components(p: &GltfParams) -> Vec<(GltfLobeKind, Component)> {
        let (ls, n) = lobes(p);
        ls[..n]
            .iter()
            .map(|&(mut l, _)| {
                l.scale = 1.0;
                (l.kind, Component::Gltf(l))
            })
            .collect()
    }

    // ---- independent reference formulas (written from the spec, not from the code) ----

    /// D_GGX = α² / (π ((n·h)² (α² − 1) + 1)²).
    fn d_ref(alpha: f64, nh: f64) -> f64 {
        if nh <= 0.0 {
            return 0.0;
        }
        let a2 = alpha * alpha;
        let k = nh * nh * (a2 - 1.0) + 1.0;
        a2 / (PI * k * k)
    }

    /// Height-correlated V = 0.5 / (NL √(NV²(1 − α²) + α²) + NV √(NL²(1 − α²) + α²)).
    fn v_ref(alpha: f64, nl: f64, nv: f64) -> f64 {
        let a2 = alpha * alpha;
        let gv = nl * (nv * nv * (1.0 - a2) + a2).sqrt();
        let gl = nv * (nl * nl * (1.0 - a2) + a2).sqrt();
        0.5 / (gv + gl)
    }

    /// The spec's specular_brdf × Schlick(f0, f90), upper hemisphere.
    fn spec_ref(alpha: f64, f0: f64, f90: f64, wo: [f64; 3], wi: [f64; 3]) -> f64 {
        if wo[2] <= 0.0 || wi[2] <= 0.0 {
            return 0.0;
        }
        let h = [wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]];
        let l = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
        let h = [h[0] / l, h[1] / l, h[2] / l];
        let vh = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2];
        let f = f0 + (f90 - f0) * (1.0 - vh.abs()).powi(5);
        f * d_ref(alpha, h[2]) * v_ref(alpha, wi[2], wo[2])
    }

    /// ∫ g(ω_i) μ_i dω_i over the upper hemisphere, midpoint rule in (μ_i, φ).
    fn hemi(n: usize, g: impl Fn([f64; 3]) -> f64) -> f64 {
        let mut s = 0.0;
        for i in 0..n {
            let mu = (i as f64 + 0.5) / n as f64;
            let st = (1.0 - mu * mu).sqrt();
            for j in 0..2 * n {
                let phi = PI * (j as f64 + 0.5) / n as f64;
                s += g([st * phi.cos(), st * phi.sin(), mu]) * mu;
            }
        }
        s * (1.0 / n as f64) * (PI / n as f64)
    }

    fn wo_at(theta: f64) -> [f64; 3] {
        [theta.sin(), 0.0, theta.cos()]
    }

    fn v3(w: [f64; 3]) -> Vec3 {
        Vec3::new(w[0] as f32, w[1] as f32, w[2] as f32)
    }

    #[test]
    fn specular_lobe_is_the_spec_formula() {
        let mut r = Rng::new(60, 0);
        for (m, ior, rough) in [
            (0.0f32, 1.5f32, 0.5f32),
            (0.0, 2.2, 0.2),
            (1.0, 1.5, 0.7),
            (0.4, 1.3, 0.35),
        ] {
            let base = Rgb::new(0.9, 0.5, 0.2);
            let p = GltfParams {
                base,
                metallic: m,
                roughness: rough,
                ior,
                ..gltf_params()
            };
            let spec = lobe_components(&p)
                .into_iter()
                .find(|(k, _)| *k == GltfLobeKind::Specular)
                .unwrap()
                .1;
            let alpha = (rough * rough) as f64;
            let f0d = ((ior as f64 - 1.0) / (ior as f64 + 1.0)).powi(2);
            for _ in 0..500 {
                let mut a = crate::sampling::uniform_sphere(r.uniform2());
                let mut b = crate::sampling::uniform_sphere(r.uniform2());
                a.z = a.z.abs();
                b.z = b.z.abs();
                let wo = [a.x as f64, a.y as f64, a.z as f64];
                let wi = [b.x as f64, b.y as f64, b.z as f64];
                let got = spec.eval(a, b).to_array();
                for (k, ch) in base.to_array().into_iter().enumerate() {
                    let metal = spec_ref(alpha, ch as f64, 1.0, wo, wi);
                    let diel = spec_ref(alpha, f0d, 1.0, wo, wi);
                    let want = (1.0 - m as f64) * diel + m as f64 * metal;
                    assert!(
                        (got[k] as f64 - want).abs() <= 2e-3 * want + 1e-5,
                        "m {m} ior {ior}: {} vs {want}",
                        got[k]
                    );
                }
            }
        }
    }

    /// The failing case of the old mixture: a rough-0.1 dielectric has a highlight.
    #[test]
    fn dielectric_has_a_specular_highlight() {
        let base = Rgb::splat(0.5);
        let m = Material {
            base_color: base,
            metallic: 0.0,
            roughness: 0.1,
            ..Default::default()
        };
        let b = Bsdf::from_material(&m, base);
        let wo = v3(wo_at(0.5));
        let mirror = Vec3::new(-wo.x, -wo.y, wo.z);
        let f = b.eval(wo, mirror).g;
        let diffuse = 0.5 / std::f32::consts::PI;
        assert!(
            f > 20.0 * diffuse,
            "f at the mirror direction {f} vs ρ/π {diffuse}"
        );
        // And away from it the material is (nearly) diffuse.
        let off = v3(wo_at(-1.0));
        let g = b.eval(wo, off).g;
        assert!((g - diffuse).abs() < 0.1 * diffuse, "{g} vs {diffuse}");
    }

    /// The literal spec `fresnel_mix` (diffuse weighted by 1 − F(V·H)) reflects more than it
    /// receives at grazing view: why the diffuse base is energy-coupled instead.
    #[test]
    fn spec_fresnel_mix_gains_energy_at_grazing() {
        let alpha = 0.09f64;
        let wo = wo_at(80f64.to_radians());
        let e = hemi(400, |wi| {
            let h = [wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]];
            let l = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
            let vh = (wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]) / l;
            let f = 0.04 + 0.96 * (1.0 - vh).powi(5);
            (1.0 - f) / PI + spec_ref(alpha, 0.04, 1.0, wo, wi)
        });
        assert!(e > 1.1, "spec fresnel_mix albedo {e}");
        let b = Bsdf::from_material(
            &Material {
                base_color: Rgb::ONE,
                roughness: 0.3,
                ..Default::default()
            },
            Rgb::ONE,
        );
        let (_, ours) = sphere_integrals(&b, v3(wo), 400, 61);
        assert!(ours[0] < 1.01, "coupled albedo {}", ours[0]);
    }

    /// ∫ spec_ref μ_i dω_i by a midpoint grid over the microfacet normal, mapped so that
    /// D cos θ_h dω_h is uniform (tan²θ_h = α² u / (1 − u)); exact for narrow lobes too.
    fn spec_albedo_ref(alpha: f64, f0: f64, f90: f64, wo: [f64; 3]) -> f64 {
        let n = 400;
        let a2 = alpha * alpha;
        let mut s = 0.0;
        for i in 0..n {
            let u = (i as f64 + 0.5) / n as f64;
            let ch = 1.0 / (1.0 + a2 * u / (1.0 - u)).sqrt();
            let sh = (1.0 - ch * ch).max(0.0).sqrt();
            for j in 0..n {
                let phi = 2.0 * PI * (j as f64 + 0.5) / n as f64;
                let h = [sh * phi.cos(), sh * phi.sin(), ch];
                let vh = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2];
                if vh <= 0.0 {
                    continue;
                }
                let wi = [
                    2.0 * vh * h[0] - wo[0],
                    2.0 * vh * h[1] - wo[1],
                    2.0 * vh * h[2] - wo[2],
                ];
                if wi[2] <= 0.0 {
                    continue;
                }
                let f = f0 + (f90 - f0) * (1.0 - vh).powi(5);
                // f D V μ_i dω_i with dω_i = 4 (ω_o·h) dω_h, divided by the grid's D cos θ_h.
                s += f * v_ref(alpha, wi[2], wo[2]) * wi[2] * 4.0 * vh / ch;
            }
        }
        s / (n * n) as f64
    }

    /// Independent quadrature of the documented model: a white dielectric reflects its
    /// specular lobe (the spec's, integrated here) and the coupled base returns the rest, so
    /// its albedo is 1 at every angle, roughness and ior; never more.
    #[test]
    fn white_dielectric_albedo_matches_quadrature_and_never_exceeds_one() {
        for rough in [0.0f32, 0.1, 0.3, 0.6, 1.0] {
            for ior in [1.0f32, 1.5, 2.5] {
                let p = GltfParams {
                    roughness: rough,
                    ior,
                    ..gltf_params()
                };
                let (ls, n) = lobes(&p);
                let b = Bsdf::from_gltf_lobes(&ls[..n]);
                let spec_lobe = lobe_components(&p)
                    .into_iter()
                    .find(|(k, _)| *k == GltfLobeKind::Specular)
                    .unwrap()
                    .1;
                let alpha = (rough as f64).powi(2);
                let f0 = ((ior as f64 - 1.0) / (ior as f64 + 1.0)).powi(2);
                for theta in [0.1f64, 0.7, 1.2, 1.45] {
                    let wo = wo_at(theta);
                    let spec = if rough == 0.0 {
                        f0 + (1.0 - f0) * (1.0 - wo[2]).powi(5)
                    } else {
                        spec_albedo_ref(alpha, f0, 1.0, wo)
                    };
                    let ctx = format!("r {rough} ior {ior} θ {theta}");
                    // The specular lobe alone integrates to the spec's lobe.
                    let (s_is, s_se) = sampled_albedo(&spec_lobe, v3(wo), 100_000, 63);
                    assert!(
                        (s_is[0] - spec).abs() < 0.005 + 4.0 * s_se[0],
                        "{ctx}: specular {} vs {spec}",
                        s_is[0]
                    );
                    // The whole material: white, so everything comes back.
                    let (is, se) = sampled_albedo(&b, v3(wo), 100_000, 64);
                    assert!(
                        is[0] <= 1.0 + 0.01 + 4.0 * se[0],
                        "{ctx}: sampled {}",
                        is[0]
                    );
                    assert!(
                        (is[0] - 1.0).abs() < 0.015 + 4.0 * se[0],
                        "{ctx}: sampled {}",
                        is[0]
                    );
                    if rough == 0.0 || rough >= 0.3 {
                        // Stratified quadrature of eval (the Dirac layer is added analytically).
                        let (_, num) = sphere_integrals(&b, v3(wo), 500, 62);
                        let quad = if rough == 0.0 { num[0] + spec } else { num[0] };
                        assert!(quad <= 1.0 + 0.01, "{ctx}: quadrature {quad}");
                        assert!((quad - 1.0).abs() < 0.015, "{ctx}: quadrature {quad}");
                    }
                }
            }
        }
    }

    /// A white metal reflects E₁(μ_o), the single-scattering GGX albedo (computed here by
    /// quadrature): 0.999, 0.912 and 0.316 at roughness 0.2, 0.5, 1 and θ_o = 0.3.
    #[test]
    fn white_metal_loses_only_the_single_scattering_energy() {
        for (rough, known) in [(0.2f32, 0.9988), (0.5, 0.9122), (1.0, 0.3157)] {
            let p = GltfParams {
                metallic: 1.0,
                roughness: rough,
                ..gltf_params()
            };
            let (ls, n) = lobes(&p);
            assert_eq!(n, 1);
            let b = Bsdf::from_gltf_lobes(&ls[..n]);
            let wo = wo_at(0.3);
            let e1 = spec_albedo_ref((rough as f64).powi(2), 1.0, 1.0, wo);
            assert!((e1 - known).abs() < 0.003, "r {rough}: E1 {e1}");
            let (is, se) = sampled_albedo(&b, v3(wo), 100_000, 65);
            assert!(
                (is[0] - e1).abs() < 0.005 + 4.0 * se[0],
                "r {rough}: {} vs {e1}",
                is[0]
            );
            let (_, num) = sphere_integrals(&b, v3(wo), 500, 66);
            assert!((num[0] - e1).abs() < 0.01, "r {rough}: {} vs {e1}", num[0]);
        }
    }

    fn variants() -> Vec<GltfParams> {
        let b = Rgb::new(0.9, 0.6, 0.3);
        vec![
            GltfParams {
                base: b,
                roughness: 0.4,
                ..gltf_params()
            },
            GltfParams {
                base: b,
                metallic: 0.5,
                roughness: 0.25,
                ..gltf_params()
            },
            GltfParams {
                base: b,
                roughness: 0.5,
                clearcoat: 1.0,
                clearcoat_roughness: 0.3,
                ..gltf_params()
            },
            GltfParams {
                base: b,
                roughness: 0.45,
                transmission: 0.7,
                ..gltf_params()
            },
            GltfParams {
                base: b,
                roughness: 0.45,
                transmission: 0.7,
                volumetric: true,
                ior: 1.33,
                ..gltf_params()
            },
            GltfParams {
                base: b,
                roughness: 0.6,
                specular: 0.7,
                specular_color: Rgb::new(2.0, 1.0, 0.5),
                ior: 1.8,
                ..gltf_params()
            },
            GltfParams {
                base: b,
                roughness: 0.5,
                oren_nayar_sigma: 0.5,
                ..gltf_params()
            },
        ]
    }

    #[test]
    fn every_lobe_samples_its_eval_and_pdf() {
        for p in variants() {
            for (kind, c) in lobe_components(&p) {
                for wo in test_directions_both_sides() {
                    let ok = check_sample_consistency(&c, wo, 2000, 66);
                    assert!(ok > 500, "{kind:?}: only {ok} samples");
                }
            }
        }
    }

    #[test]
    fn every_lobe_pdf_and_energy() {
        for p in variants() {
            for (kind, c) in lobe_components(&p) {
                let c = match c {
                    Component::Gltf(mut l) => {
                        l.dielectric.mode = super::super::TransportMode::Importance;
                        Component::Gltf(l)
                    }
                    c => c,
                };
                // Narrow lobes need a finer grid (refraction at η = 1.33 compresses the lobe).
                let narrow = kind == GltfLobeKind::Refraction
                    || matches!(c, Component::Gltf(l) if l.class_alpha().is_some_and(|a| a < 0.1));
                let n = if narrow { 1000 } else { 400 };
                for wo in [dir(0.3, 0.2), flip_dir(dir(0.8, 1.0)), dir(1.35, 2.0)] {
                    let pi = check_pdf_integral(&c, wo, n, 60_000, 67);
                    assert!(pi > 0.5, "{kind:?}: ∫pdf {pi}");
                    check_energy(&c, wo, n, 60_000, 68, 0.02);
                }
            }
        }
    }

    /// The diffuse coupling without a dielectric layer (no lookups) is what the lookups give,
    /// bit for bit, at any α (NaN included, where the lookups run) and any cosines (NaN, ±0,
    /// beyond ±1); with a layer it is the lookups' formula.
    #[test]
    fn diffuse_coupling_equals_the_lookups() {
        let by_lookup = |sh: &GltfShared, a: f32, b: f32| {
            (1.0 - sh.dielectric_albedo(a)).max(0.0)
                * (1.0 - sh.dielectric_albedo(b)).max(0.0)
                * sh.diffuse_norm
        };
        let mut r = Rng::new(75, 0);
        let mut mus = vec![0.0f32, -0.0, 1.0, -1.0, 1.5, f32::NAN, f32::INFINITY, 1e-30];
        mus.extend((0..100).map(|_| 2.0 * r.uniform() - 1.0));
        for (f0, f90) in [(0.0f32, 0.0f32), (0.04, 1.0), (0.0, 0.5)] {
            for alpha in [0.0f32, 0.3, 1.0, 2.0, f32::INFINITY, f32::NAN] {
                let sh = GltfShared {
                    coat: 0.0,
                    coat_alpha: 0.0,
                    alpha,
                    diel_f0: f0,
                    diel_f90: f90,
                    diffuse_norm: 1.25,
                };
                for (k, &a) in mus.iter().enumerate() {
                    let b = mus[(k * 5 + 1) % mus.len()];
                    let (got, want) = (sh.diffuse_coupling(a, b), by_lookup(&sh, a, b));
                    assert!(
                        got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                        "f0 {f0} f90 {f90} α {alpha} μ {a}, {b}: {got} vs {want}"
                    );
                }
            }
        }
    }

    /// The paired coat attenuation A(μ_o) A(μ_i) is the product of the single ones, bit for
    /// bit.
    #[test]
    fn paired_coat_attenuation_is_the_product() {
        let mut r = Rng::new(76, 0);
        for (coat, coat_alpha) in [(1.0f32, 0.09f32), (0.5, 0.0), (0.8, 0.6)] {
            let sh = GltfShared {
                coat,
                coat_alpha,
                alpha: 0.3,
                diel_f0: 0.04,
                diel_f90: 1.0,
                diffuse_norm: 1.1,
            };
            for _ in 0..500 {
                let (a, b) = (2.0 * r.uniform() - 1.0, 2.0 * r.uniform() - 1.0);
                let single = sh.coat_attenuation(a) * sh.coat_attenuation(b);
                assert_eq!(sh.coat_attenuation_pair(a, b).to_bits(), single.to_bits());
            }
        }
    }

    fn flip_dir(w: Vec3) -> Vec3 {
        super::flip(w)
    }

    #[test]
    fn reflective_lobes_are_reciprocal() {
        for p in variants() {
            for (kind, c) in lobe_components(&p) {
                if kind == GltfLobeKind::Refraction {
                    continue;
                }
                if kind == GltfLobeKind::ThinTransmission {
                    // f(ωo, ωi) = f(ωi, ωo) across the surface.
                    let mut r = Rng::new(69, 0);
                    for _ in 0..1000 {
                        let a = crate::sampling::uniform_sphere(r.uniform2());
                        let mut b = crate::sampling::uniform_sphere(r.uniform2());
                        b.z = -b.z.abs() * a.z.signum();
                        let (x, y) = (c.eval(a, b).r, c.eval(b, a).r);
                        assert!((x - y).abs() <= 1e-3 * x.max(y) + 1e-6, "{x} vs {y}");
                    }
                    continue;
                }
                check_reciprocity(&c, 70);
            }
            let (ls, n) = lobes(&p);
            if !ls[..n]
                .iter()
                .any(|(l, _)| l.kind == GltfLobeKind::Refraction)
            {
                check_reciprocity(&Bsdf::from_gltf_lobes(&ls[..n]), 71);
            }
        }
    }

    #[test]
    fn whole_material_samples_consistently_and_conserves_energy() {
        for p in variants() {
            let (ls, n) = lobes(&p);
            let mut b = Bsdf::from_gltf_lobes(&ls[..n]);
            for wo in test_directions_both_sides() {
                assert!(check_sample_consistency(&b, wo, 2000, 72) > 1000);
            }
            b.set_transport_mode(super::super::TransportMode::Importance);
            for wo in [dir(0.2, 0.1), dir(1.3, 1.0), flip_dir(dir(0.9, 2.0))] {
                check_energy(&b, wo, 400, 60_000, 73, 0.02);
            }
            // Weights sum to one; albedo estimates are in [0, 1].
            let w: f32 = b.components().map(|(_, w)| w).sum();
            assert!((w - 1.0).abs() < 1e-5);
            assert!(b
                .components()
                .all(|(c, _)| (0.0..=1.0).contains(&c.albedo())));
        }
    }

    #[test]
    fn roughness_zero_makes_dirac_layers() {
        let p = GltfParams {
            base: Rgb::splat(0.5),
            roughness: 0.0,
            clearcoat: 1.0,
            transmission: 0.5,
            ..gltf_params()
        };
        let (ls, n) = lobes(&p);
        let kinds: Vec<_> = ls[..n]
            .iter()
            .map(|(l, _)| (l.kind, l.is_delta()))
            .collect();
        assert_eq!(
            kinds,
            vec![
                (GltfLobeKind::Coat, true),
                (GltfLobeKind::Specular, true),
                (GltfLobeKind::Diffuse, false),
                (GltfLobeKind::ThinTransmission, true)
            ]
        );
        // Throughput of the mixture's samples: E[f cos/pdf] = coat + A²(F_S + ρ(1 − F_d)·…).
        let b = Bsdf::from_gltf_lobes(&ls[..n]);
        let wo = v3(wo_at(0.6));
        let mut r = Rng::new(74, 0);
        let mut thin = 0;
        for _ in 0..5000 {
            let s = b.sample(wo, r.uniform(), r.uniform2()).unwrap();
            if s.node == NodeType::SpecularTransmission {
                thin += 1;
                assert!(
                    (s.wi + wo).length() < 1e-5,
                    "thin transmission goes straight through"
                );
            }
        }
        assert!(thin > 100);
    }
}
