//! # `drill` — narrow caps through the original path (thesis §5.5)
//!
//! Moves the eye ray inside its film window and drills along the original path: at each
//! smooth vertex the next direction is drawn uniformly in a cap around the direction to the
//! original next vertex, Dirac vertices are followed, and a caustic remainder (any Dirac vertex
//! before the light, e.g. EDSL, EDTTL) is drilled until the light is struck. Otherwise, after
//! the first cap step, it reconnects hard with probability `p_stop` at each smooth vertex.
//! Ratio: the product over cap steps of p_cap(x)J(x)/(p_cap(y)J(y)) (see `soft-reconnection`).
//!
//! Parameters: declared below; their table, generated from the declarations, is in
//! docs/erpt.md ("The strategies"), and `flowlight plugins --markdown` prints it.

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

use flowlight_mcmc::params::FREE_CHAINS;
use flowlight_mcmc::{Extension, Policy, Strategy, StrategyMutation};
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::declare::{ChoiceParam, FloatParam};
use flowlight_sdk::{choice_param, export_mutation, float_param, Params};

/// `width`: the caps' default size.
const WIDTH: ChoiceParam = choice_param!(
    "width",
    "narrow",
    ["narrow", "wide"],
    "\"narrow\" (2 degree caps) or \"wide\" (10 degree caps)"
);

/// `cap_degrees`: the caps' half-angle, by default the one `width` names.
const CAP_DEGREES: FloatParam = float_param!(
    "cap_degrees",
    unset "by width",
    0.0 < x <= 90.0,
    "cap half-angle in degrees (overrides width)"
);

/// `p_stop`: the probability of reconnecting at a smooth vertex.
const P_STOP: FloatParam = float_param!(
    "p_stop",
    0.5,
    0.0 <= x <= 1.0,
    "probability of reconnecting at a smooth vertex of a non-caustic remainder"
);

pub struct Drill;

impl Strategy for Drill {
    const NAME: &'static str = "drill";
    const DESCRIPTION: &'static str =
        "cap-sampled drilling along the original path; caustics drilled to the light";
    const PARAMS: &'static [ParamSpec] = &[
        WIDTH.spec(),
        CAP_DEGREES.spec(),
        P_STOP.spec(),
        FREE_CHAINS.spec(),
    ];

    fn policy(p: &Params) -> Result<Policy, String> {
        let by_width = match WIDTH.get(p)? {
            "narrow" => 2.0,
            _ => 10.0,
        };
        Ok(Policy {
            min_extensions: 1,
            p_reconnect: P_STOP.get(p)? as f32,
            extension: Some(Extension::cap_degrees(
                CAP_DEGREES.get_or(p, by_width)? as f32
            )),
            drill_caustics: true,
            free_chains: FREE_CHAINS.get(p)?,
        })
    }
}

export_mutation!(StrategyMutation<Drill>);
