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
//! Parameters: declared below; their table, generated from the declarations, is in
//! docs/erpt.md ("The strategies"), and `flowlight plugins --markdown` prints it.

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

use flowlight_mcmc::{Extension, Policy, Strategy, StrategyMutation};
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::declare::{ChoiceParam, FloatParam};
use flowlight_sdk::{choice_param, export_mutation, float_param, Params};

/// `width`: how an extension is sampled.
const WIDTH: ChoiceParam = choice_param!(
    "width",
    "wide",
    ["wide", "narrow"],
    "\"wide\": BSDF-sampled extensions; \"narrow\": extensions in a cap around the original path"
);

/// `cap_degrees`: the cap's half-angle for `"narrow"`.
const CAP_DEGREES: FloatParam = float_param!(
    "cap_degrees",
    10.0,
    0.0 < x <= 90.0,
    "cap half-angle in degrees for \"narrow\""
);

/// `p_reconnect`: above 0, since a blow must be able to reconnect.
const P_RECONNECT: FloatParam = float_param!(
    "p_reconnect",
    0.5,
    0.0 < x <= 1.0,
    "probability of reconnecting at a smooth vertex (above 0: a blow must be able to reconnect)"
);

pub struct Blow;

impl Strategy for Blow {
    const NAME: &'static str = "blow";
    const DESCRIPTION: &'static str =
        "expansion near the eye, random hard reconnection vs extension (corner-trap fix)";
    const PARAMS: &'static [ParamSpec] = &[WIDTH.spec(), CAP_DEGREES.spec(), P_RECONNECT.spec()];

    fn policy(p: &Params) -> Result<Policy, String> {
        let extension = match WIDTH.get(p)? {
            "wide" => Extension::Bsdf,
            _ => Extension::cap_degrees(CAP_DEGREES.get(p)? as f32),
        };
        Ok(Policy {
            min_extensions: 0,
            p_reconnect: P_RECONNECT.get(p)? as f32,
            extension: Some(extension),
            drill_caustics: false,
            free_chains: false,
        })
    }
}

export_mutation!(StrategyMutation<Blow>);
