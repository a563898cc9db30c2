//! How the host's work units map onto chains.
//!
//! The host renders work units, a tile of P pixels × a range of sample indices, and
//! normalises a flanged integrator's film by the samples per pixel it completed (a pass cut
//! short counts the share of its tiles done). A unit runs P mutations per sample index of its
//! range: the whole render is W·H mutations per sample index, W·H·spp in all, so by
//! [`super::chain`]'s argument the film's sum per pixel is spp times the target's image in
//! expectation, and the host's division by spp gives the image, under a time budget too. Two
//! ways to cut those mutations into chains:
//!
//! * [`run_tile_chains`] (`pssmlt`'s [`render_unit_in_chains`], `mmlt`'s
//!   `super::mmlt::render_unit_in_chains`): chains of a fixed length L that run on across
//!   the units of their tile, numbered by the tile's mutation index m = s·P + i; a chain
//!   covers m ∈ [k·L, (k + 1)·L), seeded from (seed, tile, k·L), and is parked in
//!   [`TileChains`] between units. The host runs a flanged integrator's passes one after the
//!   other, so a tile's units come in order of s: the image does not depend on the thread
//!   count.
//! * [`render_unit`] (both with `chain_length = 0`): one chain per sample index s of the
//!   unit, of P mutations, seeded from (seed, tile, s): the image does not depend on the
//!   thread count, but on the tile size, which sets the chains' length.
//!
//! Either way a chain's numbers depend only on the seed, the tile and where it starts, not on
//! which unit or thread runs it. Every chain starts from a bootstrap state resampled ∝ its
//! scalar, so every mutation's deposits have their expectation whatever the chain's age: a
//! chain cut anywhere (a short tile, a time budget, a unit that finds no parked chain) stays
//! unbiased. Short chains cost one evaluation more per chain and repeat the bootstrap's own
//! noise (docs/pssmlt.md, "Work units").
//!
//! The bootstrap must be drawn from the render seed: with one fixed bootstrap every render
//! would share its b̂, and the mean of renders would be the image times b̂/b. The host's
//! `prepare` does not know the seed, so the work units of a render compute it together
//! ([`super::bootstrap::BootstrapCell`]); its numbers depend only on the seed.

use super::bootstrap::BootstrapTotals;
use super::chain::{run_chain, Bootstrap, Chain, ChainBuffers, ChainCounts, PssTarget, Splat};
use flowlight_core::rng::Rng;
use flowlight_sdk::stats::{Counter, Stats, StatsBuilder};
use flowlight_sdk::WorkUnit;
use std::collections::HashMap;
use std::sync::{Mutex, PoisonError};

/// The seed of the chain of sample index `s` of the tile of `unit`.
pub fn chain_seed(unit: &WorkUnit, s: u32) -> u64 {
    Rng::hash(&[
        unit.seed,
        0x5053_534d_4c54,
        unit.x0 as u64,
        unit.y0 as u64,
        unit.x1 as u64,
        unit.y1 as u64,
        s as u64,
    ])
}

/// Runs `unit`'s chains (module documentation), handing their splats to `deposit`.
pub fn render_unit<T: PssTarget>(
    target: &mut T,
    bootstrap: &Bootstrap,
    unit: &WorkUnit,
    buffers: &mut ChainBuffers,
    counts: &mut ChainCounts,
    deposit: &mut impl FnMut(Splat),
) {
    let pixels = (unit.x1 - unit.x0) as u64 * (unit.y1 - unit.y0) as u64;
    for s in unit.sample_begin..unit.sample_begin + unit.sample_count {
        let seed = chain_seed(unit, s);
        run_chain(
            target,
            bootstrap,
            seed,
            pixels,
            buffers,
            counts,
            deposit,
            &mut |_| {},
        );
    }
}

/// A tile's chain parked between two of the tile's work units, with what its runner needs
/// besides the chain (`mmlt`: its depth).
struct Parked<K> {
    /// The render seed it belongs to.
    seed: u64,
    /// The tile mutation index of its next mutation.
    next: u64,
    kind: K,
    chain: Chain,
}

/// Chains of a fixed length that run on across the work units of their tile
/// ([`run_tile_chains`]), parked here between units; keyed by the tile. `K` is what a
/// [`TileChainRunner`] keeps with each chain.
pub struct TileChains<K = ()> {
    parked: Mutex<HashMap<TileKey, Parked<K>>>,
}

/// A tile by its corners (x0, y0, x1, y1).
type TileKey = (u32, u32, u32, u32);

impl<K> Default for TileChains<K> {
    fn default() -> Self {
        TileChains {
            parked: Mutex::new(HashMap::new()),
        }
    }
}

