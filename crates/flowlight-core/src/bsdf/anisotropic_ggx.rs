//! Anisotropic GGX (Trowbridge–Reitz) with roughness α_x along the local x axis and α_y
//! along y, the Smith masking function and visible-normal sampling: the isotropic
//! [`super::microfacet::Ggx`] with the ellipsoid stretched per axis (Heitz 2014,
//! "Understanding the Masking-Shadowing Function", §5.4; Heitz 2018, JCGT 7(4)).
//!
//! * D(ω_m) = 1 / (π α_x α_y cos⁴θ_m (1 + tan²θ_m (cos²φ_m/α_x² + sin²φ_m/α_y²))²)
//!   = 1 / (π α_x α_y (x²/α_x² + y²/α_y² + z²)²) for unit ω_m = (x, y, z);
//! * Λ(ω) = (√(1 + (α_x² ω_x² + α_y² ω_y²)/ω_z²) − 1) / 2, G1 = 1/(1 + Λ),
//!   G2 = 1/(1 + Λ(ω_o) + Λ(ω_i)) (height-correlated);
//! * visible normals D_ωo(ω_m) = G1(ω_o) max(0, ω_o·ω_m) D(ω_m) / cos θ_o, sampled exactly by
//!   stretching ω_o to the hemisphere configuration (α_x ω_x, α_y ω_y, ω_z).
//!
//! With α_x = α_y = α every formula is the isotropic one. Directions below the surface are
//! negated first, as in the isotropic distribution.

use super::microfacet::{reflect, sample_visible_normal};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// Anisotropic GGX with roughnesses `ax` (along local x) and `ay` (along local y).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnisoGgx {
    pub ax: f32,
    pub ay: f32,
}

impl AnisoGgx {
    #[inline]
    pub fn new(ax: f32, ay: f32) -> AnisoGgx {
        AnisoGgx { ax, ay }
    }

    /// D(ω_m) (per unit projected area).
    #[inline]
    pub fn d(&self, wm: Vec3) -> f32 {
        if wm.z <= 0.0 {
            return 0.0;
        }
        let wm = wm / wm.length();
        let (x, y) = (wm.x / self.ax, wm.y / self.ay);
        let k = x * x + y * y + wm.z * wm.z;
        if k.is_nan() || k <= 0.0 {
            return 0.0;
        }
        1.0 / (PI * self.ax * self.ay * k * k)
    }

    /// Smith Λ(ω).
    #[inline]
    pub fn lambda(&self, w: Vec3) -> f32 {
        let cos2 = w.z * w.z;
        if cos2 == 0.0 {
            return f32::INFINITY;
        }
        let a2tan2 = (self.ax * self.ax * w.x * w.x + self.ay * self.ay * w.y * w.y) / cos2;
        ((1.0 + a2tan2).sqrt() - 1.0) * 0.5
    }

