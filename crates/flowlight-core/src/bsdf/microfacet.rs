//! Isotropic GGX (Trowbridge–Reitz) microfacet distribution with the Smith masking function and
//! sampling of visible normals.
//!
//! * D(ω_m) = α² / (π (sin²θ_m + α² cos²θ_m)²) = 1 / (π α² cos⁴θ_m (1 + tan²θ_m/α²)²)
//!   (Walter et al. 2007, eq. 33; pbrt-v4 §9.6.1).
//! * Λ(ω) = (√(1 + α² tan²θ) − 1) / 2, G1(ω) = 1 / (1 + Λ(ω)) (pbrt-v4 §9.6.2).
//! * G2 is the **height-correlated** Smith form G(ω_o, ω_i) = 1 / (1 + Λ(ω_o) + Λ(ω_i))
//!   (Heitz 2014, "Understanding the Masking-Shadowing Function", eq. 99).
//! * Visible normals D_ωo(ω_m) = G1(ω_o) max(0, ω_o·ω_m) D(ω_m) / |cos θ_o|, sampled exactly
//!   with Heitz 2018, "Sampling the GGX Distribution of Visible Normals" (JCGT 7(4)).
//!
//! Directions below the surface (z < 0) see the microsurface from the other side: they are
//! negated before use and the sampled normal is always in the +z hemisphere, as in pbrt-v4.

use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// Isotropic GGX distribution with roughness α (glTF: α = perceptual roughness²).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ggx {
    pub alpha: f32,
}

impl Ggx {
    #[inline]
    pub fn new(alpha: f32) -> Ggx {
        Ggx { alpha }
    }

    /// Normal distribution D(ω_m) (per unit projected area: ∫ D cos θ_m dω_m = 1).
    #[inline]
    pub fn d(&self, wm: Vec3) -> f32 {
        if wm.z <= 0.0 {
            return 0.0;
        }
        let a2 = self.alpha * self.alpha;
        // sin²θ + α² cos²θ, written so that it stays accurate for tiny α near the normal.
        let k = (wm.x * wm.x + wm.y * wm.y) + a2 * wm.z * wm.z;
        let k = k / wm.length_squared();
        if k <= 0.0 {
            return 0.0;
        }
        a2 / (PI * k * k)
    }

    /// Smith Λ(ω).
    #[inline]
    pub fn lambda(&self, w: Vec3) -> f32 {
        let cos2 = w.z * w.z;
        if cos2 == 0.0 {
            return f32::INFINITY;
        }
        let sin2 = (w.x * w.x + w.y * w.y).max(0.0);
        let a2tan2 = self.alpha * self.alpha * sin2 / cos2;
        ((1.0 + a2tan2).sqrt() - 1.0) * 0.5
    }