/// The seed of the chain of `unit`'s tile that starts at tile mutation index `m`.
fn tile_chain_seed(unit: &WorkUnit, m: u64) -> u64 {
    Rng::hash(&[
        unit.seed,
        0x4348_4149_4e53,
        unit.x0 as u64,
        unit.y0 as u64,
        unit.x1 as u64,
        unit.y1 as u64,
        m,
    ])
}

/// Where a tile's chain k (of mutations [k·L, (k + 1)·L)) starts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChainStart {
    /// The seed of every number of the chain.
    pub seed: u64,
    /// u_k = frac(U + k·φ) (φ the golden ratio's conjugate, U uniform per tile and render
    /// seed): uniform for every chain, and the successive chains of a tile spread evenly over
    /// [0, 1) (a Kronecker sequence), for a choice made once per chain (`mmlt`'s depth), so
    /// that a tile's few long chains share it out in proportion.
    pub spread: f32,
}

impl ChainStart {
    fn of(unit: &WorkUnit, m: u64, length: u64) -> ChainStart {
        const PHI: f64 = 0.618_033_988_749_894_8;
        let offset = Rng::new(tile_chain_seed(unit, u64::MAX), 0).uniform() as f64;
        let spread = (offset + (m / length) as f64 * PHI).fract() as f32;
        ChainStart {
            seed: tile_chain_seed(unit, m),
            // An f64 just below 1 may round to 1.0 as f32.
            spread: spread.min(1.0 - f32::EPSILON / 2.0),
        }
    }
}

/// What [`run_tile_chains`] asks of a plugin's chains: to start one, to run a piece of one,
/// and to take back a finished one's buffers.
pub trait TileChainRunner {
    /// What a chain keeps besides its state (`mmlt`: its depth; `pssmlt`: nothing).
    type Kind;
    /// A chain started at `start`, or `None` when there is nothing to start from (a
    /// bootstrap that found no light): the unit then deposits nothing more.
    fn start(&mut self, start: ChainStart) -> Option<(Self::Kind, Chain)>;
    /// Runs `mutations` mutations of `chain`.
    fn advance(&mut self, kind: &Self::Kind, chain: &mut Chain, mutations: u64);
    /// A chain that reached its length.
    fn finish(&mut self, chain: Chain);
}

/// Runs `unit`'s P·n mutations (P pixels, n sample indices) as pieces of its tile's chains
/// of `chain_length` mutations each (docs/pssmlt.md, "Work units"). The mutations of the
/// tile are numbered m = s·P + i (sample index s, i < P); a chain covers m ∈ [k·L, (k + 1)·L)
/// and is seeded from (render seed, tile, k·L). The first unit of a chain starts it; a unit
/// whose first mutation lies inside a chain takes it from `chains`, where the tile's previous
/// unit parked it. The host runs a flanged integrator's passes one after the other, so a
/// tile's units come in order of s and the image does not depend on the thread count nor on
/// the tile size beyond how the film is cut into chains' starting points. Should the parked
/// chain not be the one expected (another seed, or a unit run out of order, as the first unit
/// of a distributed part), the piece starts a chain of its own, seeded from its first m:
/// every mutation's deposits keep their expectation whatever the chain's age
/// ([`super::chain`]), so the image stays unbiased.
pub fn run_tile_chains<R: TileChainRunner>(
    runner: &mut R,
    unit: &WorkUnit,
    chain_length: u64,
    chains: &TileChains<R::Kind>,
) {
    let key = (unit.x0, unit.y0, unit.x1, unit.y1);
    let pixels = (unit.x1 - unit.x0) as u64 * (unit.y1 - unit.y0) as u64;
    let length = chain_length.max(1);
    let mut m = unit.sample_begin as u64 * pixels;
    let end = (unit.sample_begin + unit.sample_count) as u64 * pixels;
    let parked = chains
        .parked
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .remove(&key);
    let mut chain = parked
        .filter(|p| p.seed == unit.seed && p.next == m && !m.is_multiple_of(length))
        .map(|p| (p.kind, p.chain));
    while m < end {
        let (kind, mut current) = match chain.take() {
            Some(c) => c,
            // None: no light in the bootstrap, nothing to deposit.
            None => match runner.start(ChainStart::of(unit, m, length)) {
                Some(c) => c,
                None => return,
            },
        };
        let chain_end = (m / length + 1) * length;
        let stop = chain_end.min(end);
        runner.advance(&kind, &mut current, stop - m);
        m = stop;
        if m < chain_end {
            chain = Some((kind, current));
        } else {
            runner.finish(current);
        }
    }
    if let Some((kind, chain)) = chain {
        let parked = Parked {
            seed: unit.seed,
            next: m,
            kind,
            chain,
        };
        chains
            .parked
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .insert(key, parked);
    }
}

