//! How the host's work units map onto chains.
//!
//! The host renders work units, a tile of P pixels × a range of sample indices, and
//! normalises a flanged integrator's film by the samples per pixel it completed (a pass cut
//! short counts the share of its tiles done). A unit runs **one chain per sample index s of
//! its range, of P mutations each**, seeded from (render seed, tile, s): the whole render is
//! W·H mutations per sample index, W·H·spp in all, so by [`super::chain`]'s argument the
//! film's sum per pixel is spp times the target's image in expectation, and the host's
//! division by spp gives the image, under a time budget too. A chain's numbers depend only on
//! (seed, tile, s), not on which unit or thread runs it, nor on how the samples are split
//! into units: the image does not depend on the thread count (it does on the tile size,
//! which sets the chains' length).
//!
//! The bootstrap must be drawn from the render seed: with one fixed bootstrap every render
//! would share its b̂, and the mean of renders would be the image times b̂/b. The host's
//! `prepare` does not know the seed, so the first work unit of a render computes it
//! ([`BootstrapCell`]) while the others wait for it; its numbers depend only on the seed.
//!
//! Each chain starts from a bootstrap state resampled ∝ its scalar, so short chains (small
//! tiles) cost one evaluation more per P mutations and explore less, but stay unbiased.

use super::chain::{run_chain, Bootstrap, ChainBuffers, ChainCounts, PssTarget, Splat};
use flowlight_core::rng::Rng;
use flowlight_sdk::stats::{Counter, Stats, StatsBuilder};
use flowlight_sdk::WorkUnit;
use std::sync::{Arc, Mutex, PoisonError};

/// The bootstrap of a render seed (`pssmlt`'s [`Bootstrap`], or `mmlt`'s per-depth one),
/// computed once by the first work unit that asks for it (the others wait on the lock), and
/// again only for another seed: a fixed bootstrap would scale every render alike, biasing the
/// mean over renders.
pub struct BootstrapCell<B = Bootstrap> {
    inner: Mutex<Option<(u64, Arc<B>)>>,
}

impl<B> Default for BootstrapCell<B> {
    fn default() -> Self {
        BootstrapCell {
            inner: Mutex::new(None),
        }
    }
}

impl<B> BootstrapCell<B> {
    /// The bootstrap of render seed `seed`, from `run` if none is stored for that seed, and
    /// whether this call ran it (so that its cost is reported once).
    pub fn get_or_run(&self, seed: u64, run: impl FnOnce() -> B) -> (Arc<B>, bool) {
        let mut guard = self.inner.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some((stored, b)) = guard.as_ref() {
            if *stored == seed {
                return (b.clone(), false);
            }
        }
        let b = Arc::new(run());
        *guard = Some((seed, b.clone()));
        (b, true)
    }
}

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

/// The chain counters a primary-sample-space plugin reports (`pssmlt`, `mmlt`): chains,
/// mutations, large steps, accepted large and small steps, the large-step acceptance and
/// the invalid samples.
#[derive(Clone, Copy, Debug)]
pub struct ChainCounters {
    chains: Counter,
    mutations: Counter,
    large_steps: Counter,
    accepted_large: Counter,
    accepted_small: Counter,
    invalid: Counter,
}

impl ChainCounters {
    /// Declares the counters.
    pub fn declare(stats: &mut StatsBuilder) -> ChainCounters {
        let mutations = stats.sum("mutations");
        let large_steps = stats.sum("large steps");
        let accepted_large = stats.sum("accepted large steps");
        let accepted_small = stats.sum("accepted small steps");
        stats.ratio("large-step acceptance", accepted_large, large_steps);
        ChainCounters {
            chains: stats.sum("chains"),
            mutations,
            large_steps,
            accepted_large,
            accepted_small,
            invalid: stats.sum("invalid samples"),
        }
    }

    /// Reports a unit's counts (and, as `invalid samples`, `extra_invalid` more: a
    /// bootstrap's).
    pub fn report(&self, stats: &mut Stats, c: &ChainCounts, extra_invalid: u64) {
        stats.add(self.chains, c.chains as f64);
        stats.add(self.mutations, c.mutations as f64);
        stats.add(self.large_steps, c.large_steps as f64);
        stats.add(self.accepted_large, c.accepted_large as f64);
        stats.add(self.accepted_small, c.accepted_small as f64);
        stats.add(self.invalid, (c.invalid + extra_invalid) as f64);
    }
}
