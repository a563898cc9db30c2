//! Metropolis–Hastings over primary sample space (Kelemen et al. 2002): the target, the
//! bootstrap that normalises it, and one chain with expected-value splatting.
//!
//! # Target
//! A [`PssTarget`] turns a primary sample vector u into the splats (raster, layer, value) of
//! one sample of its estimator: F(u) = Σ splats, each at its raster position. The chain's
//! scalar target is their luminance sum, f(u) = Σ Y(value) ≥ 0 ([`scalar`]). Over uniform u,
//! E\[F\] is the image, up to the sampler's own scale (the MCPT target's image is MCPT's).
//!
//! # Normalisation (bootstrap)
//! b = ∫ f(u) du, estimated by the mean of f over B independent vectors u_1 … u_B
//! ([`Bootstrap`], each reproduced from its seed). A chain starts at u_j chosen with
//! probability f(u_j) / Σ f (sampling–importance resampling): for every g,
//! E[b̂ · g(X₀)] = E[(1/B) Σ_j f(u_j) g(u_j)] = ∫ f g du, so the start state weighted by b̂ is
//! already distributed as the target, with no start-up bias; a Metropolis–Hastings step keeps
//! f stationary, so E[b̂ · g(X_t)] = ∫ f g du at every t.
//!
//! # Expected-value splatting
//! With current state x and proposal y, the acceptance is a = min(1, f(y)/f(x)) (the small
//! step is symmetric and the large step independent uniform: [`super::samples`]). Instead of
//! the next state's splats, each mutation deposits their expectation over the acceptance:
//! the proposal's splats with weight a·b̂/f(y) and the current state's with
//! (1 − a)·b̂/f(x). By the argument above each mutation's deposits have expectation
//! ∫ F(u) du: M mutations deposit M·∫F in expectation, so dividing the film by M / (W·H)
//! (the host's samples per pixel, when M = W·H·spp) gives the image F estimates.

use super::samples::{Mutation, PrimarySamples};
use flowlight_core::rng::Rng;
use flowlight_core::Rgb;
use glam::Vec2;

/// One deposit of a sample: its raster position, its layer and its value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Splat {
    pub raster: Vec2,
    pub layer: u32,
    pub value: Rgb,
}

/// A sampler whose estimate is a function of primary samples.
pub trait PssTarget {
    /// How many interleaved streams its numbers come from (each a
    /// [`PrimarySamples::start_stream`]).
    fn streams(&self) -> u32;

    /// Evaluates the sample of `samples`' current state: clears `splats`, then pushes the
    /// sample's splats. Draws only from `samples` (the same state gives the same splats).
    fn evaluate(&mut self, samples: &PrimarySamples, splats: &mut Vec<Splat>);
}

/// The chain's scalar target of a sample: the luminance sum of its splats, or `None` when a
/// splat is not finite and non-negative (such a sample counts as f = 0: never a chain state,
/// never deposited; counted as invalid).
pub fn scalar(splats: &[Splat]) -> Option<f32> {
    let mut f = 0.0;
    for s in splats {
        if !s.value.is_valid_radiance() {
            return None;
        }
        f += s.value.luminance();
    }
    f.is_finite().then_some(f)
}

/// The seed of bootstrap vector `i` of a render with seed `seed`.
fn bootstrap_seed(seed: u64, i: u32) -> u64 {
    Rng::hash(&[seed, 0x0050_5353_424f_4f54, i as u64])
}

/// B independent samples of the target: the normalisation b̂ and the weights the chains'
/// start states are resampled by (module documentation).
#[derive(Clone, Debug)]
pub struct Bootstrap {
    seed: u64,
    mutation: Mutation,
    streams: u32,
    /// Running sums of the samples' scalars (f64: B can be large).
    cumulative: Vec<f64>,
    invalid: u64,
}

impl Bootstrap {
    /// Evaluates `count` independent vectors of `target`, vector i drawn from a seed of
    /// (`seed`, i).
    pub fn run<T: PssTarget>(
        target: &mut T,
        seed: u64,
        count: u32,
        mutation: Mutation,
    ) -> Bootstrap {
        let streams = target.streams();
        let mut splats = Vec::new();
        let mut cumulative = Vec::with_capacity(count as usize);
        let (mut sum, mut invalid) = (0.0f64, 0);
        for i in 0..count {
            let samples = PrimarySamples::new(bootstrap_seed(seed, i), mutation, streams);
            target.evaluate(&samples, &mut splats);
            let f = scalar(&splats).unwrap_or_else(|| {
                invalid += 1;
                0.0
            });
            sum += f as f64;
            cumulative.push(sum);
        }
        Bootstrap {
            seed,
            mutation,
            streams,
            cumulative,
            invalid,
        }
    }

    /// B, the number of samples.
    pub fn len(&self) -> usize {
        self.cumulative.len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.cumulative.is_empty()
    }

    /// b̂: the mean scalar target over the samples (0 without samples).
    pub fn normalisation(&self) -> f64 {
        match self.cumulative.last() {
            Some(&sum) => sum / self.cumulative.len() as f64,
            None => 0.0,
        }
    }

