//! Path-space Markov chain machinery, compiled into the ERPT integrator and into every mutation
//! plugin so that the target function and the transition densities agree exactly.
//!
//! It is the mutation tier of the plugin SDK: a plugin outside this workspace depends on it
//! as on `flowlight-sdk` (by path, `flowlight-mcmc = { path = ".../crates/flowlight-mcmc" }`,
//! which `flowlight new-plugin --kind mutation` writes) and gets what the in-tree strategies
//! are made of. It depends on the SDK, never the other way round. A strategy is a
//! [`Policy`] of the [`regenerate`] engine turned into a plugin by [`Strategy`] (a complete
//! plugin in [`strategy`]'s docs), or a hand-written `Mutation` that calls
//! [`regenerate::propose_with`] and [`regenerate::density_with`] with a [`RasterMove`] of its
//! own (`plugins/examples/gaussian-lens`); docs/writing-a-plugin.md walks through both.
//!
//! * [`measure`]: the target function f(x) of a stored path and its weak type;
//! * [`migration`]: film-plane migration, a symmetric random walk in a K×K window that travels
//!   with the chain;
//! * [`regenerate`]: the engine all unidirectional mutations of thesis §5.4–5.5 are made of —
//!   regenerate the eye end of the path and reconnect to the original — with its transition
//!   density;
//! * [`perturbation`]: Veach's jump distributions (lens jump, exponential cone) for the lens
//!   and multi-chain perturbations, which run on the [`regenerate`] engine;
//! * [`specular_chain`]: the caustic perturbation, which moves a specular chain from its light
//!   side, with the Jacobian that expresses it in the target function's measure;
//! * [`norms`]: the acceptance/rejection/hit/miss strength and streak norms of §5.5.

#![warn(missing_docs)]

pub mod measure;
pub mod migration;
pub mod norms;
pub mod params;
pub mod perturbation;
pub mod regenerate;
pub mod specular_chain;
pub mod strategy;
#[cfg(test)]
mod testscene;

pub use measure::{measurement, WeakNode};
pub use regenerate::{Extension, FilmMove, Policy, RasterMove};
pub use strategy::{Strategy, StrategyMutation};
