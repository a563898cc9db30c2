//! BSDFs in the local shading frame: `z` is the shading normal and both `wo` (towards the
//! previous vertex) and `wi` (towards the next) point away from the surface. `eval` returns the
//! BSDF value f without the cosine; integrators multiply by |cos θ_i| themselves.
//!
//! A material is a weighted mixture of at most [`MAX_COMPONENTS`] components. Samplers first
//! choose a component (the strong node type, thesis §3.6), then sample it; the full-mixture
//! `eval`/`pdf` serve multiple importance sampling. A component's value may carry the inverse
//! of its weight, so that Σ wᵢ fᵢ is the material's BSDF and one component's value alone is
//! an unbiased one-sample estimate (w f / p_m = f).
//!
//! Models: the glTF 2.0 material ([`gltf`]: coupled diffuse base, GGX specular layer, thin or
//! refracting transmission, clearcoat), which [`Bsdf::from_material`] builds; and the
//! standalone lobes [`Lambert`], [`OrenNayar`] (rough diffuse), [`Conductor`] (GGX + Schlick),
//! [`Dielectric`] (smooth or rough GGX glass, Walter et al. 2007). The GGX distribution itself
//! lives in [`microfacet`], its tabulated albedo in [`albedo`], Beer–Lambert absorption inside
//! volumetric materials in [`volume`].

pub mod albedo;
pub mod anisotropic_ggx;
mod conductor;
mod dielectric;
pub mod gltf;
mod lambert;
pub mod microfacet;
pub mod multiscatter;
mod oren_nayar;
#[cfg(test)]
mod testutil;
pub mod volume;

pub use conductor::{fresnel_schlick, Conductor};
pub use dielectric::{fresnel_dielectric, refract, Dielectric, TransportMode};
pub use gltf::{GltfLobe, GltfLobeKind, GltfParams};
pub use lambert::Lambert;
pub use microfacet::Ggx;
pub use multiscatter::MultiScatter;
pub use oren_nayar::OrenNayar;

use crate::material::{DiffuseModel, Material};
use crate::path::{NodeClass, NodeType};
use crate::sampling::rescaled;
use crate::Rgb;
use glam::{Vec2, Vec3};
use gltf::CoatAttenuation;

/// GGX α below which a lobe is treated as a Dirac (perfect mirror or smooth glass).
pub const DELTA_ALPHA: f32 = 1e-3;
/// GGX α below which a glossy lobe counts as narrow (Λα): no explicit light connection.
pub const NARROW_GLOSSY_ALPHA: f32 = 0.05;
/// Most components a [`Bsdf`] holds: the glTF lobes (coat, sheen, specular, diffuse,
/// transmission) and the metal's multiple-scattering compensation.
pub const MAX_COMPONENTS: usize = gltf::MAX_LOBES + 1;

/// One sampled direction.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    pub wi: Vec3,
    /// BSDF value for this direction (for a Dirac lobe: the lobe's weight divided by |cos θ_i|,
    /// so that `f·|cos θ_i| / pdf` is the right throughput).
    pub f: Rgb,
    /// Density of `wi` (solid angle). For a Dirac lobe: the discrete probability of choosing it.
    pub pdf: f32,
    /// Scattering mode that produced `wi`.
    pub node: NodeType,
    /// True for a Dirac lobe: `f` and `pdf` must not enter MIS.
    pub delta: bool,
    /// Relative index of refraction η' crossed by a refraction: the index of `wi`'s side over
    /// that of `wo`'s (1.5 where a camera path enters glass from air), 1 for every other event. In radiance mode a refraction scales
    /// `f` by 1/η'²; a path tracer multiplies its running η'² product by this squared to undo
    /// that scaling in its Russian roulette (Mitsuba 3 `BSDFSample3f::eta`, pbrt-v4
    /// `BSDFSample::eta`).
    pub eta: f32,
}

/// One component of a mixture.
#[derive(Clone, Copy, Debug)]
pub enum Component {
    Lambert(Lambert),
    OrenNayar(OrenNayar),
    Conductor(Conductor),
    Dielectric(Dielectric),
    /// A lobe of the glTF material.
    Gltf(GltfLobe),
    /// The metal's multiple-scattering compensation ([`multiscatter`]).
    MultiScatter(MultiScatter),
}

