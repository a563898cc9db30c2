//! Primary-sample-space Metropolis light transport (Kelemen, Szirmay-Kalos, Antal and
//! Csonka 2002, "A Simple and Robust Mutation Strategy for the Metropolis Light Transport
//! Algorithm"): Markov chains over the uniform numbers a sampler turns into paths, instead of
//! over the paths (the thesis' ERPT, ch. 5, mutates paths).
//!
//! * [`samples`]: the primary sample vector, its lazy large and small steps, its interleaved
//!   streams, and the cursor a sampler draws from ([`PssStream`]).
//! * [`chain`]: the target a sampler exposes ([`PssTarget`]), the bootstrap normalisation
//!   ([`Bootstrap`]) and one Metropolis–Hastings chain with expected-value splatting
//!   ([`run_chain`]); the formulas are there.
//! * [`bootstrap`]: the bootstrap built in pieces by the work units that wait for it.
//! * [`large_steps`]: Kelemen's balance of the large steps against the chain.
//! * [`units`]: chains per host work unit, so that `spp` keeps MCPT's meaning.
//! * [`mcpt`]: entangled MCPT as a target.
//! * [`bdpt`]: BDPT (every strategy of one sample) as a target.
//! * [`mmlt`]: multiplexed MLT: one BDPT strategy per sample, per-depth chains.
//! * [`params`]: the mutation parameters the plugins share.
//!
//! The `pssmlt` plugin is the user; docs/pssmlt.md is the user documentation.

pub mod bdpt;
pub mod bootstrap;
pub mod chain;
pub mod large_steps;
pub mod mcpt;
pub mod mmlt;
pub mod params;
pub mod samples;
pub mod units;

#[cfg(test)]
mod tests;

pub use bootstrap::{BootstrapCell, BootstrapPlan, BootstrapTotals};
pub use chain::{run_chain, scalar, Bootstrap, Chain, ChainBuffers, ChainCounts, PssTarget, Splat};
pub use mcpt::McptTarget;
pub use samples::{Mutation, PrimarySamples, PssStream};
pub use units::{chain_seed, render_unit, render_unit_in_chains, PssCounters, TileChains};
