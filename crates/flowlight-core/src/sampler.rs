//! Where a path's random numbers come from: a stream of uniform numbers in [0, 1).
//!
//! Two sources implement [`SampleStream`]:
//!
//! * [`crate::rng::Rng`], PCG32: independent numbers; what the Markov chains and every test
//!   that needs independence use;
//! * [`crate::sobol::SobolSampler`]: randomised quasi-Monte Carlo, the samples of one pixel
//!   stratified against each other dimension by dimension (Sobol' points of a shuffled index, digitally shifted).
//!
//! A path tracer asks for numbers in the same order from either. It also says which decision
//! each draw is for ([`SampleStream::seek`]: vertex and slot), so that a stratified source
//! gives the same decision at the same vertex the same dimension in every sample of a pixel,
//! even where another sample drew fewer numbers before it (a Dirac vertex has no light
//! sample, a roulette number is drawn only from `rr_depth` on); an independent source
//! ignores it, so its numbers (and images) do not change.

use crate::rng::Rng;
use glam::Vec2;

/// A source of uniform numbers in [0, 1) for one path sample.
pub trait SampleStream {
    /// The next number.
    fn uniform(&mut self) -> f32;

    /// The next pair, meant to be used together (a point on a square): a stratified source
    /// stratifies the pair in two dimensions.
    fn uniform2(&mut self) -> Vec2;

    /// The path is about to draw the numbers of `slot` (one of the `SLOT_*` constants) at
    /// its `vertex`-th scattering vertex (1 for the first surface hit): a stratified source
    /// moves to the dimension it reserves for them. Dimensions only move forward, so numbers
    /// are never reused whatever the order of calls; this only improves stratification. An
    /// independent source ignores it.
    #[inline]
    fn seek(&mut self, _vertex: u32, _slot: u32) {}

    /// The pair [`SampleStream::uniform2`] will return at `slot` of `vertex` if the draws
    /// before it stay within their own slots (at the dimension [`SampleStream::seek`]`(vertex,
    /// slot)` moves to from here), computed now: a source whose numbers are a function of
    /// their dimension can give it before the path gets there, so that its arithmetic runs
    /// beside the work in between instead of after it. `None` for a sequential source,
    /// whose numbers depend on the draws before.
    #[inline]
    fn pair_ahead(&self, _vertex: u32, _slot: u32) -> Option<PairAhead> {
        None
    }

    /// [`SampleStream::uniform2`], taking `ahead`'s value where it is the value of this
    /// draw (its key), else drawing as usual: the same number either way.
    #[inline]
    fn uniform2_ahead(&mut self, ahead: Option<PairAhead>) -> Vec2 {
        let _ = ahead;
        self.uniform2()
    }
}

/// A pair computed before its turn ([`SampleStream::pair_ahead`]): its value, and which draw
/// it is the value of in the stream's own terms, so that the stream takes it back only for
/// that draw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairAhead {
    /// The draw (for [`crate::sobol::SobolSampler`]: its sample index and dimension).
    pub key: u64,
    pub value: Vec2,
}

/// The numbers a path vertex draws, in order, as dimension slots of [`SampleStream::seek`]:
/// the light sample (one pair: the light's choice and the point on it,
/// [`crate::light::Lights::sample`]) ...
pub const SLOT_LIGHT: u32 = 0;
/// ... the roulette (one number) ...
pub const SLOT_ROULETTE: u32 = 1;
/// ... and the BSDF's: a lobe's own discrete choice (one number: a dielectric's reflect or
/// refract) and the component and direction (a pair, [`crate::bsdf::Bsdf::sample`]).
pub const SLOT_BSDF: u32 = 2;
/// The slot of the BSDF's pair, after its one number at [`SLOT_BSDF`] (the order in which
/// [`crate::bsdf::Bsdf::sample`]'s arguments are drawn).
pub const SLOT_BSDF_PAIR: u32 = SLOT_BSDF + 1;
/// Slots reserved per vertex. The camera's raster position is dimension 0.
pub const DIMS_PER_VERTEX: u32 = 4;

impl SampleStream for Rng {
    #[inline]
    fn uniform(&mut self) -> f32 {
        Rng::uniform(self)
    }

    #[inline]
    fn uniform2(&mut self) -> Vec2 {
        Rng::uniform2(self)
    }
}