impl Component {
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        match self {
            Component::Lambert(c) => c.eval(wo, wi),
            Component::OrenNayar(c) => c.eval(wo, wi),
            Component::Conductor(c) => c.eval(wo, wi),
            Component::Dielectric(c) => c.eval(wo, wi),
            Component::Gltf(c) => c.eval(wo, wi),
            Component::MultiScatter(c) => c.eval(wo, wi),
        }
    }
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        match self {
            Component::Lambert(c) => c.pdf(wo, wi),
            Component::OrenNayar(c) => c.pdf(wo, wi),
            Component::Conductor(c) => c.pdf(wo, wi),
            Component::Dielectric(c) => c.pdf(wo, wi),
            Component::Gltf(c) => c.pdf(wo, wi),
            Component::MultiScatter(c) => c.pdf(wo, wi),
        }
    }
    /// `(eval, pdf)` at once, sharing what the two compute alike (the half vector, D and
    /// Λ(ω_o), the hemisphere flips, the side tests); see [`Bsdf::eval_pdf`]. The same values
    /// as the separate calls, bit for bit.
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        self.eval_pdf_with(wo, wi, &mut CoatAttenuation::default())
    }

    /// [`Component::eval_pdf`] with the coat attenuation of a mixture pass over (`wo`, `wi`).
    #[inline]
    fn eval_pdf_with(&self, wo: Vec3, wi: Vec3, coat: &mut CoatAttenuation) -> (Rgb, f32) {
        match self {
            Component::Lambert(c) => c.eval_pdf(wo, wi),
            Component::OrenNayar(c) => c.eval_pdf(wo, wi),
            Component::Conductor(c) => c.eval_pdf(wo, wi),
            Component::Dielectric(c) => c.eval_pdf(wo, wi),
            Component::Gltf(c) => c.eval_pdf_with(wo, wi, coat),
            Component::MultiScatter(c) => c.eval_pdf(wo, wi),
        }
    }

    /// `(eval, pdf)` at the direction of `s`, which this component sampled from `wo`, taking
    /// from `s` whatever is provably the same bit for bit (see
    /// [`GltfLobe::eval_pdf_sampled`]): Lambert and Oren–Nayar sample with exactly their
    /// `eval` and `pdf` expressions wherever the pair is on one side (the test `eval` makes).
    /// The conductor and dielectric compute theirs from the sampled normal instead of the
    /// half vector, so they are evaluated anew.
    #[inline]
    fn eval_pdf_sampled(&self, wo: Vec3, s: &BsdfSample, coat: &mut CoatAttenuation) -> (Rgb, f32) {
        match self {
            Component::Lambert(_) | Component::OrenNayar(_) if !s.delta && wo.z * s.wi.z > 0.0 => {
                (s.f, s.pdf)
            }
            Component::Gltf(c) => c.eval_pdf_sampled(wo, s, coat),
            _ => self.eval_pdf_with(wo, s.wi, coat),
        }
    }

    /// Samples with two numbers. The dielectric needs a third to choose reflection or
    /// refraction and takes it from the low bits of `u.x`; prefer [`Component::sample_with`].
    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        match self {
            Component::Lambert(c) => c.sample(wo, u),
            Component::OrenNayar(c) => c.sample(wo, u),
            Component::Conductor(c) => c.sample(wo, u),
            Component::Dielectric(c) => c.sample(wo, u),
            Component::Gltf(c) => c.sample(wo, u),
            Component::MultiScatter(c) => c.sample(wo, u),
        }
    }
    /// Samples with an extra uniform `uc` for the discrete reflect/refract choice (only the
    /// dielectric lobes use it): the lobe **reflects when `uc` < R/(R + T)** (R, T its Fresnel
    /// reflectance and transmittance at `wo`, about the sampled microfacet normal for a rough
    /// lobe) and refracts otherwise. So `uc = 0` always follows the reflection and `uc` just
    /// below 1 the refraction (unless total internal reflection leaves only the reflection);
    /// the sample's `node` says which was taken. `flowlight_mcmc::measure::dirac_scatter`
    /// follows a given Dirac lobe this way.
    #[inline]
    pub fn sample_with(&self, wo: Vec3, uc: f32, u: Vec2) -> Option<BsdfSample> {
        match self {
            Component::Dielectric(c) => c.sample_with(wo, uc, u),
            Component::Gltf(c) => c.sample_with(wo, uc, u),
            _ => self.sample(wo, u),
        }
    }
    /// Directional albedo estimate in [0, 1] used by BxDF-based termination.
    #[inline]
    pub fn albedo(&self) -> f32 {
        match self {
            Component::Lambert(c) => c.albedo.max_component(),
            Component::OrenNayar(c) => c.albedo(),
            Component::Conductor(c) => c.albedo(),
            Component::Dielectric(c) => c.albedo(),
            Component::Gltf(c) => c.albedo,
            Component::MultiScatter(c) => c.albedo,
        }
    }
    /// True for a Dirac lobe (smooth mirror or smooth glass).
    #[inline]
    pub fn is_delta(&self) -> bool {
        match self {
            Component::Lambert(_) | Component::OrenNayar(_) | Component::MultiScatter(_) => false,
            Component::Conductor(c) => c.is_delta(),
            Component::Dielectric(c) => c.is_delta(),
            Component::Gltf(c) => c.is_delta(),
        }
    }
    /// Scattering mode of the pair (`wo`, `wi`) through this component, e.g. for an explicit
    /// light connection: diffuse for Lambert/Oren–Nayar, glossy or specular reflection or
    /// transmission for the conductor and dielectric.
    #[inline]
    pub fn node_type(&self, wo: Vec3, wi: Vec3) -> NodeType {
        let reflect = wo.z * wi.z > 0.0;
        match (self.is_diffuse(), self.is_delta(), reflect) {
            (true, _, true) => NodeType::DiffuseReflection,
            (true, _, false) => NodeType::DiffuseTransmission,
            (_, true, true) => NodeType::SpecularReflection,
            (_, true, false) => NodeType::SpecularTransmission,
            (_, false, true) => NodeType::GlossyReflection,
            (_, false, false) => NodeType::GlossyTransmission,
        }
    }
    /// True for the diffuse models (Lambert, Oren–Nayar, the glTF diffuse base).
    #[inline]
    pub fn is_diffuse(&self) -> bool {
        match self {
            Component::Lambert(_) | Component::OrenNayar(_) => true,
            Component::Gltf(c) => matches!(
                c.kind,
                GltfLobeKind::Diffuse | GltfLobeKind::TranslucentDiffuse
            ),
            _ => false,
        }
    }

    /// True for the components that only reflect: their value and density are zero wherever
    /// ω_o and ω_i are not strictly on one side of the surface (each tests the sides before
    /// anything else). The dielectric and the glTF transmission lobes are the others.
    #[inline]
    pub fn reflects_only(&self) -> bool {
        match self {
            Component::Lambert(_)
            | Component::OrenNayar(_)
            | Component::Conductor(_)
            | Component::MultiScatter(_) => true,
            Component::Dielectric(_) => false,
            Component::Gltf(c) => matches!(
                c.kind,
                GltfLobeKind::Coat
                    | GltfLobeKind::Specular
                    | GltfLobeKind::AnisotropicSpecular
                    | GltfLobeKind::Diffuse
                    | GltfLobeKind::Sheen
            ),
        }
    }

    /// Λα for Dirac and narrow glossy lobes (α < [`NARROW_GLOSSY_ALPHA`]), Λβ otherwise.
    #[inline]
    pub fn class(&self) -> NodeClass {
        self.class_with(NARROW_GLOSSY_ALPHA)
    }

    /// [`Component::class`] with the narrow-glossy threshold `narrow_alpha` as a parameter:
    /// Λα for Dirac lobes and GGX lobes with α < `narrow_alpha`.
    #[inline]
    pub fn class_with(&self, narrow_alpha: f32) -> NodeClass {
        let alpha = match self {
            Component::Lambert(_) | Component::OrenNayar(_) => return NodeClass::Beta,
            Component::Conductor(c) => c.alpha,
            Component::Dielectric(c) => c.alpha,
            Component::MultiScatter(c) => c.alpha,
            Component::Gltf(c) => match c.class_alpha() {
                Some(a) => a,
                None => return NodeClass::Beta,
            },
        };
        if self.is_delta() || alpha < narrow_alpha {
            NodeClass::Alpha
        } else {
            NodeClass::Beta
        }
    }
}

