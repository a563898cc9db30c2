//! Multiplexed Metropolis light transport (Hachisuka, Kaplanyan and Dachsbacher 2014, as
//! pbrt-v4's `MLTIntegrator` implements it): primary-sample-space chains whose target is
//! one bidirectional strategy at a time, the strategy itself chosen by a primary sample, so
//! that a chain moves towards the strategies that sample its paths well.
//!
//! # Target
//! A chain has a fixed depth d (interior vertices; paths of d + 2 vertices). Its state is
//! three interleaved streams: the camera subpath's numbers (stream 0, whose first pair is
//! the raster position), the light subpath's (stream 1) and the strategy choice u (stream 2,
//! one number). [`MmltTarget`] evaluates strategy (s, t) = (min(⌊u(d + 2)⌋, d + 1),
//! d + 2 − s) with [`FilmSampler::strategy_sample`]: F_d(u) = (d + 2) · w_{s,t} f / p_{s,t},
//! one splat at its raster position, and E\[F_d\] over uniform u is the depth-d image. A small
//! step moves u too, so a chain wanders between the strategies of its depth, and stays
//! longer where w_{s,t} f / p_{s,t} is large, i.e. where the strategy samples the path well.
//!
//! # Per-depth bootstrap and the choice of depths
//! [`DepthBootstrap`] runs the pss bootstrap ([`Bootstrap`]) once per depth d = 0 … D with
//! B vectors each: b̂_d, the mean scalar target of depth d (its brightness), and the start
//! states of depth-d chains, resampled ∝ f_d. A chain draws its depth with probability
//! P_d = b̂_d / Σ_k b̂_k, then runs a [`Chain`] over depth d's target and bootstrap, which
//! weighs its splats by b̂_d / f_d (expected-value splatting); its deposits are multiplied
//! by 1/P_d. Given the bootstraps, a mutation's deposits then have expectation
//!
//! ```text
//! Σ_d P_d · (1/P_d) · E[b̂_d · F_d(X_d) / f_d(X_d)] = Σ_d ∫ F_d = ∫ F,
//! ```
//!
//! each term by the pss chain's argument for depth d alone ([`super::chain`]), whose
//! bootstrap is independent of the others: the estimate is unbiased, and the normalisation
//! of the whole film is Σ_d b̂_d. Picking d ∝ b̂_d, then the start state within depth d ∝ f,
//! is the same as pbrt-v4's pick among the union of the depths' bootstrap samples ∝ f.
//! Bright depths get more chains, so more mutations, as in pbrt-v4; the depth of a chain
//! never changes (its target changes dimension with d).
//!
//! # Work units
//! As in [`super::units`]: one chain per sample index of a unit, of P mutations (P the unit's
//! pixels), seeded from (seed, tile, sample index), so that the host's division by spp gives
//! the image and the image does not depend on the thread count.

use super::bootstrap::{assemble_part, evaluate, BootstrapPlan, BootstrapTotals, Evaluated, Piece};
use super::chain::{Bootstrap, Chain, ChainBuffers, ChainCounts, PssTarget, Splat};
use super::samples::{Mutation, PrimarySamples};
use super::units::{chain_seed, run_tile_chains, ChainStart, TileChainRunner, TileChains};
use crate::bidir::sample::{FilmSampler, SampleScratch};
use flowlight_core::rng::Rng;
use flowlight_core::sampler::SampleStream;
use flowlight_sdk::WorkUnit;

/// Strategy samples of one depth over primary samples (module documentation).
pub struct MmltTarget<'s, 'a, 'b> {
    sampler: &'s FilmSampler<'a, 'b>,
    depth: u32,
    scratch: SampleScratch,
}

impl<'s, 'a, 'b> MmltTarget<'s, 'a, 'b> {
    /// Depth `depth` (≤ the sampler's `max_depth`) of `sampler`.
    pub fn new(sampler: &'s FilmSampler<'a, 'b>, depth: u32) -> Self {
        MmltTarget {
            sampler,
            depth,
            scratch: SampleScratch::default(),
        }
    }