    /// Smith masking G1(ω) = 1 / (1 + Λ(ω)).
    #[inline]
    pub fn g1(&self, w: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(w))
    }

    /// Height-correlated masking-shadowing G2(ω_o, ω_i) = 1 / (1 + Λ(ω_o) + Λ(ω_i)).
    #[inline]
    pub fn g2(&self, wo: Vec3, wi: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(wo) + self.lambda(wi))
    }

    /// Density of visible normals D_ωo(ω_m) = G1(ω_o) max(0, ω_o'·ω_m) D(ω_m) / |cos θ_o|,
    /// where ω_o' = ω_o, negated when below the surface. This is the density (solid angle of
    /// ω_m) of [`Ggx::sample_wm`].
    #[inline]
    pub fn pdf_wm(&self, wo: Vec3, wm: Vec3) -> f32 {
        let w = if wo.z < 0.0 { -wo } else { wo };
        if w.z == 0.0 {
            return 0.0;
        }
        self.g1(w) * w.dot(wm).max(0.0) * self.d(wm) / w.z
    }

    /// D(ω_m), G2(ω_o, ω_i) and the visible-normal density [`Ggx::pdf_wm`](ω_o, ω_m) at
    /// once, for the fused `eval_pdf` of the microfacet lobes: the value needs D and G2, the
    /// density D and G1(ω_o), and G1 and G2 share Λ(ω_o), so D and Λ(ω_o) (a square root and
    /// a division each) are computed once instead of twice. Each of the three equals what
    /// [`Ggx::d`], [`Ggx::g2`] and [`Ggx::pdf_wm`] return, bit for bit: the same operations in
    /// the same order (Λ depends on squares only, so Λ(−ω_o) = Λ(ω_o) exactly).
    #[inline]
    pub fn d_g2_pdf_wm(&self, wo: Vec3, wi: Vec3, wm: Vec3) -> (f32, f32, f32) {
        self.d_g2_pdf_wm_with(self.lambda(wo), wo, wi, wm)
    }

    /// [`Ggx::d_g2_pdf_wm`] with Λ(ω_o) given (`lambda_o` = [`Ggx::lambda`]`(wo)`), for the
    /// callers that evaluate many ω_i at one ω_o; the same results, bit for bit.
    #[inline]
    pub fn d_g2_pdf_wm_with(&self, lambda_o: f32, wo: Vec3, wi: Vec3, wm: Vec3) -> (f32, f32, f32) {
        let d = self.d(wm);
        let g2 = 1.0 / (1.0 + lambda_o + self.lambda(wi));
        let w = if wo.z < 0.0 { -wo } else { wo };
        let pdf_wm = if w.z == 0.0 {
            0.0
        } else {
            1.0 / (1.0 + lambda_o) * w.dot(wm).max(0.0) * d / w.z
        };
        (d, g2, pdf_wm)
    }

    /// A reflection of upper-hemisphere `wo` through a visible normal sampled with `u`:
    /// (ω_i, the normal ω_m, ω_o·ω_m, the density of ω_i, D_vis(ω_m) / (4 ω_o·ω_m)); `None`
    /// where the normal faces away from ω_o or the reflection leaves below the surface. The
    /// sampling of every GGX reflection lobe (conductor, glTF specular and coat).
    #[inline]
    pub fn sample_reflection(&self, wo: Vec3, u: Vec2) -> Option<(Vec3, Vec3, f32, f32)> {
        let wm = self.sample_wm(wo, u);
        let c = wo.dot(wm);
        if c <= 0.0 {
            return None;
        }
        let wi = reflect(wo, wm).normalize();
        if wi.z <= 0.0 {
            return None;
        }
        Some((wi, wm, c, self.pdf_wm(wo, wm) / (4.0 * c)))
    }

    /// Samples a visible normal (always z ≥ 0) for `wo` (Heitz 2018, listing 1).
    #[inline]
    pub fn sample_wm(&self, wo: Vec3, u: Vec2) -> Vec3 {
        sample_visible_normal(self.alpha, self.alpha, wo, u)
    }
}

/// A visible normal (always z ≥ 0) of the GGX distribution with roughnesses `ax`, `ay`
/// along x and y, for `wo` (negated when below the surface), from `u` (Heitz 2018,
/// listing 1): the isotropic [`Ggx`] with `ax` = `ay` = α, and the anisotropic lobe.
#[inline]
pub fn sample_visible_normal(ax: f32, ay: f32, wo: Vec3, u: Vec2) -> Vec3 {
    let w = if wo.z < 0.0 { -wo } else { wo };
    // Section 3.2: transform the view direction to the hemisphere configuration.
    let vh = Vec3::new(ax * w.x, ay * w.y, w.z).normalize();
    // Section 4.1: orthonormal basis (with special case if cross product is zero).
    let lensq = vh.x * vh.x + vh.y * vh.y;
    let t1 = if lensq > 0.0 {
        Vec3::new(-vh.y, vh.x, 0.0) / lensq.sqrt()
    } else {
        Vec3::X
    };
    let t2 = vh.cross(t1);
    // Section 4.2: parameterisation of the projected area.
    let r = u.x.sqrt();
    let phi = 2.0 * PI * u.y;
    let (sin_phi, cos_phi) = phi.sin_cos();
    let p1 = r * cos_phi;
    let mut p2 = r * sin_phi;
    let s = 0.5 * (1.0 + vh.z);
    p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * p2;
    // Section 4.3: reprojection onto the hemisphere.
    let nh = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * vh;
    // Section 3.4: transform the normal back to the ellipsoid configuration.
    Vec3::new(ax * nh.x, ay * nh.y, nh.z.max(1e-7)).normalize()
}

