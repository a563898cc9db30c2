//! The sheen layer of `KHR_materials_sheen`: the "Charlie" microfibre distribution of
//! Estevez & Kulla 2017 ("Production Friendly Microfacet Sheen BRDF") with their fitted
//! Smith Λ, and the extension's albedo scaling of the layers beneath.
//!
//! With C the sheen colour, α = sheenRoughness² (as the Khronos sample viewer squares it,
//! clamped to ≥ [`MIN_ALPHA`] so that the distribution stays finite in f32), h the half vector
//! and μ = cos θ:
//!
//!   D(h) = (2 + 1/α) sin^(1/α) θ_h / (2π),
//!   Λ(μ) = exp(L(μ)) for μ < ½, exp(2 L(½) − L(1 − μ)) otherwise,
//!   L(x) = a / (1 + b x^c) + d x + e,  (a..e) = mix(p₀, p₁, (1 − α)²)  (the paper's fit),
//!   f_sheen = C D(h) / ((1 + Λ(μ_o) + Λ(μ_i)) 4 μ_o μ_i),
//!
//! the extension's "Charlie" visibility (Fresnel 1). It is reciprocal (symmetric in ω_o, ω_i)
//! and two-sided like the other reflection lobes; it is sampled cosine-weighted (the
//! distribution has no closed-form sampling, and its lobe is broad).
//!
//! **Albedo scaling.** Light that the fibres do not reflect reaches the base. The extension
//! scales the base layers by
//!
//!   S(μ_o, μ_i) = min(1 − max(C) E(μ_o), 1 − max(C) E(μ_i)),
//!
//! E(μ) = ∫ D G2 / (4 μ μ_i) μ_i dω_i the directional albedo of the white lobe. S is symmetric,
//! so the scaled base stays reciprocal, and since S ≤ 1 − max(C) E(μ_o) the material reflects
//! at most max(C) E(μ_o) + (1 − max(C) E(μ_o)) · 1 = 1. E is tabulated once per process by
//! quadrature (deterministic: the same table, bit for bit, on every run) on [`N_MU`] cosines ×
//! [`N_ROUGH`] roughnesses and read with bilinear interpolation.
//!
//! **Grazing normalisation** (a Flowlight bound, not in the extension). With the fitted Λ the
//! lobe reflects more than it receives at grazing view for small α (E(0.05) = 1.08 at the
//! smallest α, 2.9 near μ = 0). The lobe used is f_sheen / max(1, E(μ_o), E(μ_i)): symmetric,
//! so still reciprocal, equal to the extension's wherever E ≤ 1 (every μ for
//! sheenRoughness ≥ 0.27), and its albedo is at most min(1, E(μ_o)). The albedo scaling uses
//! min(1, E) accordingly, which keeps the sum ≤ 1.

use super::to_upper;
use glam::Vec3;
use std::f32::consts::PI;
use std::sync::LazyLock;

/// Smallest Charlie α (perceptual sheen roughness 0.07, the clamp three.js and Filament use).
pub const MIN_ALPHA: f32 = 0.07 * 0.07;

/// The Charlie α of a perceptual sheen roughness.
#[inline]
pub fn sheen_alpha(roughness: f32) -> f32 {
    let r = if roughness.is_finite() {
        roughness.clamp(0.0, 1.0)
    } else {
        0.0
    };
    (r * r).max(MIN_ALPHA)
}

/// D(h) of the Charlie distribution for cos θ_h = `cos_h`.
#[inline]
pub fn charlie_d(alpha: f32, cos_h: f32) -> f32 {
    let inv = 1.0 / alpha;
    let sin2 = (1.0 - cos_h * cos_h).max(0.0);
    (2.0 + inv) * sin2.powf(0.5 * inv) / (2.0 * PI)
}

/// L(x) of the fitted Λ.
#[inline]
fn fit_l(x: f32, alpha: f32) -> f32 {
    let t = (1.0 - alpha) * (1.0 - alpha);
    let mix = |p0: f32, p1: f32| p0 + (p1 - p0) * t;
    let a = mix(21.5473, 25.3245);
    let b = mix(3.82987, 3.32435);
    let c = mix(0.19823, 0.16801);
    let d = mix(-1.97760, -1.27393);
    let e = mix(-4.32054, -4.85967);
    a / (1.0 + b * x.powf(c)) + d * x + e
}

/// The fitted Smith Λ at |cos θ| = `mu`.
#[inline]
pub fn charlie_lambda(alpha: f32, mu: f32) -> f32 {
    let mu = mu.abs().min(1.0);
    if mu < 0.5 {
        fit_l(mu, alpha).exp()
    } else {
        (2.0 * fit_l(0.5, alpha) - fit_l(1.0 - mu, alpha)).exp()
    }
}

