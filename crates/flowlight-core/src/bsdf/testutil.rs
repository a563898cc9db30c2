//! Shared checks for the BSDF tests: sample/eval consistency, stratified numerical integration
//! over the sphere, importance-sampled albedo and reciprocity.

use super::{Bsdf, BsdfSample, Component, GltfParams};
use crate::rng::Rng;
use crate::sampling::uniform_sphere;
use crate::Rgb;
use glam::{Vec2, Vec3};

/// A white glTF dielectric of roughness 0.5 and ior 1.5 with a full specular layer, nothing
/// else: the base the glTF tests vary.
pub fn gltf_params() -> GltfParams {
    GltfParams {
        base: Rgb::ONE,
        metallic: 0.0,
        roughness: 0.5,
        ior: 1.5,
        specular: 1.0,
        specular_color: Rgb::ONE,
        transmission: 0.0,
        volumetric: false,
        clearcoat: 0.0,
        clearcoat_roughness: 0.0,
        oren_nayar_sigma: 0.0,
        layers: crate::material_layers::MaterialLayers::default(),
    }
}

/// What the checks need from a component or a whole mixture.
pub trait Model {
    fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb;
    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32;
    fn sample(&self, wo: Vec3, uc: f32, u: Vec2) -> Option<BsdfSample>;
}

impl Model for Component {
    fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        Component::eval(self, wo, wi)
    }
    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        Component::pdf(self, wo, wi)
    }
    fn sample(&self, wo: Vec3, uc: f32, u: Vec2) -> Option<BsdfSample> {
        self.sample_with(wo, uc, u)
    }
}

impl Model for Bsdf {
    fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        Bsdf::eval(self, wo, wi)
    }
    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        Bsdf::pdf(self, wo, wi)
    }
    fn sample(&self, wo: Vec3, uc: f32, u: Vec2) -> Option<BsdfSample> {
        Bsdf::sample(self, wo, uc, u)
    }
}

/// Direction from spherical angles.
pub fn dir(theta: f32, phi: f32) -> Vec3 {
    Vec3::new(
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    )
}

/// The same direction seen from the other side of the surface.
pub fn flip(w: Vec3) -> Vec3 {
    Vec3::new(w.x, w.y, -w.z)
}

/// Outgoing directions from near-normal to grazing, above and below the surface.
pub fn test_directions_both_sides() -> Vec<Vec3> {
    let up = [dir(0.05, 0.3), dir(0.6, 1.1), dir(1.2, 2.0), dir(1.5, 4.0)];
    up.iter()
        .copied()
        .chain(up.iter().map(|&w| flip(w)))
        .collect()
}

/// `a` and `b` are the same float: equal bits, or both NaN (a NaN's payload may depend on
/// whether the compiler folded it).
pub fn same_float(a: f32, b: f32) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

/// [`same_float`] per channel.
pub fn same_rgb(a: Rgb, b: Rgb) -> bool {
    a.to_array()
        .into_iter()
        .zip(b.to_array())
        .all(|(x, y)| same_float(x, y))
}

/// `n` direction pairs (ω_o, ω_i) on both sides of the surface, for comparing two ways of
/// computing one function of the pair: a third uniform on the sphere (either side, ω_i on
/// ω_o's side or not at random), a third near ω_o's mirror direction (inside narrow glossy
/// lobes) on either side, a third near its straight continuation through the surface
/// (inside narrow transmission lobes); and the degenerate pairs: ω_i = ±ω_o, the exact
/// mirror, grazing directions, the normal.
pub fn direction_pairs(n: usize, seed: u64) -> Vec<(Vec3, Vec3)> {
    let mut r = Rng::new(seed, 6);
    let mut pairs = Vec::with_capacity(n + 16);
    for k in 0..n {
        let wo = uniform_sphere(r.uniform2());
        let jitter = uniform_sphere(r.uniform2()) * (0.2 * r.uniform() * r.uniform());
        let wi = match k % 3 {
            0 => uniform_sphere(r.uniform2()),
            1 => {
                let m = Vec3::new(-wo.x, -wo.y, wo.z) + jitter;
                let m = m.normalize_or(Vec3::Z);
                if r.uniform() < 0.1 {
                    flip(m)
                } else {
                    m
                }
            }
            _ => (-wo + jitter).normalize_or(Vec3::Z),
        };
        pairs.push((wo, wi));
    }
    let a = dir(0.7, 0.4);
    let grazing = Vec3::new(1.0, 0.0, 0.0);
    for (wo, wi) in [
        (a, a),
        (a, -a),
        (a, Vec3::new(-a.x, -a.y, a.z)),
        (flip(a), flip(a)),
        (flip(a), a),
        (grazing, a),
        (a, grazing),
        (grazing, -grazing),
        (grazing, grazing),
        (Vec3::Z, Vec3::Z),
        (Vec3::Z, Vec3::NEG_Z),
        (Vec3::NEG_Z, Vec3::NEG_Z),
    ] {
        pairs.push((wo, wi));
    }
    pairs
}

