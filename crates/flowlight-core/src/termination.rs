//! Termination distributions: the thesis' three depth-based ones (§3.8) and a
//! throughput-based Russian roulette.
//!
//! A path tracer decides at its k-th lighting vertex (k = 1 … N, N the path-space depth) to
//! stop with probability T_k. Choosing T_k fixes how samples are spread over lighting layers:
//!
//! * BxDF-based: T_k = 1 − clamp(albedo, 0, 0.95), the common albedo Russian roulette;
//! * equidistribution: every layer gets the same share, T_k = 1 / (N − k + 1);
//! * expodistribution: the share of layer k grows geometrically, P(k) = α₁ q^{N−k} with
//!   q = ½ and α₁ = ½ · 2^N / (2^N − 1), so T_k = P(k) / (1 − Σ_{i<k} P(i));
//! * throughput-based (not in the thesis; Mitsuba 3's and pbrt-v4's path tracers): no
//!   roulette before the start depth k₀ (`rr_depth`, default 5), then survival with
//!   probability q_k = min(max_c(β_k · ρ_k), q_max), q_max = 0.95 by default:
//!
//!   T_k = 0 for k < k₀,   T_k = 1 − min(max_c(β_k · ρ_k), q_max) for k₀ ≤ k < N,   T_N = 1,
//!
//!   where β_k is the path throughput up to vertex k (its RGB components c, every earlier
//!   1/(1 − T) factor included) and ρ_k the vertex's BSDF albedo estimate. A path whose
//!   throughput has fallen off is cut early, one that still carries much is kept; after a
//!   survival the throughput is divided by q_k, so it hovers near one from then on.
//!
//! All end with T_N = 1. Estimators divide by the probability of the branch they take, so
//! every choice is unbiased; only the variance per layer changes. The first three fix the
//! share of samples each layer gets in advance (a function of k, and of the albedo for
//! `bxdf`); under the throughput distribution the layer shares depend on each path's history,
//! so they are no longer a fixed function of the depth.
//!
//! ## The throughput rule against Mitsuba 3 and pbrt-v4
//!
//! Mitsuba 3 (`path` integrator) draws, after the BSDF sample of vertex k with its weight
//! already in β, q = min(max_c(β) · η², 0.95) from `depth ≥ rr_depth` (default 5) on, η the
//! product of the relative IORs crossed; pbrt-v4 (`PathIntegrator`) takes q = min(max_c(β ·
//! η²), 1) after the BSDF sample from the second bounce on, and only when it is below one.
//! Here the entangled samplers (MCPT's and ERPT's seeds) pass max_c(β) · η² as the throughput
//! too: a refraction into glass scales β by 1/η'² (≈ 0.44), the radiance compression across
//! the interface, and without the η² factor a path inside glass would survive with about 0.44
//! times the probability of one outside although it carries the same light. Each [`crate::bsdf::BsdfSample`]
//! reports the η' it crossed, and the tracer keeps the running product of η'². (Before
//! `1cefc37`, 2026-12-02, the factor was left out; on the glass caustic the throughput rule
//! was then 2.5× less efficient than `expo`, docs/mcpt.md.) One difference remains: the decision
//! comes *before* the BSDF sample (a stopped path then saves the sample, and the call sites
//! keep their shape), so q uses the sample's expected weight ρ_k instead of its actual weight
//! f·|cos θ|/p. For a Lambertian vertex sampled by its cosine the two are equal; for a mixture
//! it is the mixture's average.
//!
//! In the untangled sampler (thesis §3.6–3.7) stopping at a Λβ vertex *is* its light
//! connection, so T_k = 0 would leave layer k without an estimator, and the path throughput
//! multiplies both branches (connect here, or go on), so it cancels from the choice between
//! them: there the rule reduces to the vertex's own throughput factor, T_k = 1 − min(ρ_k,
//! q_max), from the first lighting vertex on (`bxdf` with the cap q_max; the same as `bxdf` at
//! the default 0.95). Taking β into account there was tried and fails: β holds the 1/(1 − ζ_e)
//! of an emitter that was passed through (thesis §3.6), ×3 in the white furnace, so layer 1
//! got T = 0.05 and the furnace's standard error tripled. k₀ applies to the entangled sampler
//! only, which estimates every layer by its light connections whether or not the path goes
//! on.
//!
//! `throughput` is the path samplers' default (`crates/flowlight-pathtrace/src/settings.rs`):
//! on the benchmark suite it had the best efficiency, 1.18× `bxdf` in the geometric mean over
//! five scenes (docs/results.md, "relMSE × spp per termination distribution").