/// Mirror reflection of `wo` about `n`.
#[inline]
pub fn reflect(wo: Vec3, n: Vec3) -> Vec3 {
    -wo + 2.0 * wo.dot(n) * n
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;
    use crate::sampling::uniform_sphere;

    fn dir(theta: f32, phi: f32) -> Vec3 {
        Vec3::new(
            theta.sin() * phi.cos(),
            theta.sin() * phi.sin(),
            theta.cos(),
        )
    }

    /// Stratified uniform-sphere integral of `g` with `16n` strata in cos θ and `n/4` in φ
    /// (the lobes here sit at the pole, where they vary mostly with θ).
    fn sphere_integral(n: usize, seed: u64, mut g: impl FnMut(Vec3) -> f64) -> f64 {
        let mut r = Rng::new(seed, 0);
        let mut sum = 0.0;
        let (nz, np) = (16 * n, (n / 4).max(1));
        for i in 0..nz {
            for j in 0..np {
                let u = Vec2::new(
                    (i as f32 + r.uniform()) / nz as f32,
                    (j as f32 + r.uniform()) / np as f32,
                );
                sum += g(uniform_sphere(u));
            }
        }
        sum * 4.0 * std::f64::consts::PI / (nz * np) as f64
    }

    #[test]
    fn d_is_normalised_over_projected_area() {
        for alpha in [0.05f32, 0.3, 0.8] {
            let ggx = Ggx::new(alpha);
            let n = if alpha < 0.1 { 800 } else { 400 };
            let v = sphere_integral(n, 1, |m| (ggx.d(m) * m.z.max(0.0)) as f64);
            assert!((v - 1.0).abs() < 0.01, "alpha {alpha}: ∫D cos = {v}");
        }
    }

    #[test]
    fn masking_satisfies_projected_area_constraint() {
        // ∫ G1(ωo) max(0, ωo·ωm) D(ωm) dωm = cos θo: the visible-normal pdf integrates to one.
        for alpha in [0.1f32, 0.5, 1.0] {
            let ggx = Ggx::new(alpha);
            for theta in [0.2f32, 1.0, 1.45] {
                let wo = dir(theta, 0.7);
                let v = sphere_integral(400, 2, |m| ggx.pdf_wm(wo, m) as f64);
                assert!((v - 1.0).abs() < 0.01, "alpha {alpha} θ {theta}: {v}");
                let wo_below = Vec3::new(wo.x, wo.y, -wo.z);
                let v = sphere_integral(400, 3, |m| ggx.pdf_wm(wo_below, m) as f64);
                assert!(
                    (v - 1.0).abs() < 0.01,
                    "below: alpha {alpha} θ {theta}: {v}"
                );
            }
        }
    }

    #[test]
    fn visible_normal_sampling_matches_its_pdf() {
        // Histogram of sampled normals in (cos θ_m, φ_m) bins against the integrated pdf.
        let ggx = Ggx::new(0.4);
        let wo = dir(1.1, 0.3);
        let mut r = Rng::new(4, 0);
        const NZ: usize = 8;
        const NP: usize = 8;
        let mut hist = [[0u32; NP]; NZ];
        let n = 200_000;
        for _ in 0..n {
            let m = ggx.sample_wm(wo, r.uniform2());
            assert!(m.z >= 0.0 && (m.length() - 1.0).abs() < 1e-4);
            let iz = ((m.z * NZ as f32) as usize).min(NZ - 1);
            let phi = m.y.atan2(m.x).rem_euclid(2.0 * PI);
            let ip = ((phi / (2.0 * PI) * NP as f32) as usize).min(NP - 1);
            hist[iz][ip] += 1;
        }
        // Expected mass per bin by midpoint quadrature (uniform in z and φ on the hemisphere).
        let sub = 24;
        for (iz, row) in hist.iter().enumerate() {
            for (ip, &count) in row.iter().enumerate() {
                let mut mass = 0.0f64;
                for a in 0..sub {
                    for b in 0..sub {
                        let z = (iz as f32 + (a as f32 + 0.5) / sub as f32) / NZ as f32;
                        let phi =
                            2.0 * PI * (ip as f32 + (b as f32 + 0.5) / sub as f32) / NP as f32;
                        let s = (1.0 - z * z).max(0.0).sqrt();
                        let m = Vec3::new(s * phi.cos(), s * phi.sin(), z);
                        mass += ggx.pdf_wm(wo, m) as f64;
                    }
                }
                let cell = (1.0 / NZ as f64) * (2.0 * std::f64::consts::PI / NP as f64);
                let expected = mass / (sub * sub) as f64 * cell * n as f64;
                let got = count as f64;
                let tol = 5.0 * expected.sqrt() + 0.02 * expected + 5.0;
                assert!(
                    (got - expected).abs() < tol,
                    "bin ({iz},{ip}): {got} vs {expected}"
                );
            }
        }
    }

    /// The fused D, G2 and visible-normal density are the separate functions' values, bit for
    /// bit, for ω_o on either side, random ω_i and ω_m (normalised and not), α from a near
    /// mirror to 1.
    #[test]
    fn fused_d_g2_pdf_wm_equals_the_separate_functions() {
        let mut r = Rng::new(5, 0);
        let mut nonzero = 0;
        for alpha in [0.002f32, 0.05, 0.3, 0.7, 1.0] {
            let ggx = Ggx::new(alpha);
            for k in 0..4000 {
                let wo = uniform_sphere(r.uniform2());
                let wi = uniform_sphere(r.uniform2());
                let wm = match k % 3 {
                    0 => (wo + wi).normalize(),
                    1 => uniform_sphere(r.uniform2()),
                    _ => wo + wi,
                };
                let (d, g2, p) = ggx.d_g2_pdf_wm(wo, wi, wm);
                assert_eq!(d.to_bits(), ggx.d(wm).to_bits(), "D at {wm:?}");
                assert_eq!(g2.to_bits(), ggx.g2(wo, wi).to_bits(), "G2 {wo:?} {wi:?}");
                assert_eq!(
                    p.to_bits(),
                    ggx.pdf_wm(wo, wm).to_bits(),
                    "pdf {wo:?} {wm:?}"
                );
                nonzero += (p > 0.0) as usize;
            }
        }
        assert!(nonzero > 5000, "only {nonzero} non-zero densities");
        // Grazing ω_o (Λ infinite, density 0) and the zero vector (D is NaN there: NaN
        // payloads may differ between constant-folded and computed values, so NaN = NaN).
        let ggx = Ggx::new(0.5);
        let same = |a: f32, b: f32| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
        for (wo, wi, wm) in [
            (Vec3::X, Vec3::Z, Vec3::Z),
            (Vec3::Z, Vec3::NEG_Z, Vec3::ZERO),
        ] {
            let (d, g2, p) = ggx.d_g2_pdf_wm(wo, wi, wm);
            assert!(same(d, ggx.d(wm)) && same(g2, ggx.g2(wo, wi)));
            assert!(same(p, ggx.pdf_wm(wo, wm)));
        }
    }

    #[test]
    fn g2_is_symmetric_and_bounded() {
        let ggx = Ggx::new(0.5);
        let a = dir(0.3, 0.1);
        let b = dir(1.3, 2.0);
        assert!((ggx.g2(a, b) - ggx.g2(b, a)).abs() < 1e-7);
        assert!(ggx.g2(a, b) <= ggx.g1(a).min(ggx.g1(b)) + 1e-7);
        assert!((ggx.g1(Vec3::Z) - 1.0).abs() < 1e-7);
    }
}
