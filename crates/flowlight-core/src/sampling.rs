//! Warping functions from the unit square and their densities.

use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

/// Concentric square-to-disk map (Shirley & Chiu 1997).
///
/// The angle is θ = φ in one wedge pair and θ = π/2 − φ in the other, with φ = (π/4)·(b/a)
/// and |b/a| ≤ 1; so (cos θ, sin θ) is (cos φ, sin φ) or (sin φ, cos φ), and only φ ∈
/// [−π/4, π/4] needs a sine and a cosine: [`sin_cos_quarter`], a short polynomial instead of
/// libm's `sincosf` with its range reduction (the diffuse lobes' sampling called it at every
/// vertex: 4.7% of a Cornell box render with the call's glue, perf).
#[inline]
pub fn concentric_disk(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    // The wedge is a coin flip for random `u`: choose its operands and results by selects
    // (one sine/cosine either way) rather than by a branch the predictor misses half the
    // time. The same operations on the same values as the two-branch form.
    let wide = o.x.abs() > o.y.abs();
    let (num, den) = if wide { (o.y, o.x) } else { (o.x, o.y) };
    let (s, c) = sin_cos_quarter((PI / 4.0) * (num / den));
    let (x, y) = if wide { (c, s) } else { (s, c) };
    den * Vec2::new(x, y)
}

/// (sin x, cos x) for |x| ≤ π/4, by their Taylor polynomials to x⁹ and x⁸, evaluated in
/// Horner form. The truncation error is below |x|¹¹/11! ≤ 2·10⁻⁹ and |x|¹⁰/10! ≤ 3·10⁻⁸,
/// under half an ulp of the results; the tests bound the total against f64 at 1.2·10⁻⁷.
#[inline]
pub fn sin_cos_quarter(x: f32) -> (f32, f32) {
    let x2 = x * x;
    let s = x
        * (1.0
            + x2 * (-1.0 / 6.0
                + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362_880.0)))));
    let c = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40_320.0))));
    (s, c)
}

