//! Directional albedo of the single-scattering GGX reflection lobe, tabulated once per process,
//! for the energy coupling of the glTF material ([`super::gltf`]).
//!
//! For Schlick's Fresnel F(c) = f0 + (f90 − f0)(1 − c)⁵ (c = |ω_o·ω_m|) the directional albedo
//! of f = F · D · G2 / (4 |cos θ_o| |cos θ_i|) is linear in f0 and f90:
//!
//!   E(μ_o) = ∫ f |cos θ_i| dω_i = f0 · (E₁(μ_o) − E₅(μ_o)) + f90 · E₅(μ_o),
//!   E₁(μ) = ∫ D G2 / (4 μ μ_i) μ_i dω_i,    E₅(μ) = ∫ (1 − ω_o·ω_m)⁵ D G2 / (4 μ μ_i) μ_i dω_i,
//!
//! so two tables over (μ, roughness) serve every f0, f90 (Kulla & Conty 2017, "Revisiting
//! Physically Based Shading at Imageworks", use the same split). Each entry is estimated with
//! visible-normal sampling, where the estimator of ∫ F D G2/(4μμ_i) μ_i dω_i is F · G2/G1(ω_o)
//! (Heitz 2018), on a stratified 32 × 32 grid.
//!
//! Layout: roughness r = √α on 32 uniform nodes in [0, 1]; μ on 32 nodes μ_j = x_j², x_j
//! uniform in [0, 1] (denser near grazing, where E changes fastest). Lookups interpolate
//! linearly in μ between nodes and linearly in r, so the hemispherical average
//! Ē = 2 ∫₀¹ E(μ) μ dμ of the *interpolated* table is exact per row (the integral of a
//! piecewise-linear function times μ) and interpolates linearly in r too. The energy coupling
//! relies on that exactness: its diffuse term integrates to exactly (1 − E(μ_o)).

// The tables' definition (what builds them) is compiled for the tests only: the renderer
// reads the committed copy, `albedo_table.rs`.
#[cfg(test)]
use super::microfacet::{reflect, Ggx};
#[cfg(test)]
use super::DELTA_ALPHA;
#[cfg(test)]
use glam::{Vec2, Vec3};

/// Nodes per axis.
const N: usize = 32;
/// Stratified samples per axis and entry.
#[cfg(test)]
const SAMPLES: usize = 32;

/// E₁ and E₅ on the (roughness, μ) grid, and their per-row averages Ē₁, Ē₅.
struct Tables {
    e1: [[f32; N]; N],
    e5: [[f32; N]; N],
    avg1: [f32; N],
    avg5: [f32; N],
    /// The μ nodes μ_j = (j / 31)², so that a lookup reads them instead of recomputing them
    /// (a conversion and a division each, twice per lookup): the same values.
    mu: [f32; N],
}

#[cfg(test)]
fn mu_node(j: usize) -> f32 {
    let x = j as f32 / (N - 1) as f32;
    x * x
}

/// E₁ and E₅ of GGX roughness α at cos θ_o = μ by stratified visible-normal sampling.
#[cfg(test)]
fn estimate(alpha: f32, mu: f32) -> (f32, f32) {
    if alpha < DELTA_ALPHA {
        // Perfect mirror: ω_m is the normal, all energy is reflected.
        return (1.0, (1.0 - mu).powi(5));
    }
    let mu = mu.max(1e-4);
    let wo = Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
    let ggx = Ggx::new(alpha);
    let g1o = ggx.g1(wo);
    let (mut e1, mut e5) = (0.0f64, 0.0f64);
    for a in 0..SAMPLES {
        for b in 0..SAMPLES {
            let u = Vec2::new(
                (a as f32 + 0.5) / SAMPLES as f32,
                (b as f32 + 0.5) / SAMPLES as f32,
            );
            let wm = ggx.sample_wm(wo, u);
            let c = wo.dot(wm);
            if c <= 0.0 {
                continue;
            }
            let wi = reflect(wo, wm).normalize();
            if wi.z <= 0.0 {
                continue;
            }
            let w = (ggx.g2(wo, wi) / g1o) as f64;
            e1 += w;
            e5 += w * ((1.0 - c).max(0.0) as f64).powi(5);
        }
    }
    let n = (SAMPLES * SAMPLES) as f64;
    ((e1 / n) as f32, (e5 / n) as f32)
}

