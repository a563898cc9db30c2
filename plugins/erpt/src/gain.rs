//! What `auto`'s pilot predicts chains gain over path tracing on the class it would chain,
//! per ray — the figure that decides whether chains run at all and fixes their budget M
//! (the rule: `auto.rs`).
//!
//! **Variance per camera sample, per part of the light.** The census traces one camera
//! sample per pixel of a grid; per part (the chained class, the path-traced rest) it keeps
//! Σ X, Σ X² and Σ X_p X_q over horizontally neighbouring samples p, q ([`Moments`]). The
//! neighbours' product estimates the square of the pixel's mean where the image is smooth at
//! the grid's scale (two independent samples of nearly the same pixel), so
//!
//!   V = E[X²] − E[X_p X_q]
//!
//! is the mean per-pixel variance of one camera sample of the part — what path tracing's
//! squared error is made of — and not its spread over the image (the square of the image's
//! mean would count a bright highlight as noise). Rare bright seeds (caustics) make V large
//! at a small share of the energy: the glass caustic's class carries 1–2% of the energy.
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
//!
//! **Prediction.** Chains of N steps from seeds of density ρ per camera sample, M steps per
//! camera sample: a seed gets M/ρ steps, M/(ρN) chains of K_N effective deposits each
//! (K_N from the pilot's K at L steps, linear in the steps: 1 + (K_L − 1)(N − 1)/(L − 1)),
//! so the class' variance per camera sample becomes V_c·ρN/(M·K_N) =: A/M (fewer than one
//! chain a seed raises it: a seed that gets no chain leaves its energy to those that do).
//! With the rest V_r path traced at w_c rays per camera sample and the chains' w_m rays a
//! step, the efficiency 1 / (variance × rays) of chains over path tracing is
//!
//!   G(M) = (V_r + V_c)·w_c / ((V_r + A/M)·(w_c + M·w_m)),
//!
//! largest at Neyman's allocation M* = √(A·w_c / (V_r·w_m)) (clamped to [1/16, 16]). Chains
//! run when G(M*) ≥ [`MIN_GAIN`]: the margin covers what the model leaves out (the chains'
//! start-up and the pilot's own time, the tile's quantum noise).

/// Predicted efficiency gain of chains over path tracing below which `auto` path traces.
pub const MIN_GAIN: f64 = 1.5;
/// Bounds of the chain budget M (mutations per camera sample).
pub const M_RANGE: (f64, f64) = (1.0 / 16.0, 16.0);

/// Per-camera-sample sums of one part of the light over the census' grid.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Moments {
    /// Camera samples.
    pub samples: u64,
    /// Σ X.
    pub sum: f64,
    /// Σ X².
    pub squares: f64,
    /// Σ X_p X_q over pairs of horizontally neighbouring samples, and their number.
    pub neighbour_products: f64,
    pub pairs: u64,
}

impl Moments {
    /// Adds one camera sample's value `x`, and `left`, the value of its left neighbour on
    /// the grid when it has one.
    pub fn add(&mut self, x: f64, left: Option<f64>) {
        self.samples += 1;
        self.sum += x;
        self.squares += x * x;
        if let Some(l) = left {
            self.neighbour_products += x * l;
            self.pairs += 1;
        }
    }

