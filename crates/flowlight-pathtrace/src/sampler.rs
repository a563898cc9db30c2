//! Where a pixel sample's random numbers come from, for the plugins that trace camera paths
//! (MCPT, ERPT's entangled seeds): the `sampler` parameter.
//!
//! Both sources depend only on (render seed, pixel, sample index), so an image does not
//! depend on threads, tiles or distributed parts. See docs/mcpt.md, "Samplers".

use flowlight_core::rng::Rng;
use flowlight_core::sampler::SampleStream;
use flowlight_core::sobol::SobolSampler;
use flowlight_sdk::declare::ChoiceParam;
use flowlight_sdk::{choice_param, Params};
use glam::Vec2;

/// The `sampler` parameter's choices.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SamplerKind {
    /// A PCG32 stream per sample.
    Independent,
    /// Sobol' points of a shuffled index, digitally shifted: a pixel's samples stratified
    /// together.
    Sobol,
}

/// `sampler`: where a pixel sample's random numbers come from (MCPT; ERPT's entangled seeds).
pub const SAMPLER: ChoiceParam = choice_param!(
    "sampler",
    "sobol",
    ["sobol", "independent"],
    "entangled paths only (untangled: \"independent\", and \"sobol\" is refused): \"sobol\", Sobol' points of a per-dimension shuffled index, digitally shifted (a pixel's samples stratified together; unbiased), or \"independent\", a PCG32 stream per sample"
);

impl SamplerKind {
    /// The `sampler` parameter ([`SAMPLER`]) of a plugin whose camera paths are entangled
    /// (`entangled`) or untangled. Untangled paths default to `"independent"` and refuse
    /// `"sobol"`, naming `needs` (the setting that would allow it): with `sobol` two
    /// white-furnace tests of the untangled estimator failed their noise guard from a few
    /// huge weights (cause not isolated; docs/mcpt.md, "Samplers").
    pub fn from_params(p: &Params, entangled: bool, needs: &str) -> Result<Self, String> {
        let kind = if entangled {
            SAMPLER.get(p)?
        } else {
            SAMPLER.get_or(p, "independent")?
        };
        match kind {
            "independent" => Ok(SamplerKind::Independent),
            _ if !entangled => Err(format!(
                "parameter 'sampler' = \"sobol\" needs {needs} (untangled paths use independent numbers; see docs/mcpt.md, Samplers)"
            )),
            _ => Ok(SamplerKind::Sobol),
        }
    }
}

/// A sample's numbers that split into independent branches: a path traced on as `k`
/// branches from a vertex (MCPT's `branches`) draws branch `j`'s numbers from
/// `branch(j, k)` from there on.
pub trait BranchStream: SampleStream + Clone {
    fn branch(&self, j: u32, k: u32) -> Self;
}

impl BranchStream for Rng {
    /// A fresh PCG32 stream from this one's state and `j`.
    #[inline]
    fn branch(&self, j: u32, _k: u32) -> Self {
        Rng::branch(self, j as u64)
    }
}

impl BranchStream for SobolSampler {
    /// Sample index i·k + j ([`SobolSampler::branch`]): the branches of a pixel's samples
    /// stratify together.
    #[inline]
    fn branch(&self, j: u32, k: u32) -> Self {
        SobolSampler::branch(self, j, k)
    }
}

/// The random numbers of one pixel sample.
pub trait PixelSampler: BranchStream {
    /// The numbers of sample `s` of pixel (`x`, `y`) of a render with seed `seed`.
    fn for_sample(seed: u64, x: u32, y: u32, s: u32) -> Self;
}

impl PixelSampler for Rng {
    /// Stream 0 of `Rng::hash([seed, x, y, s])` (ERPT's chains draw from stream 1 of it).
    #[inline]
    fn for_sample(seed: u64, x: u32, y: u32, s: u32) -> Self {
        Rng::new(Rng::hash(&[seed, x as u64, y as u64, s as u64]), 0)
    }
}

impl PixelSampler for SobolSampler {
    /// Every sample of a pixel shares the pixel's scrambles, so that they stratify together.
    #[inline]
    fn for_sample(seed: u64, x: u32, y: u32, s: u32) -> Self {
        SobolSampler::new(Rng::hash(&[seed, x as u64, y as u64]), s)
    }
}

/// The numbers of sample `s` of pixel (`x`, `y`) and the sample's jittered raster position
/// (its first pair).
#[inline]
pub fn sample_start<S: PixelSampler>(seed: u64, x: u32, y: u32, s: u32) -> (S, Vec2) {
    let mut rng = S::for_sample(seed, x, y, s);
    let raster = Vec2::new(x as f32, y as f32) + rng.uniform2();
    (rng, raster)
}