/// Cosine-weighted direction on the +z hemisphere; density `cos θ / π`.
#[inline]
pub fn cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = concentric_disk(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

#[inline]
pub fn cosine_hemisphere_pdf(cos_theta: f32) -> f32 {
    cos_theta.max(0.0) * FRAC_1_PI
}

/// Cosine-weighted direction on the hemisphere of `wo` (local frame, z = normal): the
/// sampling of two-sided diffuse lobes. Returns the direction and its density.
#[inline]
pub fn two_sided_cosine(wo: Vec3, u: Vec2) -> Option<(Vec3, f32)> {
    let mut wi = cosine_hemisphere(u);
    if wo.z < 0.0 {
        wi.z = -wi.z;
    }
    let pdf = cosine_hemisphere_pdf(wi.z.abs());
    (pdf > 0.0 && wo.z != 0.0).then_some((wi, pdf))
}

/// Density of [`two_sided_cosine`]: `|cos θ_i| / π` on the side of `wo`, else 0.
#[inline]
pub fn two_sided_cosine_pdf(wo: Vec3, wi: Vec3) -> f32 {
    if wo.z * wi.z <= 0.0 {
        return 0.0;
    }
    cosine_hemisphere_pdf(wi.z.abs())
}

/// Uniform direction on the unit sphere; density `1 / 4π`.
#[inline]
pub fn uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Uniform direction in the cone of half-angle `acos(cos_max)` around +z; density
/// `1 / (2π (1 - cos_max))`. This is the spherical cap used by soft reconnection.
#[inline]
pub fn uniform_cone(u: Vec2, cos_max: f32) -> Vec3 {
    let cos_t = 1.0 - u.x * (1.0 - cos_max);
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
}

#[inline]
pub fn uniform_cone_pdf(cos_max: f32) -> f32 {
    1.0 / (2.0 * PI * (1.0 - cos_max))
}

/// Barycentrics of a uniformly distributed point on a triangle (Heitz 2019: low distortion).
#[inline]
pub fn uniform_triangle(u: Vec2) -> [f32; 3] {
    let (b0, b1) = if u.x < u.y {
        let b0 = u.x / 2.0;
        (b0, u.y - b0)
    } else {
        let b1 = u.y / 2.0;
        (u.x - b1, b1)
    };
    [b0, b1, 1.0 - b0 - b1]
}

/// Veach's power heuristic with β = 2 for two strategies.
#[inline]
pub fn power_heuristic(pdf_a: f32, pdf_b: f32) -> f32 {
    let a = pdf_a * pdf_a;
    let b = pdf_b * pdf_b;
    if a.is_infinite() {
        return 1.0;
    }
    if a + b == 0.0 {
        0.0
    } else {
        a / (a + b)
    }
}

/// [`power_heuristic`]`(pdf_a, pdf_b) / pdf_a`, the factor a next-event estimate multiplies
/// by, with one division instead of two: a/(a² + b²). The same special cases: 1/pdf_a where
/// pdf_a² overflows (weight 1), 0 where both densities are 0.
#[inline]
pub fn power_heuristic_over(pdf_a: f32, pdf_b: f32) -> f32 {
    let a = pdf_a * pdf_a;
    let b = pdf_b * pdf_b;
    if a.is_infinite() {
        return 1.0 / pdf_a;
    }
    if a + b == 0.0 {
        0.0
    } else {
        pdf_a / (a + b)
    }
}

/// Samples an index from a cumulative distribution `cdf` (non-decreasing, last entry 1).
/// Returns the index and its probability.
#[inline]
pub fn sample_cdf(cdf: &[f32], u: f32) -> (usize, f32) {
    let (i, p, _) = sample_cdf_with_start(cdf, u);
    (i, p)
}

/// [`sample_cdf`] with the chosen entry's interval start F(i−1).
#[inline]
fn sample_cdf_with_start(cdf: &[f32], u: f32) -> (usize, f32, f32) {
    debug_assert!(!cdf.is_empty());
    let i = cdf.partition_point(|&c| c <= u).min(cdf.len() - 1);
    let lo = if i == 0 { 0.0 } else { cdf[i - 1] };
    (i, cdf[i] - lo, lo)
}

/// [`sample_cdf`] that also returns `u` rescaled into [0, 1) within the chosen entry's
/// interval: u' = (u − F(i−1)) / p_i. Given the index, u' is uniform and independent of it, so
/// a caller can take its next decision from u' instead of a fresh number (pbrt-v4's
/// `SampleDiscrete` does the same). With stratified numbers that matters: the `u`s that land
/// in one entry are a stratified subset of its interval, and their u' stay stratified on
/// [0, 1), where a fresh, independently paired number would scatter them at random.
/// Rescaling costs the bits of log₂(1/p_i), which a renderer's few or thousands of lights
/// can spare out of `f32`'s 24.
#[inline]
pub fn sample_cdf_remapped(cdf: &[f32], u: f32) -> (usize, f32, f32) {
    let (i, p, lo) = sample_cdf_with_start(cdf, u);
    (i, p, rescaled(u, lo, p))
}

/// `u` rescaled from the interval [`lo`, `lo` + `p`) it fell in to [0, 1): (u − lo)/p, or 0
/// for an empty interval. Rounding can reach 1 (and a `u` past a last entry < 1 would pass
/// it), so the result is clamped below 1.
#[inline]
pub fn rescaled(u: f32, lo: f32, p: f32) -> f32 {
    if p > 0.0 {
        ((u - lo) / p).clamp(0.0, ONE_MINUS_EPSILON)
    } else {
        0.0
    }
}

/// The largest `f32` below 1.
pub const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

/// Builds a normalised CDF from non-negative weights. Returns `None` when they sum to zero or
/// are not finite.
pub fn build_cdf(weights: &[f32]) -> Option<Vec<f32>> {
    let mut acc = 0.0f64;
    let mut cdf = Vec::with_capacity(weights.len());
    for &w in weights {
        if !(w >= 0.0 && w.is_finite()) {
            return None;
        }
        acc += w as f64;
        cdf.push(acc);
    }
    if acc <= 0.0 {
        return None;
    }
    let mut out: Vec<f32> = cdf.iter().map(|&c| (c / acc) as f32).collect();
    if let Some(last) = out.last_mut() {
        *last = 1.0;
    }
    Some(out)
}

/// Test support for the "one pair keeps its strata" tests: the mean and variance, over
/// `rounds` rounds, of two estimators' averages over a pixel's `n` × `n` jittered pairs.
/// `estimates(u, r)` gives both estimators' values at pair `u`, drawing any further numbers
/// it needs from `r`.
#[cfg(test)]
pub(crate) fn jittered_moments(
    r: &mut crate::rng::Rng,
    rounds: usize,
    n: usize,
    mut estimates: impl FnMut(Vec2, &mut crate::rng::Rng) -> [f64; 2],
) -> [(f64, f64); 2] {
    // Per estimator: mean and mean square of the round averages.
    let mut moments = [[0.0f64; 2]; 2];
    for _ in 0..rounds {
        let mut sums = [0.0f64; 2];
        for j in 0..n * n {
            let u = Vec2::new(
                ((j % n) as f32 + r.uniform()) / n as f32,
                ((j / n) as f32 + r.uniform()) / n as f32,
            );
            for (sum, e) in sums.iter_mut().zip(estimates(u, r)) {
                *sum += e;
            }
        }
        for (m, sum) in moments.iter_mut().zip(sums) {
            let mean = sum / (n * n) as f64;
            m[0] += mean / rounds as f64;
            m[1] += mean * mean / rounds as f64;
        }
    }
    moments.map(|[m, m2]| (m, m2 - m * m))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// Stratified numbers stay stratified after the choice: the `u`s of 16 equal strata that
    /// land in an entry come out equally spaced over [0, 1), and a boundary maps to 0.
    #[test]
    fn sample_cdf_remapped_keeps_the_strata_of_each_entry() {
        let cdf = [0.25, 1.0];
        let n = 16;
        let mut per_entry = [Vec::new(), Vec::new()];
        for k in 0..n {
            let u = (k as f32 + 0.5) / n as f32;
            let (i, p, remapped) = sample_cdf_remapped(&cdf, u);
            assert_eq!((i, p), sample_cdf(&cdf, u));
            per_entry[i].push(remapped);
        }
        for strata in &per_entry {
            let m = strata.len() as f32;
            for (j, &r) in strata.iter().enumerate() {
                assert!((r - (j as f32 + 0.5) / m).abs() < 1e-6, "{strata:?}");
            }
        }
        assert_eq!(per_entry.map(|v| v.len()), [4, 12]);
        assert_eq!(sample_cdf_remapped(&cdf, 0.25), (1, 0.75, 0.0));
        // Never 1, also where rounding would give it or a CDF ends below 1.
        assert!(sample_cdf_remapped(&cdf, ONE_MINUS_EPSILON).2 < 1.0);
        assert!(sample_cdf_remapped(&[0.5, 0.75], 0.9).2 < 1.0);
        assert_eq!(sample_cdf_remapped(&[0.0, 1.0], 0.0).0, 1);
    }

    #[test]
    fn quarter_sin_cos_is_within_float_rounding_of_f64() {
        let n = 200_001;
        let mut worst = (0.0f64, 0.0f64);
        for i in 0..n {
            let x = (PI / 4.0) * (2.0 * i as f32 / (n - 1) as f32 - 1.0);
            let (s, c) = sin_cos_quarter(x);
            let (ws, wc) = (x as f64).sin_cos();
            worst.0 = worst.0.max((s as f64 - ws).abs());
            worst.1 = worst.1.max((c as f64 - wc).abs());
        }
        assert!(worst.0 < 1.2e-7 && worst.1 < 1.2e-7, "{worst:?}");
        assert_eq!(sin_cos_quarter(0.0), (0.0, 1.0));
        assert_eq!(sin_cos_quarter(-0.0).0.to_bits(), (-0.0f32).to_bits());
    }

    /// The map against the textbook form with libm's sine and cosine: the same point to
    /// float rounding, inside the unit disk, every wedge and both edges included.
    #[test]
    fn concentric_disk_is_the_textbook_map() {
        let textbook = |u: Vec2| {
            let o = 2.0 * u - Vec2::ONE;
            if o.x == 0.0 && o.y == 0.0 {
                return Vec2::ZERO;
            }
            let (r, t) = if o.x.abs() > o.y.abs() {
                (o.x, (PI / 4.0) * (o.y / o.x))
            } else {
                (o.y, PI / 2.0 - (PI / 4.0) * (o.x / o.y))
            };
            r * Vec2::new(t.cos(), t.sin())
        };
        let mut r = Rng::new(5, 0);
        let edges = [0.0, 0.5, ONE_MINUS_EPSILON, 0.25, 0.75];
        let grid = edges
            .iter()
            .flat_map(|&a| edges.iter().map(move |&b| Vec2::new(a, b)));
        for u in grid.chain((0..100_000).map(|_| r.uniform2())) {
            let (got, want) = (concentric_disk(u), textbook(u));
            assert!(
                (got - want).abs().max_element() < 3e-7,
                "{u:?}: {got:?} vs {want:?}"
            );
            assert!(got.length() <= 1.0 + 3e-7, "{u:?}: {got:?}");
        }
    }

    #[test]
    fn cosine_hemisphere_is_normalised_and_upper() {
        let mut r = Rng::new(1, 0);
        let n = 100_000;
        let mut mean_z = 0.0f64;
        for _ in 0..n {
            let d = cosine_hemisphere(r.uniform2());
            assert!(d.z >= 0.0 && (d.length() - 1.0).abs() < 1e-4);
            mean_z += d.z as f64;
        }
        // E[cos θ] under cos/π is 2/3.
        assert!((mean_z / n as f64 - 2.0 / 3.0).abs() < 0.01);
    }

    #[test]
    fn cdf_sampling_matches_weights() {
        let cdf = build_cdf(&[1.0, 0.0, 3.0]).unwrap();
        let mut r = Rng::new(2, 0);
        let mut counts = [0usize; 3];
        for _ in 0..40_000 {
            let (i, p) = sample_cdf(&cdf, r.uniform());
            assert!(p > 0.0);
            counts[i] += 1;
        }
        assert_eq!(counts[1], 0);
        assert!((counts[0] as f32 / 40_000.0 - 0.25).abs() < 0.01);
        assert!(build_cdf(&[0.0, 0.0]).is_none());
        assert!(build_cdf(&[f32::NAN]).is_none());
    }

    #[test]
    fn triangle_barycentrics_are_valid() {
        let mut r = Rng::new(3, 0);
        for _ in 0..10_000 {
            let b = uniform_triangle(r.uniform2());
            assert!(b.iter().all(|&x| (-1e-6..=1.0 + 1e-6).contains(&x)));
            assert!((b[0] + b[1] + b[2] - 1.0).abs() < 1e-5);
        }
    }

    /// The one-division factor is the power heuristic divided by the first density, within
    /// float rounding, with the same special cases (an overflowing square: weight 1; both
    /// densities 0: 0).
    #[test]
    fn power_heuristic_over_is_the_weight_over_the_density() {
        let mut r = Rng::new(17, 0);
        for _ in 0..10_000 {
            let a = (r.uniform() * 40.0 - 20.0).exp2();
            let b = if r.uniform() < 0.1 {
                0.0
            } else {
                (r.uniform() * 40.0 - 20.0).exp2()
            };
            let want = power_heuristic(a, b) / a;
            let got = power_heuristic_over(a, b);
            assert!(
                (got - want).abs() <= 4.0 * f32::EPSILON * want,
                "{a} {b}: {got} vs {want}"
            );
        }
        assert_eq!(power_heuristic_over(f32::INFINITY, 1.0), 0.0);
        assert_eq!(power_heuristic_over(1e30, 1.0), 1e-30);
        assert_eq!(power_heuristic_over(0.0, 0.0), 0.0);
    }
}
