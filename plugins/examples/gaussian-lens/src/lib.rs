//! # `gaussian-lens` — a Gaussian lens perturbation on the regeneration engine (example plugin)
//!
//! An example mutation built on `flowlight-mcmc`'s regeneration engine, the crate every
//! in-tree strategy is made of: the plugin brings only its own move of the raster position
//! (a [`RasterMove`]) and the engine does the rest — it follows the new eye ray through the
//! path's Dirac (mirror, glass) vertices with x's lobe kinds, reconnects the first smooth
//! vertex y_k to x_{k+1} by a shadow ray (y keeps x_{k+1} … xₙ), and returns the proposal with
//! its transition ratio, and the density T for mixtures (thesis §5.4; Veach 1997 §11.4.3 for
//! the lens perturbation this varies).
//!
//! **The move.** The raster position u jumps by d ~ N(0, σ² I), truncated to the chain's
//! K × K film window (|d|∞ ≤ K/2, so that deposits stay within ERPT's flange) and to the film:
//!
//! ```text
//! T(u → u') = exp(−|u' − u|² / 2σ²) / (2πσ²)   if |u' − u|∞ ≤ K/2 and u' is on the film
//! ```
//!
//! (a jump outside is a domain miss). T depends on |u' − u| alone and both conditions are
//! symmetric for two points on the film, so T(u → u') = T(u' → u): the engine's rule for a
//! [`RasterMove`], which leaves the film term out of the ratio. The rest of the proposal is
//! the engine's strict reconnection, a Dirac step both ways: the ratio is 1 up to the
//! engine's free-chain bookkeeping.
//!
//! It counts its proposals and its misses (`gaussian-lens.proposals`, `gaussian-lens.misses`
//! in the render's statistics).
//!
//! | name | type | default | meaning |
//! |---|---|---|---|
//! | `sigma` | float | 1 | standard deviation σ of the jump, in pixels |

use flowlight_mcmc::regenerate::{density_with, propose_with};
use flowlight_mcmc::{Policy, RasterMove};
use flowlight_sdk::core::path::Path;
use flowlight_sdk::core::rng::Rng;
use flowlight_sdk::core::Vec2;
use flowlight_sdk::stats::{Counter, Stats, StatsBuilder};
use flowlight_sdk::{export_mutation, param, Mutation, ParamKind, ParamSpec, Params, Proposal};
use flowlight_sdk::{Scene, Tracer};

/// Float slack (pixels) of the window test in [`RasterMove::density`]: a sampled jump may
/// land a rounding error outside the exact window and must keep a positive density.
const SLACK: f32 = 1e-3;

// region: kernel
/// The Gaussian jump of the raster position (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaussianJump {
    /// Standard deviation σ, pixels.
    pub sigma: f32,
}

impl RasterMove for GaussianJump {
    fn sample(&self, x: &Path, width: u32, height: u32, rng: &mut Rng) -> Option<Vec2> {
        // Box–Muller: two independent normal deviates from two uniforms.
        let [u1, u2] = rng.uniform2().to_array();
        let r = (-2.0 * (1.0 - u1).ln()).sqrt() * self.sigma;
        let (s, c) = (std::f32::consts::TAU * u2).sin_cos();
        let d = Vec2::new(r * c, r * s);
        let to = x.raster + d;
        let inside = d.abs().max_element() <= x.film_window as f32 / 2.0;
        (inside && on_film(to, width, height)).then_some(to)
    }

    fn density(&self, x: &Path, y: &Path, width: u32, height: u32) -> f64 {
        let d = y.raster - x.raster;
        if d.abs().max_element() > x.film_window as f32 / 2.0 + SLACK
            || !on_film(y.raster, width, height)
        {
            return 0.0;
        }
        let s2 = self.sigma as f64 * self.sigma as f64;
        (-(d.length_squared() as f64) / (2.0 * s2)).exp() / (std::f64::consts::TAU * s2)
    }
}
// endregion: kernel

fn on_film(p: Vec2, width: u32, height: u32) -> bool {
    p.x >= 0.0 && p.y >= 0.0 && p.x < width as f32 && p.y < height as f32
}

