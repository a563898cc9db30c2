//! # `blow` — expansion near the eye (thesis §5.5)
//!
//! Moves the eye ray inside its film window and expands the path near the eye, reconnecting
//! to the original path as early as possible. To escape corner and cavity traps (y₁ and x₂ on
//! the same surface, §5.5) it chooses at each smooth vertex at random between a hard
//! reconnection (probability `p_reconnect`) and an extension; the transition density is the
//! mixture of the two, so each extension step contributes (1 − p_r)·p_ω·J and the
//! reconnection p_r — the expected number of extra rays per mutation stays small (a
//! geometric series).
//!
//! | parameter | type | default | meaning |
//! |---|---|---|---|
//! | `width` | string | `"wide"` | `"wide"`: BSDF-sampled extensions; `"narrow"`: extensions in a cap around the original path |
//! | `cap_degrees` | float | 10 | cap half-angle for `"narrow"` |
//! | `p_reconnect` | float | 0.5 | probability of reconnecting at a smooth vertex |

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

use flowlight_mcmc::strategy::{cap_degrees, probability};
use flowlight_mcmc::{Extension, Policy, Strategy, StrategyMutation};
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::{export_mutation, param, ParamKind, Params};

pub struct Blow;

impl Strategy for Blow {
    const NAME: &'static str = "blow";
    const DESCRIPTION: &'static str =
        "expansion near the eye, random hard reconnection vs extension (corner-trap fix)";
    const PARAMS: &'static [ParamSpec] = &[
        param(
            "width",
            ParamKind::String,
            "\"wide\"",
            "\"wide\" (BSDF extension) or \"narrow\" (cap extension)",
        ),
        param(
            "cap_degrees",
            ParamKind::Float,
            "10.0",
            "cap half-angle for the narrow variant",
        ),
        param(
            "p_reconnect",
            ParamKind::Float,
            "0.5",
            "probability of reconnecting at a smooth vertex",
        ),
    ];

    fn policy(p: &Params) -> Result<Policy, String> {
        let extension = match p.choice("width", "wide", &["wide", "narrow"])? {
            "wide" => Extension::Bsdf,
            _ => Extension::cap_degrees(cap_degrees(p, "cap_degrees", 10.0)?),
        };
        let p_reconnect = probability(p, "p_reconnect", 0.5)?;
        if p_reconnect == 0.0 {
            return Err(
                "parameter 'p_reconnect' must be > 0: a blow must be able to reconnect".into(),
            );
        }
        Ok(Policy {
            min_extensions: 0,
            p_reconnect,
            extension: Some(extension),
            drill_caustics: false,
            free_chains: false,
        })
    }
}

export_mutation!(StrategyMutation<Blow>);