/// A [`Bsdf`] at one outgoing direction ([`Bsdf::at`]): its evaluations and samples there,
/// sharing what depends on ω_o alone.
#[derive(Clone, Copy, Debug)]
pub struct BsdfAt<'a> {
    bsdf: &'a Bsdf,
    wo: Vec3,
    terms: OutgoingTerms,
}

/// What a [`BsdfAt`] computed from ω_o alone, kept without its borrow for
/// [`Bsdf::at_with`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OutgoingTerms(Option<gltf::PairOutgoing>);

impl BsdfAt<'_> {
    /// What was computed from ω_o, for [`Bsdf::at_with`].
    #[inline]
    pub fn terms(&self) -> OutgoingTerms {
        self.terms
    }

    /// [`Bsdf::is_zero_between`] ω_o and `wi`.
    #[inline]
    pub fn is_zero_between(&self, wi: Vec3) -> bool {
        self.bsdf.is_zero_between(self.wo, wi)
    }

    /// [`Bsdf::eval`] at (ω_o, `wi`).
    #[inline]
    pub fn eval(&self, wi: Vec3) -> Rgb {
        self.bsdf.eval(self.wo, wi)
    }

    /// [`Bsdf::eval_pdf`] at (ω_o, `wi`).
    #[inline]
    pub fn eval_pdf(&self, wi: Vec3) -> (Rgb, f32) {
        self.bsdf.eval_pdf_from(self.wo, self.terms.0.as_ref(), wi)
    }

    /// [`Bsdf::sample`] at ω_o.
    #[inline(always)]
    pub fn sample(&self, u_component: f32, u: Vec2) -> Option<BsdfSample> {
        self.bsdf
            .sample_from(self.wo, self.terms.0.as_ref(), u_component, u)
    }
}

