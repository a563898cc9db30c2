//! Bidirectional samples over the whole film from caller-given number streams: what the
//! Metropolis samplers in primary sample space evaluate (Kelemen et al. 2002 over BDPT;
//! multiplexed MLT, Hachisuka et al. 2014). Each sample reads a camera stream and a light
//! stream, any [`SampleStream`] (a PCG stream, or a view of a Markov chain's primary
//! samples); the camera stream's first pair is the raster position, uniform over the W×H film.
//!
//! **Units.** A deposit has the units of a `bdpt` pixel sample's: the film's pixel j holds
//! I_j = E[Σ deposits of one sample in j] · W·H, since the raster position falls in j with
//! probability 1/(W·H) and a light vertex's eye connection is weighed as one of W·H light
//! paths per sample index ([`super::light_path`]). N samples therefore estimate
//!
//! ```text
//! I_j ≈ (W·H / N) · Σ_{samples} Σ_{deposits in j} value
//! ```
//!
//! The multiple-importance weights are `bdpt`'s ([`super::mis`], N_LT = W·H light paths per
//! W·H pixel samples): one camera ray over the whole film and one light path make the same
//! density ratios as one camera ray per pixel and W·H light paths.
//!
//! * [`FilmSampler::bdpt_sample`]: one light subpath and one camera subpath with `bdpt`'s
//!   roulette and depth caps, every (s, t) strategy, each contribution splatted at its raster
//!   position (the t = 1 ones where their light vertex is seen). PSSMLT over BDPT.
//! * [`FilmSampler::strategy_sample`]: strategy (s, t) alone of a path of d = s + t − 2
//!   interior vertices (pbrt-v4's `MLTIntegrator::L`): (s, t) from one number u,
//!
//!   ```text
//!   s = min(⌊u · (d + 2)⌋, d + 1),   t = d + 2 − s,
//!   ```
//!
//!   a camera subpath of exactly t vertices (the eye included) and a light subpath of
//!   exactly s (the point on the light included; none for s ≤ 1: s = 1 is the camera
//!   vertex's light sample), both without roulette, joined once, weighed by (s, t)'s MIS
//!   weight among the d + 2 strategies of the path and multiplied by d + 2, the inverse of
//!   the uniform choice. Averaged over u, it is the depth-d part of the image:
//!   E\[value\] = Σ_s E[w_{s,t} f / p_{s,t}]. Strategy (1, 1) (a lamp seen through light
//!   tracing) has weight 0 in `bdpt` (the camera sees a lamp by hitting it) and contributes
//!   nothing. The depth d counts every interior vertex, Dirac ones included, as pbrt-v4
//!   does; `bdpt`'s lighting layer skips the camera's leading Dirac chain (the two agree on
//!   scenes the eye sees no mirror or glass in).

use super::camera_path::{CameraCounts, CameraPaths};
use super::light_path::{LightPaths, Splat};
use super::mis::{Heuristic, Iteration, Techniques};
use super::vertex::LightVertex;
use super::{strategy_layer, strategy_layer_count, BidirSettings};
use crate::{PathSettings, SampleContributions, Variant};
use flowlight_core::bsdf::NARROW_GLOSSY_ALPHA;
use flowlight_core::light::emission::scene_sphere;
use flowlight_core::sampler::SampleStream;
use flowlight_core::termination::{TerminationDistribution, TerminationSchedule};
use flowlight_core::Rgb;
use flowlight_sdk::{Scene, Tracer};
use glam::{Vec2, Vec3};

/// The buffers of one thread's samples, reused from sample to sample.
#[derive(Default)]
pub struct SampleScratch {
    vertices: Vec<LightVertex>,
    contributions: SampleContributions,
}

/// The settings of strategy (s, t) alone: the light subpath's (exactly s − 1 surfaces) and
/// the camera subpath's (exactly t − 1 surfaces), both without roulette.
struct StrategySettings {
    light: BidirSettings,
    camera: BidirSettings,
}

/// One chosen strategy's sample ([`FilmSampler::strategy_sample`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StrategySample {
    /// Where it lands on the film (pixels).
    pub raster: Vec2,
    /// w_{s,t} · f / p_{s,t} · (d + 2).
    pub value: Rgb,
}

