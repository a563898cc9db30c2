//! BSDFs in the local shading frame: `z` is the shading normal and both `wo` (towards the
//! previous vertex) and `wi` (towards the next) point away from the surface. `eval` returns the
//! BSDF value f without the cosine; integrators multiply by |cos θ_i| themselves.
//!
//! A material is a weighted mixture of at most three components (diffuse, GGX conductor,
//! dielectric). Samplers first choose a component (the strong node type, thesis §3.6), then
//! sample it; the full-mixture `eval`/`pdf` serve multiple importance sampling.

mod lambert;

pub use lambert::Lambert;

use crate::material::{DiffuseModel, Material};
use crate::path::{NodeClass, NodeType};
use crate::Rgb;
use glam::{Vec2, Vec3};

/// GGX α below which a lobe is treated as a Dirac (perfect mirror or smooth glass).
pub const DELTA_ALPHA: f32 = 1e-3;
/// GGX α below which a glossy lobe counts as narrow (Λα): no explicit light connection.
pub const NARROW_GLOSSY_ALPHA: f32 = 0.05;

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
}

/// One component of a mixture.
#[derive(Clone, Copy, Debug)]
pub enum Component {
    Lambert(Lambert),
}

impl Component {
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        match self {
            Component::Lambert(c) => c.eval(wo, wi),
        }
    }
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        match self {
            Component::Lambert(c) => c.pdf(wo, wi),
        }
    }
    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        match self {
            Component::Lambert(c) => c.sample(wo, u),
        }
    }
    /// Directional albedo estimate in [0, 1] used by BxDF-based termination.
    #[inline]
    pub fn albedo(&self) -> f32 {
        match self {
            Component::Lambert(c) => c.albedo.max_component(),
        }
    }
    #[inline]
    pub fn is_delta(&self) -> bool {
        false
    }
    #[inline]
    pub fn class(&self) -> NodeClass {
        NodeClass::Beta
    }
}

/// A material's BSDF: a weighted mixture of components. Weights sum to one.
#[derive(Clone, Copy, Debug)]
pub struct Bsdf {
    components: [Option<(Component, f32)>; 3],
    count: usize,
}

impl Bsdf {
    /// The glTF mixture: dielectric with weight `transmission`, GGX conductor with
    /// `(1 − transmission)·metallic`, diffuse with the rest. `base` is the textured base colour.
    pub fn from_material(m: &Material, base: Rgb) -> Bsdf {
        let _ = DiffuseModel::Lambert;
        Bsdf::single(Component::Lambert(Lambert { albedo: base }))
    }

    pub fn single(c: Component) -> Bsdf {
        Bsdf { components: [Some((c, 1.0)), None, None], count: 1 }
    }

    pub fn components(&self) -> impl Iterator<Item = (Component, f32)> + '_ {
        self.components[..self.count].iter().flatten().copied()
    }

    pub fn component(&self, i: usize) -> Component {
        self.components[i].expect("component index in range").0
    }

    /// Chooses a component with probability equal to its weight: (index, probability).
    #[inline]
    pub fn choose_component(&self, u: f32) -> (usize, f32) {
        let mut acc = 0.0;
        for i in 0..self.count {
            let (_, w) = self.components[i].unwrap();
            acc += w;
            if u < acc || i + 1 == self.count {
                return (i, w);
            }
        }
        (0, 1.0)
    }

    /// Mixture BSDF value Σ wᵢ fᵢ (Dirac lobes contribute nothing).
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        self.components().fold(Rgb::ZERO, |acc, (c, w)| acc + c.eval(wo, wi) * w)
    }

    /// Mixture density Σ wᵢ pᵢ (Dirac lobes contribute nothing).
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.components().map(|(c, w)| c.pdf(wo, wi) * w).sum()
    }

    /// Samples the whole mixture: chooses a component by `u_component`, samples it with `u`,
    /// and for a non-Dirac lobe returns the mixture's f and pdf (so MIS sees the true density).
    pub fn sample(&self, wo: Vec3, u_component: f32, u: Vec2) -> Option<BsdfSample> {
        let (i, p) = self.choose_component(u_component);
        let mut s = self.component(i).sample(wo, u)?;
        if s.delta {
            s.f = s.f * self.components[i].unwrap().1;
            s.pdf *= p;
        } else {
            s.f = self.eval(wo, s.wi);
            s.pdf = self.pdf(wo, s.wi);
        }
        (s.pdf > 0.0).then_some(s)
    }

    /// Weighted albedo estimate in [0, 1] for BxDF-based termination.
    pub fn albedo(&self) -> f32 {
        self.components().map(|(c, w)| c.albedo() * w).sum::<f32>().clamp(0.0, 1.0)
    }

    /// True when some component is not a Dirac lobe, i.e. a light can be connected explicitly.
    pub fn has_non_delta(&self) -> bool {
        self.components().any(|(c, _)| !c.is_delta())
    }

    /// True when every component is a Dirac lobe.
    pub fn is_delta(&self) -> bool {
        !self.has_non_delta()
    }
}