/// The termination distribution chosen in the integrator's config.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum TerminationDistribution {
    Bxdf = 0,
    Equi = 1,
    Expo = 2,
    /// Russian roulette on the path throughput from a start depth on (Mitsuba 3, pbrt-v4).
    Throughput = 3,
}

impl TerminationDistribution {
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "bxdf" => Some(Self::Bxdf),
            "equi" => Some(Self::Equi),
            "expo" => Some(Self::Expo),
            "throughput" => Some(Self::Throughput),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Bxdf => "bxdf",
            Self::Equi => "equi",
            Self::Expo => "expo",
            Self::Throughput => "throughput",
        }
    }
}

/// Default start depth k₀ of the throughput roulette (Mitsuba 3's `rr_depth`).
pub const DEFAULT_RR_DEPTH: u32 = 5;
/// Default cap q_max on the throughput roulette's survival probability (Mitsuba 3's 0.95).
pub const DEFAULT_MAX_SURVIVAL: f32 = 0.95;

/// Termination probabilities T_1 … T_N for a path-space depth N, precomputed once per render.
#[derive(Clone, Debug)]
pub struct TerminationSchedule {
    kind: TerminationDistribution,
    /// `table[k-1] = T_k` for the depth-only distributions.
    table: Vec<f32>,
    /// Throughput roulette: first lighting vertex k₀ that may stop (entangled sampler).
    rr_depth: u32,
    /// Throughput roulette: cap q_max on the survival probability, in (0, 1).
    max_survival: f32,
}

impl TerminationSchedule {
    /// The schedule of `kind` at path-space depth `depth`; the throughput roulette gets the
    /// defaults k₀ = 5, q_max = 0.95 (see [`Self::with_roulette`]).
    pub fn new(kind: TerminationDistribution, depth: u32) -> Self {
        let n = depth.max(1) as usize;
        let table = match kind {
            TerminationDistribution::Bxdf | TerminationDistribution::Throughput => vec![0.0; n],
            TerminationDistribution::Equi => (1..=n).map(|k| 1.0 / (n - k + 1) as f32).collect(),
            TerminationDistribution::Expo => {
                // Work in f64: for N near 60, 2^N / (2^N − 1) rounds to 1 in f32 anyway.
                let alpha1 = 0.5 * 2f64.powi(n as i32) / (2f64.powi(n as i32) - 1.0);
                let p = |k: usize| alpha1 * 0.5f64.powi((n - k) as i32);
                let mut survived = 1.0f64;
                (1..=n)
                    .map(|k| {
                        let t = if k == n {
                            1.0
                        } else {
                            (p(k) / survived).min(1.0)
                        };
                        survived -= p(k);
                        t as f32
                    })
                    .collect()
            }
        };
        TerminationSchedule {
            kind,
            table,
            rr_depth: DEFAULT_RR_DEPTH,
            max_survival: DEFAULT_MAX_SURVIVAL,
        }
    }

    /// Sets the throughput roulette's start depth k₀ (≥ 1) and survival cap q_max, which is
    /// clamped into [0.01, 0.999] so that the untangled sampler's T_k stays positive. The
    /// other distributions ignore both.
    pub fn with_roulette(mut self, rr_depth: u32, max_survival: f32) -> Self {
        self.rr_depth = rr_depth.max(1);
        self.max_survival = if max_survival.is_finite() {
            max_survival.clamp(0.01, 0.999)
        } else {
            DEFAULT_MAX_SURVIVAL
        };
        self
    }

    pub fn depth(&self) -> u32 {
        self.table.len() as u32
    }

    pub fn kind(&self) -> TerminationDistribution {
        self.kind
    }

    pub fn rr_depth(&self) -> u32 {
        self.rr_depth
    }

    pub fn max_survival(&self) -> f32 {
        self.max_survival
    }

    /// T_k at lighting vertex `k` (1-based) of a surface whose BSDF albedo estimate is
    /// `albedo`, for a path of unit throughput (see [`Self::probability_with_throughput`]).
    /// Beyond the depth the path always stops.
    #[inline]
    pub fn probability(&self, k: u32, albedo: f32) -> f32 {
        self.probability_with_throughput(k, albedo, 1.0)
    }

