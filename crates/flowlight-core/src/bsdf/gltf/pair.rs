//! The opaque pair: a rough specular layer over the diffuse base, evaluated and sampled in
//! one pass (the mixture most production materials make).

use super::super::albedo::Roughness;
use super::super::microfacet::Ggx;
use super::super::BsdfSample;
use super::{schlick_f0_f90, to_upper, GltfLobe, GltfLobeKind};
use crate::path::NodeType;
use crate::sampling::{cosine_hemisphere_pdf, rescaled, two_sided_cosine};
use crate::Rgb;
use glam::{Vec2, Vec3};

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
    /// Whether the two lobes are one: a specular lobe with α ≥ [`DELTA_ALPHA`] and no thin
    /// film and then the diffuse base, neither under a coat (`coat <= 0`, so a NaN coat keeps
    /// the walk).
    pub fn holds(&self) -> bool {
        self.spec.kind == GltfLobeKind::Specular
            && !self.spec.is_delta()
            && !self.spec.film.is_some()
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
    pub(super) lambda_o: f32,
    pub(super) base_o: f32,
    /// The base roughness's coordinate in the albedo tables, for the lookups at μ_i.
    pub(super) rough: Roughness,
}