/// The opaque pair's ω_o terms: the caller's ([`BsdfAt`]) where it has them, else computed.
#[inline(always)]
fn pair_terms(
    pair: &gltf::OpaquePair,
    at: Option<&gltf::PairOutgoing>,
    wo: Vec3,
) -> gltf::PairOutgoing {
    match at {
        Some(at) => *at,
        None => pair.outgoing(wo),
    }
}

/// A material's BSDF: a weighted mixture of components. Weights sum to one.
#[derive(Clone, Copy, Debug)]
pub struct Bsdf {
    components: [Option<(Component, f32)>; MAX_COMPONENTS],
    count: usize,
    /// [`Bsdf::albedo`] and [`Bsdf::has_non_delta`] of the components, kept by every
    /// constructor and mutator ([`Bsdf::summarise`]): a path tracer asks for both at every
    /// vertex, and walking the mixture for them was 2% of a Cornell box render (callgrind).
    albedo: f32,
    non_delta: bool,
    /// Whether the components are a [`gltf::OpaquePair`] (kept by [`Bsdf::summarise`]), which
    /// `eval_pdf` and `sample` take without the walk.
    opaque_pair: bool,
    /// Whether every component only reflects ([`Component::reflects_only`]).
    reflects_only: bool,
}

impl Bsdf {
    /// The glTF material ([`gltf`]): clearcoat, specular layer, energy-coupled diffuse base
    /// and thin or refracting transmission, in that order; lobes that cannot scatter are
    /// dropped. `base` is the textured base colour; every other factor is read from `m` (with
    /// any texture already multiplied in by the caller). A material that scatters nothing is
    /// one black Lambert lobe.
    pub fn from_material(m: &Material, base: Rgb) -> Bsdf {
        let sigma = match m.diffuse_model {
            DiffuseModel::Lambert => 0.0,
            DiffuseModel::OrenNayar => m.oren_nayar_sigma,
        };
        let p = GltfParams {
            base,
            metallic: m.metallic,
            roughness: m.roughness,
            ior: m.ior,
            specular: m.specular,
            specular_color: m.specular_color,
            transmission: m.transmission,
            volumetric: m.thickness > 0.0,
            clearcoat: m.clearcoat,
            clearcoat_roughness: m.clearcoat_roughness,
            oren_nayar_sigma: if sigma.is_finite() { sigma } else { 0.0 },
            layers: m.layers,
        };
        let (lobes, n) = gltf::lobes(&p);
        let bsdf = Bsdf::from_gltf_lobes(&lobes[..n]);
        if m.multiscatter != 0 {
            return bsdf.with_multiscatter(&p);
        }
        bsdf
    }

