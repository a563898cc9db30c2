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
mod conductor;
mod dielectric;
pub mod gltf;
mod lambert;
pub mod microfacet;
mod oren_nayar;
#[cfg(test)]
mod testutil;
pub mod volume;

pub use conductor::{fresnel_schlick, Conductor};
pub use dielectric::{fresnel_dielectric, refract, Dielectric, TransportMode};
pub use gltf::{GltfLobe, GltfLobeKind, GltfParams};
pub use lambert::Lambert;
pub use microfacet::Ggx;
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
/// Most components a [`Bsdf`] holds (glTF: coat, specular, diffuse, transmission).
pub const MAX_COMPONENTS: usize = 4;

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
        }
    }
    /// True for a Dirac lobe (smooth mirror or smooth glass).
    #[inline]
    pub fn is_delta(&self) -> bool {
        match self {
            Component::Lambert(_) | Component::OrenNayar(_) => false,
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
            Component::Gltf(c) => c.kind == GltfLobeKind::Diffuse,
            _ => false,
        }
    }

    /// True for the components that only reflect: their value and density are zero wherever
    /// ω_o and ω_i are not strictly on one side of the surface (each tests the sides before
    /// anything else). The dielectric and the glTF transmission lobes are the others.
    #[inline]
    pub fn reflects_only(&self) -> bool {
        match self {
            Component::Lambert(_) | Component::OrenNayar(_) | Component::Conductor(_) => true,
            Component::Dielectric(_) => false,
            Component::Gltf(c) => matches!(
                c.kind,
                GltfLobeKind::Coat | GltfLobeKind::Specular | GltfLobeKind::Diffuse
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
        };
        let (lobes, n) = gltf::lobes(&p);
        Bsdf::from_gltf_lobes(&lobes[..n])
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
mod tests {
    use super::testutil::*;
    use super::*;
    use crate::rng::Rng;
    use crate::sampling::{jittered_moments, ONE_MINUS_EPSILON};

    fn weights(b: &Bsdf) -> Vec<f32> {
        b.components().map(|(_, w)| w).collect()
    }

    /// The mixture with every dielectric switched to importance transport (R + T = 1), so
    /// energy bounds hold from inside too.
    fn without_radiance_scaling(mut b: Bsdf) -> Bsdf {
        b.set_transport_mode(TransportMode::Importance);
        b
    }

    fn kinds(b: &Bsdf) -> Vec<GltfLobeKind> {
        b.components()
            .map(|(c, _)| match c {
                Component::Gltf(l) => l.kind,
                c => panic!("not a glTF lobe: {c:?}"),
            })
            .collect()
    }

    #[test]
    fn from_material_builds_the_gltf_mixture() {
        use GltfLobeKind::*;
        let base = Rgb::new(0.8, 0.5, 0.2);
        // The default material: a rough dielectric, specular layer over a diffuse base.
        let b = Bsdf::from_material(&Material::default(), base);
        assert_eq!(kinds(&b), vec![Specular, Diffuse]);
        assert!((weights(&b).iter().sum::<f32>() - 1.0).abs() < 1e-6);

        let m = Material {
            metallic: 0.5,
            transmission: 0.2,
            roughness: 0.5,
            clearcoat: 0.5,
            ..Default::default()
        };
        let b = Bsdf::from_material(&m, base);
        assert_eq!(kinds(&b), vec![Coat, Specular, Diffuse, ThinTransmission]);
        assert!((weights(&b).iter().sum::<f32>() - 1.0).abs() < 1e-6);
        assert!(weights(&b).iter().all(|&w| w > 0.0));
        // The specular layer's F0 mixes the dielectric's 0.04 and the metal's base colour.
        let Component::Gltf(s) = b.component(1) else {
            unreachable!()
        };
        assert!((s.alpha - 0.25).abs() < 1e-6);
        assert!((s.f0.r - (0.5 * 0.04 + 0.5 * 0.8)).abs() < 1e-6 && (s.f90.r - 1.0).abs() < 1e-6);
        // Volumetric transmission refracts.
        let b = Bsdf::from_material(
            &Material {
                thickness: 1.0,
                ..m
            },
            base,
        );
        assert_eq!(kinds(&b), vec![Coat, Specular, Diffuse, Refraction]);
        let Component::Gltf(r) = b.component(3) else {
            unreachable!()
        };
        assert!(r.dielectric.eta == 1.5 && r.dielectric.tint == base);

        // A smooth metal is one Dirac mirror.
        let m = Material {
            metallic: 1.0,
            roughness: 0.0,
            ..Default::default()
        };
        let b = Bsdf::from_material(&m, base);
        assert_eq!(kinds(&b), vec![Specular]);
        assert!(b.is_delta() && !b.has_non_delta());
        assert_eq!(b.component(0).class(), NodeClass::Alpha);

        // Full glass: only the refracting interface (and the metal's share of reflection).
        let m = Material {
            transmission: 1.0,
            thickness: 1.0,
            roughness: 0.1,
            ..Default::default()
        };
        let b = Bsdf::from_material(&m, base);
        // (A dielectric's whole reflection belongs to the interface: no specular layer.)
        assert_eq!(kinds(&b), vec![Refraction]);
        assert!(!b.is_delta() && b.component(0).class() == NodeClass::Alpha);

        // Oren–Nayar base under a smooth layer.
        let m = Material {
            diffuse_model: DiffuseModel::OrenNayar,
            oren_nayar_sigma: 0.5,
            metallic: 0.25,
            roughness: 0.0,
            ..Default::default()
        };
        let b = Bsdf::from_material(&m, base);
        assert_eq!(kinds(&b), vec![Specular, Diffuse]);
        assert!(b.has_non_delta() && !b.is_delta());
        assert!(b.component(0).is_delta() && b.component(1).class() == NodeClass::Beta);
        assert!(b.albedo() > 0.0 && b.albedo() <= 1.0);

        // Nothing to scatter: a black base, no specular, no metal.
        let m = Material {
            specular: 0.0,
            ..Default::default()
        };
        let b = Bsdf::from_material(&m, Rgb::ZERO);
        assert_eq!(b.components().count(), 1);
        assert!(b.eval(Vec3::Z, Vec3::Z).is_black());
    }

    #[test]
    fn node_types_match_sampled_nodes() {
        let comps = [
            Component::Lambert(Lambert { albedo: Rgb::ONE }),
            Component::OrenNayar(OrenNayar::new(Rgb::ONE, 0.5)),
            Component::Conductor(Conductor {
                f0: Rgb::ONE,
                alpha: 0.3,
            }),
            Component::Conductor(Conductor {
                f0: Rgb::ONE,
                alpha: 0.0,
            }),
            Component::Dielectric(Dielectric::new(Rgb::ONE, 1.5, 0.3)),
            Component::Dielectric(Dielectric::new(Rgb::ONE, 1.5, 0.0)),
        ]
        .into_iter()
        .chain(
            [
                Material {
                    transmission: 0.5,
                    clearcoat: 1.0,
                    clearcoat_roughness: 0.3,
                    ..Default::default()
                },
                Material {
                    transmission: 0.5,
                    roughness: 0.0,
                    ..Default::default()
                },
                Material {
                    transmission: 0.5,
                    thickness: 1.0,
                    roughness: 0.4,
                    ..Default::default()
                },
            ]
            .into_iter()
            .flat_map(|m| {
                let b = Bsdf::from_material(&m, Rgb::ONE);
                b.components().map(|(c, _)| c).collect::<Vec<_>>()
            }),
        );
        let mut r = Rng::new(52, 0);
        for c in comps {
            for wo in test_directions_both_sides() {
                for _ in 0..200 {
                    if let Some(s) = c.sample_with(wo, r.uniform(), r.uniform2()) {
                        assert_eq!(c.node_type(wo, s.wi), s.node, "{c:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn component_selection_follows_weights() {
        let m = Material {
            metallic: 0.5,
            transmission: 0.2,
            ..Default::default()
        };
        let b = Bsdf::from_material(&m, Rgb::ONE);
        let mut r = Rng::new(41, 0);
        let mut counts = [0usize; MAX_COMPONENTS];
        for _ in 0..30_000 {
            counts[b.choose_component(r.uniform()).0] += 1;
        }
        assert_eq!(weights(&b).len(), 3);
        for (c, w) in counts.iter().zip(weights(&b)) {
            assert!((*c as f32 / 30_000.0 - w).abs() < 0.01);
        }
    }

    #[test]
    fn lambert_sampling_matches_eval_and_pdf() {
        let c = Component::Lambert(Lambert {
            albedo: Rgb::new(0.7, 0.2, 0.9),
        });
        for wo in test_directions_both_sides() {
            assert_eq!(check_sample_consistency(&c, wo, 2000, 42), 2000);
        }
    }

    #[test]
    fn lambert_pdf_and_energy() {
        let a = Rgb::new(0.7, 0.2, 1.0);
        let c = Component::Lambert(Lambert { albedo: a });
        for wo in [dir(0.3, 0.1), flip(dir(1.3, 2.0))] {
            let (p, num) = sphere_integrals(&c, wo, 400, 43);
            assert!((p - 1.0).abs() < 0.01, "∫pdf = {p}");
            let is = check_energy(&c, wo, 400, 100_000, 44, 0.01);
            for k in 0..3 {
                let ak = a.to_array()[k] as f64;
                assert!(
                    (num[k] - ak).abs() < 0.01 * ak,
                    "numerical {} vs {ak}",
                    num[k]
                );
                assert!((is[k] - ak).abs() < 0.01 * ak, "sampled {} vs {ak}", is[k]);
            }
        }
        check_reciprocity(&c, 45);
    }

    fn mixtures() -> Vec<Material> {
        vec![
            Material {
                metallic: 0.5,
                roughness: 0.6,
                ..Default::default()
            },
            Material {
                diffuse_model: DiffuseModel::OrenNayar,
                oren_nayar_sigma: 0.8,
                metallic: 0.3,
                transmission: 0.3,
                roughness: 0.45,
                ..Default::default()
            },
            Material {
                transmission: 0.6,
                metallic: 0.5,
                roughness: 0.7,
                ior: 1.33,
                ..Default::default()
            },
        ]
    }

    #[test]
    fn mixture_sampling_matches_eval_and_pdf() {
        for m in mixtures() {
            let b = Bsdf::from_material(&m, Rgb::new(0.9, 0.6, 0.3));
            for wo in test_directions_both_sides() {
                let ok = check_sample_consistency(&b, wo, 3000, 46);
                assert!(ok > 1500);
            }
        }
    }

    #[test]
    fn mixture_pdf_and_energy() {
        for m in mixtures() {
            let b = without_radiance_scaling(Bsdf::from_material(&m, Rgb::ONE));
            for wo in [dir(0.3, 0.2), flip(dir(0.7, 1.0)), dir(1.35, 2.0)] {
                let p = check_pdf_integral(&b, wo, 400, 100_000, 47);
                assert!(p > 0.8, "∫pdf = {p}");
                check_energy(&b, wo, 400, 100_000, 48, 0.02);
            }
        }
    }

    #[test]
    fn mixture_reflection_is_reciprocal() {
        let m = Material {
            metallic: 0.4,
            transmission: 0.3,
            roughness: 0.5,
            ..Default::default()
        };
        check_reciprocity(&Bsdf::from_material(&m, Rgb::new(0.9, 0.6, 0.3)), 49);
        let m = Material {
            diffuse_model: DiffuseModel::OrenNayar,
            oren_nayar_sigma: 1.0,
            ..mixtures()[0]
        };
        check_reciprocity(&Bsdf::from_material(&m, Rgb::new(0.9, 0.6, 0.3)), 50);
    }

    /// Every component type alone, with the parameters that switch its branches: smooth
    /// (Dirac), narrow and rough GGX, both transport modes, η = 1, and every glTF lobe kind.
    fn every_component() -> Vec<Component> {
        let tint = Rgb::new(0.9, 0.6, 0.3);
        let mut cs = vec![
            Component::Lambert(Lambert { albedo: tint }),
            Component::OrenNayar(OrenNayar::new(tint, 0.0)),
            Component::OrenNayar(OrenNayar::new(tint, 0.7)),
        ];
        for alpha in [0.0, 0.01, 0.3, 1.0] {
            cs.push(Component::Conductor(Conductor { f0: tint, alpha }));
            for (eta, mode) in [
                (1.5, TransportMode::Radiance),
                (1.33, TransportMode::Importance),
                (1.0, TransportMode::Radiance),
            ] {
                cs.push(Component::Dielectric(Dielectric {
                    mode,
                    ..Dielectric::new(tint, eta, alpha)
                }));
            }
        }
        for b in every_gltf_mixture() {
            cs.extend(b.components().map(|(c, _)| c));
        }
        cs
    }

    /// The glTF material's switches, alone and together: metal, rough and smooth layers,
    /// clearcoat (rough and Dirac), thin and volumetric transmission (rough and smooth),
    /// Oren–Nayar, KHR_materials_specular (coloured, and 0), η = 1; both transport modes.
    fn every_gltf_mixture() -> Vec<Bsdf> {
        let d = Material::default();
        // KHR_materials_specular, coloured, and an unusual η.
        let coloured = Material {
            roughness: 0.6,
            specular: 0.7,
            specular_color: Rgb::new(2.0, 1.0, 0.5),
            ior: 1.8,
            ..d
        };
        let materials = [
            d,
            Material {
                roughness: 0.5,
                ..d
            },
            Material {
                metallic: 0.5,
                roughness: 0.6,
                ..d
            },
            Material {
                metallic: 1.0,
                roughness: 0.4,
                ..d
            },
            Material {
                metallic: 1.0,
                roughness: 0.0,
                ..d
            },
            Material {
                metallic: 0.25,
                roughness: 0.0,
                diffuse_model: DiffuseModel::OrenNayar,
                oren_nayar_sigma: 0.5,
                ..d
            },
            Material {
                roughness: 0.5,
                clearcoat: 1.0,
                clearcoat_roughness: 0.3,
                ..d
            },
            Material {
                roughness: 0.4,
                clearcoat: 0.7,
                clearcoat_roughness: 0.0,
                ..d
            },
            Material {
                roughness: 0.45,
                transmission: 0.6,
                ..d
            },
            Material {
                roughness: 0.0,
                transmission: 0.5,
                clearcoat: 1.0,
                ..d
            },
            Material {
                roughness: 0.45,
                transmission: 0.7,
                thickness: 1.0,
                ior: 1.33,
                ..d
            },
            Material {
                roughness: 0.1,
                transmission: 1.0,
                thickness: 1.0,
                ..d
            },
            Material {
                roughness: 0.0,
                transmission: 0.5,
                thickness: 1.0,
                ..d
            },
            Material {
                metallic: 0.5,
                transmission: 0.2,
                roughness: 0.5,
                clearcoat: 0.5,
                clearcoat_roughness: 0.2,
                ..d
            },
            Material {
                metallic: 0.3,
                transmission: 0.4,
                thickness: 1.0,
                roughness: 0.3,
                clearcoat: 0.8,
                clearcoat_roughness: 0.5,
                diffuse_model: DiffuseModel::OrenNayar,
                oren_nayar_sigma: 0.8,
                ..d
            },
            coloured,
            Material {
                roughness: 0.3,
                ior: 1.0,
                ..d
            },
            // α = 0.0025: a narrow lobe, but not a Dirac one.
            Material {
                roughness: 0.05,
                metallic: 0.7,
                ..d
            },
            Material {
                diffuse_model: DiffuseModel::OrenNayar,
                oren_nayar_sigma: 0.5,
                ..coloured
            },
            // No dielectric layer (the Lambertian Cornell box): a lone diffuse lobe.
            Material { specular: 0.0, ..d },
        ];
        let mut out = Vec::new();
        for m in materials {
            let b = Bsdf::from_material(&m, Rgb::new(0.9, 0.6, 0.3));
            out.push(b);
            out.push(without_radiance_scaling(b));
        }
        out
    }

    /// Every mixture: the glTF ones, each component alone with weight 1, and hand-built
    /// mixtures of the standalone models (rough and Dirac).
    fn every_mixture() -> Vec<Bsdf> {
        let mut out = every_gltf_mixture();
        out.extend(every_component().into_iter().map(Bsdf::single));
        let tint = Rgb::new(0.9, 0.6, 0.3);
        for alpha in [0.0, 0.3] {
            let mut b = Bsdf::single(Component::OrenNayar(OrenNayar::new(tint, 0.4)));
            b.components[0] = Some((b.component(0), 0.3));
            b.components[1] = Some((Component::Conductor(Conductor { f0: tint, alpha }), 0.2));
            b.components[2] = Some((
                Component::Dielectric(Dielectric::new(tint, 1.5, alpha)),
                0.4,
            ));
            b.components[3] = Some((Component::Lambert(Lambert { albedo: tint }), 0.1));
            b.count = 4;
            // The summary (albedo, Dirac, pair, reflection only) of the mixture as built.
            out.push(b.summarise());
        }
        out
    }

    /// `eval_pdf` is `(eval, pdf)` bit for bit, for every component type and every mixture,
    /// at random pairs on both sides, pairs inside narrow lobes, degenerate pairs, and each
    /// model's own samples (where its value is surely non-zero).
    #[test]
    fn eval_pdf_equals_eval_and_pdf_bit_for_bit() {
        let pairs = direction_pairs(3000, 80);
        let mut r = Rng::new(81, 0);
        let mut nonzero = (0usize, 0usize);
        let mut check = |name: &str,
                         m: &dyn Fn(Vec3, Vec3) -> ((Rgb, f32), Rgb, f32),
                         pairs: &[(Vec3, Vec3)]| {
            for &(wo, wi) in pairs {
                let ((f, p), ef, ep) = m(wo, wi);
                assert!(
                    same_rgb(f, ef) && same_float(p, ep),
                    "{name} at wo {wo:?} wi {wi:?}: eval_pdf ({f:?}, {p}) vs ({ef:?}, {ep})"
                );
                nonzero.0 += !f.is_black() as usize;
                nonzero.1 += (p != 0.0) as usize;
            }
        };
        // 50 of a model's own samples at each test direction, drawn by `sample(wo, uc, u)`.
        let mut own_pairs = |sample: &dyn Fn(Vec3, f32, Vec2) -> Option<BsdfSample>| {
            let mut v = Vec::new();
            for wo in test_directions_both_sides() {
                for _ in 0..50 {
                    if let Some(s) = sample(wo, r.uniform(), r.uniform2()) {
                        v.push((wo, s.wi));
                    }
                }
            }
            v
        };
        for c in every_component() {
            let own = own_pairs(&|wo, uc, u| c.sample_with(wo, uc, u));
            let m = |wo, wi| (c.eval_pdf(wo, wi), c.eval(wo, wi), c.pdf(wo, wi));
            check(&format!("{c:?}"), &m, &pairs);
            check(&format!("{c:?} (own samples)"), &m, &own);
        }
        for b in every_mixture() {
            let own = own_pairs(&|wo, uc, u| b.sample(wo, uc, u));
            let m = |wo, wi| (b.eval_pdf(wo, wi), b.eval(wo, wi), b.pdf(wo, wi));
            check(&format!("{b:?}"), &m, &pairs);
            check(&format!("{b:?} (own samples)"), &m, &own);
        }
        // The comparisons saw real values, not only the zeros of the early exits.
        assert!(nonzero.0 > 100_000 && nonzero.1 > 100_000, "{nonzero:?}");
    }

    /// A glTF material whose only lobe is a plain diffuse base (specular factor 0, no coat,
    /// no transmission, σ = 0) is built as one Lambert component, and it gives what the glTF
    /// lobe gives, bit for bit: values, densities, samples, albedo. A specular layer, a coat,
    /// transmission or σ > 0 keep the glTF mixture.
    #[test]
    fn a_plain_gltf_diffuse_base_is_a_lambert_component_with_the_same_values() {
        let plain = GltfParams {
            base: Rgb::new(0.9, 0.6, 0.3),
            specular: 0.0,
            ..gltf_params()
        };
        let (lobes, n) = gltf::lobes(&plain);
        assert_eq!(n, 1);
        let lambert = Bsdf::from_gltf_lobes(&lobes[..n]);
        assert!(matches!(lambert.component(0), Component::Lambert(_)));
        assert_eq!(lambert.components().count(), 1);
        let glt = Bsdf::single(Component::Gltf(lobes[0].0));
        assert!(same_float(lambert.albedo(), glt.albedo()));
        for (wo, wi) in direction_pairs(3000, 91) {
            let ((f, p), (gf, gp)) = (lambert.eval_pdf(wo, wi), glt.eval_pdf(wo, wi));
            assert!(same_rgb(f, gf) && same_float(p, gp), "{wo:?} {wi:?}");
            assert!(same_rgb(lambert.eval(wo, wi), glt.eval(wo, wi)));
            assert!(same_float(lambert.pdf(wo, wi), glt.pdf(wo, wi)));
        }
        let mut r = Rng::new(92, 0);
        let mut sampled = 0;
        for wo in test_directions_both_sides() {
            for _ in 0..300 {
                let (uc, u) = (r.uniform(), r.uniform2());
                match (lambert.sample(wo, uc, u), glt.sample(wo, uc, u)) {
                    (Some(a), Some(b)) => {
                        assert_eq!(a.wi, b.wi);
                        assert!(same_rgb(a.f, b.f) && same_float(a.pdf, b.pdf));
                        assert_eq!((a.node, a.delta, a.eta), (b.node, b.delta, b.eta));
                        sampled += 1;
                    }
                    (None, None) => {}
                    (a, b) => panic!("{wo:?}: {a:?} against {b:?}"),
                }
            }
        }
        assert!(sampled > 1000, "{sampled}");
        for other in [
            GltfParams {
                specular: 0.5,
                ..plain
            },
            GltfParams {
                oren_nayar_sigma: 0.3,
                ..plain
            },
            GltfParams {
                clearcoat: 0.5,
                ..plain
            },
            GltfParams {
                transmission: 0.5,
                ..plain
            },
        ] {
            let (lobes, n) = gltf::lobes(&other);
            let b = Bsdf::from_gltf_lobes(&lobes[..n]);
            assert!(
                b.components().all(|(c, _)| matches!(c, Component::Gltf(_))),
                "{other:?}"
            );
        }
    }

    /// The summary a mixture keeps (albedo, whether a light can be connected) is the walk
    /// over its components, for every mixture (single components included), in both
    /// transport modes.
    #[test]
    fn summary_is_the_walk_over_the_components() {
        let mut deltas = 0;
        for mut b in every_mixture() {
            for mode in [TransportMode::Importance, TransportMode::Radiance] {
                b.set_transport_mode(mode);
                let albedo = b
                    .components()
                    .map(|(c, w)| c.albedo() * w)
                    .sum::<f32>()
                    .clamp(0.0, 1.0);
                let non_delta = b.components().any(|(c, _)| !c.is_delta());
                assert!(same_float(b.albedo(), albedo), "{b:?}");
                assert_eq!(b.has_non_delta(), non_delta, "{b:?}");
                assert_eq!(b.is_delta(), !non_delta, "{b:?}");
                deltas += b.is_delta() as usize;
            }
        }
        assert!(deltas > 0, "some all-Dirac mixture was checked");
    }

    /// Directions so close to the surface that wo.z · wi.z underflows to zero, and one in it.
    const GRAZING: [Vec3; 3] = [
        Vec3::new(1.0, 0.0, 1e-30),
        Vec3::new(0.0, -1.0, -1e-30),
        Vec3::new(1.0, 0.0, 0.0),
    ];

    /// The pair's first number chooses the lobe and, rescaled, samples it: a pixel's 64
    /// jittered pairs (8 × 8 strata) estimate a glossy-on-diffuse pair's albedo with about
    /// 1.7 times less variance than with a separate, randomly paired choice number (emulated by
    /// mapping the pair into the chosen lobe's interval). Fails if the lobe choice stops
    /// using the pair.
    #[test]
    fn a_mixture_keeps_the_pairs_strata_on_each_lobe() {
        let b = every_gltf_mixture()
            .into_iter()
            .filter(|b| b.opaque_pair().is_some())
            .max_by(|a, b| {
                a.components[0]
                    .unwrap()
                    .1
                    .total_cmp(&b.components[0].unwrap().1)
            })
            .unwrap();
        let (w_spec, w_diffuse) = (b.components[0].unwrap().1, b.components[1].unwrap().1);
        assert!(w_spec > 0.2, "{w_spec}");
        let wo = Vec3::new(0.6, 0.0, 0.8);
        let weight = |s: Option<BsdfSample>| {
            s.map_or(0.0, |s| (s.f.luminance() * s.wi.z.abs() / s.pdf) as f64)
        };
        let [pair, separate] = jittered_moments(&mut Rng::new(21, 4), 1000, 8, |u, r| {
            let separate = if r.uniform() < w_spec {
                Vec2::new(u.x * w_spec, u.y)
            } else {
                Vec2::new(w_spec + u.x * w_diffuse, u.y)
            };
            [
                weight(b.sample(wo, 0.5, u)),
                weight(b.sample(wo, 0.5, separate)),
            ]
        });
        assert!(
            (pair.0 / separate.0 - 1.0).abs() < 0.02,
            "{pair:?} {separate:?}"
        );
        assert!(
            pair.1 * 1.4 < separate.1,
            "mean and variance: {pair:?} (one pair) against {separate:?} (separate choice)"
        );
    }

    /// The direction numbers of draw `k` of a loop: near 1 for the first two (cos θ_i close to
    /// 0 at the hemisphere's rim), random after.
    fn rim_or_random(k: usize, r: &mut Rng) -> Vec2 {
        match k {
            0 => Vec2::new(ONE_MINUS_EPSILON, 0.3),
            1 => Vec2::new(1.0 - 1e-7, 0.7),
            _ => r.uniform2(),
        }
    }

    /// Asserts that two ways of sampling gave one sample bit for bit (direction, value,
    /// density, kind) or both refused; true where they drew one.
    fn same_sample(
        a: Option<BsdfSample>,
        b: Option<BsdfSample>,
        context: impl Fn() -> String,
    ) -> bool {
        match (a, b) {
            (Some(a), Some(b)) => {
                assert!(
                    a.wi == b.wi
                        && same_rgb(a.f, b.f)
                        && same_float(a.pdf, b.pdf)
                        && (a.node, a.delta, a.eta) == (b.node, b.delta, b.eta),
                    "{}: {a:?} vs {b:?}",
                    context()
                );
                true
            }
            (None, None) => false,
            (a, b) => panic!("{}: {a:?} vs {b:?}", context()),
        }
    }

    /// A lone Lambert component samples and evaluates without the mixture walk, and gives
    /// what the walk gives bit for bit: the walk is taken by the same Lambert beside a second, black
    /// component of weight 0 (which adds +0 to the value and the density), also at
    /// directions so close to the surface that wo.z · wi.z underflows to zero (refused by
    /// both).
    #[test]
    fn a_lone_lambert_samples_as_the_mixture_walk_does() {
        let lambert = Lambert {
            albedo: Rgb::new(0.9, 0.5, 0.2),
        };
        let lone = Bsdf::single(Component::Lambert(lambert));
        assert!(lone.lone_lambert().is_some());
        let mut components = [None; MAX_COMPONENTS];
        components[0] = Some((Component::Lambert(lambert), 1.0));
        components[1] = Some((Component::Lambert(Lambert { albedo: Rgb::ZERO }), 0.0));
        let walk = Bsdf {
            components,
            count: 2,
            albedo: 0.0,
            non_delta: false,
            opaque_pair: false,
            reflects_only: false,
        }
        .summarise();
        assert!(walk.lone_lambert().is_none());
        let mut r = Rng::new(93, 0);
        let (mut sampled, mut refused) = (0, 0);
        for wo in test_directions_both_sides().into_iter().chain(GRAZING) {
            for k in 0..300 {
                let u = rim_or_random(k, &mut r);
                let uc = r.uniform();
                let (a, b) = (lone.sample(wo, uc, u), walk.sample(wo, uc, u));
                match same_sample(a, b, || format!("lone against walk at {wo:?} {u:?}")) {
                    true => sampled += 1,
                    false => refused += 1,
                }
            }
        }
        assert!(
            sampled > 1000 && refused > 0,
            "{sampled} sampled, {refused} refused"
        );
        for (wo, wi) in direction_pairs(3000, 94) {
            let ((f, p), (wf, wp)) = (lone.eval_pdf(wo, wi), walk.eval_pdf(wo, wi));
            assert!(same_rgb(f, wf) && same_float(p, wp), "{wo:?} {wi:?}");
        }
    }

    /// A metallic-roughness material without coat or transmission (roughness > 0) is an
    /// opaque pair, sampled and evaluated without the walk, and the pair gives what the walk
    /// gives bit for bit: directions, values, densities, kinds and refusals, at random
    /// numbers, at numbers on the lobe boundary and the hemisphere's rim, and at directions
    /// so close to the surface that wo.z · wi.z underflows. A Dirac specular layer, a coat or
    /// transmission keep the walk.
    #[test]
    fn an_opaque_pair_samples_and_evaluates_as_the_walk_does() {
        // Every opaque pair among the glTF mixtures: rough and narrow, dielectric and metal,
        // coloured specular, Oren–Nayar base, both transport modes.
        let pairs: Vec<Bsdf> = every_gltf_mixture()
            .into_iter()
            .filter(|b| b.opaque_pair().is_some())
            .collect();
        assert!(pairs.len() >= 12, "{} pairs", pairs.len());
        let mut r = Rng::new(95, 0);
        let (mut sampled, mut refused, mut specular) = (0, 0, 0);
        for b in pairs {
            let spec_weight = b.components[0].unwrap().1;
            for wo in test_directions_both_sides().into_iter().chain(GRAZING) {
                for k in 0..400 {
                    let mut u = rim_or_random(k, &mut r);
                    // The lobe choice's boundary, on both sides.
                    match k {
                        2 => u.x = spec_weight,
                        3 => u.x = f32::from_bits(spec_weight.to_bits() - 1),
                        _ => {}
                    }
                    let uc = r.uniform();
                    let (a, w) = (b.sample(wo, uc, u), b.sample_by_walk(wo, uc, u));
                    specular += a.is_some_and(|a| a.node == NodeType::GlossyReflection) as usize;
                    match same_sample(a, w, || {
                        format!("pair against walk, {b:?} {wo:?} {uc} {u:?}")
                    }) {
                        true => sampled += 1,
                        false => refused += 1,
                    }
                }
            }
            for (wo, wi) in direction_pairs(3000, 96) {
                let ((f, p), (wf, wp)) = (b.eval_pdf(wo, wi), b.eval_pdf_by_walk(wo, wi));
                assert!(same_rgb(f, wf) && same_float(p, wp), "{b:?} {wo:?} {wi:?}");
            }
        }
        assert!(
            sampled > 10_000 && specular > 1000 && refused > 0,
            "{sampled} sampled ({specular} specular), {refused} refused"
        );
        let d = Material::default();
        for m in [
            Material {
                roughness: 0.0,
                ..d
            },
            Material {
                clearcoat: 0.5,
                ..d
            },
            Material {
                transmission: 0.5,
                ..d
            },
            Material { metallic: 1.0, ..d },
        ] {
            let b = Bsdf::from_material(&m, Rgb::new(0.9, 0.6, 0.3));
            assert!(b.opaque_pair().is_none(), "{m:?}");
        }
    }

    /// A BSDF at one ω_o ([`Bsdf::at`]) samples and evaluates as the BSDF itself does at
    /// that ω_o, bit for bit, for every glTF mixture (opaque pairs, whose ω_o terms it
    /// computes once, and the rest); so does one rebuilt from its terms ([`Bsdf::at_with`]),
    /// and one given terms of another kind of BSDF, which it ignores.
    #[test]
    fn a_bsdf_at_one_direction_gives_what_its_calls_give() {
        let mixtures = every_gltf_mixture();
        let pairs = mixtures
            .iter()
            .filter(|b| b.opaque_pair().is_some())
            .count();
        assert!(
            pairs >= 12 && mixtures.len() > pairs,
            "{pairs} of {}",
            mixtures.len()
        );
        let pair_terms = mixtures
            .iter()
            .find(|b| b.opaque_pair().is_some())
            .unwrap()
            .at(dir(0.4, 0.3))
            .terms();
        let mut r = Rng::new(98, 0);
        let mut sampled = 0;
        for b in &mixtures {
            for wo in test_directions_both_sides().into_iter().chain(GRAZING) {
                let at = b.at(wo);
                assert_eq!(at.terms().0.is_some(), b.opaque_pair().is_some());
                let kept = b.at_with(wo, at.terms());
                // Terms of a pair given to another kind, none given to a pair: recomputed.
                let other = b.at_with(
                    wo,
                    if at.terms().0.is_some() {
                        OutgoingTerms::default()
                    } else {
                        pair_terms
                    },
                );
                for k in 0..40 {
                    let u = rim_or_random(k, &mut r);
                    let uc = r.uniform();
                    let want = b.sample(wo, uc, u);
                    for got in [at.sample(uc, u), kept.sample(uc, u), other.sample(uc, u)] {
                        sampled +=
                            same_sample(got, want, || format!("{b:?} {wo:?} {u:?}")) as usize;
                    }
                }
            }
            for (wo, wi) in direction_pairs(500, 99) {
                let (f, p) = b.eval_pdf(wo, wi);
                let (af, ap) = b.at(wo).eval_pdf(wi);
                assert!(same_rgb(af, f) && same_float(ap, p), "{b:?} {wo:?} {wi:?}");
                assert!(same_rgb(b.at(wo).eval(wi), b.eval(wo, wi)));
                assert_eq!(b.at(wo).is_zero_between(wi), b.is_zero_between(wo, wi));
            }
        }
        assert!(sampled > 10_000, "{sampled} sampled");
    }

    /// Where `is_zero_between` says so, every mixture is zero (value, density and their
    /// one-pass form): at random pairs on both sides, pairs with a zero cosine (±0) and
    /// grazing pairs. It says so for a fair share of the pairs of the reflection-only
    /// mixtures, never for a mixture that transmits, and never with a NaN cosine.
    #[test]
    fn a_bsdf_is_zero_where_is_zero_between_says_so() {
        let mut pairs = direction_pairs(3000, 97);
        for z in [0.0, -0.0, 1e-30, -1e-30] {
            for w in [dir(0.6, 1.1), flip(dir(1.2, 2.0))] {
                pairs.push((Vec3::new(0.8, 0.6, z), w));
                pairs.push((w, Vec3::new(0.6, -0.8, z)));
            }
        }
        let nan = Vec3::new(0.0, 0.0, f32::NAN);
        let (mut reflecting, mut transmitting) = (0, 0);
        for b in every_mixture() {
            let transmits = b.components().any(|(c, _)| {
                matches!(c, Component::Dielectric(_))
                    || matches!(c, Component::Gltf(l) if matches!(
                        l.kind,
                        GltfLobeKind::ThinTransmission | GltfLobeKind::Refraction
                    ))
            });
            let mut zero = 0;
            for &(wo, wi) in &pairs {
                if !b.is_zero_between(wo, wi) {
                    continue;
                }
                zero += 1;
                let (f, p) = b.eval_pdf(wo, wi);
                assert!(
                    f.is_black() && p == 0.0 && b.eval(wo, wi).is_black() && b.pdf(wo, wi) == 0.0,
                    "{b:?} at {wo:?} {wi:?}: ({f:?}, {p})"
                );
            }
            assert!(!b.is_zero_between(nan, dir(0.6, 1.1)));
            assert!(!b.is_zero_between(dir(0.6, 1.1), nan));
            if transmits {
                assert_eq!(zero, 0, "{b:?} transmits");
                transmitting += 1;
            } else {
                assert!(zero > 1000, "{b:?}: {zero} pairs");
                reflecting += 1;
            }
        }
        assert!(
            reflecting > 10 && transmitting > 5,
            "{reflecting} {transmitting}"
        );
    }

    /// A non-Dirac sample of a mixture carries `eval` and `pdf` at its direction bit for bit,
    /// although `sample` reuses the chosen component's own value (and diffuse density).
    #[test]
    fn mixture_samples_carry_eval_and_pdf_bit_for_bit() {
        let mut r = Rng::new(82, 0);
        let mut smooth = 0;
        for b in every_mixture() {
            for wo in test_directions_both_sides() {
                for _ in 0..300 {
                    let Some(s) = b.sample(wo, r.uniform(), r.uniform2()) else {
                        continue;
                    };
                    if s.delta {
                        continue;
                    }
                    smooth += 1;
                    let (f, p) = (b.eval(wo, s.wi), b.pdf(wo, s.wi));
                    assert!(
                        same_rgb(s.f, f) && same_float(s.pdf, p),
                        "{b:?} wo {wo:?} wi {:?}: sampled ({:?}, {}) vs ({f:?}, {p})",
                        s.wi,
                        s.f,
                        s.pdf
                    );
                }
            }
        }
        assert!(smooth > 50_000, "{smooth}");
    }

    /// Mixtures with Dirac lobes: a Dirac sample's throughput is the lobe's value over its
    /// selection probability, continuous samples see only the continuous part, and the
    /// expected throughput is the material's albedo.
    #[test]
    fn mixture_with_dirac_lobes() {
        let base = Rgb::new(0.9, 0.6, 0.3);
        let mirror = Material {
            metallic: 0.5,
            roughness: 0.0,
            ..Default::default()
        };
        let glass = Material {
            transmission: 0.5,
            thickness: 1.0,
            roughness: 0.0,
            ..Default::default()
        };
        for m in [mirror, glass] {
            let b = without_radiance_scaling(Bsdf::from_material(&m, base));
            assert!(b.has_non_delta() && !b.is_delta());
            for wo in [dir(0.4, 0.5), flip(dir(1.0, 2.0))] {
                let mut r = Rng::new(51, 0);
                let n = 200_000;
                let mut sum = Rgb::ZERO;
                let mut dirac = Rgb::ZERO;
                for _ in 0..n {
                    let s = b.sample(wo, r.uniform(), r.uniform2()).unwrap();
                    let t = s.f * (s.wi.z.abs() / s.pdf);
                    sum += t;
                    if s.delta {
                        dirac += t;
                        if s.node == NodeType::SpecularReflection {
                            assert!((s.wi - Vec3::new(-wo.x, -wo.y, wo.z)).length() < 1e-5);
                        } else {
                            assert_eq!(s.node, NodeType::SpecularTransmission);
                        }
                    } else {
                        assert_eq!(s.node, NodeType::DiffuseReflection);
                    }
                }
                // The Dirac part: the specular layer's Schlick reflectance, plus for glass the
                // interface's reflection and tinted refraction with their weight.
                let layer = b
                    .components()
                    .find(|(c, _)| matches!(c, Component::Gltf(l) if l.kind == GltfLobeKind::Specular))
                    .map(|(c, _)| match c {
                        Component::Gltf(l) => gltf::schlick_f0_f90(l.f0, l.f90, wo.z),
                        _ => unreachable!(),
                    })
                    .unwrap();
                let expected_dirac = if m.metallic > 0.0 {
                    layer
                } else {
                    let fr = fresnel_dielectric(wo.z, 1.5);
                    layer + (Rgb::splat(fr) + base * (1.0 - fr)) * 0.5
                };
                let mean = dirac / n as f32;
                for (x, y) in mean.to_array().into_iter().zip(expected_dirac.to_array()) {
                    assert!(
                        (x - y).abs() < 0.01,
                        "Dirac throughput {mean:?} vs {expected_dirac:?}"
                    );
                }
                // The diffuse base integrates to ρ(1 − m)(1 − t)(1 − E_d(μ_o)).
                let e_d = gltf::GltfShared {
                    coat: 0.0,
                    coat_alpha: 0.0,
                    alpha: 0.0,
                    diel_f0: 0.04,
                    diel_f90: 1.0,
                    diffuse_norm: 0.0,
                }
                .dielectric_albedo(wo.z);
                let expected = expected_dirac + base * (0.5 * (1.0 - e_d));
                let mean = sum / n as f32;
                for (x, y) in mean.to_array().into_iter().zip(expected.to_array()) {
                    assert!(
                        (x - y).abs() < 0.01,
                        "mean throughput {mean:?} vs {expected:?}"
                    );
                }
            }
        }
    }
}
