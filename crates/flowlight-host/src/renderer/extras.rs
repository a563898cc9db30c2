//! What a render writes beside the beauty: the AOV layers of the host's AOV pass
//! ([`crate::aov`]) and the denoised layer ([`crate::denoise`]).

use super::Renderer;
use crate::aov::{render_aovs, AovImages, AovRequest};
use crate::error::HostError;
use flowlight_scene::config::Aov;
use std::sync::atomic::AtomicBool;

/// Layers added to the EXR after the beauty and its lighting layers.
#[derive(Default)]
pub struct ExtraLayers {
    /// The AOVs, written as layers named after them (`albedo`, `normal`, …).
    pub aovs: Option<AovImages>,
    /// The denoised beauty (planar r, g, b), written as the layer `denoised`; the PNG
    /// preview is made from it.
    pub denoised: Option<[Vec<f32>; 3]>,
    /// The denoiser and where it was found, for the EXR's `flowlight.denoiser`.
    pub denoiser: Option<String>,
}

impl Renderer {
    /// The AOV pass this render runs: the config's `[output] aovs`, plus albedo and normal
    /// when `denoise` (the denoiser's guides); `None` when there is nothing to compute.
    pub fn aov_request(&self, denoise: bool) -> Option<AovRequest> {
        let mut aovs = self.config.aovs.clone();
        if denoise {
            for a in [Aov::Albedo, Aov::Normal] {
                if !aovs.contains(&a) {
                    aovs.push(a);
                }
            }
            aovs.sort();
        }
        (!aovs.is_empty()).then_some(AovRequest {
            aovs,
            spp: self.config.aov_spp,
            seed: self.options.seed,
            threads: self.options.threads,
        })
    }

    /// Runs the AOV pass of `req` over this render's scene and camera.
    pub fn render_aovs(&self, req: &AovRequest, stop: &AtomicBool) -> Result<AovImages, HostError> {
        render_aovs(
            &self.scene,
            self.intersector.as_ref(),
            &self.camera,
            req,
            stop,
        )
        .map_err(HostError::Render)
    }
}
