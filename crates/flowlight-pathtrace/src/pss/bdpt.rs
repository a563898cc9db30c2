//! The BDPT target: one bidirectional sample over the whole film
//! ([`FilmSampler::bdpt_sample`]) as a function of primary samples, PSSMLT over BDPT
//! (Kelemen et al. 2002 ran their chains over a bidirectional sampler too). Two streams:
//! stream 0 feeds the camera subpath (its first pair is the raster position, uniform over
//! the film), stream 1 the light subpath; every strategy's weighted contribution is a splat
//! at its own raster position, the light-tracing ones (t = 1) where their light vertex is
//! seen. A deposit has the units of a `bdpt` pixel sample's ([`crate::bidir::sample`]), so
//! W·H·spp such samples deposit, per pixel, spp times BDPT's pixel value in expectation, as
//! [`super::units`] needs.

use super::chain::{PssTarget, Splat};
use super::samples::PrimarySamples;
use crate::bidir::sample::{FilmSampler, SampleScratch};
use glam::Vec2;

/// BDPT over primary samples (module documentation).
pub struct BdptTarget<'s, 'a, 'b> {
    sampler: &'s FilmSampler<'a, 'b>,
    scratch: SampleScratch,
}

impl<'s, 'a, 'b> BdptTarget<'s, 'a, 'b> {
    /// Samples of `sampler` (its settings' layers: lighting or per-strategy, else layer 0).
    pub fn new(sampler: &'s FilmSampler<'a, 'b>) -> Self {
        BdptTarget {
            sampler,
            scratch: SampleScratch::default(),
        }
    }
}

impl PssTarget for BdptTarget<'_, '_, '_> {
    fn streams(&self) -> u32 {
        2
    }

    fn evaluate(&mut self, samples: &PrimarySamples, splats: &mut Vec<Splat>) {
        splats.clear();
        let (camera, light) = (samples.start_stream(0), samples.start_stream(1));
        let mut push = |raster: Vec2, layer: u32, value| {
            splats.push(Splat {
                raster,
                layer,
                value,
            })
        };
        self.sampler
            .bdpt_sample(camera, light, &mut self.scratch, &mut push);
    }
}
