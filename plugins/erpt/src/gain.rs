//! Two measures of `auto`'s pilot beyond the §5.5 strengths (the rule: `auto.rs`): how much
//! of path tracing's noise a part of the light carries, and how far a strategy's chains
//! spread a seed's energy.
//!
//! **Noise per part.** The census traces one camera sample per pixel of a grid; per part (the
//! chained class, the path-traced rest) [`add_pass`] sums, weighted by relMSE's
//! w = 1 / (μ̂² + ε) with μ̂ the pixel's mean estimated from its grid neighbours, the squares
//! X² and the products X_p X_q of horizontally neighbouring samples ([`Moments`]). The
//! neighbours' product estimates μ² where the image is smooth at the grid's scale (two
//! independent samples of nearly the same pixel), so
//!
//!   V = E[w X²] − E[w X_p X_q]
//!
//! is the mean relative variance of one camera sample of the part — what path tracing's
//! relMSE is made of — and not the part's spread over the image (the square of the image's
//! mean would count a bright highlight as noise).
//!
//! **The bound on what chains can gain.** Chains change the chained class only; the rest is
//! path traced as before, at the same or a smaller share of the rays. So however well they
//! spread, their efficiency over path tracing is at most Amdahl's
//!
//!   G_max = (V_c + V_r) / V_r,
//!
//! and chains that cannot reach [`MIN_GAIN`] there are not worth their rays and the pilot's.
//! Where the chained part is the indirect light seen by hundreds of the census' seeds this
//! bound is measured well (veach-mis: V_c = 0.003 beside V_r = 2,652 from its glossy
//! highlights; the indirect room, the door and the lamp shade: V_r ≤ 1.2 beside
//! V_c ≥ 138). For the caustic class it is not: its noise is a tail of rare seeds that 4,096
//! camera samples do not see (the glass caustic's census measures V_c + V_r = 0.2, MCPT's
//! relMSE × spp is 3.3 there), so `auto` does not gate the caustic class by it.
//!
//! **Spread: the streak norm made a number.** Thesis §5.5 rates a chain by the lacing of its
//! events: 100 acceptances then 100 rejections pile half the deposits into one pixel, a
//! "speckle", where the alternation `RARA…` spreads them over 100 pixels. Each pilot chain of
//! L steps deposits once per step into the pixel of its state; with n_p the deposits of pixel
//! p its *effective deposits* are
//!
//!   K = (Σ n_p)² / Σ n_p²,
//!
//! L for a chain that never stays, 1 for one that never leaves its pixel, 1.98 for
//! `A¹⁰⁰R¹⁰⁰` and 100 for `(RA)¹⁰⁰` — acceptance, rejection streaks and moves too small to
//! leave a pixel in one figure. A seed's energy spread evenly over K pixels has 1/K of its
//! second moment per pixel.

/// Amdahl's bound on chains' efficiency over path tracing below which `auto` does not chain
/// indirect light.
pub const MIN_GAIN: f64 = 1.5;

/// ε of the relative error, relMSE = mean (a − b)² / (b² + ε): the host's metric's.
pub const RELATIVE_EPSILON: f64 = 1e-2;

/// Per-camera-sample sums of one part of the light over the census' grid, each weighted by
/// 1 / (μ̂² + ε), μ̂ the pixel's mean estimated from its grid neighbours.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Moments {
    /// Camera samples, and Σ w X².
    pub samples: u64,
    pub squares: f64,
    /// Pairs of horizontally neighbouring samples p, q, and Σ w_p X_p X_q.
    pub pairs: u64,
    pub neighbour_products: f64,
}

impl Moments {
    /// Adds one camera sample's value `x` with weight `w`, and `left`, the value of its
    /// left neighbour on the grid when it has one.
    pub fn add(&mut self, x: f64, left: Option<f64>, w: f64) {
        self.samples += 1;
        self.squares += w * x * x;
        if let Some(l) = left {
            self.neighbour_products += w * x * l;
            self.pairs += 1;
        }
    }

    /// V = E[w X²] − E[w X_p X_q]: the mean relative variance of one camera sample, ≥ 0.
    pub fn variance(&self) -> f64 {
        if self.samples == 0 {
            return 0.0;
        }
        let second = self.squares / self.samples as f64;
        let mean_squared = if self.pairs > 0 {
            self.neighbour_products / self.pairs as f64
        } else {
            0.0
        };
        (second - mean_squared).max(0.0)
    }
}

