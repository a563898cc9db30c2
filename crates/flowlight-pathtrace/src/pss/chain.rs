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
//!
//! With [`Bootstrap::combine_large_steps`] the weights become Kelemen's balance of the chain
//! against its large steps, b̂/f → b̂/(f + p·c) and a large step's proposal gaining
//! c/(f(y) + p·c), with the same expectation per mutation ([`super::large_steps`]).

use super::bootstrap::{evaluate, Evaluated, ScaleEstimate};
use super::large_steps::LargeStepWeights;
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
pub(super) fn bootstrap_seed(seed: u64, i: u32) -> u64 {
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
    /// The large steps' balance weights, when the chains combine them
    /// ([`Bootstrap::combine_large_steps`]).
    large_steps: Option<LargeStepWeights>,
    /// The vectors of the scale estimate combined with it, and how many were invalid.
    scale_vectors: u64,
    scale_invalid: u64,
}

impl Bootstrap {
    /// Evaluates `count` independent vectors of `target`, vector i drawn from a seed of
    /// (`seed`, i) (on one thread; [`super::bootstrap`] shares the vectors out).
    pub fn run<T: PssTarget>(
        target: &mut T,
        seed: u64,
        count: u32,
        mutation: Mutation,
    ) -> Bootstrap {
        let evaluated = evaluate(target, seed, false, 0..count, mutation);
        Bootstrap::from_pieces(seed, mutation, target.streams(), [&evaluated])
    }

