//! Turns a [`Policy`] into a mutation plugin: each strategy crate declares its name and
//! parameters and builds its policy; propose and density come from the shared engine.
//!
//! A whole engine-based mutation plugin, in or out of this workspace (the hard reconnection
//! of thesis §5.5 with a parameter for its reconnection probability):
//!
//! ```
//! use flowlight_mcmc::{Policy, Strategy, StrategyMutation};
//! use flowlight_sdk::declare::FloatParam;
//! use flowlight_sdk::{export_mutation, float_param, ParamSpec, Params};
//!
//! /// `p`: declared once; its spec, its default and its range check come from here.
//! const P: FloatParam = float_param!(
//!     "p",
//!     1.0,
//!     0.0 <= x <= 1.0,
//!     "probability of reconnecting at a smooth vertex"
//! );
//!
//! pub struct Reconnect;
//!
//! impl Strategy for Reconnect {
//!     const NAME: &'static str = "reconnect";
//!     const DESCRIPTION: &'static str = "film migration, then a hard reconnection";
//!     const PARAMS: &'static [ParamSpec] = &[P.spec()];
//!
//!     fn policy(params: &Params) -> Result<Policy, String> {
//!         Ok(Policy {
//!             min_extensions: 0,
//!             p_reconnect: P.get(params)? as f32,
//!             extension: None,
//!             drill_caustics: false,
//!             free_chains: true,
//!         })
//!     }
//! }
//!
//! export_mutation!(StrategyMutation<Reconnect>);
//! # fn main() {}
//! ```

use crate::regenerate::{density, propose, Policy};
use flowlight_core::path::Path;
use flowlight_core::rng::Rng;
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::{Mutation, Params, Proposal, Scene, Stats, StatsBuilder, Tracer};
use std::marker::PhantomData;

/// A named mutation strategy: its parameters and the policy they give.
pub trait Strategy: Send + Sync + 'static {
    /// Name the config uses (`plugin = "NAME"`).
    const NAME: &'static str;
    /// One line for `flowlight plugins`.
    const DESCRIPTION: &'static str;
    /// Parameters the plugin accepts; the host refuses others.
    const PARAMS: &'static [ParamSpec];
    /// The engine policy the parameters give.
    fn policy(params: &Params) -> Result<Policy, String>;
}

/// The mutation plugin made from a [`Strategy`]; export it with
/// `flowlight_sdk::export_mutation!(StrategyMutation<MyStrategy>)`.
pub struct StrategyMutation<S: Strategy> {
    scene: Scene<'static>,
    policy: Policy,
    _strategy: PhantomData<S>,
}

impl<S: Strategy> StrategyMutation<S> {
    /// The policy the parameters gave.
    pub fn policy(&self) -> &Policy {
        &self.policy
    }
}

impl<S: Strategy> Mutation for StrategyMutation<S> {
    const NAME: &'static str = S::NAME;
    const DESCRIPTION: &'static str = S::DESCRIPTION;
    const PARAMS: &'static [ParamSpec] = S::PARAMS;

    fn create(
        params: &Params,
        scene: Scene<'static>,
        _stats: &mut StatsBuilder,
    ) -> Result<Self, String> {
        Ok(StrategyMutation {
            scene,
            policy: S::policy(params)?,
            _strategy: PhantomData,
        })
    }

    fn propose(
        &self,
        tracer: &Tracer,
        rng: &mut Rng,
        current: &Path,
        proposal: &mut Path,
        _stats: &mut Stats,
    ) -> Result<Proposal, String> {
        Ok(propose(
            &self.scene,
            tracer,
            rng,
            &self.policy,
            current,
            proposal,
        ))
    }

    fn density(&self, from: &Path, to: &Path) -> f64 {
        density(&self.scene, &self.policy, from, to)
    }
}
