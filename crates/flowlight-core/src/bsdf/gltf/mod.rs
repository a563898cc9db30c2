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
//! **Layers** (each in its own file, with its formulas): `KHR_materials_sheen` adds a
//! Charlie sheen lobe between the coat and the rest and scales every lobe beneath by its
//! albedo scaling S(μ_o, μ_i) (`sheen.rs`); `KHR_materials_diffuse_transmission` turns the
//! diffuse base into a translucent one that also transmits to the back side
//! (`diffuse_transmission.rs`); `KHR_materials_iridescence` mixes a thin film's Fresnel into the
//! specular layer's (`iridescence.rs`). Without them the lobes are the ones above, bit for bit.
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

use super::albedo::{average, schlick_average};
use super::microfacet::Ggx;
use super::{BsdfSample, Dielectric, Lambert, OrenNayar, DELTA_ALPHA};
use crate::material_layers::MaterialLayers;
use crate::path::NodeType;
use crate::sampling::{cosine_hemisphere_pdf, two_sided_cosine, two_sided_cosine_pdf};
use crate::Rgb;
use glam::{Vec2, Vec3};

mod anisotropy;
mod diffuse_transmission;
mod iridescence;
mod pair;
mod shared;
mod sheen;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_layers;

pub use anisotropy::Anisotropy;
pub use iridescence::{iridescence_fresnel, ThinFilm};
pub(crate) use pair::{OpaquePair, PairOutgoing};
pub(crate) use shared::CoatAttenuation;
use shared::{flip, to_upper};
pub use shared::{schlick_f0_f90, GltfShared};
pub use sheen::{sheen_albedo, sheen_alpha, SheenScaling};

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
    /// The Charlie sheen layer (`KHR_materials_sheen`, `sheen.rs`).
    Sheen,
    /// The specular layer with an anisotropic GGX distribution (`KHR_materials_anisotropy`,
    /// `anisotropy.rs`).
    AnisotropicSpecular,
    /// The diffuse base with a Lambertian transmission part
    /// (`KHR_materials_diffuse_transmission`, `diffuse_transmission.rs`).
    TranslucentDiffuse,
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
    /// The albedo scaling of a sheen layer above this lobe (none by default).
    pub sheen: SheenScaling,
    /// Specular: the thin film of `KHR_materials_iridescence` (none by default).
    pub film: ThinFilm,
    /// Anisotropic specular: the roughnesses and direction.
    pub aniso: Anisotropy,
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
            sheen: SheenScaling::default(),
            film: ThinFilm::default(),
            aniso: Anisotropy::default(),
        }
    }

    #[inline]
    pub fn is_delta(&self) -> bool {
        match self.kind {
            GltfLobeKind::Diffuse
            | GltfLobeKind::Sheen
            | GltfLobeKind::TranslucentDiffuse
            | GltfLobeKind::AnisotropicSpecular => false,
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
            GltfLobeKind::Diffuse | GltfLobeKind::Sheen | GltfLobeKind::TranslucentDiffuse => None,
            GltfLobeKind::AnisotropicSpecular => Some(self.aniso.class_alpha()),
            GltfLobeKind::Refraction => Some(self.dielectric.alpha),
            _ => Some(self.alpha),
        }
    }

    /// Coat attenuation on the way in and out; 1 for the coat itself.
    #[inline]
    fn attenuation(&self, wo: Vec3, wi: Vec3) -> f32 {
        if self.kind == GltfLobeKind::Coat || self.shared.coat <= 0.0 {
            return self.with_sheen(1.0, wo, wi);
        }
        self.with_sheen(self.shared.coat_attenuation_pair(wo.z, wi.z), wo, wi)
    }

    /// `a` times the albedo scaling of a sheen layer above this lobe; `a` itself without one.
    #[inline]
    fn with_sheen(&self, a: f32, wo: Vec3, wi: Vec3) -> f32 {
        if !self.sheen.is_some() {
            return a;
        }
        a * self.sheen.factor(wo.z, wi.z)
    }

    /// The specular lobe's Fresnel at ω_o·h = `c`: Schlick's, or mixed with the thin film's.
    #[inline]
    fn fresnel(&self, c: f32) -> Rgb {
        let f = schlick_f0_f90(self.f0, self.f90, c);
        if !self.film.is_some() {
            return f;
        }
        self.film.fresnel(f, c)
    }

    /// [`GltfLobe::attenuation`] through a mixture pass's [`CoatAttenuation`].
    #[inline]
    fn attenuation_with(&self, wo: Vec3, wi: Vec3, coat: &mut CoatAttenuation) -> f32 {
        if self.kind == GltfLobeKind::Coat || self.shared.coat <= 0.0 {
            return self.with_sheen(1.0, wo, wi);
        }
        self.with_sheen(coat.get(&self.shared, wo, wi), wo, wi)
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
                    Some((s, c)) => self.fresnel(c) * s,
                    None => Rgb::ZERO,
                }
            }
            GltfLobeKind::Diffuse => self.raw_diffuse(wo, wi),
            GltfLobeKind::Sheen => self.f0 * sheen::sheen_value(self.alpha, wo, wi),
            GltfLobeKind::TranslucentDiffuse => self.translucent_eval_pdf(wo, wi).0,
            GltfLobeKind::AnisotropicSpecular => self.anisotropic_eval_pdf(wo, wi).0,
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
                    Some((s, c, pdf)) => (self.fresnel(c) * s, pdf),
                    None => NONE,
                }
            }
            GltfLobeKind::Sheen => (
                self.f0 * sheen::sheen_value(self.alpha, wo, wi),
                two_sided_cosine_pdf(wo, wi),
            ),
            GltfLobeKind::TranslucentDiffuse => self.translucent_eval_pdf(wo, wi),
            GltfLobeKind::AnisotropicSpecular => self.anisotropic_eval_pdf(wo, wi),
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
            GltfLobeKind::Diffuse | GltfLobeKind::Sheen => two_sided_cosine_pdf(wo, wi),
            GltfLobeKind::TranslucentDiffuse => self.translucent_eval_pdf(wo, wi).1,
            GltfLobeKind::AnisotropicSpecular => self.anisotropic_eval_pdf(wo, wi).1,
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
            GltfLobeKind::Sheen => {
                let (wi, pdf) = two_sided_cosine(wo, u)?;
                BsdfSample {
                    wi,
                    f: self.raw_eval(wo, wi),
                    pdf,
                    node: NodeType::GlossyReflection,
                    delta: false,
                    eta: 1.0,
                }
            }
            GltfLobeKind::TranslucentDiffuse => self.sample_translucent(wo, u)?,
            GltfLobeKind::AnisotropicSpecular => self.sample_anisotropic(wo, u)?,
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
                self.fresnel(c)
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
    /// Sheen, diffuse transmission, iridescence and anisotropy, resolved at the point (all off by
    /// default).
    pub layers: MaterialLayers,
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

