//! # `drill` — narrow caps through the original path (thesis §5.5)
//!
//! Moves the eye ray inside its film window and drills along the original path: at each
//! smooth vertex the next direction is drawn uniformly in a cap around the direction to the
//! original next vertex, Dirac vertices are followed, and a caustic remainder (any Dirac vertex
//! before the light, e.g. EDSL, EDTTL) is drilled until the light is struck. Otherwise, after
//! the first cap step, it reconnects hard with probability `p_stop` at each smooth vertex.
//! Ratio: the product over cap steps of p_cap(x)J(x)/(p_cap(y)J(y)) (see `soft-reconnection`).
//!
//! | parameter | type | default | meaning |
//! |---|---|---|---|
//! | `width` | string | `"narrow"` | `"narrow"` (2° caps) or `"wide"` (10° caps) |
//! | `cap_degrees` | float | by width | cap half-angle, overrides `width` |
//! | `p_stop` | float | 0.5 | probability of reconnecting at a smooth vertex of a non-caustic remainder |
//! | `free_chains` | bool | true | follow mirror chains to any length (`flowlight_mcmc::regenerate`, "Dirac chains of any length"; docs/erpt.md); `false`: Veach's rule, every chain keeps x's number of vertices |

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

use flowlight_mcmc::strategy::{cap_degrees, probability};
use flowlight_mcmc::{Extension, Policy, Strategy, StrategyMutation};
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::{export_mutation, param, ParamKind, Params};

pub struct Drill;

impl Strategy for Drill {
    const NAME: &'static str = "drill";
    const DESCRIPTION: &'static str =
        "cap-sampled drilling along the original path; caustics drilled to the light";
    const PARAMS: &'static [ParamSpec] = &[
        param(
            "width",
            ParamKind::String,
            "\"narrow\"",
            "\"narrow\" (2 degree caps) or \"wide\" (10 degree caps)",
        ),
        param(
            "cap_degrees",
            ParamKind::Float,
            "by width",
            "cap half-angle in degrees (overrides width)",
        ),
        param(
            "p_stop",
            ParamKind::Float,
            "0.5",
            "probability of reconnecting at a smooth vertex (non-caustic remainder)",
        ),
        param(
            "free_chains",
            ParamKind::Bool,
            "true",
            "follow mirror chains to whatever length they have (false: keep every chain's number of bounces)",
        ),
    ];

    fn policy(p: &Params) -> Result<Policy, String> {
        let default_cap = match p.choice("width", "narrow", &["narrow", "wide"])? {
            "narrow" => 2.0,
            _ => 10.0,
        };
        Ok(Policy {
            min_extensions: 1,
            p_reconnect: probability(p, "p_stop", 0.5)?,
            extension: Some(Extension::cap_degrees(cap_degrees(
                p,
                "cap_degrees",
                default_cap,
            )?)),
            drill_caustics: true,
            free_chains: p.boolean("free_chains", true)?,
        })
    }
}

export_mutation!(StrategyMutation<Drill>);