    /// The target's depth.
    pub fn depth(&self) -> u32 {
        self.depth
    }
}

/// The stream of the strategy choice (after the camera's 0 and the light's 1).
const STRATEGY_STREAM: u32 = 2;

/// The streams of an [`MmltTarget`]: the camera's, the light's and the strategy's.
const STREAMS: u32 = 3;

impl PssTarget for MmltTarget<'_, '_, '_> {
    fn streams(&self) -> u32 {
        STREAMS
    }

    fn evaluate(&mut self, samples: &PrimarySamples, splats: &mut Vec<Splat>) {
        splats.clear();
        let u = samples.start_stream(STRATEGY_STREAM).uniform();
        let (camera, light) = (samples.start_stream(0), samples.start_stream(1));
        let sample = self
            .sampler
            .strategy_sample(self.depth, u, camera, light, &mut self.scratch);
        if let Some(s) = sample {
            splats.push(Splat {
                raster: s.raster,
                layer: 0,
                value: s.value,
            });
        }
    }
}

/// One bootstrap per depth, and the depths' brightness (module documentation).
#[derive(Clone, Debug)]
pub struct DepthBootstrap {
    depths: Vec<Bootstrap>,
    /// Running sums of b̂_d over d.
    cumulative: Vec<f64>,
}

impl DepthBootstrap {
    /// Bootstraps of `count` vectors for every depth 0 ..= `max_depth` of `sampler`, depth d
    /// from a seed of (`seed`, d), on one thread. With `combine_large_steps`, each depth's
    /// chains weigh their deposits against their large steps ([`super::large_steps`]) with
    /// that depth's c, the mean of count/8 vectors apart from its bootstrap's.
    pub fn run(
        sampler: &FilmSampler,
        max_depth: u32,
        seed: u64,
        count: u32,
        mutation: Mutation,
        combine_large_steps: bool,
    ) -> DepthBootstrap {
        let plan = DepthBootstrap::plan(max_depth, count, combine_large_steps);
        let pieces = plan.pieces();
        let evaluated: Vec<Evaluated> = pieces
            .iter()
            .map(|piece| DepthBootstrap::evaluate_piece(sampler, piece, seed, mutation))
            .collect();
        DepthBootstrap::assemble(&pieces, &evaluated, plan, seed, mutation)
    }

    /// The pieces of [`DepthBootstrap::run`]'s vectors: one part per depth.
    pub fn plan(max_depth: u32, count: u32, combine_large_steps: bool) -> BootstrapPlan {
        BootstrapPlan::new(max_depth + 1, count, combine_large_steps)
    }

    /// The seed of depth `d`'s bootstrap and scale estimate in a render of seed `seed`.
    fn depth_seed(seed: u64, d: u32) -> u64 {
        Rng::hash(&[seed, 0x4d4d_4c54, u64::from(d)])
    }

    /// Evaluates `piece` of a [`DepthBootstrap::plan`] (of render seed `seed`) over `sampler`.
    pub fn evaluate_piece(
        sampler: &FilmSampler,
        piece: &Piece,
        seed: u64,
        mutation: Mutation,
    ) -> Evaluated {
        let mut target = MmltTarget::new(sampler, piece.part);
        let depth_seed = DepthBootstrap::depth_seed(seed, piece.part);
        evaluate(
            &mut target,
            depth_seed,
            piece.scale,
            piece.vectors.clone(),
            mutation,
        )
    }

    /// The bootstrap from `evaluated`, the evaluations of `plan`'s `pieces` in its order.
    pub fn assemble(
        pieces: &[Piece],
        evaluated: &[Evaluated],
        plan: BootstrapPlan,
        seed: u64,
        mutation: Mutation,
    ) -> DepthBootstrap {
        let mut depths = Vec::with_capacity(plan.parts as usize);
        let mut cumulative = Vec::with_capacity(plan.parts as usize);
        let mut sum = 0.0;
        for d in 0..plan.parts {
            let depth_seed = DepthBootstrap::depth_seed(seed, d);
            let bootstrap = assemble_part(pieces, evaluated, d, depth_seed, mutation, STREAMS);
            sum += bootstrap.normalisation();
            cumulative.push(sum);
            depths.push(bootstrap);
        }
        DepthBootstrap { depths, cumulative }
    }