fn rel_close(a: f32, b: f32, rel: f32) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()) + 1e-6
}

/// For `n` samples from `wo`: every non-Dirac sample's `pdf` and `f` equal `pdf(wo, wi)` and
/// `eval(wo, wi)` (relative 1e-3); Dirac samples have zero eval/pdf. Returns how many samples
/// succeeded.
pub fn check_sample_consistency<M: Model>(m: &M, wo: Vec3, n: usize, seed: u64) -> usize {
    let mut r = Rng::new(seed, 1);
    let mut ok = 0;
    for _ in 0..n {
        let uc = r.uniform();
        let Some(s) = m.sample(wo, uc, r.uniform2()) else {
            continue;
        };
        ok += 1;
        assert!(
            (s.wi.length() - 1.0).abs() < 1e-3,
            "wi not normalised: {:?}",
            s.wi
        );
        assert!(
            s.pdf > 0.0 && s.pdf.is_finite(),
            "bad pdf {} for wo {wo:?}",
            s.pdf
        );
        assert!(s.f.is_valid_radiance(), "bad f {:?}", s.f);
        if s.delta {
            continue;
        }
        let pdf = m.pdf(wo, s.wi);
        let f = m.eval(wo, s.wi);
        assert!(
            rel_close(s.pdf, pdf, 1e-3),
            "pdf mismatch for wo {wo:?} wi {:?} ({:?}): sampled {} vs eval {}",
            s.wi,
            s.node,
            s.pdf,
            pdf
        );
        for (a, b) in s.f.to_array().into_iter().zip(f.to_array()) {
            assert!(
                rel_close(a, b, 1e-3),
                "f mismatch for wo {wo:?} wi {:?} ({:?}): sampled {:?} vs eval {:?}",
                s.wi,
                s.node,
                s.f,
                f
            );
        }
    }
    ok
}

/// Stratified uniform-sphere integration with `n × n` strata of ∫ pdf dω and ∫ f |cos θ_i| dω.
pub fn sphere_integrals<M: Model>(m: &M, wo: Vec3, n: usize, seed: u64) -> (f64, [f64; 3]) {
    let mut r = Rng::new(seed, 2);
    let mut p = 0.0f64;
    let mut e = [0.0f64; 3];
    for i in 0..n {
        for j in 0..n {
            let u = Vec2::new(
                (i as f32 + r.uniform()) / n as f32,
                (j as f32 + r.uniform()) / n as f32,
            );
            let wi = uniform_sphere(u);
            p += m.pdf(wo, wi) as f64;
            let f = m.eval(wo, wi) * wi.z.abs();
            for (acc, v) in e.iter_mut().zip(f.to_array()) {
                *acc += v as f64;
            }
        }
    }
    let scale = 4.0 * std::f64::consts::PI / (n * n) as f64;
    (p * scale, e.map(|v| v * scale))
}