/// 2 ∫₀¹ E(μ) μ dμ of the piecewise-linear interpolant through the nodes.
#[cfg(test)]
fn row_average(row: &[f32; N]) -> f32 {
    let mut s = 0.0f64;
    for j in 0..N - 1 {
        let (a, b) = (mu_node(j) as f64, mu_node(j + 1) as f64);
        let (ea, eb) = (row[j] as f64, row[j + 1] as f64);
        s += (b - a) / 6.0 * (ea * (2.0 * a + b) + eb * (a + 2.0 * b));
    }
    (2.0 * s) as f32
}

/// The tables, built on first use. Inlined, so that a lookup's check for them is a load and
/// a branch in the caller rather than a call (the build itself stays out of line).
#[inline]
fn tables() -> &'static Tables {
    &TABLES
}

/// The tables as [`build_tables`] makes them, committed as source (`albedo_table.rs`,
/// written by `FLOWLIGHT_WRITE_ALBEDO_TABLE=1 cargo test -p flowlight-core committed_table`):
/// building them took about 195 M instructions, once per process and again in every plugin
/// (each cdylib has its own copy of this crate), so an ERPT render with four mutation plugins
/// spent about 0.2 s on five copies before its first sample. The test
/// `committed_table_is_the_built_one` rebuilds them and fails when they drift.
static TABLES: Tables = include!("albedo_table.rs");

/// The tables from their definition; the renderer reads the committed copy ([`TABLES`]).
#[cfg(test)]
fn build_tables() -> Tables {
    let mut t = Tables {
        e1: [[0.0; N]; N],
        e5: [[0.0; N]; N],
        avg1: [0.0; N],
        avg5: [0.0; N],
        mu: std::array::from_fn(mu_node),
    };
    for i in 0..N {
        let r = i as f32 / (N - 1) as f32;
        for j in 0..N {
            let (e1, e5) = estimate(r * r, mu_node(j));
            t.e1[i][j] = e1.min(1.0);
            t.e5[i][j] = e5.min(t.e1[i][j]);
        }
        t.avg1[i] = row_average(&t.e1[i]);
        t.avg5[i] = row_average(&t.e5[i]);
    }
    t
}

/// ⌊x⌋ clamped to a cell index, 0..=N − 2, for x ≥ 0 or NaN (0): `(x as usize).min(N − 2)`
/// with the cheaper 32-bit saturating conversion (the same index for every such x).
#[inline]
fn cell(x: f32) -> usize {
    (x as i32).clamp(0, N as i32 - 2) as usize
}

/// Index and fraction of `r = √α` on the roughness axis.
#[inline]
fn roughness_coord(alpha: f32) -> (usize, f32) {
    let r = alpha.clamp(0.0, 1.0).sqrt() * (N - 1) as f32;
    // r ≥ 0 (or NaN, which casts to 0 either way), so truncation is the floor, without the
    // libm call that `floor` is on baseline x86-64 (no SSE4.1 `roundss`).
    let i = cell(r);
    (i, (r - i as f32).clamp(0.0, 1.0))
}

/// Index and fraction (linear in μ) on the μ axis.
#[inline]
fn mu_coord(t: &Tables, mu: f32) -> (usize, f32) {
    let mu = mu.abs().min(1.0);
    let x = mu.sqrt() * (N - 1) as f32;
    let j = cell(x); // x ≥ 0: truncation is the floor
    let (a, b) = (t.mu[j], t.mu[j + 1]);
    (j, ((mu - a) / (b - a)).clamp(0.0, 1.0))
}

