//! # `hard-reconnection` — strict reconnection mutation
//!
//! Moves the eye ray inside its film window (K×K, the chain's `film_window`), follows it (and
//! any Dirac vertices right after the eye) to the first smooth vertex y_k, and connects y_k
//! to the original path's next vertex x_{k+1}, keeping the rest of the original path.
//! The reconnection is deterministic (a Dirac step, thesis §5.4) and the film move symmetric,
//! so T(y→x)/T(x→y) = 1. A proposal is a domain miss when the eye ray finds a vertex of another
//! type, x_{k+1} is a Dirac vertex (no connection possible), or the connection is blocked.
//!
//! No parameters.

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

use flowlight_mcmc::{Policy, Strategy, StrategyMutation};
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::{export_mutation, Params};

pub struct HardReconnection;

impl Strategy for HardReconnection {
    const NAME: &'static str = "hard-reconnection";
    const DESCRIPTION: &'static str =
        "film-plane migration + strict reconnection y_k -> x_{k+1} (ratio 1)";
    const PARAMS: &'static [ParamSpec] = &[];

    fn policy(_: &Params) -> Result<Policy, String> {
        Ok(Policy {
            min_extensions: 0,
            p_reconnect: 1.0,
            extension: None,
            drill_caustics: false,
            free_chains: false,
        })
    }
}

export_mutation!(StrategyMutation<HardReconnection>);