/// What every film-wide sample of a scene shares that needs no tracer: the settings, the MIS
/// iteration, the scene's sphere, the film and the per-strategy settings. Made once per render
/// (a plugin's `create`), not per work unit: the strategy table holds two settings per strategy
/// of every depth.
pub struct FilmPlan {
    settings: BidirSettings,
    it: Iteration,
    sphere: (Vec3, f32),
    film: Vec2,
    /// Per strategy layer index ([`strategy_layer`]) up to `max_depth`.
    strategies: Vec<StrategySettings>,
}

impl FilmPlan {
    /// The plan of BDPT with `settings` (its heuristic; its depth caps and roulette for
    /// [`FilmSampler::bdpt_sample`]) whose strategy samples reach depths up to `max_depth`.
    pub fn new(scene: &Scene, settings: BidirSettings, max_depth: u32) -> Self {
        let camera = &scene.camera;
        let film_pixels = camera.width as f32 * camera.height as f32;
        let it = Iteration::new(
            settings.heuristic,
            Techniques::BDPT,
            (film_pixels, film_pixels),
            0.0,
            0.0,
        );
        // Layer order: depth by depth, s = 0 … d + 1 within a depth.
        let mut strategies = Vec::with_capacity(strategy_layer_count(max_depth) as usize);
        for d in 0..=max_depth {
            for s in 0..d + 2 {
                debug_assert_eq!(strategy_layer(s, d + 2 - s) as usize, strategies.len());
                strategies.push(strategy_settings(&settings, s, d + 2 - s));
            }
        }
        FilmPlan {
            settings,
            it,
            sphere: scene_sphere(scene.bounds_min, scene.bounds_max),
            film: Vec2::new(camera.width as f32, camera.height as f32),
            strategies,
        }
    }
}

/// Film-wide samples of a scene: its [`FilmPlan`] with the scene and a work unit's tracer.
pub struct FilmSampler<'a, 'b> {
    scene: &'a Scene<'b>,
    tracer: &'a Tracer<'a>,
    plan: &'a FilmPlan,
}

impl<'a, 'b> FilmSampler<'a, 'b> {
    /// The sampler of `plan` (made for `scene`) tracing with `tracer`.
    pub fn new(scene: &'a Scene<'b>, tracer: &'a Tracer<'a>, plan: &'a FilmPlan) -> Self {
        FilmSampler {
            scene,
            tracer,
            plan,
        }
    }

