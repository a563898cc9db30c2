//! BSDFs in the local shading frame: `z` is the shading normal and both `wo` (towards the
//! previous vertex) and `wi` (towards the next) point away from the surface. `eval` returns the
//! BSDF value f without the cosine; integrators multiply by |cos θ_i| themselves.
//!
//! A material is a weighted mixture of at most three components (diffuse, GGX conductor,
//! dielectric). Samplers first choose a component (the strong node type, thesis §3.6), then
//! sample it; the full-mixture `eval`/`pdf` serve multiple importance sampling.
//!
//! Models: [`Lambert`], [`OrenNayar`] (rough diffuse), [`Conductor`] (GGX + Schlick, glTF
//! metal), [`Dielectric`] (smooth or rough GGX glass, Walter et al. 2007); the GGX distribution
//! itself lives in [`microfacet`].

mod conductor;
mod dielectric;
mod lambert;
pub mod microfacet;
mod oren_nayar;
#[cfg(test)]
mod testutil;

pub use conductor::{fresnel_schlick, Conductor};
pub use dielectric::{fresnel_dielectric, refract, Dielectric, TransportMode};
pub use lambert::Lambert;
pub use microfacet::Ggx;
pub use oren_nayar::OrenNayar;

use crate::material::{DiffuseModel, Material};
use crate::path::{NodeClass, NodeType};
use crate::Rgb;
use glam::{Vec2, Vec3};

/// GGX α below which a lobe is treated as a Dirac (perfect mirror or smooth glass).
pub const DELTA_ALPHA: f32 = 1e-3;
/// GGX α below which a glossy lobe counts as narrow (Λα): no explicit light connection.
pub const NARROW_GLOSSY_ALPHA: f32 = 0.05;
/// Largest f32 below one.
const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

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
    OrenNayar(OrenNayar),
    Conductor(Conductor),
    Dielectric(Dielectric),
}