// region: mutation
/// The mutation: the jump, the engine policy it runs with and its counters.
pub struct GaussianLens {
    scene: Scene<'static>,
    jump: GaussianJump,
    policy: Policy,
    proposals: Counter,
    misses: Counter,
}

impl Mutation for GaussianLens {
    const NAME: &'static str = "gaussian-lens";
    const DESCRIPTION: &'static str =
        "example: Gaussian raster jump, Dirac chain followed, reconnect (regeneration engine)";
    const PARAMS: &'static [ParamSpec] = &[param(
        "sigma",
        ParamKind::Float,
        "1",
        "standard deviation of the jump, in pixels",
    )];

    fn create(p: &Params, scene: Scene<'static>, stats: &mut StatsBuilder) -> Result<Self, String> {
        let sigma = p.float("sigma", 1.0)?;
        if !(sigma > 0.0 && sigma <= 1024.0) {
            return Err(format!(
                "parameter 'sigma' must be in (0, 1024] pixels, got {sigma}"
            ));
        }
        // The lens perturbation's eye end: follow the Dirac chain, reconnect at once.
        let policy = Policy {
            min_extensions: 0,
            p_reconnect: 1.0,
            extension: None,
            drill_caustics: false,
            free_chains: true,
        };
        let (proposals, misses) = (stats.sum("proposals"), stats.sum("misses"));
        let jump = GaussianJump {
            sigma: sigma as f32,
        };
        Ok(GaussianLens {
            scene,
            jump,
            policy,
            proposals,
            misses,
        })
    }

    fn propose(
        &self,
        tracer: &Tracer,
        rng: &mut Rng,
        x: &Path,
        y: &mut Path,
        stats: &mut Stats,
    ) -> Result<Proposal, String> {
        let p = propose_with(&self.scene, tracer, rng, &self.policy, self.jump, x, y);
        stats.add(self.proposals, 1.0);
        stats.add(self.misses, (p == Proposal::Miss) as u32 as f64);
        Ok(p)
    }

    fn density(&self, from: &Path, to: &Path) -> f64 {
        density_with(&self.scene, &self.policy, self.jump, from, to)
    }
}

export_mutation!(GaussianLens);
// endregion: mutation

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_library_is_named_after_the_plugin() {
        let expected = format!("flowlight_{}", GaussianLens::NAME.replace('-', "_"));
        assert_eq!(env!("CARGO_CRATE_NAME"), expected);
    }

    fn at(raster: Vec2, film_window: u32) -> Path {
        let mut p = Path::empty();
        p.raster = raster;
        p.film_window = film_window;
        p
    }

    #[test]
    fn the_jump_is_a_truncated_gaussian_and_symmetric() {
        let jump = GaussianJump { sigma: 1.5 };
        let mut rng = Rng::new(11, 3);
        let x = at(Vec2::new(30.3, 20.7), 8);
        let (trials, mut kept, mut within_sigma) = (40_000, 0, 0);
        for _ in 0..trials {
            let Some(u) = jump.sample(&x, 64, 64, &mut rng) else {
                continue;
            };
            kept += 1;
            let y = at(u, 8);
            let d = jump.density(&x, &y, 64, 64);
            assert!(d > 0.0, "sampled {u} but density 0");
            assert_eq!(d, jump.density(&y, &x, 64, 64), "symmetric");
            within_sigma += ((u - x.raster).abs().max_element() <= 1.5) as u32;
        }
        // P(|d|∞ ≤ 4) for σ = 1.5: (2Φ(4/1.5) − 1)² = 0.9847; P(|d|∞ ≤ σ) = 0.6827² = 0.4661.
        let kept_share = kept as f64 / trials as f64;
        assert!((kept_share - 0.9847).abs() < 0.005, "{kept_share}");
        let share = within_sigma as f64 / trials as f64;
        assert!((share - 0.4661).abs() < 0.01, "{share}");
        // Outside the window or off the film: no density.
        assert_eq!(jump.density(&x, &at(Vec2::new(34.4, 20.7), 8), 64, 64), 0.0);
        assert_eq!(jump.density(&x, &at(Vec2::new(30.3, 64.5), 8), 64, 64), 0.0);
    }
}