    /// V = E[X²] − E[X_p X_q]: the mean per-pixel variance of one camera sample, ≥ 0.
    pub fn variance(&self) -> f64 {
        if self.samples == 0 {
            return 0.0;
        }
        let second = self.squares / self.samples as f64;
        let mean_squared = if self.pairs > 0 {
            self.neighbour_products / self.pairs as f64
        } else {
            (self.sum / self.samples as f64).powi(2)
        };
        (second - mean_squared).max(0.0)
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

/// K_N from the pilot's K at `pilot_steps` steps, linear in the steps, within [1, N].
pub fn spread_at(pilot_spread: f64, pilot_steps: u32, chain_length: u32) -> f64 {
    if pilot_steps <= 1 {
        return 1.0;
    }
    let per_step = (pilot_spread - 1.0).max(0.0) / (pilot_steps - 1) as f64;
    (1.0 + per_step * (chain_length.max(1) - 1) as f64).clamp(1.0, chain_length.max(1) as f64)
}

/// What the pilot's figures predict for chains on a class.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Prediction {
    /// V_c and V_r: per-camera-sample variance of the class and of the path-traced rest.
    pub class_variance: f64,
    pub rest_variance: f64,
    /// K_N: effective deposits of one chain of the mixture.
    pub spread: f64,
    /// M*: the budget that maximises the gain, within [`M_RANGE`].
    pub mutations_per_sample: f64,
    /// G(M*): efficiency of chains over path tracing.
    pub gain: f64,
}

/// The figures a prediction is made from.
#[derive(Clone, Copy, Debug)]
pub struct Inputs {
    pub class_variance: f64,
    pub rest_variance: f64,
    /// ρ: the class' seeds per camera sample.
    pub seeds_per_sample: f64,
    pub chain_length: u32,
    /// K_N of the mixture.
    pub spread: f64,
    /// w_c: rays per camera sample; w_m: rays per chain step.
    pub sample_work: f64,
    pub step_work: f64,
}

/// G(M) of the module docs.
pub fn gain_at(i: &Inputs, m: f64) -> f64 {
    let a = class_factor(i);
    let before = (i.rest_variance + i.class_variance) * i.sample_work;
    let after = (i.rest_variance + a / m) * (i.sample_work + m * i.step_work);
    if after > 0.0 {
        before / after
    } else {
        0.0
    }
}

/// A = V_c·ρN/K_N: the class' variance per camera sample at one chain step per camera sample.
fn class_factor(i: &Inputs) -> f64 {
    i.class_variance * i.seeds_per_sample * i.chain_length as f64 / i.spread.max(1.0)
}

/// M* and G(M*).
pub fn predict(i: &Inputs) -> Prediction {
    let a = class_factor(i);
    let m = if i.rest_variance > 0.0 && i.step_work > 0.0 {
        (a * i.sample_work / (i.rest_variance * i.step_work)).sqrt()
    } else {
        M_RANGE.1
    };
    let m = if m.is_finite() { m } else { M_RANGE.0 };
    let m = m.clamp(M_RANGE.0, M_RANGE.1);
    Prediction {
        class_variance: i.class_variance,
        rest_variance: i.rest_variance,
        spread: i.spread,
        mutations_per_sample: m,
        gain: if i.class_variance > 0.0 {
            gain_at(i, m)
        } else {
            0.0
        },
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
    fn the_spread_scales_with_the_chain_length() {
        assert_eq!(spread_at(32.0, 32, 64), 64.0);
        assert!((spread_at(4.1, 32, 64) - (1.0 + 3.1 * 63.0 / 31.0)).abs() < 1e-12);
        assert_eq!(spread_at(1.0, 32, 64), 1.0);
        assert_eq!(spread_at(40.0, 32, 16), 16.0);
    }

    #[test]
    fn the_variance_is_the_noise_not_the_image() {
        // A smooth image (every sample 2): no variance, though its second moment is 4.
        let mut smooth = Moments::default();
        let mut spiky = Moments::default();
        for k in 0..100 {
            smooth.add(2.0, (k % 10 != 0).then_some(2.0));
            // One sample in 10 carries 10, the rest 0: mean 1, second moment 10.
            let x = if k % 10 == 5 { 10.0 } else { 0.0 };
            spiky.add(x, (k % 10 != 0).then_some(0.0));
        }
        assert!(smooth.variance().abs() < 1e-12);
        assert!((spiky.variance() - 10.0).abs() < 1e-12);
    }

    fn inputs(class_variance: f64, rest_variance: f64, spread: f64) -> Inputs {
        Inputs {
            class_variance,
            rest_variance,
            seeds_per_sample: 0.05,
            chain_length: 64,
            spread,
            sample_work: 4.0,
            step_work: 5.0,
        }
    }

    #[test]
    fn chains_pay_where_the_class_carries_the_noise_and_they_spread_it() {
        // The glass caustic's kind: the class' noise 10× the rest's, chains spreading a
        // seed over 20 pixels.
        let p = predict(&inputs(10.0, 1.0, 20.0));
        assert!(p.gain >= MIN_GAIN, "{p:?}");
        // M* = √(A·w_c / (V_r·w_m)), A = 10·0.05·64/20 = 1.6.
        assert!((p.mutations_per_sample - (1.6f64 * 4.0 / 5.0).sqrt()).abs() < 1e-12);
        // M* is where the gain peaks.
        let at = |m: f64| gain_at(&inputs(10.0, 1.0, 20.0), m);
        let m = p.mutations_per_sample;
        assert!(at(m) >= at(m * 1.2) && at(m) >= at(m / 1.2));
    }

    #[test]
    fn chains_do_not_pay_on_a_quiet_class_or_without_spread() {
        // A class of little noise beside a noisy rest (direct light under glossy highlights):
        // whatever the chains do, the rays they cost are lost.
        assert!(predict(&inputs(0.01, 1.0, 30.0)).gain < MIN_GAIN);
        // A noisy class, but chains that stay in their pixel (K = 1): spreading nothing,
        // they only cost.
        assert!(predict(&inputs(10.0, 1.0, 1.0)).gain < MIN_GAIN);
        // No class variance at all: no gain.
        assert_eq!(predict(&inputs(0.0, 1.0, 30.0)).gain, 0.0);
    }
}