/// `pssmlt`'s chains over one target and bootstrap, for [`run_tile_chains`].
struct PssRunner<'r, T, D> {
    target: &'r mut T,
    bootstrap: &'r Bootstrap,
    buffers: &'r mut ChainBuffers,
    counts: &'r mut ChainCounts,
    deposit: &'r mut D,
}

impl<T: PssTarget, D: FnMut(Splat)> TileChainRunner for PssRunner<'_, T, D> {
    type Kind = ();

    fn start(&mut self, start: ChainStart) -> Option<((), Chain)> {
        Chain::start(
            self.target,
            self.bootstrap,
            start.seed,
            self.buffers,
            self.counts,
        )
        .map(|c| ((), c))
    }

    fn advance(&mut self, _: &(), chain: &mut Chain, mutations: u64) {
        chain.advance(
            self.target,
            self.bootstrap,
            mutations,
            self.buffers,
            self.counts,
            self.deposit,
            &mut |_| {},
        );
    }

    fn finish(&mut self, chain: Chain) {
        chain.recycle(self.buffers);
    }
}

/// Runs `unit`'s mutations as pieces of its tile's chains of `chain_length` mutations over
/// `target` ([`run_tile_chains`]), handing their splats to `deposit`; `chain_length` 0 runs
/// one chain per sample index instead ([`render_unit`]).
#[allow(clippy::too_many_arguments)]
pub fn render_unit_in_chains<T: PssTarget>(
    target: &mut T,
    bootstrap: &Bootstrap,
    unit: &WorkUnit,
    chain_length: u64,
    chains: &TileChains,
    buffers: &mut ChainBuffers,
    counts: &mut ChainCounts,
    deposit: &mut impl FnMut(Splat),
) {
    if chain_length == 0 {
        return render_unit(target, bootstrap, unit, buffers, counts, deposit);
    }
    let mut runner = PssRunner {
        target,
        bootstrap,
        buffers,
        counts,
        deposit,
    };
    run_tile_chains(&mut runner, unit, chain_length, chains);
}

/// The counters a primary-sample-space plugin reports (`pssmlt`, `mmlt`): its chains'
/// (chains, mutations, large steps, accepted large and small steps, the large-step
/// acceptance) and its bootstrap's (`bootstrap samples`: the vectors evaluated, scale
/// estimates included; `bootstrap b`: the film's normalisation), and the invalid samples of
/// both.
#[derive(Clone, Copy, Debug)]
pub struct PssCounters {
    chains: Counter,
    mutations: Counter,
    large_steps: Counter,
    accepted_large: Counter,
    accepted_small: Counter,
    invalid: Counter,
    bootstrap_samples: Counter,
    normalisation: Counter,
}

impl PssCounters {
    /// Declares the counters.
    pub fn declare(stats: &mut StatsBuilder) -> PssCounters {
        let mutations = stats.sum("mutations");
        let large_steps = stats.sum("large steps");
        let accepted_large = stats.sum("accepted large steps");
        let accepted_small = stats.sum("accepted small steps");
        stats.ratio("large-step acceptance", accepted_large, large_steps);
        PssCounters {
            chains: stats.sum("chains"),
            mutations,
            large_steps,
            accepted_large,
            accepted_small,
            invalid: stats.sum("invalid samples"),
            bootstrap_samples: stats.sum("bootstrap samples"),
            normalisation: stats.max("bootstrap b"),
        }
    }

    /// Reports a unit's chain counts `c` and what it saw of its seed's `bootstrap`: its
    /// samples and invalid ones only from the unit that assembled it (`assembled`), so that
    /// they count once per seed; its normalisation from every unit (a maximum).
    pub fn report(
        &self,
        stats: &mut Stats,
        c: &ChainCounts,
        bootstrap: &impl BootstrapTotals,
        assembled: bool,
    ) {
        stats.add(self.chains, c.chains as f64);
        stats.add(self.mutations, c.mutations as f64);
        stats.add(self.large_steps, c.large_steps as f64);
        stats.add(self.accepted_large, c.accepted_large as f64);
        stats.add(self.accepted_small, c.accepted_small as f64);
        let mut invalid = c.invalid;
        if assembled {
            invalid += bootstrap.invalid();
            stats.add(self.bootstrap_samples, bootstrap.samples() as f64);
        }
        stats.add(self.invalid, invalid as f64);
        stats.add(self.normalisation, bootstrap.normalisation());
    }
}