    /// The deepest depth D.
    pub fn max_depth(&self) -> u32 {
        self.depths.len() as u32 - 1
    }

    /// b̂_d: depth `d`'s mean scalar target.
    pub fn brightness(&self, d: u32) -> f64 {
        self.depths[d as usize].normalisation()
    }

    /// Σ_d b̂_d: the normalisation of the whole film.
    pub fn total(&self) -> f64 {
        self.cumulative.last().copied().unwrap_or(0.0)
    }

    /// Depth `d`'s bootstrap.
    pub fn depth(&self, d: u32) -> &Bootstrap {
        &self.depths[d as usize]
    }

    /// The depth whose share of Σ b̂ covers `u` ∈ [0, 1): d with probability b̂_d / Σ b̂.
    /// `None` when every depth is black.
    pub fn pick(&self, u: f32) -> Option<u32> {
        let total = self.total();
        if total <= 0.0 {
            return None;
        }
        let target = u as f64 * total;
        let d = self.cumulative.partition_point(|&c| c <= target);
        let d = d.min(self.cumulative.len() - 1) as u32;
        // Rounding can leave the target at the total: the deepest depth with light.
        (0..=d).rev().find(|&k| self.brightness(k) > 0.0)
    }
}

/// Summed over the depths; the normalisation is Σ_d b̂_d ([`DepthBootstrap::total`]).
impl BootstrapTotals for DepthBootstrap {
    fn samples(&self) -> u64 {
        self.depths.iter().map(Bootstrap::samples).sum()
    }

    fn invalid(&self) -> u64 {
        self.depths.iter().map(Bootstrap::invalid).sum()
    }

    fn normalisation(&self) -> f64 {
        self.total()
    }
}

/// A thread's reusable buffers of MMLT chains.
#[derive(Default)]
pub struct MmltBuffers {
    pub chain: ChainBuffers,
    scratch: SampleScratch,
}

/// What a unit's chains counted: the pss chain counts, and mutations per depth.
#[derive(Clone, Debug, Default)]
pub struct MmltCounts {
    pub chains: ChainCounts,
    pub mutations_per_depth: Vec<u64>,
}

/// Runs `unit`'s chains (module documentation), handing their splats to `deposit`, already
/// multiplied by 1/P_d; `visit` sees each chain's depth and the splats of its state after
/// every mutation.
pub fn render_unit(
    sampler: &FilmSampler,
    bootstrap: &DepthBootstrap,
    unit: &WorkUnit,
    buffers: &mut MmltBuffers,
    counts: &mut MmltCounts,
    deposit: &mut impl FnMut(Splat),
    visit: &mut impl FnMut(u32, &[Splat]),
) {
    let pixels = (unit.x1 - unit.x0) as u64 * (unit.y1 - unit.y0) as u64;
    let mut runner = MmltRunner::new(sampler, bootstrap, buffers, counts, deposit, visit);
    for s in unit.sample_begin..unit.sample_begin + unit.sample_count {
        let seed = chain_seed(unit, s);
        // Stream 3 picks the depth: the chain draws its start and acceptances from stream 1.
        let start = ChainStart {
            seed,
            spread: Rng::new(seed, 3).uniform(),
        };
        let Some((d, mut chain)) = runner.start(start) else {
            return;
        };
        runner.advance(&d, &mut chain, pixels);
        runner.finish(chain);
    }
}

/// `mmlt`'s chains, for [`render_unit`] and [`run_tile_chains`]: a chain's kind is its
/// depth; `visit` sees the depth and the state's splats after every mutation.
struct MmltRunner<'r, 's, 'a, 'b, D, V> {
    sampler: &'s FilmSampler<'a, 'b>,
    bootstrap: &'r DepthBootstrap,
    buffers: &'r mut MmltBuffers,
    counts: &'r mut MmltCounts,
    deposit: &'r mut D,
    visit: &'r mut V,
}