impl Component {
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        match self {
            Component::Lambert(c) => c.eval(wo, wi),
            Component::OrenNayar(c) => c.eval(wo, wi),
            Component::Conductor(c) => c.eval(wo, wi),
            Component::Dielectric(c) => c.eval(wo, wi),
        }
    }
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        match self {
            Component::Lambert(c) => c.pdf(wo, wi),
            Component::OrenNayar(c) => c.pdf(wo, wi),
            Component::Conductor(c) => c.pdf(wo, wi),
            Component::Dielectric(c) => c.pdf(wo, wi),
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
        }
    }
    /// Samples with an extra uniform `uc` for the discrete reflect/refract choice (only the
    /// dielectric uses it).
    #[inline]
    pub fn sample_with(&self, wo: Vec3, uc: f32, u: Vec2) -> Option<BsdfSample> {
        match self {
            Component::Dielectric(c) => c.sample_with(wo, uc, u),
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
        }
    }
    /// True for a Dirac lobe (smooth mirror or smooth glass).
    #[inline]
    pub fn is_delta(&self) -> bool {
        match self {
            Component::Lambert(_) | Component::OrenNayar(_) => false,
            Component::Conductor(c) => c.is_delta(),
            Component::Dielectric(c) => c.is_delta(),
        }
    }
    /// Scattering mode of the pair (`wo`, `wi`) through this component, e.g. for an explicit
    /// light connection: diffuse for Lambert/Oren–Nayar, glossy or specular reflection or
    /// transmission for the conductor and dielectric.
    #[inline]
    pub fn node_type(&self, wo: Vec3, wi: Vec3) -> NodeType {
        let reflect = wo.z * wi.z > 0.0;
        match (self, self.is_delta(), reflect) {
            (Component::Lambert(_) | Component::OrenNayar(_), _, true) => {
                NodeType::DiffuseReflection
            }
            (Component::Lambert(_) | Component::OrenNayar(_), _, false) => {
                NodeType::DiffuseTransmission
            }
            (_, true, true) => NodeType::SpecularReflection,
            (_, true, false) => NodeType::SpecularTransmission,
            (_, false, true) => NodeType::GlossyReflection,
            (_, false, false) => NodeType::GlossyTransmission,
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
        };
        if self.is_delta() || alpha < narrow_alpha {
            NodeClass::Alpha
        } else {
            NodeClass::Beta
        }
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
    /// Components are stored in the order diffuse, conductor, dielectric; those with zero
    /// weight are dropped. α = roughness²; the conductor's F0, the diffuse albedo and the
    /// dielectric's transmission tint are all `base`.
    pub fn from_material(m: &Material, base: Rgb) -> Bsdf {
        let unit = |x: f32| {
            if x.is_finite() {
                x.clamp(0.0, 1.0)
            } else {
                0.0
            }
        };
        let transmission = unit(m.transmission);
        let metallic = unit(m.metallic);
        let roughness = unit(m.roughness);
        let alpha = roughness * roughness;
        let w_dielectric = transmission;
        let w_conductor = (1.0 - transmission) * metallic;
        let w_diffuse = (1.0 - transmission) * (1.0 - metallic);
        let diffuse = match m.diffuse_model {
            DiffuseModel::Lambert => Component::Lambert(Lambert { albedo: base }),
            DiffuseModel::OrenNayar => {
                Component::OrenNayar(OrenNayar::new(base, m.oren_nayar_sigma.max(0.0)))
            }
        };
        let candidates = [
            (diffuse, w_diffuse),
            (
                Component::Conductor(Conductor { f0: base, alpha }),
                w_conductor,
            ),
            (
                Component::Dielectric(Dielectric::new(base, m.ior, alpha)),
                w_dielectric,
            ),
        ];
        let mut bsdf = Bsdf {
            components: [None; 3],
            count: 0,
        };
        let total: f32 = candidates
            .iter()
            .map(|&(_, w)| w)
            .filter(|&w| w > 0.0)
            .sum();
        for (c, w) in candidates {
            if w > 0.0 {
                bsdf.components[bsdf.count] = Some((c, w / total));
                bsdf.count += 1;
            }
        }
        bsdf
    }

    pub fn single(c: Component) -> Bsdf {
        Bsdf {
            components: [Some((c, 1.0)), None, None],
            count: 1,
        }
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
        self.components()
            .fold(Rgb::ZERO, |acc, (c, w)| acc + c.eval(wo, wi) * w)
    }

    /// Mixture density Σ wᵢ pᵢ (Dirac lobes contribute nothing).
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.components().map(|(c, w)| c.pdf(wo, wi) * w).sum()
    }

    /// Samples the whole mixture: chooses a component by `u_component`, samples it with `u`,
    /// and for a non-Dirac lobe returns the mixture's f and pdf (so MIS sees the true density).
    ///
    /// For a Dirac lobe i chosen with probability pᵢ = wᵢ, `f = wᵢ fᵢ` and `pdf = pᵢ · P_i`
    /// (P_i the lobe's own discrete probability), so the throughput f|cos|/pdf is the lobe's own
    /// throughput: the weight cancels against the selection probability. The remainder of
    /// `u_component` within the chosen component's interval is rescaled to [0, 1) and passed on
    /// as the component's discrete sample (the dielectric's reflect/refract choice).
    pub fn sample(&self, wo: Vec3, u_component: f32, u: Vec2) -> Option<BsdfSample> {
        let (i, p) = self.choose_component(u_component);
        let lo: f32 = self.components[..i].iter().flatten().map(|&(_, w)| w).sum();
        let uc = if p > 0.0 {
            ((u_component - lo) / p).clamp(0.0, ONE_MINUS_EPSILON)
        } else {
            0.0
        };
        let (c, w) = self.components[i]?;
        let mut s = c.sample_with(wo, uc, u)?;
        if s.delta {
            s.f *= w;
            s.pdf *= p;
        } else {
            s.f = self.eval(wo, s.wi);
            s.pdf = self.pdf(wo, s.wi);
        }
        (s.pdf > 0.0).then_some(s)
    }

    /// Weighted albedo estimate in [0, 1] for BxDF-based termination.
    pub fn albedo(&self) -> f32 {
        self.components()
            .map(|(c, w)| c.albedo() * w)
            .sum::<f32>()
            .clamp(0.0, 1.0)
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

#[cfg(test)]
mod tests {
    use super::testutil::*;
    use super::*;
    use crate::rng::Rng;

    fn weights(b: &Bsdf) -> Vec<f32> {
        b.components().map(|(_, w)| w).collect()
    }

    /// The mixture with every dielectric switched to importance transport (R + T = 1), so
    /// energy bounds hold from inside too.
    fn without_radiance_scaling(mut b: Bsdf) -> Bsdf {
        for (c, _) in b.components.iter_mut().flatten() {
            if let Component::Dielectric(d) = c {
                d.mode = TransportMode::Importance;
            }
        }
        b
    }

    #[test]
    fn from_material_builds_the_gltf_mixture() {
        let base = Rgb::new(0.8, 0.5, 0.2);
        let b = Bsdf::from_material(&Material::default(), base);
        assert_eq!(weights(&b), vec![1.0]);
        assert!(matches!(b.component(0), Component::Lambert(l) if l.albedo == base));

        let m = Material {
            metallic: 0.5,
            transmission: 0.2,
            roughness: 0.5,
            ..Default::default()
        };
        let b = Bsdf::from_material(&m, base);
        let w = weights(&b);
        assert_eq!(w.len(), 3);
        assert!(
            (w[0] - 0.4).abs() < 1e-6 && (w[1] - 0.4).abs() < 1e-6 && (w[2] - 0.2).abs() < 1e-6
        );
        assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        assert!(
            matches!(b.component(1), Component::Conductor(c) if (c.alpha - 0.25).abs() < 1e-6 && c.f0 == base)
        );
        assert!(
            matches!(b.component(2), Component::Dielectric(d) if d.eta == 1.5 && d.tint == base)
        );

        let m = Material {
            metallic: 1.0,
            roughness: 0.0,
            ..Default::default()
        };
        let b = Bsdf::from_material(&m, base);
        assert_eq!(weights(&b), vec![1.0]);
        assert!(b.is_delta() && !b.has_non_delta());
        assert_eq!(b.component(0).class(), NodeClass::Alpha);

        let m = Material {
            transmission: 1.0,
            metallic: 0.7,
            roughness: 0.1,
            ..Default::default()
        };
        let b = Bsdf::from_material(&m, base);
        assert_eq!(weights(&b), vec![1.0]);
        assert!(matches!(b.component(0), Component::Dielectric(_)));
        assert!(!b.is_delta() && b.component(0).class() == NodeClass::Alpha);

        let m = Material {
            diffuse_model: DiffuseModel::OrenNayar,
            oren_nayar_sigma: 0.5,
            metallic: 0.25,
            roughness: 0.0,
            ..Default::default()
        };
        let b = Bsdf::from_material(&m, base);
        assert!(matches!(b.component(0), Component::OrenNayar(_)));
        assert!(b.has_non_delta() && !b.is_delta());
        assert_eq!(b.component(0).class(), NodeClass::Beta);
        assert!(b.component(1).is_delta());
        assert!((b.albedo() - (0.75 * 0.8 + 0.25 * 0.8)).abs() < 1e-6);
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
        ];
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
        let mut counts = [0usize; 3];
        for _ in 0..30_000 {
            counts[b.choose_component(r.uniform()).0] += 1;
        }
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

    /// Mixtures with Dirac lobes: a Dirac sample's throughput is the lobe's own (weight and
    /// selection probability cancel), continuous samples see only the continuous part, and the
    /// expected throughput is Σ wᵢ (albedo of lobe i).
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
            roughness: 0.0,
            ..Default::default()
        };
        for m in [mirror, glass] {
            let b = without_radiance_scaling(Bsdf::from_material(&m, base));
            assert!(b.has_non_delta() && !b.is_delta());
            for wo in [dir(0.4, 0.5), flip(dir(1.0, 2.0))] {
                let mut r = Rng::new(51, 0);
                let n = 100_000;
                let mut sum = Rgb::ZERO;
                let mut n_delta = 0;
                for _ in 0..n {
                    let s = b.sample(wo, r.uniform(), r.uniform2()).unwrap();
                    let t = s.f * (s.wi.z.abs() / s.pdf);
                    sum += t;
                    if s.delta {
                        n_delta += 1;
                        let dirac = b.component(b.count - 1);
                        assert!(dirac.is_delta() && dirac.eval(wo, s.wi).is_black());
                        let expected = if m.metallic > 0.0 {
                            assert_eq!(s.node, NodeType::SpecularReflection);
                            assert!((s.wi - Vec3::new(-wo.x, -wo.y, wo.z)).length() < 1e-5);
                            fresnel_schlick(base, wo.z)
                        } else if s.node == NodeType::SpecularReflection {
                            Rgb::ONE
                        } else {
                            assert_eq!(s.node, NodeType::SpecularTransmission);
                            base
                        };
                        for (x, y) in t.to_array().into_iter().zip(expected.to_array()) {
                            assert!(
                                (x - y).abs() < 1e-4,
                                "Dirac throughput {t:?} vs {expected:?}"
                            );
                        }
                    } else {
                        assert_eq!(s.node, NodeType::DiffuseReflection);
                        for (x, y) in t.to_array().into_iter().zip(base.to_array()) {
                            assert!((x - y).abs() < 1e-4, "diffuse throughput {t:?} vs {base:?}");
                        }
                    }
                }
                assert!((n_delta as f32 / n as f32 - 0.5).abs() < 0.01);
                // E[throughput] = ½ base + ½ (Dirac lobe's albedo).
                let dirac = if m.metallic > 0.0 {
                    fresnel_schlick(base, wo.z)
                } else {
                    let fr = fresnel_dielectric(wo.z, 1.5);
                    Rgb::splat(fr) + base * (1.0 - fr)
                };
                let expected = (base + dirac) * 0.5;
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
