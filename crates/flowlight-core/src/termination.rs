//! Depth-based termination distributions (thesis §3.8).
//!
//! A path tracer decides at its k-th lighting vertex (k = 1 … N, N the path-space depth) to
//! stop with probability T_k. Choosing T_k fixes how samples are spread over lighting layers:
//!
//! * BxDF-based: T_k = 1 − clamp(albedo, 0, 0.95), the common albedo Russian roulette;
//! * equidistribution: every layer gets the same share, T_k = 1 / (N − k + 1);
//! * expodistribution: the share of layer k grows geometrically, P(k) = α₁ q^{N−k} with
//!   q = ½ and α₁ = ½ · 2^N / (2^N − 1), so T_k = P(k) / (1 − Σ_{i<k} P(i)).
//!
//! All three end with T_N = 1. Estimators divide by the probability of the branch they take,
//! so every choice is unbiased; only the variance per layer changes.

/// The termination distribution chosen in the integrator's config.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum TerminationDistribution {
    Bxdf = 0,
    Equi = 1,
    Expo = 2,
}

impl TerminationDistribution {
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "bxdf" => Some(Self::Bxdf),
            "equi" => Some(Self::Equi),
            "expo" => Some(Self::Expo),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Bxdf => "bxdf",
            Self::Equi => "equi",
            Self::Expo => "expo",
        }
    }
}

/// Termination probabilities T_1 … T_N for a path-space depth N, precomputed once per render.
#[derive(Clone, Debug)]
pub struct TerminationSchedule {
    kind: TerminationDistribution,
    /// `table[k-1] = T_k` for the depth-only distributions.
    table: Vec<f32>,
}

impl TerminationSchedule {
    pub fn new(kind: TerminationDistribution, depth: u32) -> Self {
        let n = depth.max(1) as usize;
        let table = match kind {
            TerminationDistribution::Bxdf => vec![0.0; n],
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
        TerminationSchedule { kind, table }
    }

    pub fn depth(&self) -> u32 {
        self.table.len() as u32
    }

    pub fn kind(&self) -> TerminationDistribution {
        self.kind
    }

    /// T_k at lighting vertex `k` (1-based) of a surface whose BSDF albedo estimate is
    /// `albedo`. Beyond the depth the path always stops.
    #[inline]
    pub fn probability(&self, k: u32, albedo: f32) -> f32 {
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
            _ => self.table[k as usize - 1],
        }
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
}