/// Most lobes of one glTF material: coat, sheen, specular, diffuse base, transmission.
pub const MAX_LOBES: usize = 5;

/// The lobes (each with its selection weight, summing to one) of a glTF material; at most
/// [`MAX_LOBES`]. An empty list means the material scatters nothing.
pub fn lobes(p: &GltfParams) -> ([(GltfLobe, f32); MAX_LOBES], usize) {
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
    let film = thin_film(&p.layers, (1.0 - m) * (1.0 - t_v), f0_d, m, base);
    let (diel_f0, diel_f90) = if film.is_some() {
        // The base receives what the film leaves (iridescence.rs, `coupling_f0`).
        let f = film.factor;
        (film.coupling_f0(f0_d.max_component()), s + (1.0 - s) * f)
    } else {
        (f0_d.max_component(), s)
    };
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

    let sheen_color = clamp_rgb(p.layers.sheen_color);
    let sheen = if sheen_color.max_component() > 0.0 {
        SheenScaling {
            strength: sheen_color.max_component(),
            alpha: sheen_alpha(p.layers.sheen_roughness),
        }
    } else {
        SheenScaling::default()
    };
    // What the sheen leaves to the layers beneath, on average (for the selection weights).
    let att = if sheen.is_some() {
        att * (1.0 - sheen.strength * sheen::sheen_average(sheen.alpha))
    } else {
        att
    };
    let t_d = unit(p.layers.diffuse_transmission);

    let mut out: [(GltfLobe, f32); MAX_LOBES] =
        [(GltfLobe::new(GltfLobeKind::Diffuse, shared), 0.0); MAX_LOBES];
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
    if sheen.is_some() {
        let mut l = GltfLobe::new(GltfLobeKind::Sheen, shared);
        l.f0 = sheen_color;
        l.alpha = sheen.alpha;
        let coat_att = (1.0 - coat_avg).powi(2);
        push(
            l,
            coat_att * sheen.strength * sheen::sheen_average(sheen.alpha),
        );
    }
    {
        let k = (1.0 - m) * (1.0 - t_v);
        let mut l = GltfLobe::new(GltfLobeKind::Specular, shared);
        l.f0 = f0_d * k + base * m;
        l.f90 = Rgb::splat(s * k + m);
        l.film = film;
        let s_a = p.layers.anisotropy_strength;
        if s_a.is_finite() && s_a > 0.0 {
            let [dx, dy] = p.layers.anisotropy_direction;
            l.kind = GltfLobeKind::AnisotropicSpecular;
            l.aniso = Anisotropy::new(s_a, Vec2::new(dx, dy), alpha);
        }
        let e = l.f0 * (a1 - a5) + l.f90 * a5;
        push(l, att * e.max_component());
    }
    if t_d > 0.0 {
        let w = (1.0 - m) * (1.0 - t);
        let mut l = GltfLobe::new(GltfLobeKind::TranslucentDiffuse, shared);
        l.f0 = base * (w * (1.0 - t_d));
        l.f90 = clamp_rgb(p.layers.diffuse_transmission_color) * (w * t_d);
        l.diffuse = OrenNayar::new(Rgb::ONE, p.oren_nayar_sigma.max(0.0));
        if shared.diffuse_norm > 0.0 {
            let e = l.f0.max_component() + l.f90.max_component();
            push(l, att * e * (1.0 - e_d));
        }
    } else {
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

    if sheen.is_some() {
        for (l, _) in out[..n].iter_mut() {
            if !matches!(l.kind, GltfLobeKind::Coat | GltfLobeKind::Sheen) {
                l.sheen = sheen;
            }
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

/// The thin film of `KHR_materials_iridescence` over the specular lobe whose dielectric part
/// has weight `k` and F0 `f0_d`, its metal part weight `m` and F0 `base` (none where the
/// factor is 0). The albedo AOV builds the same film (`flowlight-host`'s `aov::albedo`).
pub fn thin_film(layers: &MaterialLayers, k: f32, f0_d: Rgb, m: f32, base: Rgb) -> ThinFilm {
    let factor = layers.iridescence;
    if !(factor.is_finite() && factor > 0.0) {
        return ThinFilm::default();
    }
    let finite = |x: f32, d: f32| if x.is_finite() { x } else { d };
    ThinFilm {
        factor: factor.min(1.0),
        ior: finite(layers.iridescence_ior, 1.3).max(1.0),
        thickness: finite(layers.iridescence_thickness_max, 400.0).max(0.0),
        diel_weight: k,
        diel_f0: f0_d,
        metal_weight: m,
        metal_f0: base,
    }
}