/// Adds one pass of the census over a grid of `cols` columns: `cells[row · cols + col]`
/// holds a camera sample's light per part (the parts `0` and `1` make up all of it). Each
/// sample is weighted by 1 / (μ̂² + ε), μ̂ the mean light of its up to 8 grid neighbours:
/// relMSE's weight, with the pixel's mean from samples independent of its own.
pub fn add_pass<const P: usize>(moments: &mut [Moments; P], cols: usize, cells: &[[f64; P]]) {
    if cols == 0 {
        return;
    }
    let rows = cells.len() / cols;
    let total = |r: usize, c: usize| cells[r * cols + c][0] + cells[r * cols + c][1];
    for r in 0..rows {
        for c in 0..cols {
            let (mut sum, mut count) = (0.0, 0.0);
            for nr in r.saturating_sub(1)..(r + 2).min(rows) {
                for nc in c.saturating_sub(1)..(c + 2).min(cols) {
                    if (nr, nc) != (r, c) {
                        sum += total(nr, nc);
                        count += 1.0;
                    }
                }
            }
            let mean = if count > 0.0 { sum / count } else { 0.0 };
            let w = 1.0 / (mean * mean + RELATIVE_EPSILON);
            let here = cells[r * cols + c];
            let left = (c > 0).then(|| cells[r * cols + c - 1]);
            for (i, m) in moments.iter_mut().enumerate() {
                m.add(here[i], left.map(|l| l[i]), w);
            }
        }
    }
}

/// K = (Σ n_p)² / Σ n_p² of one chain's deposits, `pixels` the pixel of its state at each
/// step (reordered in place).
pub fn effective_deposits(pixels: &mut [(i64, i64)]) -> f64 {
    if pixels.is_empty() {
        return 0.0;
    }
    pixels.sort_unstable();
    let (mut squares, mut run) = (0.0, 1.0);
    for i in 1..=pixels.len() {
        if i < pixels.len() && pixels[i] == pixels[i - 1] {
            run += 1.0;
        } else {
            squares += run * run;
            run = 1.0;
        }
    }
    (pixels.len() as f64).powi(2) / squares
}

/// G_max = (V_c + V_r) / V_r: the most chains on a class of variance V_c can gain over path
/// tracing beside a path-traced rest of variance V_r (infinite for V_r = 0; 0 without V_c).
pub fn amdahl_bound(class_variance: f64, rest_variance: f64) -> f64 {
    if class_variance <= 0.0 {
        0.0
    } else if rest_variance <= 0.0 {
        f64::INFINITY
    } else {
        (class_variance + rest_variance) / rest_variance
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn effective_deposits_follow_the_streaks() {
        // (RA)^100 from one pixel to the next: every accepted move a new pixel, each kept
        // for two steps.
        let mut alternating: Vec<_> = (0..200).map(|k| (k / 2, 0)).collect();
        assert!((effective_deposits(&mut alternating) - 100.0).abs() < 1e-9);
        // A^100 R^100: 99 pixels once, the last 101 times.
        let mut streak: Vec<_> = (0..200).map(|k: i64| (k.min(99), 0)).collect();
        let k = 200.0f64.powi(2) / (99.0 + 101.0f64.powi(2));
        assert!((effective_deposits(&mut streak) - k).abs() < 1e-9);
        assert!(k < 4.0);
        let mut stuck = vec![(3, 4); 32];
        assert_eq!(effective_deposits(&mut stuck), 1.0);
        assert_eq!(effective_deposits(&mut []), 0.0);
    }

    #[test]
    fn the_variance_is_the_relative_noise_not_the_image() {
        // A smooth image of 2 (part 0) on a 10 × 10 grid: no variance, though its second
        // moment is 4.
        let smooth = vec![[2.0, 0.0]; 100];
        let mut m = [Moments::default(); 2];
        add_pass(&mut m, 10, &smooth);
        assert!(m[0].variance().abs() < 1e-12 && m[1].variance() == 0.0);
        // Part 1: 4 isolated samples of 100 carry 10 over the smooth 2. Relative to their
        // pixels' mean, 2 (from the neighbours, which hold no spike), each adds 100 / 4.01.
        let spike = |k: usize| k / 10 % 5 == 2 && k % 5 == 2;
        let spiky: Vec<[f64; 2]> = (0..100)
            .map(|k| [2.0, if spike(k) { 10.0 } else { 0.0 }])
            .collect();
        let mut m = [Moments::default(); 2];
        add_pass(&mut m, 10, &spiky);
        let v = m[1].variance();
        assert!((v - 4.0 * 100.0 / 4.01 / 100.0).abs() < 1e-9, "{v}");
        // The same spikes over a dark image (weight 1/ε): far more relative noise.
        let dark: Vec<[f64; 2]> = spiky.iter().map(|c| [0.0, c[1]]).collect();
        let mut d = [Moments::default(); 2];
        add_pass(&mut d, 10, &dark);
        assert!((d[1].variance() - 400.0).abs() < 1e-9, "{:?}", d[1]);
        assert_eq!(d[0].variance(), 0.0);
    }

    #[test]
    fn chains_gain_at_most_the_share_of_the_noise_they_take() {
        // veach-mis' indirect light beside its glossy highlights: nothing to gain.
        assert!(amdahl_bound(0.003, 2652.0) < 1.0001);
        assert!(amdahl_bound(0.003, 2652.0) < MIN_GAIN);
        // The class carries 9/10 of the noise: at most 10×.
        assert!((amdahl_bound(9.0, 1.0) - 10.0).abs() < 1e-12);
        assert_eq!(amdahl_bound(5.0, 0.0), f64::INFINITY);
        assert_eq!(amdahl_bound(0.0, 1.0), 0.0);
    }
}