    /// A mixture of glTF lobes with their weights (as [`gltf::lobes`] returns them).
    ///
    /// A lone plain diffuse base ([`GltfLobe::as_lambert`]: no specular layer, coat or
    /// transmission left, σ = 0, as in a material with `KHR_materials_specular` factor 0 like
    /// the Cornell box's) becomes a [`Lambert`] component, which gives the same values bit
    /// for bit without the glTF lobe's coupling and coat checks at every evaluation.
    pub fn from_gltf_lobes(lobes: &[(GltfLobe, f32)]) -> Bsdf {
        if lobes.is_empty() {
            return Bsdf::single(Component::Lambert(Lambert { albedo: Rgb::ZERO }));
        }
        if let [(lobe, w)] = lobes {
            if let Some(lambert) = lobe.as_lambert().filter(|_| *w == 1.0) {
                return Bsdf::single(Component::Lambert(lambert));
            }
        }
        let mut bsdf = Bsdf {
            components: [None; MAX_COMPONENTS],
            count: 0,
            albedo: 0.0,
            non_delta: false,
            opaque_pair: false,
            reflects_only: false,
        };
        for &(l, w) in lobes.iter().take(MAX_COMPONENTS) {
            bsdf.components[bsdf.count] = Some((Component::Gltf(l), w));
            bsdf.count += 1;
        }
        bsdf.summarise()
    }

    /// Sets the summary fields from the components.
    fn summarise(mut self) -> Bsdf {
        self.albedo = self
            .components()
            .map(|(c, w)| c.albedo() * w)
            .sum::<f32>()
            .clamp(0.0, 1.0);
        let non_delta = self.components().any(|(c, _)| !c.is_delta());
        self.non_delta = non_delta;
        self.opaque_pair = self.two_gltf_lobes().is_some_and(|p| p.holds());
        let reflects_only = self.components().all(|(c, _)| c.reflects_only());
        self.reflects_only = reflects_only;
        self
    }

    /// Switches every refracting lobe to `mode` (camera paths carry radiance, the default;
    /// light paths importance).
    pub fn set_transport_mode(&mut self, mode: TransportMode) {
        for (c, _) in self.components.iter_mut().flatten() {
            match c {
                Component::Dielectric(d) => d.mode = mode,
                Component::Gltf(l) => l.dielectric.mode = mode,
                _ => {}
            }
        }
        *self = self.summarise();
    }

    pub fn single(c: Component) -> Bsdf {
        let mut components = [None; MAX_COMPONENTS];
        components[0] = Some((c, 1.0));
        Bsdf {
            components,
            count: 1,
            albedo: 0.0,
            non_delta: false,
            opaque_pair: false,
            reflects_only: false,
        }
        .summarise()
    }