    /// The bootstrap of seed `seed` over a target of `streams` streams from the evaluations
    /// of its vectors, piece by piece in vector order (summed in that order, so any split of
    /// the vectors gives the same bits).
    pub fn from_pieces<'e>(
        seed: u64,
        mutation: Mutation,
        streams: u32,
        pieces: impl IntoIterator<Item = &'e Evaluated>,
    ) -> Bootstrap {
        let (mut cumulative, mut sum, mut invalid) = (Vec::new(), 0.0f64, 0);
        for e in pieces {
            cumulative.reserve(e.scalars.len());
            for &f in &e.scalars {
                sum += f as f64;
                cumulative.push(sum);
            }
            invalid += e.invalid;
        }
        Bootstrap {
            seed,
            mutation,
            streams,
            cumulative,
            invalid,
            large_steps: None,
            scale_vectors: 0,
            scale_invalid: 0,
        }
    }

    /// Weights for large-step probability `probability` although the chains draw theirs with
    /// the mutation's: a deliberately wrong combination, for the test that must fail.
    #[cfg(test)]
    pub(crate) fn combine_large_steps_as(&mut self, probability: f32, scale: f64) {
        self.large_steps = LargeStepWeights::new(probability, scale);
    }

    /// Makes the chains started from this bootstrap weigh their deposits against their large
    /// steps by the balance heuristic ([`super::large_steps`]), with `scale.c` an estimate of b
    /// drawn independently of this bootstrap (its vectors and invalid ones count as the
    /// bootstrap's: [`Bootstrap::samples`], [`Bootstrap::invalid`]); a c of 0 (or a
    /// large-step probability of 0) keeps the plain splatting.
    pub fn combine_large_steps(&mut self, scale: ScaleEstimate) {
        self.large_steps = LargeStepWeights::new(self.mutation.large_step, scale.c);
        self.scale_vectors = scale.vectors;
        self.scale_invalid = scale.invalid;
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

    /// The vectors evaluated to build it: B, and the scale estimate's.
    pub fn samples(&self) -> u64 {
        self.cumulative.len() as u64 + self.scale_vectors
    }

    /// Samples (of the bootstrap and its scale estimate) whose splats were not finite and
    /// non-negative (counted as f = 0).
    pub fn invalid(&self) -> u64 {
        self.invalid + self.scale_invalid
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
    /// A spare splat list for the next chain's current state.
    current: Vec<Splat>,
    proposal: Vec<Splat>,
}

/// One Metropolis–Hastings chain of a target between its mutations: its primary sample
/// vector, the generator of its start and acceptances, its state's scalar and splats. A
/// chain can be advanced in pieces (a tile's chain runs on across its work units,
/// [`super::units`]): the mutations of `advance(m)` then `advance(n)` are those of
/// `advance(m + n)`.
pub struct Chain {
    samples: PrimarySamples,
    rng: Rng,
    f_x: f64,
    current: Vec<Splat>,
}

impl Chain {
    /// A chain started from a bootstrap sample chosen ∝ its scalar, every number from
    /// `chain_seed`; `None` when there is no state to start from (the bootstrap found no
    /// light). Counts the chain.
    pub fn start<T: PssTarget>(
        target: &mut T,
        bootstrap: &Bootstrap,
        chain_seed: u64,
        buffers: &mut ChainBuffers,
        counts: &mut ChainCounts,
    ) -> Option<Chain> {
        let mut rng = Rng::new(chain_seed, 1);
        let start = bootstrap.pick(rng.uniform())?;
        let mut samples = bootstrap.state(start);
        let mut current = std::mem::take(&mut buffers.current);
        target.evaluate(&samples, &mut current);
        // The state reproduces its bootstrap evaluation; should a target not be
        // deterministic, a non-positive value here would make the chain's weights meaningless.
        let Some(f_x) = scalar(&current).filter(|&f| f > 0.0) else {
            buffers.current = current;
            return None;
        };
        samples.reseed(Rng::hash(&[chain_seed, 0x6d75_7461_7465]));
        counts.chains += 1;
        Some(Chain {
            samples,
            rng,
            f_x: f_x as f64,
            current,
        })
    }

    /// Hands the chain's splat list back to `buffers` for the next chain.
    pub fn recycle(self, buffers: &mut ChainBuffers) {
        buffers.current = self.current;
    }

    /// Runs `mutations` mutations of `target` (which must be the one the chain started
    /// with, over `bootstrap`). Each mutation hands its weighted splats to `deposit`
    /// (expected-value splatting, module documentation); after each, `visit` sees the
    /// splats of the chain's state (a test histograms the states through it).
    #[allow(clippy::too_many_arguments)]
    pub fn advance<T: PssTarget>(
        &mut self,
        target: &mut T,
        bootstrap: &Bootstrap,
        mutations: u64,
        buffers: &mut ChainBuffers,
        counts: &mut ChainCounts,
        deposit: &mut impl FnMut(Splat),
        visit: &mut impl FnMut(&[Splat]),
    ) {
        let b = bootstrap.normalisation();
        let proposal = &mut buffers.proposal;
        for _ in 0..mutations {
            let large = self.samples.start_iteration();
            target.evaluate(&self.samples, proposal);
            let f_y = match scalar(proposal) {
                Some(f) => f as f64,
                None => {
                    counts.invalid += 1;
                    0.0
                }
            };
            let a = (f_y / self.f_x).min(1.0);
            if a > 0.0 {
                let w = match &bootstrap.large_steps {
                    Some(m) => m.proposal(a, b, f_y, large),
                    None => a * b / f_y,
                } as f32;
                for s in proposal.iter() {
                    deposit(Splat {
                        value: s.value * w,
                        ..*s
                    });
                }
            }
            if a < 1.0 {
                let w = match &bootstrap.large_steps {
                    Some(m) => m.current(a, b, self.f_x),
                    None => (1.0 - a) * b / self.f_x,
                } as f32;
                for s in &self.current {
                    deposit(Splat {
                        value: s.value * w,
                        ..*s
                    });
                }
            }
            counts.mutations += 1;
            counts.large_steps += u64::from(large);
            if (self.rng.uniform() as f64) < a {
                self.samples.accept();
                std::mem::swap(&mut self.current, proposal);
                self.f_x = f_y;
                if large {
                    counts.accepted_large += 1;
                } else {
                    counts.accepted_small += 1;
                }
            } else {
                self.samples.reject();
            }
            visit(&self.current);
        }
    }
}

/// Runs one chain of `mutations` Metropolis–Hastings mutations of `target`, started from a
/// bootstrap sample chosen ∝ its scalar, every number from `chain_seed` ([`Chain`]). Each
/// mutation hands its weighted splats to `deposit` (expected-value splatting, module
/// documentation): over many chains, the deposits of M mutations sum to M·∫F in
/// expectation. After each mutation `visit` sees the splats of the chain's state. Returns
/// `None`, having run nothing, when there is no state to start from (b̂ = 0).
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
    let mut chain = Chain::start(target, bootstrap, chain_seed, buffers, counts)?;
    chain.advance(
        target, bootstrap, mutations, buffers, counts, deposit, visit,
    );
    chain.recycle(buffers);
    Some(())
}
