//! Where a pixel sample's random numbers come from, for the plugins that trace camera paths
//! (MCPT, ERPT's entangled seeds): the `sampler` parameter.
//!
//! Both sources depend only on (render seed, pixel, sample index), so an image does not
//! depend on threads, tiles or distributed parts. See docs/mcpt.md, "Samplers".

use flowlight_core::rng::Rng;
use flowlight_core::sampler::SampleStream;
use flowlight_core::sobol::SobolSampler;
use glam::Vec2;

/// The `sampler` parameter's choices.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SamplerKind {
    /// A PCG32 stream per sample.
    Independent,
    /// Owen-scrambled, shuffled Sobol' points: a pixel's samples stratified together.
    Sobol,
}

/// The random numbers of one pixel sample.
pub trait PixelSampler: SampleStream + Clone {
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
