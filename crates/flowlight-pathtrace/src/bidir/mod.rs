//! Bidirectional path sampling, shared by the `lighttrace`, `bdpt` and `vcm` plugins: light
//! subpaths ([`light_path`]), camera subpaths and the strategies that join them
//! ([`camera_path`]), their multiple-importance weights ([`mis`]), the merging grid
//! ([`grid`]) and the per-work-unit driver ([`render`]); [`sample`] makes film-wide samples
//! (a whole BDPT sample, or one strategy of a fixed depth) from caller-given number streams
//! for the Metropolis samplers in primary sample space. Both subpaths draw from any
//! [`SampleStream`](flowlight_core::sampler::SampleStream) and scatter with the
//! walker's [`extend`](crate::walk::step::extend) (roulette and BSDF sample), the light side
//! with the adjoint BSDF ([`vertex`]).
//!
//! **Strategies.** A path of k + 1 vertices y₀ (on a light) … x₀ (the eye) is sampled by
//!
//! * s = 0: a camera subpath that hits an emitter or escapes to the environment;
//! * s = 1: a light sample at a camera vertex (next-event estimation);
//! * s ≥ 2, t ≥ 2: a connection between a camera vertex and a vertex of the same pixel
//!   sample's light subpath (Veach 1997 §10.2);
//! * t = 1: a light vertex connected to the eye and splatted at its raster position (light
//!   tracing; [`light_path`]);
//! * merging: a camera vertex and a light vertex of the iteration within radius r, joined
//!   by a density estimate (photon mapping; Georgiev et al. 2012, Hachisuka et al. 2012).
//!
//! [`mis::Techniques`] picks which: light tracing alone, BDPT (no merging), VCM (all) or
//! progressive photon mapping (merging alone). With merging the estimator is biased for a
//! fixed radius and consistent as the radius shrinks: iteration i (the sample index, from 0)
//! merges within
//!
//! ```text
//! r_i = r₀ · (i + 1)^((α − 1)/2),     r₀ = radius × the scene's bounding-sphere radius
//! ```
//!
//! (Knaus & Zwicker 2011; α = 1 keeps r constant). An iteration is one sample index of a
//! work unit: the unit traces one light subpath per pixel, merges with those (N_VM = the
//! unit's pixel count), and each pixel's camera path connects to its own light subpath.
//! Every light subpath also splats to the whole film, so N_LT = W·H light paths per camera
//! sample. The image therefore depends on the tile size (the merging sets do), never on the
//! thread count.
//!
//! **Depths.** A deposit's lighting layer is the number of scattering vertices of its path
//! after the camera's leading Dirac chain, as in MCPT (layer k = paths of virtual length
//! k + 1); `path_depth` caps it. With `strategies`, layer index [`strategy_layer`] (s, t)
//! replaces it: Veach's per-strategy images (his fig. 10.3), for paths of at most
//! `path_depth` + 2 vertices; deposits of longer paths (Dirac chains seen from the eye)
//! land in the image only.

pub mod camera_path;
pub mod grid;
pub mod light_path;
pub mod mis;
pub mod params;
pub mod render;
pub mod sample;
pub mod strategy_seeds;
pub mod vertex;

#[cfg(test)]
mod tests;

use crate::PathSettings;
pub use mis::{Heuristic, Techniques};

/// Settings of a bidirectional render.
#[derive(Clone, Debug)]
pub struct BidirSettings {
    /// Depth caps and the roulette (`path_depth`, `max_ray_depth`, `termination`, `rr_depth`,
    /// `rr_max_survival`), as MCPT reads them.
    pub path: PathSettings,
    pub heuristic: Heuristic,
    pub techniques: Techniques,
    /// Deposits keep their lighting layers (the render writes them).
    pub lighting_layers: bool,
    /// Deposits go to per-strategy layers ([`strategy_layer`]) instead of lighting layers.
    pub strategy_layers: bool,
    /// r₀ as a fraction of the scene's bounding-sphere radius (merging only).
    pub radius: f32,
    /// α of the radius schedule (module docs); 1 keeps the radius constant.
    pub radius_alpha: f32,
    /// Make strategy (s, t) alone ([`sample::FilmSampler::strategy_sample`]): the camera subpath stops
    /// at its t-th vertex and only (s, t)'s contribution is evaluated. `None` for every
    /// strategy the techniques allow.
    pub only_strategy: Option<(u32, u32)>,
}

impl BidirSettings {
    /// Whether deposits keep a layer (lighting or strategy).
    pub fn layers(&self) -> bool {
        self.lighting_layers || self.strategy_layers
    }

    /// Whether strategy (`s`, `t`) is evaluated ([`Self::only_strategy`]).
    #[inline(always)]
    pub fn wants(&self, s: u32, t: u32) -> bool {
        self.only_strategy.is_none_or(|only| only == (s, t))
    }

    /// The merging radius of iteration (sample index) `i` for a scene of bounding-sphere
    /// radius `scene_radius`.
    pub fn radius_at(&self, i: u32, scene_radius: f32) -> f32 {
        let r0 = self.radius * scene_radius;
        r0 * ((i as f32) + 1.0).powf((self.radius_alpha - 1.0) * 0.5)
    }
}

/// The layer index of strategy (s, t): paths of n = s + t vertices take the indices after
/// those of n − 1 vertices, in order of s (0 … n − 1).
pub fn strategy_layer(s: u32, t: u32) -> u32 {
    let n = s + t;
    // Paths of m vertices have m strategies (s = 0 … m − 1); m runs from 2.
    (n - 1) * n / 2 - 1 + s
}

/// The number of per-strategy layers for paths of up to `path_depth` + 2 vertices.
pub fn strategy_layer_count(path_depth: u32) -> u32 {
    let n = path_depth + 2;
    strategy_layer(n - 1, 1) + 1
}