/// (E₁, E₅) at the roughness coordinate `(i, s)` and the μ coordinate `(j, u)`.
#[inline]
fn lookup(t: &Tables, (i, s): (usize, f32), (j, u): (usize, f32)) -> (f32, f32) {
    let lerp2 = |tab: &[[f32; N]; N]| {
        let r0 = tab[i][j] * (1.0 - u) + tab[i][j + 1] * u;
        let r1 = tab[i + 1][j] * (1.0 - u) + tab[i + 1][j + 1] * u;
        r0 * (1.0 - s) + r1 * s
    };
    (lerp2(&t.e1), lerp2(&t.e5))
}

/// (E₁(μ), E₅(μ)) for GGX roughness `alpha` at cos θ_o = `mu` (|μ| is used).
#[inline]
pub fn directional(alpha: f32, mu: f32) -> (f32, f32) {
    let t = tables();
    lookup(t, roughness_coord(alpha), mu_coord(t, mu))
}

/// [`directional`] at two cosines (of ω_o and ω_i) for one roughness, as the energy coupling
/// needs them: the roughness coordinate (a square root) and the table's once-per-process
/// initialisation check are shared. Each pair equals [`directional`]'s, bit for bit.
#[inline]
pub fn directional_pair(alpha: f32, mu_a: f32, mu_b: f32) -> ((f32, f32), (f32, f32)) {
    let t = tables();
    let r = roughness_coord(alpha);
    (
        lookup(t, r, mu_coord(t, mu_a)),
        lookup(t, r, mu_coord(t, mu_b)),
    )
}

/// A roughness's coordinate on the tables' roughness axis (its cell and the fraction across
/// it; a square root to find), for a caller that looks up many cosines at one roughness.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Roughness {
    cell: u32,
    fraction: f32,
}

impl Roughness {
    #[inline]
    pub fn new(alpha: f32) -> Roughness {
        let (i, s) = roughness_coord(alpha);
        Roughness {
            cell: i as u32,
            fraction: s,
        }
    }
}

/// [`schlick_albedo`] at the roughness coordinate `r` ([`Roughness::new`] of its α); the
/// same value, bit for bit.
#[inline]
pub fn schlick_albedo_at(f0: f32, f90: f32, r: Roughness, mu: f32) -> f32 {
    let t = tables();
    let (e1, e5) = lookup(t, (r.cell as usize, r.fraction), mu_coord(t, mu));
    f0 * (e1 - e5) + f90 * e5
}

/// Hemispherical averages (Ē₁, Ē₅) = 2 ∫₀¹ (E₁, E₅)(μ) μ dμ of [`directional`], exactly.
#[inline]
pub fn average(alpha: f32) -> (f32, f32) {
    let t = tables();
    let (i, s) = roughness_coord(alpha);
    (
        t.avg1[i] * (1.0 - s) + t.avg1[i + 1] * s,
        t.avg5[i] * (1.0 - s) + t.avg5[i + 1] * s,
    )
}

/// Directional albedo of the Schlick-Fresnel GGX lobe with scalar `f0`, `f90`.
#[inline]
pub fn schlick_albedo(f0: f32, f90: f32, alpha: f32, mu: f32) -> f32 {
    let (e1, e5) = directional(alpha, mu);
    f0 * (e1 - e5) + f90 * e5
}

/// [`schlick_albedo`] at two cosines, through [`directional_pair`]; the same values.
#[inline]
pub fn schlick_albedo_pair(f0: f32, f90: f32, alpha: f32, mu_a: f32, mu_b: f32) -> (f32, f32) {
    let ((a1, a5), (b1, b5)) = directional_pair(alpha, mu_a, mu_b);
    (f0 * (a1 - a5) + f90 * a5, f0 * (b1 - b5) + f90 * b5)
}