    /// G1(ω) = 1 / (1 + Λ(ω)).
    #[inline]
    pub fn g1(&self, w: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(w))
    }

    /// G2(ω_o, ω_i) = 1 / (1 + Λ(ω_o) + Λ(ω_i)).
    #[inline]
    pub fn g2(&self, wo: Vec3, wi: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(wo) + self.lambda(wi))
    }

    /// Density of visible normals for `wo` (negated when below the surface).
    #[inline]
    pub fn pdf_wm(&self, wo: Vec3, wm: Vec3) -> f32 {
        let w = if wo.z < 0.0 { -wo } else { wo };
        if w.z == 0.0 {
            return 0.0;
        }
        self.g1(w) * w.dot(wm).max(0.0) * self.d(wm) / w.z
    }

    /// A visible normal (z ≥ 0) for `wo`, from `u` (Heitz 2018, listing 1, per-axis stretch).
    #[inline]
    pub fn sample_wm(&self, wo: Vec3, u: Vec2) -> Vec3 {
        sample_visible_normal(self.ax, self.ay, wo, u)
    }

    /// A reflection of upper-hemisphere `wo` through a sampled visible normal: (ω_i, ω_m,
    /// ω_o·ω_m, density of ω_i); `None` where it leaves below the surface.
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

    /// Density of the reflection of upper-hemisphere `wo` to `wi` (0 below the surface).
    #[inline]
    pub fn reflection_pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let Some(wm) = (wo + wi).try_normalize() else {
            return 0.0;
        };
        let c = wo.dot(wm);
        if c <= 0.0 {
            return 0.0;
        }
        self.pdf_wm(wo, wm) / (4.0 * c)
    }

    /// D G2 / (4 cos θ_o cos θ_i) and ω_o·h for upper-hemisphere `wo`, `wi`.
    #[inline]
    pub fn reflection(&self, wo: Vec3, wi: Vec3) -> Option<(f32, f32)> {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return None;
        }
        let wm = (wo + wi).try_normalize()?;
        Some((
            self.d(wm) * self.g2(wo, wi) / (4.0 * wo.z * wi.z),
            wo.dot(wm),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::microfacet::Ggx;
    use crate::rng::Rng;
    use crate::sampling::uniform_sphere;

    /// Equal roughnesses give the isotropic distribution.
    #[test]
    fn equal_roughnesses_are_the_isotropic_ggx() {
        let (a, i) = (AnisoGgx::new(0.3, 0.3), Ggx::new(0.3));
        let mut r = Rng::new(1, 0);
        for _ in 0..1000 {
            let (wo, mut wm) = (uniform_sphere(r.uniform2()), uniform_sphere(r.uniform2()));
            wm.z = wm.z.abs();
            let close = |x: f32, y: f32| (x - y).abs() <= 1e-4 * x.abs().max(y.abs()) + 1e-6;
            assert!(close(a.d(wm), i.d(wm)));
            assert!(close(a.lambda(wo), i.lambda(wo)));
            assert!(close(a.pdf_wm(wo, wm), i.pdf_wm(wo, wm)));
        }
    }

    /// ∫ D cos θ_m = 1 and ∫ D_ωo = 1 (the visible-normal density is normalised).
    #[test]
    fn anisotropic_distribution_is_normalised() {
        let g = AnisoGgx::new(0.6, 0.15);
        let n = 600;
        let mut r = Rng::new(2, 0);
        let wo = Vec3::new(0.5, 0.4, 0.768).normalize();
        let (mut d, mut v) = (0.0f64, 0.0f64);
        for i in 0..n {
            for j in 0..n {
                let u = Vec2::new(
                    (i as f32 + r.uniform()) / n as f32,
                    (j as f32 + r.uniform()) / n as f32,
                );
                let m = uniform_sphere(u);
                d += (g.d(m) * m.z.max(0.0)) as f64;
                v += g.pdf_wm(wo, m) as f64;
            }
        }
        let s = 4.0 * std::f64::consts::PI / (n * n) as f64;
        assert!((d * s - 1.0).abs() < 0.01, "∫D cos = {}", d * s);
        assert!((v * s - 1.0).abs() < 0.01, "∫D_vis = {}", v * s);
    }

    /// Sampled normals have the density `pdf_wm` (their mean of 1/pdf over the sphere's
    /// visible part equals its solid angle weighted by nothing: E[g/pdf] = ∫ g for g = D_vis).
    #[test]
    fn sampled_reflections_have_their_density() {
        let g = AnisoGgx::new(0.5, 0.1);
        let wo = Vec3::new(-0.3, 0.6, 0.742).normalize();
        let mut r = Rng::new(3, 0);
        for _ in 0..2000 {
            let Some((wi, _, _, pdf)) = g.sample_reflection(wo, r.uniform2()) else {
                continue;
            };
            let p = g.reflection_pdf(wo, wi);
            assert!((p - pdf).abs() <= 2e-3 * p.max(pdf), "{p} vs {pdf}");
        }
    }
}
