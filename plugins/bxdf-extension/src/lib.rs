//! # `bxdf-extension` — free extension mutation
//!
//! Moves the eye ray inside its film window, and at the first smooth vertex y_k samples a new
//! direction from the BSDF (its smooth components) — a free extension — then reconnects hard
//! to the original path as soon as it can (or ends on a light). Ratio, in area measure:
//!
//! ```text
//! T(y→x)/T(x→y) = p_bsdf(x_k → x_{k+1}) J(x_k→x_{k+1}) / (p_bsdf(y_k → y_{k+1}) J(y_k→y_{k+1}))
//! ```
//!
//! For a Lambertian vertex p_bsdf = cos θ/π, and the ratio of the densities alone is the
//! thesis' cos θ_x / cos θ_y form (§5.4); the Jacobians cancel against the target function's
//! geometric terms.
//!
//! No parameters.

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

use flowlight_mcmc::{Extension, Policy, Strategy, StrategyMutation};
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::{export_mutation, Params};

pub struct BxdfExtension;

impl Strategy for BxdfExtension {
    const NAME: &'static str = "bxdf-extension";
    const DESCRIPTION: &'static str =
        "film-plane migration + one BSDF-sampled extension, then reconnection";
    const PARAMS: &'static [ParamSpec] = &[];

    fn policy(_: &Params) -> Result<Policy, String> {
        Ok(Policy {
            min_extensions: 1,
            p_reconnect: 1.0,
            extension: Some(Extension::Bsdf),
            drill_caustics: false,
            free_chains: false,
        })
    }
}

export_mutation!(StrategyMutation<BxdfExtension>);