/// Hemispherical average of [`schlick_albedo`].
#[inline]
pub fn schlick_average(f0: f32, f90: f32, alpha: f32) -> f32 {
    let (a1, a5) = average(alpha);
    f0 * (a1 - a5) + f90 * a5
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;
    use crate::sampling::uniform_sphere;

    /// `albedo_table.rs` as source: a `Tables` literal, one row per line, each `f32` in the
    /// shortest form that reads back as the same bits.
    fn table_source(t: &Tables) -> String {
        let row = |r: &[f32; N]| {
            let items: Vec<String> = r.iter().map(|x| format!("{x:?}")).collect();
            format!("[{}]", items.join(", "))
        };
        let grid = |g: &[[f32; N]; N]| {
            let rows: Vec<String> = g.iter().map(|r| format!("        {},", row(r))).collect();
            format!("[\n{}\n    ]", rows.join("\n"))
        };
        format!(
            "// Generated by `FLOWLIGHT_WRITE_ALBEDO_TABLE=1 cargo test -p flowlight-core committed_table`\n\
             // from `build_tables` in albedo.rs (GGX E1, E5 on 32 roughness x 32 mu nodes, their\n\
             // row averages and the mu nodes); checked by `committed_table_is_the_built_one`.\n\
             Tables {{\n    e1: {},\n    e5: {},\n    avg1: {},\n    avg5: {},\n    mu: {},\n}}\n",
            grid(&t.e1),
            grid(&t.e5),
            row(&t.avg1),
            row(&t.avg5),
            row(&t.mu)
        )
    }

    /// The committed table is what `build_tables` computes today (to 2e-6: a libm whose sine
    /// differs in the last bit moves an entry by far less; a change to the GGX code or the
    /// layout moves it by far more). With `FLOWLIGHT_WRITE_ALBEDO_TABLE` set, writes it first.
    #[test]
    fn committed_table_is_the_built_one() {
        let built = build_tables();
        if std::env::var_os("FLOWLIGHT_WRITE_ALBEDO_TABLE").is_some() {
            let path = concat!(env!("CARGO_MANIFEST_DIR"), "/src/bsdf/albedo_table.rs");
            std::fs::write(path, table_source(&built)).unwrap();
            return;
        }
        let close = |a: f32, b: f32| (a - b).abs() <= 2e-6;
        let hint = "albedo_table.rs is stale: FLOWLIGHT_WRITE_ALBEDO_TABLE=1 cargo test -p flowlight-core committed_table";
        for i in 0..N {
            for j in 0..N {
                assert!(
                    close(built.e1[i][j], TABLES.e1[i][j]),
                    "e1[{i}][{j}]: {hint}"
                );
                assert!(
                    close(built.e5[i][j], TABLES.e5[i][j]),
                    "e5[{i}][{j}]: {hint}"
                );
            }
            assert!(close(built.avg1[i], TABLES.avg1[i]), "avg1[{i}]: {hint}");
            assert!(close(built.avg5[i], TABLES.avg5[i]), "avg5[{i}]: {hint}");
            assert_eq!(built.mu[i], TABLES.mu[i], "mu[{i}]: {hint}");
        }
    }

    /// Brute-force E₁, E₅ by uniform-sphere Monte Carlo of the formula itself (no VNDF).
    fn brute(alpha: f32, mu: f32, n: usize) -> (f64, f64) {
        let ggx = Ggx::new(alpha);
        let wo = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
        let mut r = Rng::new(7, 0);
        let (mut e1, mut e5) = (0.0, 0.0);
        for _ in 0..n {
            let mut wi = uniform_sphere(r.uniform2());
            wi.z = wi.z.abs();
            let wm = (wo + wi).normalize();
            let f = ggx.d(wm) * ggx.g2(wo, wi) / (4.0 * wo.z * wi.z) * wi.z;
            if !f.is_finite() {
                continue;
            }
            e1 += f as f64;
            e5 += (f * (1.0 - wo.dot(wm)).powi(5)) as f64;
        }
        let s = 2.0 * std::f64::consts::PI / n as f64;
        (e1 * s, e5 * s)
    }

    #[test]
    fn table_matches_brute_force_integration() {
        for alpha in [0.25f32, 0.6, 1.0] {
            for mu in [0.2f32, 0.5, 0.9] {
                let (t1, t5) = directional(alpha, mu);
                let (b1, b5) = brute(alpha, mu, 400_000);
                assert!(
                    (t1 as f64 - b1).abs() < 0.01,
                    "α {alpha} μ {mu}: E1 {t1} vs {b1}"
                );
                assert!(
                    (t5 as f64 - b5).abs() < 0.005,
                    "α {alpha} μ {mu}: E5 {t5} vs {b5}"
                );
            }
        }
        // Mirror: E1 = 1, E5 = (1 − μ)^5 (up to interpolation between nodes).
        let (e1, e5) = directional(0.0, 0.3);
        assert!((e1 - 1.0).abs() < 1e-6 && (e5 - 0.7f32.powi(5)).abs() < 2e-3);
    }

    #[test]
    fn cell_is_the_clamped_floor() {
        let mut xs = vec![
            0.0f32,
            -0.0,
            0.5,
            1.0,
            29.999,
            30.0,
            30.5,
            31.0,
            1e9,
            f32::NAN,
        ];
        xs.extend((0..=3100).map(|k| k as f32 * 0.01));
        for x in xs {
            assert_eq!(cell(x), (x as usize).min(N - 2), "{x}");
        }
    }

    /// The paired lookup is the single one twice, bit for bit, for cosines of either sign,
    /// on and between the nodes, and out of range.
    #[test]
    fn paired_lookup_equals_two_single_ones() {
        let mut r = Rng::new(8, 0);
        let mut mus: Vec<f32> = (0..N).map(mu_node).collect();
        mus.extend([-1.0, -0.3, 0.0, 1.0, 1.5, f32::MIN_POSITIVE]);
        mus.extend((0..200).map(|_| 2.0 * r.uniform() - 1.0));
        for alpha in [0.0f32, 1e-3, 0.09, 0.37, 1.0] {
            for (k, &a) in mus.iter().enumerate() {
                let b = mus[(k * 7 + 3) % mus.len()];
                let (pa, pb) = directional_pair(alpha, a, b);
                let bits = |(x, y): (f32, f32)| (x.to_bits(), y.to_bits());
                assert_eq!(bits(pa), bits(directional(alpha, a)), "α {alpha} μ {a}");
                assert_eq!(bits(pb), bits(directional(alpha, b)), "α {alpha} μ {b}");
                let (sa, sb) = schlick_albedo_pair(0.04, 0.9, alpha, a, b);
                assert_eq!(sa.to_bits(), schlick_albedo(0.04, 0.9, alpha, a).to_bits());
                assert_eq!(sb.to_bits(), schlick_albedo(0.04, 0.9, alpha, b).to_bits());
            }
        }
    }

    #[test]
    fn averages_are_the_exact_integrals_of_the_lookup() {
        for alpha in [0.0f32, 0.1, 0.37, 1.0] {
            let n = 20_000;
            let (mut s1, mut s5) = (0.0f64, 0.0f64);
            for k in 0..n {
                let mu = (k as f32 + 0.5) / n as f32;
                let (e1, e5) = directional(alpha, mu);
                s1 += (e1 * mu) as f64;
                s5 += (e5 * mu) as f64;
            }
            let (a1, a5) = average(alpha);
            assert!((2.0 * s1 / n as f64 - a1 as f64).abs() < 2e-4, "α {alpha}");
            assert!((2.0 * s5 / n as f64 - a5 as f64).abs() < 2e-4, "α {alpha}");
        }
    }
}
