//! The mutation parameters every primary-sample-space plugin declares (`pssmlt`, `mmlt`):
//! declared once here so that their names, defaults, ranges and docs cannot drift apart.

use super::Mutation;
use flowlight_sdk::declare::FloatParam;
use flowlight_sdk::{float_param, Params};

/// `large_step`: the large-step probability (pbrt-v4's default).
pub const LARGE_STEP: FloatParam = float_param!(
    "large_step",
    0.3,
    0.0 <= x <= 1.0,
    "probability that a mutation is a large step (every primary sample drawn afresh: an independent sample); otherwise a small step"
);

/// `sigma`: the small step's size (pbrt-v4's default).
pub const SIGMA: FloatParam = float_param!(
    "sigma",
    0.01,
    0.0 < x <= 1.0,
    "standard deviation of a small step: every primary sample moves by a normal offset of this size, wrapped into [0, 1)"
);

/// The mutation `large_step` and `sigma` describe.
pub fn mutation_from_params(p: &Params) -> Result<Mutation, String> {
    Ok(Mutation::new(
        LARGE_STEP.get(p)? as f32,
        SIGMA.get(p)? as f32,
    ))
}