    /// T_k of the entangled sampler at lighting vertex `k` (1-based), albedo estimate
    /// `albedo`, and `beta_max` = max_c β_k, the largest RGB component of the path throughput
    /// that arrives at the vertex. Only the throughput distribution reads `beta_max` (and
    /// does not stop before k₀). Beyond the depth the path always stops.
    #[inline]
    pub fn probability_with_throughput(&self, k: u32, albedo: f32, beta_max: f32) -> f32 {
        let n = self.table.len() as u32;
        if k >= n {
            return 1.0;
        }
        match self.kind {
            TerminationDistribution::Throughput if k < self.rr_depth => 0.0,
            TerminationDistribution::Throughput => {
                // max(β·ρ) = max(β)·ρ for a scalar albedo; NaN stops the path.
                1.0 - clamp_or_zero(beta_max * albedo.max(0.0), self.max_survival)
            }
            _ => self.connection_probability(k, albedo),
        }
    }

    /// T_k of the untangled sampler, whose stop at a Λβ vertex is its light connection. The
    /// path throughput multiplies both branches there (connect here or go on), so it cancels
    /// from the choice: the throughput distribution reduces to the vertex's own throughput
    /// factor, T_k = 1 − min(ρ_k, q_max), from the first lighting vertex on (a zero T_k would
    /// leave layer k without an estimator). The other distributions are as in
    /// [`Self::probability`].
    #[inline]
    pub fn connection_probability(&self, k: u32, albedo: f32) -> f32 {
        let n = self.table.len() as u32;
        if k >= n {
            return 1.0;
        }
        match self.kind {
            TerminationDistribution::Bxdf => {
                let a = if albedo.is_finite() {
                    albedo.clamp(0.0, 0.95)
                } else {
                    0.0
                };
                1.0 - a
            }
            TerminationDistribution::Throughput => 1.0 - clamp_or_zero(albedo, self.max_survival),
            _ => self.table[k as usize - 1],
        }
    }
}

