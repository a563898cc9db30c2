//! # `soft-reconnection` — non-strict reconnection mutation
//!
//! Moves the eye ray inside its film window, and at the first smooth vertex y_k samples a
//! direction uniformly in a spherical cap around the direction to the original x_{k+1}
//! (thesis §5.4: "extension and termination through the soft reconnection"); the new vertex
//! y_{k+1} lands near x_{k+1} or on another object. From y_{k+1} it reconnects hard to
//! x_{k+2} when it can; on a light it ends the path. Ratio, in area measure:
//!
//! ```text
//! T(y→x)/T(x→y) = p_cap(x_k → x_{k+1}) J(x_k→x_{k+1}) / (p_cap(y_k → y_{k+1}) J(y_k→y_{k+1}))
//! ```
//!
//! with p_cap = 1/(2π(1 − cos α)) inside the cap (0 outside: the reverse cap is centred on the
//! direction from x_k to y_{k+1}), so equal caps leave only the Jacobians.
//!
//! Parameters: declared below; their table, generated from the declarations, is in
//! docs/erpt.md ("The strategies"), and `flowlight plugins --markdown` prints it.

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

use flowlight_mcmc::{Extension, Policy, Strategy, StrategyMutation};
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::declare::FloatParam;
use flowlight_sdk::{export_mutation, float_param, Params};

/// `cap_degrees`: the cap's half-angle α.
const CAP_DEGREES: FloatParam = float_param!(
    "cap_degrees",
    5.0,
    0.0 < x <= 90.0,
    "cap half-angle alpha in degrees"
);

pub struct SoftReconnection;

impl Strategy for SoftReconnection {
    const NAME: &'static str = "soft-reconnection";
    const DESCRIPTION: &'static str =
        "film-plane migration + cap-sampled reconnection around x_{k+1}";
    const PARAMS: &'static [ParamSpec] = &[CAP_DEGREES.spec()];

    fn policy(p: &Params) -> Result<Policy, String> {
        Ok(Policy {
            min_extensions: 1,
            p_reconnect: 1.0,
            extension: Some(Extension::cap_degrees(CAP_DEGREES.get(p)? as f32)),
            drill_caustics: false,
            free_chains: false,
        })
    }
}

export_mutation!(StrategyMutation<SoftReconnection>);