/// The white sheen lobe D G2 / (4 μ_o μ_i) / max(1, E(μ_o), E(μ_i)) for `wo`, `wi` on one
/// side; 0 otherwise (module docs, "Grazing normalisation").
#[inline]
pub fn sheen_value(alpha: f32, wo: Vec3, wi: Vec3) -> f32 {
    let v = charlie_value(alpha, wo, wi);
    if v == 0.0 {
        return v;
    }
    let e = sheen_raw_albedo(alpha, wo.z).max(sheen_raw_albedo(alpha, wi.z));
    if e > 1.0 {
        v / e
    } else {
        v
    }
}

/// The Charlie lobe D G2 / (4 μ_o μ_i) as the extension writes it, for `wo`, `wi` on one
/// side; 0 otherwise.
#[inline]
fn charlie_value(alpha: f32, wo: Vec3, wi: Vec3) -> f32 {
    if wo.z * wi.z <= 0.0 {
        return 0.0;
    }
    let (wo, wi) = to_upper(wo, wi);
    let Some(h) = (wo + wi).try_normalize() else {
        return 0.0;
    };
    let g2 = 1.0 / (1.0 + charlie_lambda(alpha, wo.z) + charlie_lambda(alpha, wi.z));
    let v = charlie_d(alpha, h.z) * g2 / (4.0 * wo.z * wi.z);
    if v.is_finite() {
        v
    } else {
        0.0
    }
}

/// Cosine nodes of the albedo table (μ_j = (j / (N_MU − 1))², dense near grazing).
const N_MU: usize = 32;
/// Roughness nodes of the albedo table (perceptual r_i = i / (N_ROUGH − 1), α = max(r², MIN)).
const N_ROUGH: usize = 16;
/// Quadrature points per axis (θ_i in cos, φ_i over [0, π], the lobe being symmetric in φ).
const QUAD: usize = 48;

/// E(μ) on the (roughness, μ) grid and the hemispherical average 2 ∫ E μ dμ per row.
struct SheenTable {
    e: [[f32; N_MU]; N_ROUGH],
    avg: [f32; N_ROUGH],
}

/// μ node j of the table.
#[inline]
fn mu_node(j: usize) -> f32 {
    let x = j as f32 / (N_MU - 1) as f32;
    x * x
}

/// E(μ_o) of the white Charlie lobe at α by midpoint quadrature in (μ_i, φ).
fn quadrature(alpha: f32, mu_o: f32) -> f32 {
    let mu_o = mu_o.clamp(1e-3, 1.0);
    let wo = Vec3::new((1.0 - mu_o * mu_o).sqrt(), 0.0, mu_o);
    let mut sum = 0.0f64;
    for a in 0..QUAD {
        // μ_i = x², denser near grazing where the sheen lives.
        let x = (a as f32 + 0.5) / QUAD as f32;
        let mu_i = x * x;
        let s = (1.0 - mu_i * mu_i).max(0.0).sqrt();
        for b in 0..QUAD {
            let phi = PI * (b as f32 + 0.5) / QUAD as f32;
            let wi = Vec3::new(s * phi.cos(), s * phi.sin(), mu_i);
            // dω = dμ dφ = 2x dx dφ; φ over [0, π] counts twice.
            sum += (charlie_value(alpha, wo, wi) * mu_i * 2.0 * x) as f64;
        }
    }
    let cell = (1.0 / QUAD as f64) * (PI as f64 / QUAD as f64);
    (2.0 * sum * cell) as f32
}

static TABLE: LazyLock<SheenTable> = LazyLock::new(|| {
    let mut e = [[0.0f32; N_MU]; N_ROUGH];
    let mut avg = [0.0f32; N_ROUGH];
    for (i, row) in e.iter_mut().enumerate() {
        let alpha = sheen_alpha(i as f32 / (N_ROUGH - 1) as f32);
        for (j, v) in row.iter_mut().enumerate() {
            *v = quadrature(alpha, mu_node(j));
        }
        // 2 ∫ min(E, 1) μ dμ of the row (trapezoids of E μ between the nodes).
        let mut s = 0.0;
        for j in 0..N_MU - 1 {
            let (m0, m1) = (mu_node(j), mu_node(j + 1));
            s += 0.5 * (m1 - m0) * (row[j].min(1.0) * m0 + row[j + 1].min(1.0) * m1);
        }
        avg[i] = 2.0 * s;
    }
    SheenTable { e, avg }
});

/// Perceptual roughness of a Charlie α, for the table's axis.
#[inline]
fn rough_coord(alpha: f32) -> (usize, f32) {
    let r = alpha.max(0.0).sqrt().min(1.0) * (N_ROUGH - 1) as f32;
    let i = (r as usize).min(N_ROUGH - 2);
    (i, (r - i as f32).clamp(0.0, 1.0))
}