/// `x` clamped into [0, hi]; NaN gives 0 (+∞ gives hi).
#[inline]
fn clamp_or_zero(x: f32, hi: f32) -> f32 {
    if x.is_nan() {
        0.0
    } else {
        x.clamp(0.0, hi)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Probability that a path stops exactly at vertex k under a depth-only schedule.
    fn layer_shares(s: &TerminationSchedule) -> Vec<f64> {
        let mut alive = 1.0f64;
        (1..=s.depth())
            .map(|k| {
                let t = s.probability(k, 0.5) as f64;
                let share = alive * t;
                alive *= 1.0 - t;
                share
            })
            .collect()
    }

    #[test]
    fn equidistribution_gives_equal_layers() {
        let s = TerminationSchedule::new(TerminationDistribution::Equi, 8);
        let shares = layer_shares(&s);
        for sh in &shares {
            assert!((sh - 1.0 / 8.0).abs() < 1e-6, "{shares:?}");
        }
        assert_eq!(s.probability(8, 0.5), 1.0);
    }

    #[test]
    fn expodistribution_doubles_each_layer() {
        let s = TerminationSchedule::new(TerminationDistribution::Expo, 6);
        let shares = layer_shares(&s);
        let total: f64 = shares.iter().sum();
        assert!((total - 1.0).abs() < 1e-6);
        for w in shares.windows(2) {
            assert!((w[1] / w[0] - 2.0).abs() < 1e-4, "{shares:?}");
        }
    }

    #[test]
    fn bxdf_follows_albedo_and_stops_at_depth() {
        let s = TerminationSchedule::new(TerminationDistribution::Bxdf, 5);
        assert!((s.probability(1, 0.7) - 0.3).abs() < 1e-6);
        assert!((s.probability(2, 1.0) - 0.05).abs() < 1e-6);
        assert_eq!(s.probability(1, f32::NAN), 1.0);
        assert_eq!(s.probability(5, 0.9), 1.0);
    }

    #[test]
    fn throughput_waits_for_rr_depth_then_follows_the_throughput() {
        let s = TerminationSchedule::new(TerminationDistribution::Throughput, 8);
        assert_eq!((s.rr_depth(), s.max_survival()), (5, 0.95));
        // Before k₀ = 5 the entangled sampler never stops, whatever the throughput.
        for k in 1..5 {
            assert_eq!(s.probability_with_throughput(k, 0.5, 1e-6), 0.0, "k = {k}");
        }
        // From k₀ on: T = 1 − min(β·ρ, 0.95).
        assert!((s.probability_with_throughput(5, 0.5, 0.25) - 0.875).abs() < 1e-6);
        assert!((s.probability_with_throughput(6, 0.8, 0.5) - 0.6).abs() < 1e-6);
        assert!((s.probability_with_throughput(7, 0.9, 4.0) - 0.05).abs() < 1e-6);
        assert_eq!(s.probability_with_throughput(7, 0.0, 4.0), 1.0);
        assert_eq!(s.probability_with_throughput(6, 0.5, f32::NAN), 1.0);
        assert!((s.probability_with_throughput(6, 0.5, f32::INFINITY) - 0.05).abs() < 1e-6);
        // The deepest layer always stops, also before k₀.
        assert_eq!(s.probability_with_throughput(8, 0.5, 1.0), 1.0);
        let shallow = TerminationSchedule::new(TerminationDistribution::Throughput, 3);
        assert_eq!(shallow.probability_with_throughput(3, 0.5, 1.0), 1.0);
        assert_eq!(shallow.probability_with_throughput(2, 0.5, 1.0), 0.0);
    }

    #[test]
    fn throughput_roulette_settings_and_untangled_connection() {
        let s =
            TerminationSchedule::new(TerminationDistribution::Throughput, 8).with_roulette(2, 0.8);
        assert_eq!(s.probability_with_throughput(1, 0.5, 1.0), 0.0);
        assert!((s.probability_with_throughput(2, 0.5, 1.0) - 0.5).abs() < 1e-6);
        assert!((s.probability_with_throughput(2, 1.0, 1.0) - 0.2).abs() < 1e-6);
        // The untangled sampler's stop is its light connection: the rule acts from k = 1 on
        // the vertex's albedo alone, capped by q_max.
        assert!((s.connection_probability(1, 0.5) - 0.5).abs() < 1e-6);
        assert!((s.connection_probability(1, 1.0) - 0.2).abs() < 1e-6);
        assert_eq!(s.connection_probability(2, f32::NAN), 1.0);
        assert_eq!(s.connection_probability(8, 0.5), 1.0);
        // q_max is kept inside (0, 1), so T never reaches 0 there.
        let capped =
            TerminationSchedule::new(TerminationDistribution::Throughput, 8).with_roulette(0, 1.0);
        assert_eq!(capped.rr_depth(), 1);
        assert!(capped.connection_probability(1, 1.0) > 0.0);
        // The other distributions ignore the throughput and the roulette settings.
        let b = TerminationSchedule::new(TerminationDistribution::Bxdf, 8).with_roulette(7, 0.5);
        assert!((b.probability_with_throughput(1, 0.7, 0.01) - 0.3).abs() < 1e-6);
        assert!((b.connection_probability(1, 0.7) - 0.3).abs() < 1e-6);
        let e = TerminationSchedule::new(TerminationDistribution::Equi, 4);
        assert!((e.probability_with_throughput(2, 0.7, 0.01) - 1.0 / 3.0).abs() < 1e-6);
    }

    /// Layer shares of the throughput roulette in a white furnace of albedo a, where each
    /// survivor's throughput is deterministic: β_{k+1} = β_k·a / (1 − T_k). With a = ½, N = 8,
    /// k₀ = 5: β_5 = 1/16, so T_5 = 1 − 1/32; a survivor then carries β = 1, and T = ½ after.
    #[test]
    fn throughput_layer_shares_in_a_furnace_are_history_dependent() {
        let a = 0.5f32;
        let s = TerminationSchedule::new(TerminationDistribution::Throughput, 8);
        let mut beta = 1.0f32;
        let mut alive = 1.0f64;
        let mut shares = Vec::new();
        for k in 1..=8 {
            let t = s.probability_with_throughput(k, a, beta);
            shares.push(alive * t as f64);
            alive *= 1.0 - t as f64;
            if t < 1.0 {
                beta *= a / (1.0 - t);
            }
        }
        let expected = [
            0.0,
            0.0,
            0.0,
            0.0,
            31.0 / 32.0,
            1.0 / 64.0,
            1.0 / 128.0,
            1.0 / 128.0,
        ];
        for (got, want) in shares.iter().zip(expected) {
            assert!((got - want).abs() < 1e-6, "{shares:?}");
        }
        // A survivor's throughput is back at one: β_k·a / q_k = 1 once the roulette acts.
        assert!((beta - 1.0).abs() < 1e-6);
    }
}