    /// The light subpaths of `settings` (no seed recorder).
    fn light_paths<'s>(&'s self, settings: &'s BidirSettings) -> LightPaths<'s, 'b> {
        LightPaths {
            scene: self.scene,
            tracer: self.tracer,
            settings,
            it: &self.plan.it,
            sphere: self.plan.sphere,
            recorder: None,
        }
    }

    /// The camera subpaths of `settings` (no seed recorder).
    fn camera_paths<'s>(&'s self, settings: &'s BidirSettings) -> CameraPaths<'s, 'b> {
        CameraPaths {
            scene: self.scene,
            tracer: self.tracer,
            settings,
            it: &self.plan.it,
            sphere: self.plan.sphere,
            recorder: None,
        }
    }

    /// The raster position the camera stream's first pair picks: uniform over the film.
    #[inline]
    fn raster(&self, camera: &mut impl SampleStream) -> Vec2 {
        let r = camera.uniform2() * self.plan.film;
        // The pair is < 1, but the product may round up to the film's edge.
        r.min(self.plan.film - self.plan.film * f32::EPSILON)
    }

    /// One BDPT sample (module docs): every strategy's weighted contribution splatted to
    /// `out` at its raster position, in the layer `bdpt` gives it (0 where the settings keep
    /// no layers). Contributions that are not finite are splatted as they are: the caller
    /// decides.
    pub fn bdpt_sample<C: SampleStream, L: SampleStream>(
        &self,
        camera: C,
        light: L,
        scratch: &mut SampleScratch,
        out: &mut impl Splat,
    ) {
        let settings = &self.plan.settings;
        let layers = settings.layers();
        let layer = |l: u32| if layers { l } else { 0 };
        let mut camera = camera;
        let raster = self.raster(&mut camera);
        scratch.vertices.clear();
        let light_paths = self.light_paths(settings);
        let mut splat = |r: Vec2, l: u32, v: Rgb| out.splat(r, layer(l), v);
        light_paths.trace(light, &mut scratch.vertices, &mut splat);
        let camera_paths = self.camera_paths(settings);
        let contributions = &mut scratch.contributions;
        contributions.clear();
        let mut counts = CameraCounts::default();
        let own = &scratch.vertices;
        camera_paths.trace(camera, raster, own, None, contributions, &mut counts);
        for &(l, value) in &contributions.entries {
            out.splat(raster, layer(l), value);
        }
    }

    /// Strategy (s, t) of depth `depth` ≤ the sampler's `max_depth`, chosen by `u_strategy`
    /// (module docs); `None` where it contributes nothing. The camera stream's first pair is
    /// the raster position whatever the strategy, so that a chain's camera numbers keep
    /// their meaning when its strategy changes.
    pub fn strategy_sample<C: SampleStream, L: SampleStream>(
        &self,
        depth: u32,
        u_strategy: f32,
        camera: C,
        light: L,
        scratch: &mut SampleScratch,
    ) -> Option<StrategySample> {
        let (s, t) = strategy_of(depth, u_strategy);
        let strategy = &self.plan.strategies[strategy_layer(s, t) as usize];
        let mut camera = camera;
        let raster = self.raster(&mut camera);
        scratch.vertices.clear();
        let mut found: Option<(Vec2, Rgb)> = None;
        if s >= 2 {
            let light_paths = self.light_paths(&strategy.light);
            let mut splat = |r: Vec2, _: u32, v: Rgb| found = Some((r, v));
            light_paths.trace(light, &mut scratch.vertices, &mut splat);
            if scratch.vertices.last().is_none_or(|y| y.length != s - 1) {
                // The light subpath ended before its s-th vertex (or that vertex is
                // Dirac): nothing joins it.
                return found.map(|(raster, v)| self.scaled(depth, raster, v));
            }
        }
        if t >= 2 {
            let camera_paths = self.camera_paths(&strategy.camera);
            let contributions = &mut scratch.contributions;
            contributions.clear();
            let mut counts = CameraCounts::default();
            let own = &scratch.vertices[scratch.vertices.len().saturating_sub(1)..];
            camera_paths.trace(camera, raster, own, None, contributions, &mut counts);
            found = contributions.entries.first().map(|&(_, v)| (raster, v));
        }
        found.map(|(raster, v)| self.scaled(depth, raster, v))
    }

    #[inline]
    fn scaled(&self, depth: u32, raster: Vec2, value: Rgb) -> StrategySample {
        StrategySample {
            raster,
            value: value * (depth + 2) as f32,
        }
    }
}

/// The settings of a sampler used for strategy samples alone ([`FilmSampler::strategy_sample`]
/// overrides their depths and roulette): `heuristic`, no layers.
pub fn strategy_only_settings(heuristic: Heuristic) -> BidirSettings {
    BidirSettings {
        path: PathSettings {
            variant: Variant::Entangled,
            path_depth: 1,
            max_ray_depth: 1,
            termination: TerminationSchedule::new(TerminationDistribution::Throughput, 1),
            narrow_glossy_alpha: NARROW_GLOSSY_ALPHA,
            branches: 1,
        },
        heuristic,
        techniques: Techniques::BDPT,
        lighting_layers: false,
        strategy_layers: false,
        radius: 0.0,
        radius_alpha: 1.0,
        only_strategy: None,
    }
}

/// The strategy (s, t) that `u` ∈ [0, 1) picks among the d + 2 of depth `depth`.
#[inline]
pub fn strategy_of(depth: u32, u: f32) -> (u32, u32) {
    let n = depth + 2;
    let s = ((u * n as f32) as u32).min(n - 1);
    (s, n - s)
}

/// The settings of strategy (s, t) alone, from `base` (its heuristic).
fn strategy_settings(base: &BidirSettings, s: u32, t: u32) -> StrategySettings {
    let depth = s + t - 2;
    // No roulette: the throughput rule never stops before its start depth, and the
    // schedule's depth lies beyond every vertex of the path.
    let termination = TerminationSchedule::new(TerminationDistribution::Throughput, depth + 3)
        .with_roulette(u32::MAX, 1.0);
    let mut camera = base.clone();
    camera.path.termination = termination;
    camera.path.path_depth = depth;
    camera.path.max_ray_depth = depth + 1;
    camera.techniques = Techniques::BDPT;
    camera.lighting_layers = false;
    camera.strategy_layers = false;
    camera.only_strategy = Some((s, t));
    let mut light = camera.clone();
    // The light subpath stops at its (s − 1)-th surface.
    light.path.path_depth = s.saturating_sub(1).max(1);
    light.path.max_ray_depth = s.saturating_sub(1).max(1);
    StrategySettings { light, camera }
}
