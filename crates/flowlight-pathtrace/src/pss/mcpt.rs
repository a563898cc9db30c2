//! The MCPT target: one entangled path-tracing camera sample ([`crate::entangled::trace`])
//! as a function of primary samples (one stream). The stream's first pair is the raster
//! position over the whole film, (u₁·W, u₂·H); the path draws the numbers after it. Every
//! contribution is splatted at that raster position, per lighting layer when the plugin
//! writes layers, else summed into layer 0, as MCPT deposits them. Over uniform numbers the
//! raster position is uniform on the film, so W·H·spp such samples deposit, per pixel, spp
//! times MCPT's pixel value in expectation.

use super::chain::{PssTarget, Splat};
use super::samples::PrimarySamples;
use crate::settings::PathSettings;
use crate::{entangled, SampleContributions};
use flowlight_core::sampler::SampleStream;
use flowlight_sdk::{Scene, Tracer};
use glam::Vec2;

/// Entangled MCPT over primary samples (module documentation).
pub struct McptTarget<'a> {
    scene: &'a Scene<'a>,
    tracer: &'a Tracer<'a>,
    settings: &'a PathSettings,
    layers: bool,
    contributions: SampleContributions,
}

impl<'a> McptTarget<'a> {
    /// Paths of `settings` through `scene`; `layers`: one splat per lighting layer (else
    /// their sum in layer 0).
    pub fn new(
        scene: &'a Scene<'a>,
        tracer: &'a Tracer<'a>,
        settings: &'a PathSettings,
        layers: bool,
    ) -> Self {
        McptTarget {
            scene,
            tracer,
            settings,
            layers,
            contributions: SampleContributions::default(),
        }
    }
}

/// The raster position of the film point `u` ∈ [0, 1)² on a `width` × `height` film,
/// kept inside the film where u·W rounds up to W.
pub fn film_point(u: Vec2, width: u32, height: u32) -> Vec2 {
    let below = |n: u32| f32::from_bits((n as f32).to_bits() - 1);
    Vec2::new(
        (u.x * width as f32).min(below(width)),
        (u.y * height as f32).min(below(height)),
    )
}

impl PssTarget for McptTarget<'_> {
    fn streams(&self) -> u32 {
        1
    }

    fn evaluate(&mut self, samples: &PrimarySamples, splats: &mut Vec<Splat>) {
        splats.clear();
        let camera = &self.scene.camera;
        let mut stream = samples.start_stream(0);
        let raster = film_point(stream.uniform2(), camera.width, camera.height);
        self.contributions.clear();
        entangled::trace(
            self.scene,
            self.tracer,
            self.settings,
            &stream,
            raster,
            &mut self.contributions,
        );
        if self.layers {
            splats.extend(
                self.contributions
                    .entries
                    .iter()
                    .map(|&(layer, value)| Splat {
                        raster,
                        layer,
                        value,
                    }),
            );
        } else if !self.contributions.entries.is_empty() {
            splats.push(Splat {
                raster,
                layer: 0,
                value: self.contributions.total(),
            });
        }
    }
}