/// ∫ pdf dω over the sphere (stratified, `n × n`) equals the probability that sampling
/// succeeds (estimated from `n_is` samples), and is at most one. Returns the integral.
pub fn check_pdf_integral<M: Model>(m: &M, wo: Vec3, n: usize, n_is: usize, seed: u64) -> f64 {
    let (p, _) = sphere_integrals(m, wo, n, seed);
    let mut r = Rng::new(seed, 5);
    let mut ok = 0usize;
    for _ in 0..n_is {
        let uc = r.uniform();
        if m.sample(wo, uc, r.uniform2()).is_some_and(|s| !s.delta) {
            ok += 1;
        }
    }
    let q = ok as f64 / n_is as f64;
    let se = (q * (1.0 - q) / n_is as f64).sqrt();
    assert!(p <= 1.01, "wo {wo:?}: ∫pdf = {p} > 1");
    assert!(
        (p - q).abs() < 0.01 + 4.0 * se,
        "wo {wo:?}: ∫pdf = {p} but sampling succeeds with {q}"
    );
    p
}

/// Importance-sampled estimate of ∫ f |cos θ_i| dω (failed samples count as zero) and its
/// standard error, per channel.
pub fn sampled_albedo<M: Model>(m: &M, wo: Vec3, n: usize, seed: u64) -> ([f64; 3], [f64; 3]) {
    let mut r = Rng::new(seed, 3);
    let mut sum = [0.0f64; 3];
    let mut sum2 = [0.0f64; 3];
    for _ in 0..n {
        let uc = r.uniform();
        let Some(s) = m.sample(wo, uc, r.uniform2()) else {
            continue;
        };
        let w = s.f * (s.wi.z.abs() / s.pdf);
        for (k, v) in w.to_array().into_iter().enumerate() {
            sum[k] += v as f64;
            sum2[k] += (v as f64) * (v as f64);
        }
    }
    let nf = n as f64;
    let mean = sum.map(|s| s / nf);
    let se = std::array::from_fn(|k| ((sum2[k] / nf - mean[k] * mean[k]).max(0.0) / nf).sqrt());
    (mean, se)
}

/// ∫ f |cos θ_i| dω by importance sampling (`n_is` samples) agrees with stratified uniform
/// integration (`n_grid²` strata) within `tol` (absolute, plus 4 standard errors), and neither
/// exceeds one (the model must have albedo-1 inputs). Returns the sampled estimate.
pub fn check_energy<M: Model>(
    m: &M,
    wo: Vec3,
    n_grid: usize,
    n_is: usize,
    seed: u64,
    tol: f64,
) -> [f64; 3] {
    let (_, num) = sphere_integrals(m, wo, n_grid, seed);
    let (is, se) = sampled_albedo(m, wo, n_is, seed + 1);
    for k in 0..3 {
        assert!(
            (is[k] - num[k]).abs() < tol + 4.0 * se[k],
            "wo {wo:?} channel {k}: importance sampled {} ± {} vs numerical {}",
            is[k],
            se[k],
            num[k]
        );
        assert!(
            is[k] <= 1.0 + 0.01 + 4.0 * se[k],
            "energy gain (sampled) {} at wo {wo:?}",
            is[k]
        );
        assert!(
            num[k] <= 1.0 + 0.01,
            "energy gain (numerical) {} at wo {wo:?}",
            num[k]
        );
    }
    is
}

/// f(wo, wi) = f(wi, wo) for random pairs on the same side (both sides tried).
pub fn check_reciprocity<M: Model>(m: &M, seed: u64) {
    let mut r = Rng::new(seed, 4);
    let mut nonzero = 0;
    for k in 0..2000 {
        let mut a = uniform_sphere(r.uniform2());
        let mut b = uniform_sphere(r.uniform2());
        a.z = a.z.abs();
        b.z = b.z.abs();
        if k % 2 == 1 {
            a.z = -a.z;
            b.z = -b.z;
        }
        let fab = m.eval(a, b);
        let fba = m.eval(b, a);
        for (x, y) in fab.to_array().into_iter().zip(fba.to_array()) {
            assert!(
                rel_close(x, y, 1e-3),
                "f({a:?}, {b:?}) = {fab:?} but f(wi, wo) = {fba:?}"
            );
        }
        if !fab.is_black() {
            nonzero += 1;
        }
    }
    assert!(
        nonzero > 100,
        "reciprocity test saw only {nonzero} non-zero values"
    );
}