    /// Samples whose splats were not finite and non-negative (counted as f = 0).
    pub fn invalid(&self) -> u64 {
        self.invalid
    }

    /// The scalar target of sample `i`.
    pub fn scalar(&self, i: usize) -> f64 {
        let before = if i == 0 { 0.0 } else { self.cumulative[i - 1] };
        self.cumulative[i] - before
    }

    /// The sample whose scalar's share of the sum covers `u` ∈ [0, 1): sample i with
    /// probability f_i / Σ f. `None` when every scalar is 0.
    pub fn pick(&self, u: f32) -> Option<usize> {
        let total = *self.cumulative.last()?;
        if total <= 0.0 {
            return None;
        }
        let target = u as f64 * total;
        let i = self.cumulative.partition_point(|&c| c <= target);
        // Rounding can leave the target at the total: the last sample with weight.
        let i = i.min(self.cumulative.len() - 1);
        let i = (0..=i).rev().find(|&j| self.scalar(j) > 0.0).unwrap_or(i);
        Some(i)
    }

    /// Sample `i`'s primary vector, as it was evaluated (to be read by the same target).
    pub fn state(&self, i: usize) -> PrimarySamples {
        PrimarySamples::new(
            bootstrap_seed(self.seed, i as u32),
            self.mutation,
            self.streams,
        )
    }
}

/// What chains counted.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ChainCounts {
    pub chains: u64,
    pub mutations: u64,
    pub large_steps: u64,
    pub accepted_large: u64,
    pub accepted_small: u64,
    /// Proposals whose splats were not finite and non-negative (rejected, not deposited).
    pub invalid: u64,
}

impl ChainCounts {
    /// Adds another's counts.
    pub fn add(&mut self, o: &ChainCounts) {
        self.chains += o.chains;
        self.mutations += o.mutations;
        self.large_steps += o.large_steps;
        self.accepted_large += o.accepted_large;
        self.accepted_small += o.accepted_small;
        self.invalid += o.invalid;
    }
}

/// Reusable buffers of a chain (one per thread, so a chain allocates nothing once warm).
#[derive(Default)]
pub struct ChainBuffers {
    current: Vec<Splat>,
    proposal: Vec<Splat>,
}

/// Runs one chain of `mutations` Metropolis–Hastings mutations of `target`, started from a
/// bootstrap sample chosen ∝ its scalar, every number from `chain_seed`. Each mutation hands
/// its weighted splats to `deposit` (expected-value splatting, module documentation): over
/// many chains, the deposits of M mutations sum to M·∫F in expectation. Nothing is deposited
/// when the bootstrap found no light (b̂ = 0). After each mutation `visit` sees the splats
/// of the chain's state (a test histograms the states through it). Returns `None`, having
/// run nothing, when there is no state to start from.
#[allow(clippy::too_many_arguments)]
pub fn run_chain<T: PssTarget>(
    target: &mut T,
    bootstrap: &Bootstrap,
    chain_seed: u64,
    mutations: u64,
    buffers: &mut ChainBuffers,
    counts: &mut ChainCounts,
    deposit: &mut impl FnMut(Splat),
    visit: &mut impl FnMut(&[Splat]),
) -> Option<()> {
    let b = bootstrap.normalisation();
    let mut rng = Rng::new(chain_seed, 1);
    let start = bootstrap.pick(rng.uniform())?;
    let mut samples = bootstrap.state(start);
    target.evaluate(&samples, &mut buffers.current);
    // The state reproduces its bootstrap evaluation; should a target not be deterministic,
    // a non-positive value here would make the chain's weights meaningless.
    let mut f_x = scalar(&buffers.current).filter(|&f| f > 0.0)? as f64;
    samples.reseed(Rng::hash(&[chain_seed, 0x6d75_7461_7465]));
    counts.chains += 1;
    for _ in 0..mutations {
        let large = samples.start_iteration();
        target.evaluate(&samples, &mut buffers.proposal);
        let f_y = match scalar(&buffers.proposal) {
            Some(f) => f as f64,
            None => {
                counts.invalid += 1;
                0.0
            }
        };
        let a = (f_y / f_x).min(1.0);
        if a > 0.0 {
            let w = (a * b / f_y) as f32;
            for s in &buffers.proposal {
                deposit(Splat {
                    value: s.value * w,
                    ..*s
                });
            }
        }
        if a < 1.0 {
            let w = ((1.0 - a) * b / f_x) as f32;
            for s in &buffers.current {
                deposit(Splat {
                    value: s.value * w,
                    ..*s
                });
            }
        }
        counts.mutations += 1;
        counts.large_steps += u64::from(large);
        if (rng.uniform() as f64) < a {
            samples.accept();
            std::mem::swap(&mut buffers.current, &mut buffers.proposal);
            f_x = f_y;
            if large {
                counts.accepted_large += 1;
            } else {
                counts.accepted_small += 1;
            }
        } else {
            samples.reject();
        }
        visit(&buffers.current);
    }
    Some(())
}