impl<'r, 's, 'a, 'b, D, V> MmltRunner<'r, 's, 'a, 'b, D, V> {
    fn new(
        sampler: &'s FilmSampler<'a, 'b>,
        bootstrap: &'r DepthBootstrap,
        buffers: &'r mut MmltBuffers,
        counts: &'r mut MmltCounts,
        deposit: &'r mut D,
        visit: &'r mut V,
    ) -> Self {
        counts
            .mutations_per_depth
            .resize(bootstrap.max_depth() as usize + 1, 0);
        MmltRunner {
            sampler,
            bootstrap,
            buffers,
            counts,
            deposit,
            visit,
        }
    }

    /// Depth `d`'s target, holding the thread's scratch until [`Self::put_back`].
    fn target(&mut self, d: u32) -> MmltTarget<'s, 'a, 'b> {
        MmltTarget {
            sampler: self.sampler,
            depth: d,
            scratch: std::mem::take(&mut self.buffers.scratch),
        }
    }

    fn put_back(&mut self, target: MmltTarget) {
        self.buffers.scratch = target.scratch;
    }
}

impl<D: FnMut(Splat), V: FnMut(u32, &[Splat])> TileChainRunner
    for MmltRunner<'_, '_, '_, '_, D, V>
{
    type Kind = u32;

    fn start(&mut self, start: ChainStart) -> Option<(u32, Chain)> {
        // The depth from the tile's evenly spread numbers: each chain's is d with probability
        // P_d, and a tile's chains share the depths out in proportion.
        let d = self.bootstrap.pick(start.spread)?;
        let mut target = self.target(d);
        let chain = Chain::start(
            &mut target,
            self.bootstrap.depth(d),
            start.seed,
            &mut self.buffers.chain,
            &mut self.counts.chains,
        );
        self.put_back(target);
        chain.map(|c| (d, c))
    }

    fn advance(&mut self, &d: &u32, chain: &mut Chain, mutations: u64) {
        let scale = (self.bootstrap.total() / self.bootstrap.brightness(d)) as f32;
        let mut target = self.target(d);
        let (deposit, visit) = (&mut *self.deposit, &mut *self.visit);
        chain.advance(
            &mut target,
            self.bootstrap.depth(d),
            mutations,
            &mut self.buffers.chain,
            &mut self.counts.chains,
            &mut |splat: Splat| {
                deposit(Splat {
                    value: splat.value * scale,
                    ..splat
                })
            },
            &mut |state: &[Splat]| visit(d, state),
        );
        self.put_back(target);
        self.counts.mutations_per_depth[d as usize] += mutations;
    }

    fn finish(&mut self, chain: Chain) {
        chain.recycle(&mut self.buffers.chain);
    }
}

/// Runs `unit`'s mutations as pieces of its tile's chains of `chain_length` mutations each
/// ([`run_tile_chains`]; a chain draws its depth once, when it starts), handing their
/// splats, multiplied by 1/P_d, to `deposit`; `chain_length` 0 runs one chain per sample
/// index instead ([`render_unit`]).
#[allow(clippy::too_many_arguments)]
pub fn render_unit_in_chains(
    sampler: &FilmSampler,
    bootstrap: &DepthBootstrap,
    unit: &WorkUnit,
    chain_length: u64,
    chains: &TileChains<u32>,
    buffers: &mut MmltBuffers,
    counts: &mut MmltCounts,
    deposit: &mut impl FnMut(Splat),
) {
    let mut visit = |_: u32, _: &[Splat]| {};
    if chain_length == 0 {
        return render_unit(
            sampler, bootstrap, unit, buffers, counts, deposit, &mut visit,
        );
    }
    let mut runner = MmltRunner::new(sampler, bootstrap, buffers, counts, deposit, &mut visit);
    run_tile_chains(&mut runner, unit, chain_length, chains);
}