    pub fn components(&self) -> impl Iterator<Item = (Component, f32)> + '_ {
        self.components[..self.count].iter().flatten().copied()
    }

    pub fn component(&self, i: usize) -> Component {
        self.components[i].expect("component index in range").0
    }

    /// Chooses a component with probability equal to its weight: (index, probability). With
    /// `u` the first number of [`Bsdf::sample`]'s pair, it is the component that sample drew.
    #[inline]
    pub fn choose_component(&self, u: f32) -> (usize, f32) {
        let (i, w, _) = self.choose(u);
        (i, w)
    }

    /// [`Bsdf::choose_component`] and the sum of the weights before the chosen one (the lower
    /// end of its interval of `u`, which the walk has at hand).
    #[inline]
    fn choose(&self, u: f32) -> (usize, f32, f32) {
        let mut acc = 0.0;
        for i in 0..self.count {
            let (_, w) = self.components[i].unwrap();
            let lo = acc;
            acc += w;
            if u < acc || i + 1 == self.count {
                return (i, w, lo);
            }
        }
        (0, 1.0, 0.0)
    }

    /// The components by reference (the hot loops: a component is ~100 bytes).
    #[inline]
    fn component_refs(&self) -> impl Iterator<Item = &(Component, f32)> + '_ {
        self.components[..self.count].iter().flatten()
    }

    /// Mixture BSDF value Σ wᵢ fᵢ (Dirac lobes contribute nothing).
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        self.component_refs()
            .fold(Rgb::ZERO, |acc, (c, w)| acc + c.eval(wo, wi) * *w)
    }

    /// Mixture density Σ wᵢ pᵢ (Dirac lobes contribute nothing).
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.component_refs().map(|(c, w)| c.pdf(wo, wi) * w).sum()
    }

    /// `(eval(wo, wi), pdf(wo, wi))` in one pass over the components, for the callers that
    /// need both at one pair: a light connection's value and its MIS weight, and the mixture
    /// re-evaluation of [`Bsdf::sample`]. Each component shares the work its value and its
    /// density do alike (half vector and its normalisation, GGX D and Λ(ω_o), the hemisphere
    /// flips, side tests), and a coated glTF material looks its coat attenuation up once for
    /// all lobes instead of once per lobe.
    ///
    /// Both results equal the separate calls bit for bit: the components' values are, and
    /// the sums are made in the same order from the same start (`eval` folds from zero,
    /// `pdf`'s `Iterator::sum` from −0.0), so images do not change.
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        self.eval_pdf_from(wo, None, wi)
    }

    /// [`Bsdf::eval_pdf`] with the opaque pair's ω_o terms where the caller has them
    /// ([`BsdfAt`]); the same results, bit for bit.
    #[inline]
    fn eval_pdf_from(&self, wo: Vec3, at: Option<&gltf::PairOutgoing>, wi: Vec3) -> (Rgb, f32) {
        if let Some(lambert) = self.lone_lambert() {
            // The walk's 0 + f·1 and −0 + p·1 (see `sample`'s lone Lambert).
            return lambert.eval_pdf(wo, wi);
        }
        if let Some(pair) = self.opaque_pair() {
            return pair.eval_pdf_with(&pair_terms(&pair, at, wo), wo, wi);
        }
        self.eval_pdf_by_walk(wo, wi)
    }

    /// This BSDF at one outgoing direction `wo`, for a caller that evaluates or samples it
    /// there more than once (a path vertex: its light connection and BSDF sample, and each
    /// branch's where the path splits). What the evaluations at `wo` share is computed here
    /// once: for the glTF opaque pair (`gltf::PairOutgoing`) the specular lobe's Λ(ω_o)
    /// and the diffuse coupling's albedo lookup at μ_o, which otherwise every
    /// [`Bsdf::eval_pdf`] and [`Bsdf::sample`] computes again. Every result equals those
    /// calls' at `wo`, bit for bit.
    #[inline]
    pub fn at(&self, wo: Vec3) -> BsdfAt<'_> {
        BsdfAt {
            bsdf: self,
            wo,
            terms: OutgoingTerms(self.opaque_pair().map(|pair| pair.outgoing(wo))),
        }
    }

    /// [`Bsdf::at`] from terms kept from an earlier `at` of this BSDF at this `wo`
    /// ([`BsdfAt::terms`]), for an evaluation made once the borrow has ended (a light
    /// connection evaluated after its shadow ray). Terms of another BSDF or direction give
    /// wrong values; terms of another kind of BSDF are ignored.
    #[inline]
    pub fn at_with(&self, wo: Vec3, terms: OutgoingTerms) -> BsdfAt<'_> {
        match terms.0 {
            Some(_) if self.opaque_pair => BsdfAt {
                bsdf: self,
                wo,
                terms,
            },
            _ => self.at(wo),
        }
    }

    /// [`Bsdf::eval_pdf`] over the components one by one (every mixture but the lone Lambert
    /// and the opaque pair, which give the same bits without it).
    fn eval_pdf_by_walk(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        let mut coat = CoatAttenuation::default();
        let mut f = Rgb::ZERO;
        let mut pdf = -0.0f32;
        for (c, w) in self.component_refs() {
            let (cf, cp) = c.eval_pdf_with(wo, wi, &mut coat);
            f += cf * *w;
            pdf += cp * w;
        }
        (f, pdf)
    }

    /// [`Bsdf::eval_pdf`] at the direction of `s`, a non-Dirac sample of component `chosen`:
    /// that component's terms come from [`Component::eval_pdf_sampled`], which reuses the
    /// sample's own value (and for the diffuse lobes its density) where they are provably
    /// equal to `eval` and `pdf`. The same results as `eval_pdf(wo, s.wi)`, bit for bit.
    #[inline]
    fn eval_pdf_sampled(&self, wo: Vec3, chosen: usize, s: &BsdfSample) -> (Rgb, f32) {
        let mut coat = CoatAttenuation::default();
        let mut f = Rgb::ZERO;
        let mut pdf = -0.0f32;
        // By index, as `sample` chose (`component_refs` would skip an empty slot).
        for (i, slot) in self.components[..self.count].iter().enumerate() {
            let Some((c, w)) = slot else { continue };
            let (cf, cp) = if i == chosen {
                c.eval_pdf_sampled(wo, s, &mut coat)
            } else {
                c.eval_pdf_with(wo, s.wi, &mut coat)
            };
            f += cf * *w;
            pdf += cp * w;
        }
        (f, pdf)
    }

    /// Samples the whole mixture: chooses a component by `u.x`, samples it with `u.x` rescaled
    /// into the chosen component's interval ([`crate::sampling::rescaled`]) and `u.y`, passes
    /// `u_component` on as the component's own discrete sample (the dielectric's
    /// reflect/refract choice), and for a non-Dirac lobe returns the mixture's f and pdf (so
    /// MIS sees the true density). Choosing with the direction's own pair keeps a pixel's
    /// stratified pairs stratified on each lobe, where a separate, randomly paired choice
    /// number scattered them (on `dragon.toml` the image's relMSE fell by 2.7%).
    ///
    /// For a Dirac lobe i chosen with probability pᵢ = wᵢ, `f = wᵢ fᵢ` and `pdf = pᵢ · P_i`
    /// (P_i the lobe's own discrete probability), so the throughput f|cos|/pdf is the lobe's own
    /// throughput: the weight cancels against the selection probability.
    ///
    /// The mixture's f and pdf come from one pass ([`Bsdf::eval_pdf`]) that takes the chosen
    /// component's own terms from the sample where they are provably the same; f and pdf are
    /// bit for bit `eval(wo, s.wi)` and `pdf(wo, s.wi)`.
    #[inline(always)]
    pub fn sample(&self, wo: Vec3, u_component: f32, u: Vec2) -> Option<BsdfSample> {
        self.sample_from(wo, None, u_component, u)
    }

    /// [`Bsdf::sample`] with the opaque pair's ω_o terms where the caller has them
    /// ([`BsdfAt`]); the same sample, bit for bit.
    #[inline(always)]
    fn sample_from(
        &self,
        wo: Vec3,
        at: Option<&gltf::PairOutgoing>,
        u_component: f32,
        u: Vec2,
    ) -> Option<BsdfSample> {
        if let Some(lambert) = self.lone_lambert() {
            // The walk below, for one Lambert component of weight 1, returns this sample
            // itself: its value and density are `eval`'s and `pdf`'s where ω_o and ω_i are on
            // one side (the test `eval` makes; elsewhere both are 0 and the sample is
            // refused), and Σ wᵢ fᵢ = 0 + f·1, Σ wᵢ pᵢ = −0 + p·1 change no bit. Returning it
            // directly keeps the sample in registers: the walk's copy through the stack was
            // 3.8% of a Cornell box render (store-to-load forwarding stalls, perf).
            let s = lambert.sample(wo, u)?;
            return (wo.z * s.wi.z > 0.0).then_some(s);
        }
        self.sample_mixture(wo, at, u_component, u)
    }

    /// [`Bsdf::sample`] of every mixture but the lone Lambert, out of line: `sample` itself is
    /// inlined into its callers so that a Lambert sample stays in registers (returned through
    /// memory, its direction was reloaded wider than it was stored, a store-forwarding stall
    /// at every diffuse vertex), and this keeps the glTF code out of them.
    #[inline(never)]
    fn sample_mixture(
        &self,
        wo: Vec3,
        at: Option<&gltf::PairOutgoing>,
        u_component: f32,
        u: Vec2,
    ) -> Option<BsdfSample> {
        if let Some(pair) = self.opaque_pair() {
            return pair.sample_with(&pair_terms(&pair, at, wo), wo, u_component, u);
        }
        self.sample_by_walk(wo, u_component, u)
    }

    /// [`Bsdf::sample`] through the components (every mixture but the lone Lambert and the
    /// opaque pair, which give the same bits without it).
    fn sample_by_walk(&self, wo: Vec3, u_component: f32, u: Vec2) -> Option<BsdfSample> {
        // `lo`, the weights before i summed in order, is the sum the walk had reached.
        let (i, p, lo) = self.choose(u.x);
        let u = Vec2::new(rescaled(u.x, lo, p), u.y);
        let (c, w) = self.components[i].as_ref()?;
        let mut s = c.sample_with(wo, u_component, u)?;
        if s.delta {
            s.f *= *w;
            s.pdf *= p;
        } else {
            (s.f, s.pdf) = self.eval_pdf_sampled(wo, i, &s);
        }
        (s.pdf > 0.0).then_some(s)
    }

    /// Weighted albedo estimate in [0, 1] for BxDF-based termination.
    #[inline]
    pub fn albedo(&self) -> f32 {
        self.albedo
    }

    /// The component when this BSDF is one Lambert component of weight 1 (every plain glTF
    /// diffuse material, [`Bsdf::from_gltf_lobes`]).
    #[inline]
    fn lone_lambert(&self) -> Option<&Lambert> {
        match &self.components[0] {
            Some((Component::Lambert(l), w)) if self.count == 1 && *w == 1.0 => Some(l),
            _ => None,
        }
    }

    /// The two components as an [`gltf::OpaquePair`] where both are glTF lobes, whatever
    /// their kinds ([`gltf::OpaquePair::holds`] checks those).
    #[inline]
    fn two_gltf_lobes(&self) -> Option<gltf::OpaquePair<'_>> {
        if self.count != 2 {
            return None;
        }
        match (&self.components[0], &self.components[1]) {
            (Some((Component::Gltf(spec), ws)), Some((Component::Gltf(diffuse), wd))) => {
                Some(gltf::OpaquePair {
                    spec,
                    spec_weight: *ws,
                    diffuse,
                    diffuse_weight: *wd,
                })
            }
            _ => None,
        }
    }

    /// The components as a [`gltf::OpaquePair`] where [`Bsdf::summarise`] found them one
    /// (every constructor and mutator ends with it, so the kinds are not checked again here).
    #[inline]
    fn opaque_pair(&self) -> Option<gltf::OpaquePair<'_>> {
        if !self.opaque_pair {
            return None;
        }
        self.two_gltf_lobes()
    }

    /// True when no component transmits ([`Component::reflects_only`]): the value and
    /// density are zero wherever ω_o and ω_i are not strictly on one side.
    #[inline]
    pub fn reflects_only(&self) -> bool {
        self.reflects_only
    }

    /// True where the value and density at (`wo`, `wi`) are surely zero from the signs of the
    /// two cosines alone: no component transmits and the directions are not strictly on one
    /// side of the surface (a zero cosine counts as another side; a NaN one does not, since
    /// the components' own side tests let NaN through). Then [`Bsdf::eval_pdf`] returns
    /// zeros, so a light connection there can be dropped before it is evaluated or traced.
    /// False says nothing: the BSDF may still be zero.
    #[inline]
    pub fn is_zero_between(&self, wo: Vec3, wi: Vec3) -> bool {
        self.reflects_only && ((wo.z <= 0.0 && wi.z >= 0.0) || (wo.z >= 0.0 && wi.z <= 0.0))
    }

    /// True when some component is not a Dirac lobe, i.e. a light can be connected explicitly.
    #[inline]
    pub fn has_non_delta(&self) -> bool {
        self.non_delta
    }

    /// True when every component is a Dirac lobe.
    #[inline]
    pub fn is_delta(&self) -> bool {
        !self.non_delta
    }
}

#[cfg(test)]
mod tests;