/// Directional albedo E(μ) of the white Charlie lobe at α, as the extension writes the lobe
/// (above 1 at grazing view for small α).
#[inline]
fn sheen_raw_albedo(alpha: f32, mu: f32) -> f32 {
    let t = &*TABLE;
    let (i, s) = rough_coord(alpha);
    let mu = mu.abs().min(1.0);
    let x = mu.sqrt() * (N_MU - 1) as f32;
    let j = (x as usize).min(N_MU - 2);
    let (a, b) = (mu_node(j), mu_node(j + 1));
    let u = ((mu - a) / (b - a)).clamp(0.0, 1.0);
    let row = |r: &[f32; N_MU]| r[j] + (r[j + 1] - r[j]) * u;
    row(&t.e[i]) * (1.0 - s) + row(&t.e[i + 1]) * s
}

/// min(1, E(μ)): a bound of the directional albedo of the (normalised) sheen lobe at α.
#[inline]
pub fn sheen_albedo(alpha: f32, mu: f32) -> f32 {
    sheen_raw_albedo(alpha, mu).min(1.0)
}

/// Hemispherical average 2 ∫ min(1, E(μ)) μ dμ of the white sheen lobe at α.
#[inline]
pub fn sheen_average(alpha: f32) -> f32 {
    let t = &*TABLE;
    let (i, s) = rough_coord(alpha);
    t.avg[i] * (1.0 - s) + t.avg[i + 1] * s
}

/// The albedo scaling a sheen layer applies to the lobes beneath it: the largest channel of
/// the sheen colour and the Charlie α. `strength` 0 (the default) is no sheen: factor 1.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SheenScaling {
    /// max(C); 0 without a sheen layer.
    pub strength: f32,
    pub alpha: f32,
}

impl SheenScaling {
    #[inline]
    pub fn is_some(&self) -> bool {
        self.strength > 0.0
    }

    /// S(μ_o, μ_i) = min(1 − max(C) E(μ_o), 1 − max(C) E(μ_i)) (module docs), in [0, 1].
    #[inline]
    pub fn factor(&self, mu_o: f32, mu_i: f32) -> f32 {
        let e = sheen_albedo(self.alpha, mu_o).max(sheen_albedo(self.alpha, mu_i));
        (1.0 - self.strength * e).clamp(0.0, 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ∫ D cos θ_h dω_h = 1: the Charlie distribution is normalised over projected area.
    #[test]
    fn charlie_distribution_is_normalised() {
        for r in [0.1f32, 0.3, 0.6, 1.0] {
            let alpha = sheen_alpha(r);
            let n = 4000;
            let mut s = 0.0f64;
            for k in 0..n {
                let mu = (k as f32 + 0.5) / n as f32;
                s += (charlie_d(alpha, mu) * mu) as f64;
            }
            let v = s * 2.0 * std::f64::consts::PI / n as f64;
            assert!((v - 1.0).abs() < 0.01, "r {r}: ∫ D cos = {v}");
        }
    }

    /// The tabulated albedo of the Charlie lobe follows the quadrature between nodes (within
    /// 3% or 0.01), and its bound `sheen_albedo` lies in [0, 1].
    #[test]
    fn albedo_table_matches_quadrature_between_nodes() {
        for r in [0.0f32, 0.25, 0.5, 0.77, 1.0] {
            let alpha = sheen_alpha(r);
            for mu in [0.01f32, 0.05, 0.2, 0.47, 0.8, 1.0] {
                let (t, q) = (sheen_raw_albedo(alpha, mu), quadrature(alpha, mu));
                assert!((t - q).abs() < 0.03 * q + 0.01, "r {r} μ {mu}: {t} vs {q}");
                assert!((0.0..=1.0).contains(&sheen_albedo(alpha, mu)));
            }
            assert!((0.0..1.0).contains(&sheen_average(alpha)));
        }
    }

    /// Where the Charlie lobe reflects more than it receives (grazing view, small α: E = 1.08
    /// at μ = 0.05 for the smallest α), the normalised lobe reflects at most what it receives.
    #[test]
    fn normalised_lobe_never_gains_energy() {
        let alpha = sheen_alpha(0.0);
        assert!(sheen_raw_albedo(alpha, 0.05) > 1.0);
        for mu in [0.02f32, 0.05, 0.1, 0.5] {
            let wo = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
            let mut r = crate::rng::Rng::new(3, 0);
            let n = 200_000;
            let mut s = 0.0f64;
            for _ in 0..n {
                let (wi, pdf) = crate::sampling::two_sided_cosine(wo, r.uniform2()).unwrap();
                s += (sheen_value(alpha, wo, wi) * wi.z / pdf) as f64;
            }
            let e = s / n as f64;
            assert!(e <= 1.01, "μ {mu}: albedo {e}");
        }
    }

    #[test]
    fn no_sheen_scales_by_one() {
        let s = SheenScaling::default();
        assert!(!s.is_some());
        assert_eq!(s.factor(0.3, 0.9), 1.0);
    }
}
