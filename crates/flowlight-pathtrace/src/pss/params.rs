//! The parameters every primary-sample-space plugin declares (`pssmlt`, `mmlt`): the
//! mutation, the chains' length and the large steps' weighting, declared once here so that
//! their names, defaults, ranges and docs cannot drift apart.

use super::Mutation;
use flowlight_sdk::declare::{BoolParam, FloatParam, IntParam};
use flowlight_sdk::{bool_param, float_param, int_param, Params};

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

/// `combine_large_steps`: Kelemen's balance of the chain against its large steps.
pub const COMBINE_LARGE_STEPS: BoolParam = bool_param!(
    "combine_large_steps",
    true,
    "weigh each deposit against the large steps by the balance heuristic (Kelemen et al. 2002, as LuxCore's Metropolis sampler): a large step's proposal also counts as an independent sample, so dark regions the chains rarely visit get a path tracer's estimate; the weights use an estimate of b from bootstrap/8 further independent samples; false: plain expected-value splatting (pbrt-v4's)"
);

/// `chain_length`: mutations per chain, whatever the tile.
pub const CHAIN_LENGTH: IntParam = int_param!(
    "chain_length",
    65536,
    0..=1_000_000_000,
    "mutations per chain: a tile's chains run on across its work units (its passes), each started from the bootstrap, so that the bootstrap's own noise, which every chain's first mutations repeat, is spread over this many mutations; 0: one chain per work unit (a tile's pixels long, the image depending on the tile size)"
);

/// `chain_length` of `mmlt`: shorter than `pssmlt`'s, because each chain renders one depth,
/// and a tile's chains share the depths out in proportion to their brightness only when they
/// are many (at 4 s on six scenes, chains of 65,536 lost 10–17% against 4,096 on the glass
/// caustic and `lens-spot`, docs/results.md).
pub const MMLT_CHAIN_LENGTH: IntParam = int_param!(
    "chain_length",
    4096,
    0..=1_000_000_000,
    "mutations per chain: a tile's chains run on across its work units (its passes), each started from its depth's bootstrap, and each draws its depth once, spread evenly over the tile's chains; 0: one chain per sample index of a work unit (a tile's pixels long, the image depending on the tile size)"
);

/// The mutation `large_step` and `sigma` describe.
pub fn mutation_from_params(p: &Params) -> Result<Mutation, String> {
    Ok(Mutation::new(
        LARGE_STEP.get(p)? as f32,
        SIGMA.get(p)? as f32,
    ))
}
